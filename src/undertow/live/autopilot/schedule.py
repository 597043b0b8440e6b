"""When undertow sends: a fixed rate r = ``live.autopilot_rate_hz`` on average, with each
message's moment chosen for latency. A token bucket (session seconds):

    tokens += r dt, at most 2;   a message spends one token;

- a new state that carries a DVL report (a preview run on its arrival) goes at once while
  tokens >= 0 (it may borrow the next period's token, down to -1): while the DVL is not faster
  than r it never waits, so the DVL-to-message latency is the filter's;
- else the newest state (the filter advanced over the IMU records since) goes when tokens >= 1,
  unless the next DVL report is expected (``dvl_next``, from the reports' own rhythm) within
  EKF3's state spacing plus ``DVL_WAIT_S``: then the DVL's state takes the token (a state sent
  just before it would hold it back by the spacing); with no DVL the messages are exactly 1 / r
  apart, and no token is lost, so the long-run rate is r;
- in any window of length W at most r W + 3 messages go.

EKF3's own limits are kept: it drops an external-navigation sample whose time is within 20 ms of
the previous one's (``extNavIntervalMin_ms``, on the message's corrected time: AP_NavEKF3.h,
``writeExtNavData`` in AP_NavEKF3_Measurements.cpp) and a body-odometry one that arrives within
50 ms of the previous (``sensorIntervalMin_ms``, on its arrival time, ``writeBodyFrameOdom``):
``min_state_spacing_s`` between the states' times and ``min_send_spacing_s`` between sends
(:data:`SPACING_S`, each with a millisecond's margin and the transport's 5 ms for the second).
Periods in which the bucket was full and nothing could go (the gate held, no new state, the loop
stalled) are counted as missed.
"""

from __future__ import annotations

import collections
import math

#: how long past its expected time a DVL report is waited for (s)
DVL_WAIT_S = 0.01
#: (min_send_spacing_s, min_state_spacing_s) per mode (module docstring)
SPACING_S = {
    "odometry": (0.0, 0.021),
    "vision-position": (0.0, 0.021),
    "velocity-delta": (0.055, 0.021),
}


class SendSchedule:
    """The token bucket of the module docstring."""

    def __init__(self, rate_hz: float, min_send_spacing_s: float = 0.0,
                 min_state_spacing_s: float = 0.0) -> None:  # fmt: skip
        if not rate_hz > 0:
            raise ValueError("rate must be positive")
        self.period = 1.0 / float(rate_hz)
        self.min_send = float(min_send_spacing_s)
        self.min_state = float(min_state_spacing_s)
        self.tokens = 1.0
        self._at: float | None = None  # when tokens was last brought up to date
        self.last_sent = -math.inf
        self.last_state = -math.inf
        self.missed = 0
        self._overflow = 0.0

    @property
    def started(self) -> bool:
        return self._at is not None

    def _refill(self, now: float) -> None:
        if self._at is None:
            self._at = float(now)
        gained = max(now - self._at, 0.0) / self.period
        self._at = max(self._at, float(now))
        free = self.tokens + gained
        if free > 2.0:  # tokens lost: periods that passed without a message
            self._overflow += free - 2.0
            whole = int(self._overflow)
            self.missed += whole
            self._overflow -= whole
        self.tokens = min(free, 2.0)

    def due(self, now: float, fresh: bool, state_t: float | None = None,
            dvl_next: float | None = None) -> bool:  # fmt: skip
        """Whether a message may go now: ``fresh`` = the state carries a new DVL report;
        ``state_t`` its time (the state spacing is checked when given); ``dvl_next`` when the
        next DVL report is expected (None: not known)."""
        self._refill(now)
        if now - self.last_sent < self.min_send:
            return False
        if state_t is not None and state_t - self.last_state < self.min_state:
            return False
        if fresh:
            return self.tokens >= 0.0
        return self.tokens >= 1.0 - 1e-9 and self._wait_for(now, dvl_next) is None

    def _wait_for(self, now: float, dvl_next: float | None) -> float | None:
        """Until when a fallback waits for an expected DVL report (None: it does not)."""
        if dvl_next is None or not math.isfinite(dvl_next):
            return None
        until = dvl_next + DVL_WAIT_S
        return until if now < until and dvl_next - now <= self.min_state + DVL_WAIT_S else None

    def sent(self, now: float, state_t: float = math.nan) -> None:
        self._refill(now)
        self.tokens -= 1.0
        self.last_sent = float(now)
        if math.isfinite(state_t):
            self.last_state = float(state_t)

    def next_due(self, now: float, fresh: bool = False, dvl_next: float | None = None) -> float:
        """The next moment (session s) a message may go: for a ``fresh`` state as soon as a
        token is there (and the spacings allow), else when a token is (after an expected DVL
        report, when one is near)."""
        self._refill(now)
        need = 0.0 if fresh else 1.0
        at = now + max(need - self.tokens, 0.0) * self.period
        if fresh:
            at = max(at, self.last_state + self.min_state)
        else:
            wait = self._wait_for(at, dvl_next)
            at = at if wait is None else wait
        return max(at, self.last_sent + self.min_send)


class Rhythm:
    """When the next DVL report is expected: the last arrival plus the median of the last ``n``
    intervals, when they are regular (their interquartile range below a quarter of the median;
    the A50 reports at a steady rate for a given altitude); None otherwise."""

    def __init__(self, n: int = 8) -> None:
        self._times: collections.deque = collections.deque(maxlen=int(n) + 1)

    def arrived(self, t: float) -> None:
        if math.isfinite(t) and (not self._times or t > self._times[-1]):
            self._times.append(float(t))

    def next(self) -> float | None:
        if len(self._times) < 4:
            return None
        gaps = sorted(b - a for a, b in zip(self._times, list(self._times)[1:], strict=False))
        n = len(gaps)
        median, iqr = gaps[n // 2], gaps[(3 * n) // 4] - gaps[n // 4]
        return self._times[-1] + median if iqr < 0.25 * median else None
