"""ArduSub 4.x's rules for external navigation, as read from ArduPilot's source (GPL-3.0,
github.com/ArduPilot/ardupilot; the SITL of ``../shared/tools/ardusub`` is commit 90700977,
ArduSub V4.7.0-dev): what the virtual autopilot (:mod:`undertow.sim.robot.autopilot`) accepts,
how it reduces a covariance to one error, its parameters and timeouts.

Messages (``libraries/GCS_MAVLink/GCS_Common.cpp``, ``handle_odometry``,
``handle_vision_position_estimate``, ``handle_vision_position_delta``):

- ``ODOMETRY`` is used only with ``frame_id`` = MAV_FRAME_LOCAL_FRD (20) and ``child_frame_id`` =
  MAV_FRAME_BODY_FRD (12); any other pair returns before anything is recorded (no reply, no
  text). Its velocity (body FRD) is rotated by the message's quaternion to NED and fused as an
  external-navigation velocity with error ``VISO_VEL_M_NSE`` (its velocity covariance is unused).
- ``VISION_POSITION_ESTIMATE`` takes the same pose path with quality 0 (it has no quality field).
- ``VISION_POSITION_DELTA`` is a body-frame velocity v = position_delta / (time_delta_usec 1e-6)
  stamped with its arrival time (``AP_VisualOdom_Backend.cpp``), whose 1-sigma error is
  ``velErr = EK3_VIS_VERR_MIN + (EK3_VIS_VERR_MAX - EK3_VIS_VERR_MIN) (1 - 0.01 confidence)``
  (``AP_NavEKF3_Measurements.cpp``, ``writeBodyFrameOdom``); no quality gate.

The covariance reduction (``handle_odometry`` / ``handle_common_vision_position_estimate_data``)
when c[0] is not NaN, else 0 (c: the 21 upper-triangle terms, row-major):

- ``cbrt`` (ArduPilot up to PR 32084 of February 2026, i.e. every ArduSub 4.x release and the
  SITL here, whose dataflash VISP.PErr shows it): posErr = cbrt(c0^2 + c6^2 + c11^2),
  angErr = cbrt(c15^2 + c18^2 + c20^2);
- ``sqrt`` (ArduPilot master after PR 32084): posErr = sqrt(c0 + c6 + c11),
  angErr = sqrt(c15 + c18 + c20).

Then (``AP_VisualOdom_MAV.cpp``, ``handle_pose_estimate``): posErr clamped to
[VISO_POS_M_NSE, 100] m, angErr to [VISO_YAW_M_NSE, 1.5] rad, positions multiplied by
VISO_SCALE, and the sample is passed to EKF3 only when quality >= VISO_QUAL_MIN (also for the
velocity). EKF3 (``AP_NavEKF3_Measurements.cpp``, ``writeExtNavData``) drops a sample closer than
``extNavIntervalMin_ms`` = 20 ms to the previous one, and any before its states are initialised;
a changed ``reset_counter`` (``AP_VisualOdom_Backend::get_reset_timestamp_ms``) marks the sample
as a position reset, which EKF3 applies by jumping its position to it
(``AP_NavEKF3_PosVelFusion.cpp``, ``SelectVelPosFusion``) instead of gating it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

#: MAV_FRAME_LOCAL_FRD and MAV_FRAME_BODY_FRD (common.xml): the only ODOMETRY pair EKF3 takes
FRAME_LOCAL_FRD = 20
FRAME_BODY_FRD = 12
COVARIANCE_RULES = ("cbrt", "sqrt")
#: EKF3's minimum spacing of external-navigation samples, s (AP_NavEKF3.h extNavIntervalMin_ms)
EXTNAV_INTERVAL_MIN_S = 0.020
#: minimum spacing of body-odometry samples, s (AP_NavEKF3.h sensorIntervalMin_ms)
BODY_ODOM_INTERVAL_MIN_S = 0.050
#: body odometry must be fresher than this to start relative aiding, s (AP_NavEKF3_Control.cpp
#: readyToUseBodyOdm) and its velErr below 1 m/s
BODY_ODOM_FRESH_S = 0.200
BODY_ODOM_MAX_ERR_M_S = 1.0
#: AP_NavEKF3.h: posRetryTimeNoVel_ms, posRetryTimeUseVel_ms, tiltDriftTimeMax_ms; relative
#: aiding ends 5 s after the last body-odometry fusion (AP_NavEKF3_Control.cpp setAidingMode)
POS_RETRY_NO_VEL_S = 7.0
POS_RETRY_USE_VEL_S = 10.0
TILT_DRIFT_MAX_S = 15.0
BODY_ODOM_TIMEOUT_S = 5.0
#: ArduPilot's limit of a SET_GPS_GLOBAL_ORIGIN altitude (AP_Common/Location.h), m
LOCATION_ALT_MAX_M = 83000.0

#: EKF_STATUS_REPORT flags (common.xml EKF_STATUS_FLAGS; set in AP_NavEKF3_Control.cpp
#: updateFilterStatus and sent by AP_NavEKF3.cpp send_status_report)
EKF_ATTITUDE = 1
EKF_VELOCITY_HORIZ = 2
EKF_VELOCITY_VERT = 4
EKF_POS_HORIZ_REL = 8
EKF_POS_HORIZ_ABS = 16
EKF_POS_VERT_ABS = 32
EKF_CONST_POS_MODE = 128
EKF_PRED_POS_HORIZ_REL = 256
EKF_PRED_POS_HORIZ_ABS = 512
EKF_UNINITIALIZED = 1024


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: its default in the SITL here (read with PARAM_REQUEST_LIST), its MAVLink
    type (MAV_PARAM_TYPE: 2 int8, 4 int16, 6 int32, 9 real32) and whether ArduPilot's parameter
    docs say ``@RebootRequired: True`` (the value read at boot is the one used)."""

    default: float
    mav_type: int = 9
    reboot: bool = False


#: The parameters that decide whether EKF3 uses external navigation, with where they are
#: documented: AHRS_EKF_TYPE (AP_AHRS.cpp), EK3_* (AP_NavEKF3.cpp; EK3_SRCn_* in
#: AP_NavEKF/AP_NavEKF_Source.cpp, no reboot), GPS1_TYPE (AP_GPS.cpp), VISO_* (AP_VisualOdom.cpp).
PARAMS: dict[str, ParamSpec] = {
    "AHRS_EKF_TYPE": ParamSpec(3, 2),
    "AHRS_OPTIONS": ParamSpec(0, 4),
    "EK2_ENABLE": ParamSpec(0, 2, True),
    "EK3_ENABLE": ParamSpec(1, 2, True),
    "EK3_IMU_MASK": ParamSpec(3, 2, True),
    "EK3_SRC1_POSXY": ParamSpec(3, 2),
    "EK3_SRC1_VELXY": ParamSpec(3, 2),
    "EK3_SRC1_POSZ": ParamSpec(1, 2),
    "EK3_SRC1_VELZ": ParamSpec(0, 2),
    "EK3_SRC1_YAW": ParamSpec(1, 2),
    "EK3_SRC_OPTIONS": ParamSpec(0, 4),
    "EK3_VIS_VERR_MIN": ParamSpec(0.1),
    "EK3_VIS_VERR_MAX": ParamSpec(0.9),
    "EK3_POS_I_GATE": ParamSpec(500, 4),
    "EK3_VEL_I_GATE": ParamSpec(500, 4),
    "EK3_GLITCH_RAD": ParamSpec(25, 2),
    "EK3_ACC_P_NSE": ParamSpec(0.35),
    "GPS1_TYPE": ParamSpec(1, 2, True),
    "VISO_TYPE": ParamSpec(0, 2, True),
    "VISO_POS_X": ParamSpec(0.0),
    "VISO_POS_Y": ParamSpec(0.0),
    "VISO_POS_Z": ParamSpec(0.0),
    "VISO_ORIENT": ParamSpec(0, 2),
    "VISO_SCALE": ParamSpec(1.0),
    "VISO_DELAY_MS": ParamSpec(10, 4),
    "VISO_VEL_M_NSE": ParamSpec(0.1),
    "VISO_POS_M_NSE": ParamSpec(0.2),
    "VISO_YAW_M_NSE": ParamSpec(0.2),
    "VISO_QUAL_MIN": ParamSpec(0, 2),
}

#: EK3_SRCn_* values (AP_NavEKF_Source.h SourceXY / SourceZ / SourceYaw)
SOURCE_EXTNAV = 6
SOURCE_BARO = 1


def param_value(mav_type: int, value: float) -> float:
    """``value`` as a parameter of ``mav_type`` stores it: integer types round toward zero (as
    AP_Param's cast does) and saturate; real32 rounds to float32."""
    import numpy as np

    if mav_type == 9:
        return float(np.float32(value))
    bits = {1: 8, 2: 8, 3: 16, 4: 16, 5: 32, 6: 32}.get(mav_type, 32)
    low, high = (
        (0, 2**bits - 1) if mav_type in (1, 3, 5) else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    )
    v = math.trunc(value) if math.isfinite(value) else 0
    return float(min(max(v, low), high))


def reduce_covariance(cov: Sequence[float], rule: str = "cbrt") -> tuple[float, float]:
    """(posErr, angErr) of a 21-term pose covariance (module docstring): 0, 0 when c[0] is NaN."""
    if rule not in COVARIANCE_RULES:
        raise ValueError(f"covariance rule {rule!r}: expected one of {COVARIANCE_RULES}")
    c = [float(v) for v in cov]
    if len(c) < 21 or math.isnan(c[0]):
        return 0.0, 0.0
    if rule == "cbrt":
        return (
            math.cbrt(c[0] ** 2 + c[6] ** 2 + c[11] ** 2),
            math.cbrt(c[15] ** 2 + c[18] ** 2 + c[20] ** 2),
        )
    pos, ang = c[0] + c[6] + c[11], c[15] + c[18] + c[20]
    return (math.sqrt(pos) if pos >= 0 else math.nan, math.sqrt(ang) if ang >= 0 else math.nan)


def covariance_for_error(pos_err_m: float, ang_err_rad: float, rule: str = "cbrt") -> list[float]:
    """The 21-term diagonal covariance (equal variances per axis) that :func:`reduce_covariance`
    turns back into (pos_err_m, ang_err_rad): variance v = sqrt(e^3 / 3) under ``cbrt``
    (3 v^2 = e^3), v = e^2 / 3 under ``sqrt``."""
    if rule not in COVARIANCE_RULES:
        raise ValueError(f"covariance rule {rule!r}: expected one of {COVARIANCE_RULES}")

    def var(e: float) -> float:
        return math.sqrt(e**3 / 3.0) if rule == "cbrt" else e**2 / 3.0

    cov = [0.0] * 21
    cov[0] = cov[6] = cov[11] = var(pos_err_m)
    cov[15] = cov[18] = cov[20] = var(ang_err_rad)
    return cov


def clamp_errors(
    pos_err: float, ang_err: float, pos_floor: float, yaw_floor: float
) -> tuple[float, float]:
    """EKF3's view of the errors: posErr in [VISO_POS_M_NSE, 100] m, angErr in
    [VISO_YAW_M_NSE, 1.5] rad (constrain_float: a NaN comes out as the floor)."""

    def constrain(v: float, low: float, high: float) -> float:
        return low if math.isnan(v) else min(max(v, low), high)

    return constrain(pos_err, pos_floor, 100.0), constrain(ang_err, yaw_floor, 1.5)


def body_odometry_error(confidence: float, verr_min: float, verr_max: float) -> float:
    """velErr (m/s) of a VISION_POSITION_DELTA with ``confidence`` (0-100, module docstring)."""
    return verr_min + (verr_max - verr_min) * (1.0 - 0.01 * float(confidence))


def valid_origin(lat_e7: int, lon_e7: int, alt_mm: int) -> bool:
    """GCS_Common.cpp ``handle_set_gps_global_origin`` and ``set_ekf_origin``: a latitude within
    +-90 deg, a longitude within +-180 deg, |altitude| <= LOCATION_ALT_MAX_M, and not all
    zero; anything else is dropped silently."""
    if abs(lat_e7) > 900_000_000 or abs(lon_e7) > 1_800_000_000:
        return False
    if abs(alt_mm) > LOCATION_ALT_MAX_M * 1000:
        return False
    return not (lat_e7 == 0 and lon_e7 == 0 and int(alt_mm * 0.1) == 0)


def quaternion_rotate(q_wxyz: Sequence[float], v: Sequence[float]) -> tuple[float, float, float]:
    """q v q* for a MAVLink quaternion (w, x, y, z): ArduPilot's ``q * vel`` (body to NED)."""
    w, x, y, z = (float(a) for a in q_wxyz)
    n = math.sqrt(w * w + x * x + y * y + z * z) or 1.0
    w, x, y, z = w / n, x / n, y / n, z / n
    vx, vy, vz = (float(a) for a in v)
    tx, ty, tz = 2 * (y * vz - z * vy), 2 * (z * vx - x * vz), 2 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )
