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
:class:`~undertow.io.links.common.ClockPolicy` (shifted to this machine's clock by a recorded
offset), which removes the network jitter from the autopilot's sample spacing.
A link silent for ``idle_timeout_s`` re-opens its connection (counted as a disconnect).
"""

from __future__ import annotations

import math
import time

from ...errors import ConfigError
from ..mavlink import MavlinkConfig, MavlinkMapper
from .common import Backoff, ClockPolicy, Link, LinkCounters

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
    ) -> None:
        if time_source not in TIME_SOURCES:
            raise ConfigError(f"mavlink time_source: '{time_source}' is not one of {TIME_SOURCES}")
        counters = LinkCounters()
        super().__init__(
            callback,
            backoff=backoff,
            max_queue=max_queue,
            clock=ClockPolicy(counters, max_offset_s=max_offset_s),
        )
        self.address = str(address)
        self.baud = int(baud)
        self.config = config or MavlinkConfig()
        self.mapper = MavlinkMapper(self.config, source=self.address)
        self.time_source = time_source
        self.idle_timeout_s = float(idle_timeout_s)
        self.message_counts: dict[str, int] = {}
        self._conn = None

    def _connect(self):
        from pymavlink import mavutil

        try:
            conn = mavutil.mavlink_connection(
                self.address, baud=self.baud, source_system=255, robust_parsing=True
            )
        except Exception as exc:  # pymavlink raises bare Exceptions for bad addresses
            raise OSError(f"{self.address}: {exc}") from None
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
            self.handle(msg, time.time())

    def handle(self, msg, arrival: float) -> None:
        """Map one decoded message received at ``arrival`` (Unix s) and deliver its records."""
        name = msg.get_type()
        if name == "BAD_DATA":
            self.counters.malformed += 1
            return
        self.message_counts[name] = self.message_counts.get(name, 0) + 1
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
