"""What the sending did, as figures: the DVL-to-message latency, the spacing of the messages
and its jitter, the age of the states sent, and the slots held (by reason).

- latency: for each DVL report, from its arrival (the link's receive time, as the session's own
  DVL-to-pose latency) to the send of the first message whose state includes it (wall s);
- interval: the wall time between consecutive messages; jitter = the standard deviation of the
  intervals and the 99th percentile of |interval - 1 / rate|;
- state age: the session clock at the send minus the state's time: how old the estimate is when
  it leaves (its least value is what VISO_DELAY_MS should be, :mod:`.params`).
"""

from __future__ import annotations

from ..._util.histogram import Durations


class SendStats:
    """Figures of the module docstring (wall seconds from ``time.perf_counter``), in bounded
    memory (:class:`~undertow._util.histogram.Durations`: exact count, mean, std, least and
    largest; percentiles to about 1 %)."""

    def __init__(self, period_wall_s: float) -> None:
        self.period = float(period_wall_s)
        self.latency = Durations()
        self.interval = Durations()
        self.deviation = Durations()  # |interval - period|
        self.age = Durations()
        self.holds: dict[str, int] = {}
        self.sent = 0
        self._last: float | None = None

    def on_send(self, wall: float, age_s: float, arrivals) -> None:
        if self._last is not None:
            interval = wall - self._last
            self.interval.add(interval)
            self.deviation.add(abs(interval - self.period))
        self._last = wall
        self.sent += 1
        self.age.add(age_s)
        self.latency.add([wall - a for a in arrivals])

    def on_hold(self, reason: str) -> None:
        self.holds[reason] = self.holds.get(reason, 0) + 1

    def rate(self) -> dict:
        iv = self.interval
        if not iv.n:
            return {"n": 0}
        mean = iv.mean()
        return {"n": iv.n, "rate_hz": float(1.0 / mean) if mean > 0 else None,
                "mean_ms": mean * 1e3, "std_ms": iv.std() * 1e3,
                "p99_abs_deviation_ms": self.deviation.percentile(99.0) * 1e3,
                "max_ms": iv.max * 1e3}  # fmt: skip

    def summary(self) -> dict:
        age = self.age.summary_ms()
        return {
            "sent": self.sent,
            "latency": self.latency.summary_ms(),
            "interval": self.rate(),
            "state_age": age,
            "viso_delay_ms": int(round(age["min_ms"])) if age["n"] else None,
            "holds": dict(self.holds),
        }
