"""Live link to the autopilot (ArduSub) over MAVLink with pymavlink.

``address`` is any pymavlink connection string: ``udpin:0.0.0.0:14550`` (listen for the
packets BlueOS/mavlink-router sends; the usual set-up), ``udpout:HOST:PORT``, ``tcp:HOST:PORT``
or a serial device (``/dev/ttyACM0``, with ``baud``). Messages are decoded and CRC-checked by
pymavlink (``robust_parsing``: bytes that do not form a valid message come back as
``BAD_DATA`` and are counted as malformed) and mapped to records by
:class:`~undertow.io.mavlink.MavlinkMapper`, the mapping of the ``.tlog`` reader (units there).

Time (``time_source``): ``arrival`` (default) stamps each record with its arrival time, as a
``.tlog`` stamps its receive time, so a recorded session reads back identically; ``sensor``
uses the message's own time (``time_boot_ms``/``time_usec``) through the link's
:class:`~undertow.live.links.base.ClockPolicy` (shifted to this machine's clock by a recorded
offset), which removes the network jitter from the autopilot's sample spacing.
A link silent for ``idle_timeout_s`` re-opens its connection (counted as a disconnect).

``deferred`` (UDP only; the live session's choice): the link's thread only receives each
datagram and takes its arrival time; :meth:`MavlinkLink.pump`, called by the consumer's loop,
decodes what queued since and delivers the records from that thread. The decoding then runs in
batches in the thread that uses the records, instead of once per datagram in a thread woken
for each (with the GIL passed back and forth: here most of the link's CPU). The records, their
times and the counters are those of the immediate mode; a datagram holding the message mapped to
the DVL (VISION_POSITION_DELTA) calls ``wake`` at once, so that a loop waiting for DVL reports
need not wait for its next turn. At most ``max_queue`` datagrams wait (the oldest dropped,
counted as overflow).

``polled`` (UDP only; the live session's choice when an A50 link wakes its loop): no thread
receives at all. :meth:`MavlinkLink.pump` reads the socket itself, without blocking, and stamps
each datagram with the time the kernel received it (``SO_TIMESTAMPNS``, Linux socket(7);
taken through the clock's ``at``, the read time when there is none), so a datagram read late
is stamped as if read at once. The link's thread only connects, attaches the kernel filter and
watches for silence. Each datagram then costs no thread wake-up (and no GIL hand-over), the
larger part of its cost otherwise; in exchange no DVL message wakes the loop, which reads it at
its next turn. Datagrams the kernel dropped because the receive buffer was full are counted as
overflow (``SO_RXQ_OVFL``: the kernel tells them with the next datagram it keeps).

Sending (:meth:`MavlinkLink.send`, used by :mod:`undertow.live.autopilot`): a message is packed
as MAVLink 2 by an encoder of the link's own (system ``source_system``, component
``source_component``, its own sequence numbers), whatever version the connection parses, and
written on the connection: to the address the last datagram came from for ``udpin`` (pymavlink's
own UDP server sends to the clients its reads saw, which the link's reads bypass), else through
pymavlink's ``write`` (``udpout``, ``tcp``, serial). :meth:`MavlinkLink.observe` hands the
messages a consumer names (decoded, with their arrival times) to its callback, from the thread
that decodes them; those messages pass the kernel filter.
"""

from __future__ import annotations

import importlib
import math
import socket
import sys
import threading
import time

from ...errors import ConfigError
from ...io.mavlink import MavlinkConfig, MavlinkMapper
from . import mavlink_filter, stamped
from .base import Backoff, ClockPolicy, Link, LinkCounters

TIME_SOURCES = ("arrival", "sensor")


class MavlinkLink(Link):
    """Receives MAVLink from ``address`` and delivers IMU, pressure, DVL (VISION_POSITION_DELTA),
    dead-reckoning and range records (see :class:`~undertow.io.mavlink.MavlinkConfig`)."""

    name = "mavlink"

    def __init__(
        self,
        address: str = "udpin:0.0.0.0:14550",
        callback=None,
        *,
        config: MavlinkConfig | None = None,
        baud: int = 115200,
        time_source: str = "arrival",
        idle_timeout_s: float = 5.0,
        max_offset_s: float = 1.0,
        backoff: Backoff | None = None,
        max_queue: int = 10_000,
        now=None,
        deferred: bool = False,
        wake=None,
        kernel_filter: bool = False,
        polled: bool = False,
        source_component: int = 0,
    ) -> None:
        if time_source not in TIME_SOURCES:
            raise ConfigError(f"mavlink time_source: '{time_source}' is not one of {TIME_SOURCES}")
        counters = LinkCounters()
        super().__init__(
            callback,
            backoff=backoff,
            max_queue=max_queue,
            clock=ClockPolicy(counters, max_offset_s=max_offset_s),
            now=now,
        )
        self.address = str(address)
        self.baud = int(baud)
        self.config = config or MavlinkConfig()
        self.mapper = MavlinkMapper(self.config, source=self.address)
        self.time_source = time_source
        self.idle_timeout_s = float(idle_timeout_s)
        self.message_counts: dict[str, int] = {}
        self._conn = None
        self.deferred = bool(deferred)
        self.wake = wake
        self.kernel_filter = bool(kernel_filter)
        self.polled = bool(polled)
        self._polling = None  # (conn, stamped.Reader) that pump() reads (polled, connected)
        self._last_read = 0.0  # time.monotonic() of pump()'s last datagram
        self._frames: _SingleFrames | None = None
        self.source_component = int(source_component)
        self._observed: set[str] = set()
        self._observer = None
        self._peer = None  # (host, port) of the last datagram (udpin: where sends go)
        self._encoder = None
        self._send_lock = threading.Lock()
        self.sent_counts: dict[str, int] = {}
        self.unsent = 0

    @property
    def message_types(self) -> tuple[str, ...]:
        """The messages decoded: the mapper's and the observed ones."""
        return (
            *self.mapper.message_types,
            *sorted(self._observed - set(self.mapper.message_types)),
        )

    def observe(self, names, callback) -> None:
        """Hand every message named in ``names`` to ``callback(msg, arrival)`` (before the link
        connects: the kernel filter and the decoder are built with them)."""
        self._observed |= set(names)
        self._observer = callback

    def send(self, msg) -> bool:
        """Pack ``msg`` (a pymavlink MAVLink 2 message) and write it (module docstring); False
        when there is no connection or no peer yet (counted in ``unsent``)."""
        conn = self._conn
        with self._send_lock:
            if self._encoder is None:
                from pymavlink.dialects.v20 import ardupilotmega

                compid = self.source_component
                self._encoder = ardupilotmega.MAVLink(None, srcSystem=255, srcComponent=compid)
            try:
                buf = msg.pack(self._encoder)
                self._encoder.seq = (self._encoder.seq + 1) % 256
                sock = getattr(conn, "port", None)
                if conn is None:
                    raise OSError("not connected")
                if getattr(conn, "udp_server", False) and isinstance(sock, socket.socket):
                    if self._peer is None:
                        raise OSError("no datagram received yet")
                    sock.sendto(buf, self._peer)
                else:
                    conn.write(buf)
            except (OSError, ValueError, AttributeError):
                self.unsent += 1
                return False
        name = msg.get_type()
        self.sent_counts[name] = self.sent_counts.get(name, 0) + 1
        return True

    def load(self) -> None:
        from pymavlink import mavutil

        _preload_mavlink2(mavutil.current_dialect)

    def _connect(self):
        from pymavlink import mavutil

        try:
            conn = mavutil.mavlink_connection(
                self.address, baud=self.baud, source_system=255, robust_parsing=True
            )
        except Exception as exc:  # pymavlink raises bare Exceptions for bad addresses
            raise OSError(f"{self.address}: {exc}") from None
        _grow_receive_buffer(conn)
        _preload_mavlink2(mavutil.current_dialect)
        self._conn = conn
        return conn

    def _interrupt(self) -> None:
        conn = self._conn
        if conn is not None:
            try:
                conn.close()
            except (OSError, AttributeError):
                pass

    def _run_session(self, conn) -> None:
        sock = getattr(conn, "port", None)
        if isinstance(sock, socket.socket) and sock.type == socket.SOCK_DGRAM:
            return self._run_udp(conn, sock)
        last = time.monotonic()
        while not self.stopping:
            try:
                msg = conn.recv_match(blocking=True, timeout=0.2)
            except (OSError, ValueError):
                if self.stopping:
                    return
                raise
            if msg is None:
                if time.monotonic() - last > self.idle_timeout_s:
                    raise OSError(f"no MAVLink for {self.idle_timeout_s} s")
                continue
            last = time.monotonic()
            self.handle(msg, self.now())

    def _run_udp(self, conn, sock) -> None:
        """UDP: one blocking read per datagram (``recv_match`` polls, which costs several
        times the decoding at telemetry rates), decoded at once or (``deferred``) queued for
        :meth:`pump`; ``polled``: :meth:`_watch`."""
        if self.kernel_filter:
            self.info["kernel_filter"] = self._attach_filter(conn, sock)
        if self.polled:
            return self._watch(conn, sock)
        sock.settimeout(0.2)
        dvl_id = _message_id(conn.mav, "VISION_POSITION_DELTA")
        last = time.monotonic()
        while not self.stopping:
            try:
                data, self._peer = sock.recvfrom(65535)
            except TimeoutError:
                if time.monotonic() - last > self.idle_timeout_s:
                    raise OSError(f"no MAVLink for {self.idle_timeout_s} s") from None
                continue
            except OSError:
                if self.stopping:
                    return
                raise
            last = time.monotonic()
            arrival = self.now()
            if not self.deferred:
                self._decode(conn, arrival, data)
                continue
            self._defer((conn, arrival, data))
            if self.wake is not None and _frame_id(data) == dvl_id:
                self.wake()

    def _watch(self, conn, sock) -> None:
        """``polled``: hand the socket to :meth:`pump` and watch for silence (no datagram read
        for ``idle_timeout_s``: the session ends, and the connection is opened again)."""
        stamped.enable(sock)
        self._last_read = time.monotonic()
        self._polling = (conn, stamped.Reader(sock, self.now))
        try:
            while not self._stop.wait(0.2):
                if time.monotonic() - self._last_read > self.idle_timeout_s:
                    raise OSError(f"no MAVLink for {self.idle_timeout_s} s")
        finally:
            self._polling = None

    def _read_polled(self) -> None:
        """Read and decode every datagram waiting on the polled socket, each stamped with its
        kernel receive time."""
        polling = self._polling
        if polling is None:
            return
        conn, reader = polling
        while (got := reader.read()) is not None:
            self._last_read = time.monotonic()
            self._peer = reader.address
            self.counters.overflow += reader.dropped  # (told with this datagram)
            reader.dropped = 0
            self._decode(conn, got[1], got[0])

    def _attach_filter(self, conn, sock) -> bool:
        """The kernel drops the single frames of messages no stream uses (:mod:`.mavlink_filter`);
        HEARTBEAT kept: the sign of a live autopilot (``idle_timeout_s``)."""
        names = (*self.message_types, "HEARTBEAT")
        keep_v2 = {i for i in (_message_id(conn.mav, n) for n in names) if i is not None}
        keep_v1 = {i for i in (_message_id(conn.mav, n, version=1) for n in names)
                   if i is not None}  # fmt: skip
        return mavlink_filter.attach(sock, keep_v2, keep_v1)

    def pump(self) -> None:
        """Decode the datagrams the thread queued (``deferred``), or read (``polled``), and
        deliver their records."""
        raw = self._raw
        while raw:
            self._decode(*raw.popleft())
        self._read_polled()

    def _decode(self, conn, arrival: float, data: bytes) -> None:
        """One datagram: counted if it is a valid frame of a message no stream uses, else
        decoded (:class:`_SingleFrames`, or the connection's own parser) and mapped."""
        if conn.first_byte:  # MAVLink 1 or 2, from the first packet (as recv_match does)
            conn.auto_mavlink_version(data)
        frames = self._frames
        if frames is None or frames.mav is not conn.mav:  # (a new connection or version)
            frames = self._frames = _SingleFrames(conn.mav, self.message_types)
        done = frames.check(data)
        if done is None:
            for msg in conn.mav.parse_buffer(data) or ():
                self.handle(msg, arrival)
        elif done[1] is None:  # a valid frame of a message no stream uses: counted only
            self.message_counts[done[0]] = self.message_counts.get(done[0], 0) + 1
        else:
            self.handle(done[1], arrival)

    def handle(self, msg, arrival: float) -> None:
        """Map one decoded message received at ``arrival`` (Unix s) and deliver its records."""
        name = msg.get_type()
        if name == "BAD_DATA":
            self.counters.malformed += 1
            return
        self.message_counts[name] = self.message_counts.get(name, 0) + 1
        if name in self._observed:
            self._observer(msg, arrival)
        before = self.mapper.malformed
        records = self.mapper.records(msg, arrival, arrival)
        self.counters.malformed += self.mapper.malformed - before
        if records:
            self.counters.received += 1
        for record in records:
            sensor = record.sensor_time if self.time_source == "sensor" else None
            if sensor is not None and not math.isfinite(sensor):
                sensor = None
            t = self.clock.stamp(record.stream, arrival, sensor)
            if t is None:
                continue
            if t != record.t:
                record = type(record)(
                    record.stream, t, record.data, arrival, record.sensor_time, record.source
                )
            self._emit(record)


class _SingleFrames:
    """Handles a datagram that is exactly one unsigned MAVLink 2 frame (what an autopilot or a
    router sends over UDP), checked as pymavlink's ``decode`` checks it: the length byte against
    the datagram, the message id in the dialect, the CRC-16/MCRF4XX of the frame after the magic
    byte extended by the message's CRC_EXTRA (MAVLink serialization,
    https://mavlink.io/en/guide/serialization.html). Then:

    - a message the mapper does not use (an autopilot streams many: SCALED_IMU2 beside
      ATTITUDE, HEARTBEAT, SYS_STATUS) is only named, to be counted;
    - a used one without array or text fields (ATTITUDE, SCALED_PRESSURE2, ...) is decoded here
      with pymavlink's own definition of it (its struct, field order and class; a MAVLink 2
      payload cut of its trailing zeros padded back), into the message pymavlink would make.

    Anything else, a failed check included, goes to pymavlink's parser, which keeps its buffer and
    its verdicts (BAD_DATA) for it; pymavlink's own packet counters omit the frames done here.
    Both shortcuts are fuzzed against pymavlink's parser (tests/test_fuzz_links.py)."""

    def __init__(self, mav, used: tuple[str, ...]) -> None:
        module = sys.modules[type(mav).__module__]
        self.mav = mav
        self.crc = module.x25crc
        self.header = getattr(module, "MAVLink_header", None)
        self.v2 = getattr(module, "WIRE_PROTOCOL_VERSION", "") == "2.0"
        self.unused = {msgid: (cls.msgname, cls.crc_extra)
                       for msgid, cls in module.mavlink_map.items()
                       if cls.msgname not in used}  # fmt: skip
        self.simple = {msgid: cls for msgid, cls in module.mavlink_map.items()
                       if cls.msgname in used and _simple_layout(cls)}  # fmt: skip

    def check(self, data: bytes):
        """(name, None) for a valid frame of an unused message, (name, message) for one decoded
        here, None for what goes to pymavlink's parser."""
        n = len(data)
        if (n < 12 or data[0] != 0xFD or data[2] != 0 or n != data[1] + 12 or not self.v2
                or self.mav.buf_len() or self.mav.signing.secret_key is not None):  # fmt: skip
            return None
        msgid = data[7] | data[8] << 8 | data[9] << 16
        known = self.unused.get(msgid)
        cls = None if known is not None else self.simple.get(msgid)
        if known is None and (cls is None or self.header is None):
            return None
        name, crc_extra = known if known is not None else (cls.msgname, cls.crc_extra)
        crc = data[-2] | data[-1] << 8
        if self.crc(bytearray(data[1:-2]) + bytes((crc_extra,))).crc != crc:
            return None
        if cls is None:
            return name, None
        size = cls.unpacker.size
        payload = bytes(data[10:-2]).ljust(size, b"\0")[:size]
        fields = cls.unpacker.unpack(payload)
        msg = cls(*[fields[k] for k in cls.orders])
        msg._signed = False
        msg._msgbuf = bytearray(data)
        msg._payload = msg._msgbuf[6:-2]  # (as pymavlink sets it)
        msg._crc = crc
        msg._header = self.header(msgid, 0, data[3], data[1], data[4], data[5], data[6])
        return name, msg


def _simple_layout(cls) -> bool:
    """A message of scalar numeric fields only (no arrays, no text): decoded by its struct."""
    fmt = cls.unpacker.format
    fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
    return sum(cls.lengths) == len(cls.lengths) and "s" not in fmt and "c" not in fmt


def _message_id(mav, name: str, version: int = 2) -> int | None:
    """The id of message ``name`` in the MAVLink 2 (or 1) module of the dialect of ``mav`` (a
    connection starts in MAVLink 1, whose module may lack the messages of ids above 255); None
    if it has none."""
    module = type(mav).__module__
    module = module.replace(".v10.", ".v20.") if version == 2 else module.replace(".v20.", ".v10.")
    try:
        module = importlib.import_module(module)
    except ImportError:
        return None
    return getattr(module, f"MAVLINK_MSG_ID_{name}", None)


def _frame_id(data: bytes) -> int | None:
    """The message id of a datagram that starts with a MAVLink 2 or 1 frame (None if not)."""
    if len(data) >= 10 and data[0] == 0xFD:
        return data[7] | data[8] << 8 | data[9] << 16
    if len(data) >= 6 and data[0] == 0xFE:
        return data[5]
    return None


def _preload_mavlink2(dialect: str) -> None:
    """Import the MAVLink 2 module of ``dialect`` now: the connection starts in MAVLink 1 and
    switches to 2 at the first MAVLink 2 packet (``auto_mavlink_version``), importing that
    module then (tens of ms for the ``all`` dialect), which would stall the first messages."""
    try:
        importlib.import_module(f"pymavlink.dialects.v20.{dialect}")
    except ImportError:  # a dialect pymavlink generates on demand: it does so at the switch
        pass


#: the UDP receive buffer asked for (the kernel caps it at twice net.core.rmem_max)
RECEIVE_BUFFER_BYTES = 4 << 20


def _grow_receive_buffer(conn) -> None:
    """A larger socket receive buffer for a UDP connection: each small datagram takes about
    1 kB of buffer in the kernel, so the default (~208 kB) holds only a few hundred MAVLink
    messages, about a second of an autopilot's telemetry while this process is busy."""
    sock = getattr(conn, "port", None)
    if isinstance(sock, socket.socket) and sock.type == socket.SOCK_DGRAM:
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
        except OSError:
            pass
