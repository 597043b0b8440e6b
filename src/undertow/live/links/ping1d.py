"""Live link to a Blue Robotics Ping1D echosounder through ``bluerobotics-ping`` (``brping``).

The Ping protocol (Blue Robotics ping-protocol; frames ``BR``, payload length, message id,
source and destination ids, payload, 16-bit sum checksum) is spoken by ``brping.Ping1D`` over a
serial device (``connect_serial``, 115200 baud) or UDP (``connect_udp``; BlueOS shares the Ping
of a BlueROV2 on UDP port 9090). The link polls the ``distance`` message (id 1212) at
``rate_hz``: ``distance`` (mm) -> range r = 1e-3 distance (m), ``confidence`` (%) -> 0..1
(NaN when above 100), plus ``ping_number`` (a report repeated with the same ping number, polled
faster than the sonar pings, is dropped as a duplicate), read by
:func:`undertow.io.ping.distance_data`.

Time: the Ping has no clock in its messages; each range is stamped with its arrival time on this
machine (``time.time()``), which lags the acoustic measurement by the transmit duration, the
processing and the transport (a few ms on a tether; see docs/live.md).
"""

from __future__ import annotations

import contextlib
import io
import math
import select
import socket
import time

from ...errors import ConfigError
from ...io.ping import PING1D_DISTANCE, distance_data, load_brping
from ...records import Record
from .base import Backoff, ClockPolicy, Link, LinkCounters

DEFAULT_UDP_PORT = 9090

_QUIET = None


def _quiet_ping1d():
    """``brping.Ping1D`` without its prints: UDP connection opened silently, unrecognized
    messages counted in ``unrecognized`` instead of printed."""
    global _QUIET
    if _QUIET is None:
        brping, _, _ = load_brping()

        class QuietPing1D(brping.Ping1D):
            unrecognized = 0

            def connect_udp(self, host: str = None, port: int = 12345):
                self.server_address = (host or "0.0.0.0", port)
                self.iodev = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                self.iodev.connect(self.server_address)
                self.iodev.setblocking(False)

            def wait_message(self, message_ids, timeout=0.5):
                """brping's, over UDP waiting for the socket to be readable (``select``)
                instead of reading every 5 ms: the reply is taken, and stamped, as it comes,
                without the polls in between."""
                if not isinstance(self.iodev, socket.socket):
                    return super().wait_message(message_ids, timeout)
                deadline = time.monotonic() + timeout
                while True:
                    msg = self.read()
                    if msg is not None and msg.message_id in message_ids:
                        return msg
                    if msg is not None or len(self._input_buffer):
                        continue  # more to parse in what was read
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        return None
                    try:
                        select.select([self.iodev], [], [], remaining)
                    except ValueError:  # (closed: its descriptor is -1)
                        raise OSError("Ping1D socket closed") from None

            def handle_message(self, msg):
                if not hasattr(msg, "payload_field_names"):
                    self.unrecognized += 1
                    return False
                for attr in msg.payload_field_names:
                    setattr(self, "_" + attr, getattr(msg, attr, None))
                return True

        _QUIET = QuietPing1D
    return _QUIET


def parse_device(device: str) -> tuple[str, str, int]:
    """('udp', host, port) for ``udp://HOST:PORT`` or ``HOST:PORT``; ('serial', path, baud) for a
    device path, optionally ``serial:///dev/ttyUSB0?baud=115200``."""
    text = str(device).strip()
    if text.startswith("udp://") or (":" in text and not text.startswith(("/", "serial:"))):
        host, _, port = text.removeprefix("udp://").rpartition(":")
        try:
            number = int(port)
        except ValueError:
            number = -1
        if not host or not 0 < number < 65536:
            raise ConfigError(f"ping device '{device}': expected udp://HOST:PORT")
        return "udp", host, number
    path, _, query = text.removeprefix("serial://").partition("?baud=")
    if not path:
        raise ConfigError(
            f"ping device '{device}': expected a serial device path or udp://HOST:PORT"
        )
    try:
        baud = int(query) if query else 115200
    except ValueError:
        raise ConfigError(f"ping device '{device}': baud must be an integer") from None
    return "serial", path, baud


class Ping1DLink(Link):
    """Polls a Ping1D's distance through ``brping.Ping1D`` (see the module docstring); the
    connection is re-opened with backoff after ``max_timeouts`` unanswered requests in a row.
    """

    name = "ping1d"

    def __init__(
        self,
        device: str,
        callback=None,
        *,
        rate_hz: float = 10.0,
        request_timeout_s: float = 0.5,
        max_timeouts: int = 5,
        backoff: Backoff | None = None,
        max_queue: int = 10_000,
        now=None,
    ) -> None:
        if not 0 < rate_hz <= 100:
            raise ConfigError("ping rate_hz: expected 0 < rate <= 100")
        counters = LinkCounters()
        super().__init__(
            callback, backoff=backoff, max_queue=max_queue, clock=ClockPolicy(counters), now=now
        )
        self.kind, self.address, self.port_or_baud = parse_device(device)
        self.source = str(device)
        self.rate_hz = float(rate_hz)
        self.request_timeout_s = float(request_timeout_s)
        self.max_timeouts = int(max_timeouts)
        self.timeouts = 0
        self._device = None

    def load(self) -> None:
        load_brping()

    def _connect(self):
        device = _quiet_ping1d()()
        try:
            if self.kind == "udp":
                device.connect_udp(self.address, self.port_or_baud)
            else:
                with contextlib.redirect_stdout(io.StringIO()):  # brping prints "Opening ..."
                    device.connect_serial(self.address, self.port_or_baud)
        except Exception as exc:  # brping wraps every failure in a bare Exception
            raise OSError(str(exc)) from None
        if not device.initialize():
            self._close_device(device)
            raise OSError(f"no answer from a Ping1D at {self.source}")
        self._device = device
        return device

    @staticmethod
    def _close_device(device) -> None:
        iodev = getattr(device, "iodev", None)
        if iodev is not None:
            try:
                iodev.close()
            except OSError:
                pass

    def _close(self, device) -> None:
        self._close_device(device)

    def _run_session(self, device) -> None:
        period = 1.0 / self.rate_hz
        misses = 0
        next_time = time.monotonic()
        while not self.stopping:
            errors = device.parser.errors + device.unrecognized
            msg = device.legacyRequest(PING1D_DISTANCE, self.request_timeout_s)
            arrival = self.now()
            self.counters.malformed += device.parser.errors + device.unrecognized - errors
            reply = (
                None if msg is None else {n: getattr(msg, n, None) for n in msg.payload_field_names}
            )
            if reply is None:
                misses += 1
                self.timeouts += 1
                if misses >= self.max_timeouts:
                    raise OSError(f"{misses} Ping1D requests unanswered")
            else:
                misses = 0
                self._deliver(reply, arrival)
            next_time += period
            delay = next_time - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
            else:
                next_time = time.monotonic()

    def _deliver(self, reply: dict, arrival: float) -> None:
        self.counters.received += 1
        try:
            data = distance_data(reply.get("distance"), reply.get("confidence"))
        except (ValueError, TypeError):
            self.counters.malformed += 1
            return
        t = self.clock.stamp("sonar", arrival, None, key=reply.get("ping_number"))
        if t is not None:
            self._emit(Record("sonar", t, data, arrival, math.nan, self.source))
