"""Asking the autopilot for the messages undertow needs when they do not come on their own.

A bare autopilot (ArduSub's SITL on TCP 5760, a serial port) streams little until a ground station
asks; MAV_CMD_SET_MESSAGE_INTERVAL (511, common.xml: param1 the message id, param2 the interval
in microseconds) asks for one message at one rate. :class:`StreamRequests` asks for each needed
message that has not arrived within ``grace_s`` of the autopilot being found, again every
``retry_s`` while it stays away, at most ``tries`` times, then says once that it does not come.
A message that arrives needs nothing (the vehicle's own rate is kept).
"""

from __future__ import annotations

MAV_CMD_SET_MESSAGE_INTERVAL = 511
#: what undertow needs from the autopilot and at what rate (Hz): ATTITUDE is the filter's IMU
#: stream (rates and orientation), the pressure message its depth, the rest what the autopilot
#: reports back (recorded and shown)
NEEDED_RATES_HZ = {
    "ATTITUDE": 25.0,
    "EKF_STATUS_REPORT": 2.0,
    "LOCAL_POSITION_NED": 5.0,
}


class StreamRequests:
    """Which SET_MESSAGE_INTERVAL requests are due (module docstring); times in session s."""

    def __init__(self, rates_hz: dict[str, float], *, grace_s: float = 2.0, retry_s: float = 5.0,
                 tries: int = 3) -> None:  # fmt: skip
        self.rates_hz = dict(rates_hz)
        self.grace_s, self.retry_s, self.tries = float(grace_s), float(retry_s), int(tries)
        self._found: float | None = None
        self._last_seen: dict[str, float] = {}
        self._asked: dict[str, int] = {}
        self._next: dict[str, float] = {}
        self.requested: dict[str, int] = {}
        self.absent: list[str] = []

    def found(self, now: float) -> None:
        """The autopilot was found (its first HEARTBEAT) at ``now``."""
        if self._found is None:
            self._found = now

    def rebooted(self) -> None:
        self._found = None
        self._asked.clear()
        self._next.clear()
        self.absent.clear()

    def seen(self, name: str, now: float) -> None:
        if name in self.rates_hz:
            self._last_seen[name] = now

    def due(self, now: float) -> tuple[list[tuple[str, int]], list[str]]:
        """([(name, interval_us)] to request now, notes)."""
        if self._found is None or now < self._found + self.grace_s:
            return [], []
        out, notes = [], []
        for name, rate in self.rates_hz.items():
            last = self._last_seen.get(name)
            if last is not None and now - last <= self.grace_s:
                continue
            if now < self._next.get(name, -1.0) or name in self.absent:
                continue
            asked = self._asked.get(name, 0)
            if asked >= self.tries:
                self.absent.append(name)
                notes.append(f"{name} does not arrive although asked for {asked} times "
                             "(MAV_CMD_SET_MESSAGE_INTERVAL)")  # fmt: skip
                continue
            self._asked[name] = asked + 1
            self._next[name] = now + self.retry_s
            self.requested[name] = self.requested.get(name, 0) + 1
            out.append((name, int(round(1e6 / rate))))
        return out, notes
