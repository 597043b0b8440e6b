"""The safety rules: when undertow must not drive the vehicle, and when the autopilot must be
told the estimate jumped.

undertow **stops sending** (every mode) while

- the filter has not started, or started (or restarted: its state time went back, or the
  caller says so) less than ``settle_s`` of filter time ago;
- no valid DVL velocity came for ``dvl_timeout_s`` (session s; default 1 s, two reports at the
  A50's slowest rate of 2 Hz): the horizontal position is then inertial only;
- (position modes) the horizontal std sqrt(k (Pxx + Pyy)) is above ``max_position_std_m``
  (default 5 m: the horizontal accuracy above which EKF3 refuses to start on a GPS,
  ``calcGpsGoodToAlign`` in AP_NavEKF3_VehicleStatus.cpp at EK3_CHECK_SCALE 100 %; an
  estimate EKF3 would not take from a GPS it does not get from undertow);
- (velocity-delta) the horizontal velocity std is above EK3_VIS_VERR_MAX: EKF3 would take
  confidence 0 as an error of VIS_VERR_MAX, less than the truth.

Why stop rather than send ``quality`` 0: ArduPilot reads quality 0 as "unknown" and fuses it
whenever VISO_QUAL_MIN <= 0 (its default, 0: AP_VisualOdom.cpp and AP_VisualOdom_MAV.cpp);
quality -1 ("failed") would be dropped, but only ODOMETRY carries a quality
(VISION_POSITION_ESTIMATE passes 0, VISION_POSITION_DELTA none; GCS_Common.cpp). Silence works
for every mode and every VISO_QUAL_MIN: EKF3 stops fusing, its external-navigation position is
stale after 3 s (AP_NavEKF3_Control.cpp, ``extNavPosRecent``; body odometry after 200 ms,
``readyToUseBodyOdm``), and it falls back to its other sources (docs/bluerov2.md).

``reset_counter`` goes up (mod 256) when sending **resumes** after a stop (undertow's position
and the autopilot's have drifted apart meanwhile) and on a **jump**: a step of the sent
position that the velocity does not explain, |p_b - p_a - R_a v_a dt| > ``jump_m``. ArduPilot
turns a changed counter into a position reset of EKF3 instead of fusing the step as an innovation
(AP_VisualOdom_Backend.cpp ``get_reset_timestamp_ms``; AP_NavEKF3_Measurements.cpp
``writeExtNavData``). Its start value is random, so that a new undertow session is a reset too.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import numpy as np

from ...rotations import rpy_to_matrix
from .covariance import VIS_VERR_MAX_DEFAULT, horizontal_std, velocity_std


@dataclass(frozen=True)
class Verdict:
    """``send``: go ahead; ``reason``: why not (or ""); ``reset``: the counter went up now."""

    send: bool
    reason: str = ""
    reset: bool = False


class SendGate:
    """The rules of the module docstring. Times are session seconds: ``now`` the clock, ``t``
    the state's time."""

    def __init__(self, *, mode: str = "odometry", max_position_std_m: float = 5.0,
                 dvl_timeout_s: float = 1.0, settle_s: float = 2.0, jump_m: float = 0.5,
                 inflation: float = 1.0, reset_counter: int | None = None) -> None:  # fmt: skip
        self.mode = mode
        self.max_position_std_m = float(max_position_std_m)
        self.dvl_timeout_s = float(dvl_timeout_s)
        self.settle_s = float(settle_s)
        self.jump_m = float(jump_m)
        self.inflation = float(inflation)
        self.max_velocity_std_m_s = VIS_VERR_MAX_DEFAULT
        start = random.randrange(256) if reset_counter is None else int(reset_counter)
        self.reset_counter = start % 256
        self.resets = 0
        self.jumps = 0
        self.restarts = 0
        self._started_at: float | None = None  # state time the filter (re)started
        self._last_t: float | None = None  # newest state time seen
        self._last_dvl: float | None = None  # session time of the newest valid DVL
        self._sent: tuple | None = None  # (t, x) of the last state sent
        self._stopped = False  # sending was held since the last message

    def note_dvl(self, t: float, valid: bool) -> None:
        """A DVL record at session time ``t``; only a valid velocity counts."""
        if valid and math.isfinite(t):
            self._last_dvl = t if self._last_dvl is None else max(self._last_dvl, t)

    def restart(self) -> None:
        """The filter started again (its states no longer continue the previous ones)."""
        self._started_at = None
        self._last_t = None
        self.restarts += 1

    def check(self, now: float, t: float, x, P) -> Verdict:
        """May the state (t, x, P) go now? (module docstring)"""
        if self._last_t is not None and t < self._last_t - 1e-9:
            self.restart()
        if self._started_at is None:
            self._started_at = t
        self._last_t = t if self._last_t is None else max(self._last_t, t)
        reason = self._hold_reason(now, t, P)
        if reason:
            self._stopped = True
            return Verdict(False, reason)
        return Verdict(True)

    def _hold_reason(self, now: float, t: float, P) -> str:
        if t - self._started_at < self.settle_s:
            return f"filter settling ({self.settle_s:g} s after a start)"
        if self._last_dvl is None or now - self._last_dvl > self.dvl_timeout_s:
            return f"no valid DVL for {self.dvl_timeout_s:g} s"
        if self.mode == "velocity-delta":
            s = velocity_std(P, self.inflation)
            if not s <= self.max_velocity_std_m_s:
                return f"velocity std above EK3_VIS_VERR_MAX {self.max_velocity_std_m_s:g} m/s"
            return ""
        s = horizontal_std(P, self.inflation)
        if not s <= self.max_position_std_m:
            return f"horizontal position std above {self.max_position_std_m:g} m"
        return ""

    def prepare(self, t: float, x) -> tuple[int, bool]:
        """(reset_counter for the message of state (t, x), whether it is a new value): new
        after a stop, or on a jump from the last state sent (module docstring)."""
        reset = self._stopped and self._sent is not None
        if not reset and self._sent is not None:
            ta, xa = self._sent
            x = np.asarray(x, dtype=float)
            step = x[0:3] - xa[0:3] - rpy_to_matrix(xa[3:6]) @ xa[6:9] * (t - ta)
            reset = bool(float(np.linalg.norm(step)) > self.jump_m)
        return ((self.reset_counter + 1) % 256 if reset else self.reset_counter), reset

    def sent(self, t: float, x, reset: bool) -> None:
        """The state (t, x) went, with a new counter when ``reset`` (from :meth:`prepare`)."""
        if reset:
            self.reset_counter = (self.reset_counter + 1) % 256
            self.resets += 1
            self.jumps += 0 if self._stopped else 1
        self._sent = (t, np.array(x, dtype=float))
        self._stopped = False

    def hold(self) -> None:
        """Sending was held for a reason outside these rules (no clock or heading yet, no
        autopilot): the next message is a reset, as after any stop."""
        self._stopped = True
