"""Live link to a Water Linked DVL A50 over its TCP JSON protocol.

The A50 serves one JSON object per line on TCP port 16171 (Water Linked DVL protocol
documentation, "JSON protocol over TCP"): velocity reports (json_v1 without ``type``, json_v2/v3
with ``type: "velocity"``, ``covariance`` and ``time_of_validity`` in Unix us),
``position_local`` dead-reckoning reports (``ts`` s, ``x y z`` m, roll/pitch/yaw in degrees) and
``type: "response"`` answers to commands (``{"command": "get_config"}`` and the others). Each
line is decoded by the same functions as the offline reader (:mod:`undertow.io.a50_json`), so a
live report and a logged one give the same numbers.

Times: a velocity report's sensor time is ``time_of_validity`` (us -> s), a position report's its
``ts``; json_v1 reports have none and are stamped on arrival. The link's
:class:`~undertow.live.links.base.ClockPolicy` decides (trust the sensor clock when it agrees with
arrival within ``max_offset_s``, else shift it by a recorded offset). Exact duplicate lines are
dropped and counted; undecodable lines (broken JSON, absurd values, lines longer than
``MAX_LINE_BYTES``) are counted as malformed; neither ever stops the link.

``deferred`` (the live session's choice): the link's thread only receives the bytes and takes
their arrival time, calling ``wake``; :meth:`A50TcpLink.pump`, called by the consumer's loop,
splits and decodes them and delivers the records from that thread (the decoding then runs in
the thread that uses the records; records, times and counters are those of the immediate mode).
"""

from __future__ import annotations

import json
import math
import socket
import time
from typing import Any

import numpy as np

from ...io.a50_json import is_position_report, is_velocity_report, position_fields, velocity_fields
from ...io.collect import MALFORMED
from ...records import Record
from .base import Backoff, ClockPolicy, Link, LinkCounters

DEFAULT_PORT = 16171
#: longest line accepted (a velocity report is about 1 kB); longer ones are dropped as malformed
MAX_LINE_BYTES = 64 * 1024
MAX_RESPONSES = 100


class A50LineDecoder:
    """Decodes A50 JSON lines into records (velocity -> ``dvl``, ``position_local`` ->
    ``dead_reckoning``), stamping them with ``clock`` and counting into ``counters``; command
    responses are kept in :attr:`responses` (the last ``MAX_RESPONSES``)."""

    def __init__(self, counters: LinkCounters, clock: ClockPolicy, source: str = "a50") -> None:
        self.counters = counters
        self.clock = clock
        self.source = source
        self.responses: list[dict] = []
        self.formats: set[str] = set()

    def decode(self, line: bytes | str, arrival: float) -> list[Record]:
        """The records of one line (none for blank lines, responses, or what is dropped)."""
        text = line.decode("utf-8", errors="replace") if isinstance(line, bytes) else line
        text = text.strip()
        if not text:
            return []
        self.counters.received += 1
        try:
            with np.errstate(all="ignore"):
                return self._decode(text, arrival)
        except MALFORMED:
            self.counters.malformed += 1
            return []

    def _decode(self, text: str, arrival: float) -> list[Record]:
        obj = json.loads(text)
        if not isinstance(obj, dict):
            raise ValueError("not a JSON object")
        if obj.get("type") == "response":
            self.responses = [*self.responses[-(MAX_RESPONSES - 1) :], obj]
            return []
        if is_position_report(obj):
            data, ts = position_fields(obj)
            return self._stamped("dead_reckoning", data, arrival, ts, text)
        if is_velocity_report(obj):
            fields, tov = velocity_fields(obj)
            self.formats.add(str(obj.get("format", "json_v1")))
            return self._stamped("dvl", fields, arrival, tov, text)
        if "type" not in obj:
            raise ValueError("not a DVL report")
        return []  # another report type of a newer protocol: ignored

    def _stamped(self, stream, data, arrival, sensor_time, key) -> list[Record]:
        sensor = sensor_time if math.isfinite(sensor_time) else None
        t = self.clock.stamp(stream, arrival, sensor, key=key)
        if t is None:
            return []
        st = sensor if sensor is not None else math.nan
        return [Record(stream, t, data, arrival, st, self.source)]


class LineBuffer:
    """Splits a byte stream into lines; a line longer than ``MAX_LINE_BYTES`` is discarded and
    counted as malformed, so memory stays bounded whatever the peer sends."""

    def __init__(self, counters: LinkCounters, max_bytes: int = MAX_LINE_BYTES) -> None:
        self.counters = counters
        self.max_bytes = max_bytes
        self.pending = b""
        self.discarding = False

    def feed(self, chunk: bytes) -> list[bytes]:
        *lines, rest = (self.pending + chunk).split(b"\n")
        if self.discarding and lines:  # the end of an over-long line
            lines = lines[1:]
            self.discarding = False
        out = []
        for line in lines:
            if len(line) > self.max_bytes:
                self._overflow()
            else:
                out.append(line)
        if len(rest) > self.max_bytes:
            if not self.discarding:
                self._overflow()
            self.discarding, rest = True, b""
        self.pending = rest
        return out

    def _overflow(self) -> None:
        self.counters.received += 1
        self.counters.malformed += 1


def command_line(command: str, **parameters) -> bytes:
    """A JSON command line, e.g. ``{"command": "get_config"}``."""
    obj: dict[str, Any] = {"command": command}
    if parameters:
        obj["parameters"] = parameters
    return (json.dumps(obj) + "\n").encode()


class A50TcpLink(Link):
    """Client of the A50 TCP JSON protocol, reconnecting after drops (see :class:`Link`).

    ``get_config`` is sent after every connection (its response is in ``info['config']``);
    ``reset_dead_reckoning`` and ``calibrate_gyro`` only when asked, once, after the first
    connection. A connection silent for ``idle_timeout_s`` is treated as dropped. ``clock``
    defaults to :class:`ClockPolicy` with ``max_offset_s``.
    """

    name = "a50_tcp"

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_PORT,
        callback=None,
        *,
        get_config: bool = True,
        reset_dead_reckoning: bool = False,
        calibrate_gyro: bool = False,
        connect_timeout_s: float = 2.0,
        idle_timeout_s: float = 5.0,
        max_offset_s: float = 1.0,
        clock: ClockPolicy | None = None,
        backoff: Backoff | None = None,
        max_queue: int = 10_000,
        now=None,
        deferred: bool = False,
        wake=None,
    ) -> None:
        counters = LinkCounters()
        clock = clock or ClockPolicy(counters, max_offset_s=max_offset_s)
        super().__init__(callback, backoff=backoff, max_queue=max_queue, clock=clock, now=now)
        self.host, self.port = host, int(port)
        self.source = f"tcp://{host}:{self.port}"
        self.decoder = A50LineDecoder(self.counters, self.clock, self.source)
        self.get_config = get_config
        self._once = [
            c
            for c, on in (
                ("reset_dead_reckoning", reset_dead_reckoning),
                ("calibrate_gyro", calibrate_gyro),
            )
            if on
        ]
        self.connect_timeout_s = connect_timeout_s
        self.idle_timeout_s = idle_timeout_s
        self._sock: socket.socket | None = None
        self.deferred = bool(deferred)
        self.wake = wake
        self._pump_lines: tuple[object, LineBuffer] | None = None  # (session, its lines)

    @property
    def responses(self) -> list[dict]:
        return self.decoder.responses

    def _connect(self):
        sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout_s)
        sock.settimeout(0.25)
        self._sock = sock
        commands = (["get_config"] if self.get_config else []) + self._once
        self._once = []
        if commands:
            sock.sendall(b"".join(command_line(c) for c in commands))
        return sock

    def _interrupt(self) -> None:
        sock = self._sock
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def _run_session(self, sock: socket.socket) -> None:
        session = object()  # deferred: pump() keeps a line buffer of its own per connection
        lines = None if self.deferred else LineBuffer(self.counters)
        last = time.monotonic()
        while not self.stopping:
            try:
                chunk = sock.recv(65536)
            except TimeoutError:
                if time.monotonic() - last > self.idle_timeout_s:
                    raise OSError(f"no data for {self.idle_timeout_s} s") from None
                continue
            if not chunk:
                return  # closed by the sensor
            last = time.monotonic()
            arrival = self.now()
            if not self.deferred:
                self._decode(lines, chunk, arrival)
                continue
            self._defer((session, arrival, chunk))
            if self.wake is not None:
                self.wake()

    def pump(self) -> None:
        """Split and decode the bytes the thread queued (``deferred``); deliver the records."""
        raw = self._raw
        while raw:
            session, arrival, chunk = raw.popleft()
            if self._pump_lines is None or self._pump_lines[0] is not session:
                self._pump_lines = (session, LineBuffer(self.counters))
            self._decode(self._pump_lines[1], chunk, arrival)

    def _decode(self, lines: LineBuffer, chunk: bytes, arrival: float) -> None:
        for line in lines.feed(chunk):
            for record in self.decoder.decode(line, arrival):
                self._emit(record)
        self._note_config()

    def _note_config(self) -> None:
        for response in reversed(self.decoder.responses):
            if response.get("response_to") == "get_config":
                self.info["config"] = response.get("result")
                return
