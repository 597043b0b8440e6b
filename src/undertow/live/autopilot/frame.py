"""The autopilot's frame and clock, as seen from undertow's.

**Frame.** undertow's world frame is z down with its heading wherever the filter started (the
first DVL dead-reckoning yaw, or the IMU's orientation report: :func:`~undertow.estimation.rows.
initial_state`); ArduPilot takes external-navigation positions as north-east-down about its EKF
origin (MAV_FRAME_LOCAL_FRD, "forward-right-down, fixed relative to earth", with its own yaw
from the compass by default). The two differ by a heading offset dpsi and a translation; the
translation does not matter (EKF3 resets its position to the first external-navigation fix,
AP_NavEKF3_Control.cpp), the heading does. :class:`HeadingOffset` finds dpsi as the circular
mean of (autopilot yaw - undertow yaw) over the first ``samples`` pairs taken within
``max_gap_s`` of each other (ATTITUDE.yaw against the state's psi), latches it and states it;
``live.autopilot_yaw_offset_deg`` overrides. What is sent is then

    p_ap = Rz(dpsi) p,   (phi, theta, psi)_ap = (phi, theta, psi + dpsi)

(turning the world about z changes only the yaw of R = Rz(psi) Ry(theta) Rx(phi)).

**Clock.** ArduPilot stamps its messages with time since boot (``time_boot_ms``) and takes
``time_usec`` of ODOMETRY and VISION_POSITION_ESTIMATE as the measurement's time in any clock: it
corrects an offboard time onto its own by the smallest lag seen, "the incoming packet that had
the least lag" (libraries/AP_RTC/JitterCorrection.cpp, through
``correct_offboard_timestamp_usec_to_ms`` in GCS_Common.cpp). undertow stamps the state's time
in the autopilot's clock: :class:`AutopilotClock` keeps offset = min(arrival - time_boot) over
a sliding window (the same least-lag estimate, so a clock drift is followed), autopilot time =
t - offset; a time_boot that goes back by more than a second is a reboot (the offset is found
again, counted).
"""

from __future__ import annotations

import collections
import math

from ...rotations import wrap_angle

#: seconds of samples the clock's least-lag offset is taken over
CLOCK_WINDOW_S = 30.0
#: a time_boot this far behind the last one is a reboot of the autopilot
REBOOT_BACK_S = 1.0


class AutopilotClock:
    """The autopilot's boot clock against the session's (module docstring)."""

    def __init__(self, window_s: float = CLOCK_WINDOW_S) -> None:
        self.window_s = float(window_s)
        self._samples: collections.deque = collections.deque()  # (arrival, offset)
        self._last_boot: float | None = None
        self.reboots = 0

    def observe(self, boot_s: float, arrival: float) -> bool:
        """Take a message's time since boot (s) and its arrival (session s); True when it shows
        a reboot (the estimate starts again)."""
        if not (math.isfinite(boot_s) and math.isfinite(arrival)) or boot_s < 0:
            return False
        rebooted = self._last_boot is not None and boot_s < self._last_boot - REBOOT_BACK_S
        if rebooted:
            self.reboots += 1
            self._samples.clear()
        self._last_boot = boot_s
        offset = arrival - boot_s
        samples = self._samples  # offsets increasing from the front: the front is the minimum
        while samples and samples[0][0] < arrival - self.window_s:
            samples.popleft()
        while samples and samples[-1][1] >= offset:
            samples.pop()
        samples.append((arrival, offset))
        return rebooted

    @property
    def offset(self) -> float | None:
        """min(arrival - time_boot) over the window (s), None before a sample."""
        return self._samples[0][1] if self._samples else None

    def to_autopilot_usec(self, t: float) -> int | None:
        """The session time ``t`` in the autopilot's microseconds since boot (None: unknown)."""
        offset = self.offset
        if offset is None or not math.isfinite(t):
            return None
        return max(int(round((t - offset) * 1e6)), 0)

    def to_session(self, boot_s: float) -> float | None:
        """A time since boot (s) on the session clock (None: unknown)."""
        offset = self.offset
        return None if offset is None else boot_s + offset


class HeadingOffset:
    """dpsi = autopilot heading - undertow heading (module docstring); ``fixed_rad`` overrides
    the detection."""

    def __init__(self, fixed_rad: float | None = None, samples: int = 5,
                 max_gap_s: float = 0.1) -> None:  # fmt: skip
        self.samples = max(int(samples), 1)
        self.max_gap_s = float(max_gap_s)
        self._diffs: list[float] = []
        self.value: float | None = None if fixed_rad is None else float(fixed_rad)
        self.source = "set" if fixed_rad is not None else "detected"
        self.spread_rad = 0.0

    def observe(self, t_autopilot: float, yaw_autopilot: float, t_state: float,
                yaw_state: float) -> bool:  # fmt: skip
        """Take a pair; True when it latched dpsi now."""
        if self.value is not None:
            return False
        values = (t_autopilot, yaw_autopilot, t_state, yaw_state)
        if not all(math.isfinite(v) for v in values) or abs(t_autopilot - t_state) > self.max_gap_s:
            return False
        self._diffs.append(float(wrap_angle(yaw_autopilot - yaw_state)))
        if len(self._diffs) < self.samples:
            return False
        s = sum(math.sin(d) for d in self._diffs)
        c = sum(math.cos(d) for d in self._diffs)
        self.value = math.atan2(s, c)
        # the circular standard deviation sqrt(-2 ln R), R the mean resultant length
        r = min(math.hypot(s, c) / len(self._diffs), 1.0)
        self.spread_rad = math.sqrt(max(-2.0 * math.log(r), 0.0)) if r > 0 else math.pi
        return True

    def describe(self, sent_turned: bool = True) -> str:
        if self.value is None:
            return "heading offset: not known yet"
        deg = math.degrees(self.value)
        spread = math.degrees(self.spread_rad)
        how = ("set by live.autopilot_yaw_offset_deg" if self.source == "set" else
               f"found from {self.samples} ATTITUDE yaws, spread {spread:.1f} deg")  # fmt: skip
        use = ("positions and yaw are sent turned by it" if sent_turned else
               "used to show the autopilot's position in undertow's frame")  # fmt: skip
        return (
            f"undertow's frame is turned {deg:+.1f} deg from the autopilot's heading ({how}); {use}"
        )
