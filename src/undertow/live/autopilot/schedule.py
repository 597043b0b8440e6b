"""When undertow sends: one message per slot of T = 1 / ``live.autopilot_rate_hz`` (session
seconds), so the rate is fixed, with the message's moment inside its slot chosen for latency.

Slot k is [t0 + k T, t0 + (k + 1) T). In a slot that has not sent yet:

- a new state that carries a DVL report (a preview run on its arrival) is sent at once: the
  DVL-to-message latency is the filter's, not the slot's, while the DVL is not faster than the
  rate;
- else, at ``fallback`` T into the slot (0.8), the newest state (the filter advanced over the
  IMU records since) is sent: a slot never passes without a message while states come.

Never two messages closer than ``min_spacing_s``: EKF3 drops an external-navigation sample within
20 ms of the previous one (``extNavIntervalMin_ms``) and a body-odometry one within 50 ms
(``sensorIntervalMin_ms``; AP_NavEKF3.h, used in AP_NavEKF3_Measurements.cpp). A DVL state that
comes after its slot's message waits for the next slot. A slot that passes unsent (the loop
stalled, or the safety gate held) is counted as missed.
"""

from __future__ import annotations

import math

#: where in its slot the fallback message goes (fraction of T)
FALLBACK_AT = 0.8
#: the least spacing per message (s): EKF3's external-navigation and body-odometry intervals
#: plus 5 ms for the transport's jitter
MIN_SPACING_S = {"odometry": 0.025, "vision-position": 0.025, "velocity-delta": 0.055}


class SendSchedule:
    """The slot clock of the module docstring; times in session seconds."""

    def __init__(self, rate_hz: float, min_spacing_s: float = 0.025,
                 fallback: float = FALLBACK_AT) -> None:  # fmt: skip
        if not rate_hz > 0:
            raise ValueError("rate must be positive")
        self.period = 1.0 / float(rate_hz)
        self.min_spacing = float(min_spacing_s)
        self.fallback = float(fallback)
        self.t0: float | None = None
        self.last_slot = -1
        self.last_sent = -math.inf
        self.missed = 0

    def slot(self, now: float) -> int:
        if self.t0 is None:
            self.t0 = float(now)
        return int(math.floor((now - self.t0) / self.period))

    def due(self, now: float, fresh: bool) -> bool:
        """Whether a message goes now: ``fresh`` = a state carrying a new DVL report waits."""
        k = self.slot(now)
        if k <= self.last_slot or now - self.last_sent < self.min_spacing:
            return False
        return fresh or now >= self.t0 + (k + self.fallback) * self.period

    def sent(self, now: float) -> None:
        k = self.slot(now)
        if self.last_slot >= 0 and k > self.last_slot + 1:
            self.missed += k - self.last_slot - 1
        self.last_slot, self.last_sent = k, float(now)

    def next_due(self, now: float, fresh: bool = False) -> float:
        """The next moment (session s) a message may go: for a ``fresh`` state waiting, the
        first moment of a slot without a message; else this slot's fallback point if it has not
        sent, else the next slot's; no earlier than the spacing allows."""
        k = self.slot(now)
        if k <= self.last_slot:
            k = self.last_slot + 1
        at = self.t0 + (k + (0.0 if fresh else self.fallback)) * self.period
        return max(at, self.last_sent + self.min_spacing)
