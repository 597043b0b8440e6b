"""What undertow's covariance becomes on its way to the autopilot, and what ArduPilot makes of it.

MAVLink's 21-term covariances (``ODOMETRY.pose_covariance``, ``ODOMETRY.velocity_covariance``,
``VISION_POSITION_ESTIMATE.covariance``; common.xml) are "the row-major representation of a 6x6
cross-covariance matrix upper right triangle: the first six entries are the first row, the next
five the second row, etc.": for a 6x6 C, c = (C00..C05, C11..C15, C22..C25, C33..C35, C44, C45,
C55), its diagonal at 0, 6, 11, 15, 18, 20 (:func:`upper_triangle`, :func:`from_upper_triangle`).

What undertow sends (:func:`pose_covariance`): the filter's covariance of (x, y, z, roll, pitch,
yaw), P[0:6, 0:6] of the 18-state model, carried into the autopilot's frame (the world frame
turned by the heading offset dpsi about z, :mod:`.frame`) and inflated,

    C = k T P T^T,   T = diag(Rz(dpsi), I3),

``k`` = ``live.autopilot_covariance_inflation`` (default 2): EKF3 fuses each message as
independent of what it already knows, but undertow's estimate shares information with EKF3's own
state (the autopilot's attitude and gyro rates, which undertow's filter takes as its IMU, and the
same pressure sensor); for two estimates of unknown cross-correlation, covariance intersection
(Julier and Uhlmann, "A non-divergent estimation algorithm in the presence of unknown
correlations", ACC 1997) fuses P_c^-1 = w P_a^-1 + (1 - w) P_b^-1, consistent for every
correlation, which is fusing each with its covariance divided by its weight; the even weight
w = 1/2 is the factor 2. The velocity covariance is P[6:12, 6:12] (body u, v, w, p, q, r:
ODOMETRY's child frame is the body), times k.

What ArduPilot does with it (:func:`ardupilot_errors`; ArduPilot's
libraries/GCS_MAVLink/GCS_Common.cpp, ``handle_odometry`` and
``handle_common_vision_position_estimate_data``): when c[0] is not NaN, in every ArduSub 4.x
release (and the SITL build the tests run, whose dataflash VISP.PErr shows it)

    posErr = cbrt(c0^2 + c6^2 + c11^2),   angErr = cbrt(c15^2 + c18^2 + c20^2),

and since ArduPilot PR 32084 (February 2026, master) posErr = sqrt(c0 + c6 + c11), angErr =
sqrt(c15 + c18 + c20) (else both 0), clamped to [VISO_POS_M_NSE, 100] m and [VISO_YAW_M_NSE,
1.5] rad (libraries/AP_VisualOdom/AP_VisualOdom_MAV.cpp, ``handle_pose_estimate``); EKF3 then
takes posErr as the standard deviation of each position axis (AP_NavEKF3_Measurements.cpp,
``writeExtNavData``) and the yaw error as at least 5 degrees. Either reduction takes one number
for the three axes: for a round horizontal error s over a well-known depth (sx = sy = s, sz
small) the square root gives sqrt(2) s, the cube root 2^(1/3) s^(4/3) (not a length: below 0.5 m
it reports less than s, above more). The velocity covariance of ODOMETRY is not read: EKF3 takes
VISO_VEL_M_NSE (GCS_Common.cpp passes 0 as the velocity error).

VISION_POSITION_DELTA carries a ``confidence`` c (%) instead; EKF3 maps it linearly onto a
velocity error (AP_NavEKF3_Measurements.cpp, ``writeBodyFrameOdom``),

    velErr = EK3_VIS_VERR_MIN + (EK3_VIS_VERR_MAX - EK3_VIS_VERR_MIN) (1 - c / 100),

so undertow sends the c whose velErr is its own velocity std (:func:`confidence_from_std`, the
inverse, clamped to [0, 100]; defaults 0.1 and 0.9 m/s, AP_NavEKF3.cpp).
"""

from __future__ import annotations

import math

import numpy as np

#: (row, column) of each of the 21 terms, row-major upper triangle of a 6x6
UPPER = tuple((i, j) for i in range(6) for j in range(i, 6))
#: where the diagonal of the 6x6 sits among the 21 terms
DIAGONAL = (0, 6, 11, 15, 18, 20)
#: EK3_VIS_VERR_MIN / MAX defaults (m/s), AP_NavEKF3.cpp
VIS_VERR_MIN_DEFAULT, VIS_VERR_MAX_DEFAULT = 0.1, 0.9


def upper_triangle(C) -> list[float]:
    """The 21 terms of a 6x6 C: C[i, j] for i <= j, row by row (module docstring)."""
    C = np.asarray(C, dtype=float)
    return [float(C[i, j]) for i, j in UPPER]


def from_upper_triangle(c) -> np.ndarray:
    """The symmetric 6x6 of 21 upper-triangle terms (inverse of :func:`upper_triangle`)."""
    C = np.zeros((6, 6))
    for k, (i, j) in enumerate(UPPER):
        C[i, j] = C[j, i] = float(c[k])
    return C


def rotate_z(yaw_offset_rad: float) -> np.ndarray:
    """Rz(dpsi): turns a world vector into the autopilot's frame (:mod:`.frame`)."""
    c, s = math.cos(yaw_offset_rad), math.sin(yaw_offset_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def pose_covariance(P, yaw_offset_rad: float = 0.0, inflation: float = 1.0) -> np.ndarray:
    """C = k T P[0:6, 0:6] T^T, T = diag(Rz(dpsi), I3) (module docstring)."""
    P = np.asarray(P, dtype=float)
    T = np.eye(6)
    T[:3, :3] = rotate_z(yaw_offset_rad)
    C = float(inflation) * (T @ P[:6, :6] @ T.T)
    return 0.5 * (C + C.T)


def velocity_covariance(P, inflation: float = 1.0) -> np.ndarray:
    """k P[6:12, 6:12]: body velocity (u, v, w) and rates (p, q, r), the child frame's."""
    V = float(inflation) * np.asarray(P, dtype=float)[6:12, 6:12]
    return 0.5 * (V + V.T)


#: ArduPilot's reductions of the 21 terms: ``cbrt`` (ArduSub 4.x), ``sqrt`` (master since PR 32084)
REDUCTIONS = ("cbrt", "sqrt")


def ardupilot_errors(c, rule: str = "cbrt") -> tuple[float, float]:
    """(posErr m, angErr rad) as ArduPilot reduces 21 terms, before its clamps (module doc;
    GCS_Common.cpp): ``cbrt`` cbrt(c0^2 + c6^2 + c11^2), cbrt(c15^2 + c18^2 + c20^2) (ArduSub
    4.x), ``sqrt`` sqrt(c0 + c6 + c11), sqrt(c15 + c18 + c20); both 0 when c[0] is NaN."""
    if rule not in REDUCTIONS:
        raise ValueError(f"covariance reduction {rule!r}: expected one of {REDUCTIONS}")
    if math.isnan(c[0]):
        return 0.0, 0.0
    if rule == "cbrt":
        return (math.cbrt(c[0] ** 2 + c[6] ** 2 + c[11] ** 2),
                math.cbrt(c[15] ** 2 + c[18] ** 2 + c[20] ** 2))  # fmt: skip
    return math.sqrt(c[0] + c[6] + c[11]), math.sqrt(c[15] + c[18] + c[20])


def clamped_errors(c, pos_noise: float = 0.2, yaw_noise: float = 0.2) -> tuple[float, float]:
    """posErr in [VISO_POS_M_NSE, 100] m and angErr in [VISO_YAW_M_NSE, 1.5] rad, what EKF3
    receives (AP_VisualOdom_MAV.cpp; parameter defaults 0.2 and 0.2, AP_VisualOdom.cpp)."""
    pos, ang = ardupilot_errors(c)
    return min(max(pos, pos_noise), 100.0), min(max(ang, yaw_noise), 1.5)


def horizontal_std(P, inflation: float = 1.0) -> float:
    """sqrt(k (Pxx + Pyy)): the radius of the horizontal one-sigma error (m), the quantity the
    safety bound is on (independent of the heading offset: a rotation keeps the trace)."""
    P = np.asarray(P, dtype=float)
    return math.sqrt(max(float(inflation) * (P[0, 0] + P[1, 1]), 0.0))


def velocity_std(P, inflation: float = 1.0) -> float:
    """sqrt(k (Puu + Pvv) / 2): the horizontal body-velocity std (m/s) per axis, root mean
    square of the two axes EKF3 fuses a body-frame velocity with one error."""
    P = np.asarray(P, dtype=float)
    return math.sqrt(max(float(inflation) * (P[6, 6] + P[7, 7]) / 2.0, 0.0))


def confidence_from_std(std_m_s: float, err_min: float = VIS_VERR_MIN_DEFAULT,
                        err_max: float = VIS_VERR_MAX_DEFAULT) -> float:  # fmt: skip
    """c = 100 (1 - (std - min) / (max - min)) clamped to [0, 100]: the confidence whose EKF3
    velocity error is ``std`` (module docstring); NaN std gives 0."""
    if not (err_max > err_min) or not math.isfinite(std_m_s):
        return 0.0
    c = 100.0 * (1.0 - (std_m_s - err_min) / (err_max - err_min))
    return min(max(c, 0.0), 100.0)


def ekf_velocity_error(confidence: float, err_min: float = VIS_VERR_MIN_DEFAULT,
                       err_max: float = VIS_VERR_MAX_DEFAULT) -> float:  # fmt: skip
    """velErr = min + (max - min) (1 - 0.01 c): EKF3's mapping (writeBodyFrameOdom)."""
    return err_min + (err_max - err_min) * (1.0 - 0.01 * confidence)


def quality_from_std(std_m: float, bound_m: float) -> int:
    """ODOMETRY ``quality`` (1 worst .. 100 best; 0 unknown, -1 failed): 100 (1 - s / bound)
    rounded, at least 1 while undertow sends (it stops above the bound). ArduPilot drops a
    message whose quality is below VISO_QUAL_MIN (AP_VisualOdom_MAV.cpp), so VISO_QUAL_MIN q
    makes the autopilot ignore undertow from a std of (1 - q / 100) bound on."""
    if not math.isfinite(std_m) or not bound_m > 0:
        return 1
    return int(min(max(round(100.0 * (1.0 - std_m / bound_m)), 1), 100))
