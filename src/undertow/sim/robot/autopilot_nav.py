"""The virtual autopilot's navigation: EKF3's aiding modes, gates, timeouts and status flags
(ArduPilot ``libraries/AP_NavEKF3/AP_NavEKF3_Control.cpp`` setAidingMode, readyToUseExtNav,
readyToUseBodyOdm, updateFilterStatus; ``AP_NavEKF3_PosVelFusion.cpp`` SelectVelPosFusion,
FuseVelPosNED), around a small stand-in for EKF3's 24-state filter.

The stand-in: per horizontal axis a constant-velocity Kalman filter, state (p, v), prediction
p += v dt, P = F P F^T + Q with Q from white acceleration noise q = EK3_ACC_P_NSE^2
(Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]]); position updates with R = clamp(posErr, 0.01, 10)^2
(FuseVelPosNED's R_OBS[3]), velocity updates (external-navigation NED velocity, or body
odometry rotated by the autopilot's yaw) with R = clamp(err, 0.05, 5)^2. What is EKF3's:

- aiding starts (NONE to ABSOLUTE) on the first external-navigation position once the tilt is
  aligned, EK3_SRC1_POSXY = 6 and external navigation was configured at boot; the position (and
  the velocity, when external-navigation velocity is present) is reset to the sample and the
  STATUSTEXTs "EKF3 IMU0 is using external nav data", "... initial pos NED = x,y,z (m)" (and
  "... initial vel NED") are sent; NONE to RELATIVE ("started relative aiding") on body
  odometry fresher than 200 ms with velErr < 1 m/s, EK3_SRC1_VELXY = 6, tilt aligned and gyro
  biases learned;
- the position innovation gate: ratio = (iN^2 + iE^2) / (max(EK3_POS_I_GATE / 100, 1)^2
  (vN + vE)) with v = P + R; the sample is fused when ratio < 1, else rejected; a sample whose
  reset_counter changed resets the position to it; after posRetryTime without a passing sample
  (7 s, 10 s while a velocity is fused) the position has timed out and the next sample resets
  it; a variance above EK3_GLITCH_RAD^2 also resets;
- ABSOLUTE ends ("EKF3 IMU0 stopped aiding") after 15 s without position or velocity; RELATIVE
  after 5 s without body odometry;
- flags: attitude, horizontal and vertical velocity and vertical position once tilt-aligned;
  constant-position mode in NONE; POS_HORIZ_REL/ABS and PRED_POS_HORIZ_REL/ABS in ABSOLUTE
  until the position times out; POS_HORIZ_REL and PRED_POS_HORIZ_REL in RELATIVE;
  UNINITIALIZED before the EKF starts (SITL: 1024, 167 before aiding, 831 while fusing, 39
  after a position timeout).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .autopilot_rules import (
    BODY_ODOM_FRESH_S,
    BODY_ODOM_MAX_ERR_M_S,
    BODY_ODOM_TIMEOUT_S,
    EKF_ATTITUDE,
    EKF_CONST_POS_MODE,
    EKF_POS_HORIZ_ABS,
    EKF_POS_HORIZ_REL,
    EKF_POS_VERT_ABS,
    EKF_PRED_POS_HORIZ_ABS,
    EKF_PRED_POS_HORIZ_REL,
    EKF_UNINITIALIZED,
    EKF_VELOCITY_HORIZ,
    EKF_VELOCITY_VERT,
    POS_RETRY_NO_VEL_S,
    POS_RETRY_USE_VEL_S,
    SOURCE_EXTNAV,
    TILT_DRIFT_MAX_S,
)

AID_NONE, AID_RELATIVE, AID_ABSOLUTE = "none", "relative", "absolute"


@dataclass
class ExtNavSample:
    """One external-navigation sample as EKF3 receives it: position NED (m), posErr (m), angErr
    (rad), arrival time (s), and whether its reset_counter changed."""

    pos: tuple[float, float, float]
    pos_err: float
    ang_err: float
    t: float
    reset: bool = False


@dataclass
class _Axis:
    x: np.ndarray = field(default_factory=lambda: np.zeros(2))
    P: np.ndarray = field(default_factory=lambda: np.diag([1.0e4, 1.0e2]))

    def predict(self, dt: float, q: float) -> None:
        if dt <= 0:
            return
        F = np.array([[1.0, dt], [0.0, 1.0]])
        Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + Q

    def update(self, row: int, z: float, r: float) -> None:
        s = self.P[row, row] + r
        k = self.P[:, row] / s
        self.x = self.x + k * (z - self.x[row])
        self.P = self.P - np.outer(k, self.P[row, :])

    def reset(self, row: int, z: float, var: float) -> None:
        self.x[row] = z
        self.P[row, :] = 0.0
        self.P[:, row] = 0.0
        self.P[row, row] = var


class NavFilter:
    """EKF3's aiding logic around the stand-in filter (module docstring). ``params`` is a
    callable giving a parameter's active value; ``extnav_configured``: some EK3_SRCn_ was 6 at
    boot (EKF3 allocates its external-navigation buffers only then:
    ``AP_NavEKF3_core.cpp`` setup_core)."""

    def __init__(self, params, extnav_configured: bool, texts: list[str]) -> None:
        self.p = params
        self.extnav_configured = bool(extnav_configured)
        self.texts = texts
        self.mode = AID_NONE
        self.initialised = False
        self.tilt_aligned = False
        self.bias_learned = False
        self.axes = [_Axis(), _Axis()]
        self.z = 0.0
        self.vz = 0.0
        self.t = math.nan
        self.pos_timeout = True
        self.last_pos_pass = -math.inf
        self.last_vel_pass = -math.inf
        self.last_body_fuse = -math.inf
        self.last_body_meas = -math.inf
        self.last_body_err = math.inf
        self.pos_test_ratio = 0.0
        self.rejected = 0

    # time ---------------------------------------------------------------------------------
    def advance(self, now: float) -> None:
        if not self.initialised:
            self.t = now
            return
        if math.isfinite(self.t) and now > self.t:
            q = float(self.p("EK3_ACC_P_NSE")) ** 2
            for a in self.axes:
                a.predict(now - self.t, q)
        self.t = max(now, self.t) if math.isfinite(self.t) else now
        self._timeouts(now)

    def _timeouts(self, now: float) -> None:
        if self.mode == AID_ABSOLUTE:
            pos_used = now - self.last_pos_pass <= POS_RETRY_NO_VEL_S
            vel_used = max(self.last_vel_pass, self.last_body_fuse) >= now - POS_RETRY_NO_VEL_S
            if (
                not pos_used
                and not vel_used
                and (
                    now - self.last_pos_pass > TILT_DRIFT_MAX_S
                    and now - max(self.last_vel_pass, self.last_body_fuse) > TILT_DRIFT_MAX_S
                )
            ):
                self._stop_aiding()
            elif not pos_used:
                limit = POS_RETRY_USE_VEL_S if vel_used else POS_RETRY_NO_VEL_S
                if now - self.last_pos_pass > limit:
                    self.pos_timeout = True
        elif self.mode == AID_RELATIVE and now - self.last_body_fuse > BODY_ODOM_TIMEOUT_S:
            self._stop_aiding()

    def _stop_aiding(self) -> None:
        self.mode = AID_NONE
        self.pos_timeout = True
        self.texts.append("EKF3 IMU0 stopped aiding")

    # measurements -------------------------------------------------------------------------
    def _source(self, name: str) -> int:
        return int(self.p(name))

    def extnav_position(self, s: ExtNavSample, vel: tuple[float, float, float] | None) -> str:
        """Fuse (or start aiding with) a position sample; what happened: "started", "fused",
        "reset", "rejected", "not_ready" or "not_source"."""
        self.advance(s.t)
        if not self.extnav_configured or self._source("EK3_SRC1_POSXY") != SOURCE_EXTNAV:
            return "not_source"
        if not self.tilt_aligned:
            return "not_ready"
        if self._source("EK3_SRC1_POSZ") == SOURCE_EXTNAV:
            self.z = s.pos[2]
        if self.mode != AID_ABSOLUTE:
            self._start_absolute(s, vel)
            return "started"
        r = min(max(s.pos_err, 0.01), 10.0) ** 2
        glitch = float(self.p("EK3_GLITCH_RAD")) ** 2
        if s.reset or self.pos_timeout or sum(a.P[0, 0] for a in self.axes) > glitch:
            for a, z in zip(self.axes, s.pos[:2], strict=True):
                a.reset(0, z, r)
            self.pos_timeout, self.last_pos_pass, self.pos_test_ratio = False, s.t, 0.0
            return "reset"
        innov = [a.x[0] - z for a, z in zip(self.axes, s.pos[:2], strict=True)]
        var = sum(a.P[0, 0] + r for a in self.axes)
        gate = max(0.01 * float(self.p("EK3_POS_I_GATE")), 1.0)
        self.pos_test_ratio = (innov[0] ** 2 + innov[1] ** 2) / (gate**2 * var)
        if self.pos_test_ratio >= 1.0:
            self.rejected += 1
            return "rejected"
        for a, z in zip(self.axes, s.pos[:2], strict=True):
            a.update(0, z, r)
        self.last_pos_pass = s.t
        return "fused"

    def _start_absolute(self, s: ExtNavSample, vel) -> None:
        self.mode = AID_ABSOLUTE
        r = min(max(s.pos_err, 0.01), 10.0) ** 2
        for i, a in enumerate(self.axes):
            a.reset(0, s.pos[i], r)
            a.reset(1, vel[i] if vel is not None else 0.0, 0.5**2)
        self.pos_timeout, self.last_pos_pass, self.last_vel_pass = False, s.t, s.t
        x, y, z = s.pos[0], s.pos[1], s.pos[2]
        self.texts.append("EKF3 IMU0 is using external nav data")
        self.texts.append(f"EKF3 IMU0 initial pos NED = {x:3.1f},{y:3.1f},{z:3.1f} (m)")
        if vel is not None:
            vx, vy, vz = vel
            self.texts.append(f"EKF3 IMU0 initial vel NED = {vx:3.1f},{vy:3.1f},{vz:3.1f} (m/s)")

    def extnav_velocity(self, vel: tuple[float, float, float], err: float, t: float) -> bool:
        """Fuse an external-navigation NED velocity (EK3_SRC1_VELXY = 6, in ABSOLUTE)."""
        self.advance(t)
        if not self.extnav_configured or self._source("EK3_SRC1_VELXY") != SOURCE_EXTNAV:
            return False
        if self.mode != AID_ABSOLUTE:
            return False
        r = min(max(err, 0.05), 5.0) ** 2
        for a, v in zip(self.axes, vel[:2], strict=True):
            a.update(1, v, r)
        self.vz = vel[2]
        self.last_vel_pass = t
        return True

    def body_odometry(
        self, vel_ned: tuple[float, float, float], err: float, t: float, delay_s: float = 0.0
    ) -> str:
        """A body-odometry velocity already rotated to NED, arrived at ``t`` and stamped
        ``t - delay_s`` (VISO_DELAY_MS): "started", "fused" or why not. Fresh means the stamp is
        less than 200 ms old when EKF3 looks (readyToUseBodyOdm), so a delay of 200 ms or more
        never starts relative aiding."""
        self.advance(t)
        self.last_body_meas, self.last_body_err = t - delay_s, err
        if self._source("EK3_SRC1_VELXY") != SOURCE_EXTNAV:
            return "not_source"
        if self.mode == AID_NONE:
            fresh = err < BODY_ODOM_MAX_ERR_M_S and t - self.last_body_meas < BODY_ODOM_FRESH_S
            if not (fresh and self.tilt_aligned and self.bias_learned):
                return "not_ready"
            self.mode = AID_RELATIVE
            self.texts.append("EKF3 IMU0 started relative aiding")
            for a in self.axes:
                a.reset(0, a.x[0], 0.0)
        r = min(max(err, 0.05), 5.0) ** 2
        for a, v in zip(self.axes, vel_ned[:2], strict=True):
            a.update(1, v, r)
        self.last_body_fuse = t
        return "fused"

    # outputs ------------------------------------------------------------------------------
    def flags(self) -> int:
        """EKF_STATUS_REPORT flags (module docstring)."""
        if not self.initialised:
            return EKF_UNINITIALIZED
        if not self.tilt_aligned:
            return 0
        f = EKF_ATTITUDE | EKF_VELOCITY_HORIZ | EKF_VELOCITY_VERT | EKF_POS_VERT_ABS
        if self.mode == AID_NONE:
            f |= EKF_CONST_POS_MODE
        elif self.mode == AID_ABSOLUTE and not self.pos_timeout:
            f |= EKF_POS_HORIZ_REL | EKF_POS_HORIZ_ABS | EKF_PRED_POS_HORIZ_REL
            f |= EKF_PRED_POS_HORIZ_ABS
        elif self.mode == AID_RELATIVE:
            f |= EKF_POS_HORIZ_REL | EKF_PRED_POS_HORIZ_REL
        return f

    def position(self) -> tuple[float, float, float] | None:
        """The NED position (m) the autopilot would use; None when not aiding (EKF3's getPosNE
        is false in constant-position mode, so no LOCAL_POSITION_NED is sent)."""
        if not self.initialised or self.mode == AID_NONE:
            return None
        return float(self.axes[0].x[0]), float(self.axes[1].x[0]), float(self.z)

    def velocity(self) -> tuple[float, float, float]:
        return float(self.axes[0].x[1]), float(self.axes[1].x[1]), float(self.vz)

    def position_std(self) -> float:
        """sqrt(P_NN + P_EE) of the stand-in filter, m."""
        return math.sqrt(sum(a.P[0, 0] for a in self.axes))
