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

import numpy as np


def _ms(values) -> dict:
    v = np.asarray(values, dtype=float) * 1e3
    if v.size == 0:
        return {"n": 0}
    return {"n": int(v.size), "min_ms": float(v.min()), "median_ms": float(np.median(v)),
            "p99_ms": float(np.percentile(v, 99)), "max_ms": float(v.max())}  # fmt: skip


class SendStats:
    """Figures of the module docstring (wall seconds from ``time.perf_counter``)."""

    def __init__(self, period_wall_s: float) -> None:
        self.period = float(period_wall_s)
        self.latency_s: list[float] = []
        self.interval_s: list[float] = []
        self.age_s: list[float] = []
        self.holds: dict[str, int] = {}
        self.sent = 0
        self._last: float | None = None

    def on_send(self, wall: float, age_s: float, arrivals) -> None:
        if self._last is not None:
            self.interval_s.append(wall - self._last)
        self._last = wall
        self.sent += 1
        self.age_s.append(float(age_s))
        self.latency_s.extend(wall - a for a in arrivals)

    def on_hold(self, reason: str) -> None:
        self.holds[reason] = self.holds.get(reason, 0) + 1

    def rate(self) -> dict:
        iv = np.asarray(self.interval_s, dtype=float)
        if iv.size == 0:
            return {"n": 0}
        dev = np.abs(iv - self.period) * 1e3
        return {"n": int(iv.size), "rate_hz": float(1.0 / iv.mean()) if iv.mean() > 0 else None,
                "mean_ms": float(iv.mean() * 1e3), "std_ms": float(iv.std() * 1e3),
                "p99_abs_deviation_ms": float(np.percentile(dev, 99)),
                "max_ms": float(iv.max() * 1e3)}  # fmt: skip

    def summary(self) -> dict:
        age = _ms(self.age_s)
        return {
            "sent": self.sent,
            "latency": _ms(self.latency_s),
            "interval": self.rate(),
            "state_age": age,
            "viso_delay_ms": int(round(age["min_ms"])) if age["n"] else None,
            "holds": dict(self.holds),
        }
