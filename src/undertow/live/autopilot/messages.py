"""The three messages undertow sends the autopilot, built from one filter state (x, P) of
:mod:`undertow.estimation.model` (x[0:3] position, x[3:6] roll-pitch-yaw, x[6:9] body velocity
u, v, w, x[9:12] body rates p, q, r), in the autopilot's frame (:mod:`.frame`: heading offset
dpsi) with the covariance of :mod:`.covariance` (inflation k). Field meanings and units are
MAVLink's common.xml (pymavlink's ``ardupilotmega`` dialect, MAVLink 2).

- ``odometry``: ODOMETRY (331) with frame_id MAV_FRAME_LOCAL_FRD (20) and child_frame_id
  MAV_FRAME_BODY_FRD (12), the one pair ArduPilot accepts (any other is dropped without a word:
  GCS_Common.cpp, ``handle_odometry``); position, attitude quaternion q = (w, x, y, z), body
  velocity and rates (child frame), ``pose_covariance`` and ``velocity_covariance`` (21 terms
  each), ``reset_counter``, ``estimator_type`` MAV_ESTIMATOR_TYPE_VIO (3) and ``quality``.
  The estimator type: undertow is an inertial filter aided by a velocity sensor with a real
  covariance; MAV_ESTIMATOR_TYPE_NAIVE (1) is defined as "a naive estimator without any real
  covariance feedback", which it is not, and VIO ("visual-inertial estimate") is the enum's
  aided-inertial class (none names acoustic aiding); ArduPilot does not read the field.
- ``vision_position_estimate``: VISION_POSITION_ESTIMATE (102): position, roll, pitch, yaw,
  the same 21-term pose covariance, ``reset_counter`` (ArduPilot passes quality 0 for it).
- ``vision_position_delta``: VISION_POSITION_DELTA (11011) over the interval dt between two
  states: ``position_delta`` = v^B dt (the filtered body velocity at the newer state times dt, in
  its body frame), ``angle_delta`` = Log(R_a^T R_b) (the rotation vector from the older to the
  newer body frame; :func:`rotation_vector`), ``time_delta_usec`` = dt, ``confidence`` from
  the velocity std (:func:`~.covariance.confidence_from_std`). ArduPilot rotates both deltas by
  VISO_ORIENT (AP_VisualOdom_Backend.cpp): it must be 0 (forward), the body frame undertow uses.

Times (``time_usec``/``usec``) are the state's time in the autopilot's clock (:mod:`.frame`).
"""

from __future__ import annotations

import math

import numpy as np

from ...rotations import rpy_to_matrix, rpy_to_quaternion_scalar, wrap_angle
from . import covariance as cov

MAV_FRAME_LOCAL_FRD = 20
MAV_FRAME_BODY_FRD = 12
MAV_ESTIMATOR_TYPE_VIO = 3
#: what undertow sends in each mode (``live.autopilot_mode``)
MESSAGE_OF_MODE = {
    "odometry": "ODOMETRY",
    "vision-position": "VISION_POSITION_ESTIMATE",
    "velocity-delta": "VISION_POSITION_DELTA",
}


def dialect():
    """pymavlink's MAVLink 2 ``ardupilotmega`` module (imported on first use)."""
    from pymavlink.dialects.v20 import ardupilotmega

    return ardupilotmega


def autopilot_pose(x, yaw_offset_rad: float) -> tuple[np.ndarray, tuple[float, float, float]]:
    """(Rz(dpsi) p, (phi, theta, wrap(psi + dpsi))) of a state (:mod:`.frame`)."""
    x = np.asarray(x, dtype=float)
    p = cov.rotate_z(yaw_offset_rad) @ x[0:3]
    rpy = (float(x[3]), float(x[4]), float(wrap_angle(x[5] + yaw_offset_rad)))
    return p, rpy


def quaternion_wxyz(rpy) -> list[float]:
    """MAVLink's attitude quaternion (w, x, y, z) of roll, pitch, yaw."""
    qx, qy, qz, qw = rpy_to_quaternion_scalar(*(float(a) for a in rpy))
    return [qw, qx, qy, qz]


def odometry(time_usec: int, x, P, *, yaw_offset_rad: float = 0.0, inflation: float = 1.0,
             reset_counter: int = 0, quality: int = 100):  # fmt: skip
    """ODOMETRY of the state (module docstring)."""
    x = np.asarray(x, dtype=float)
    p, rpy = autopilot_pose(x, yaw_offset_rad)
    pose = cov.upper_triangle(cov.pose_covariance(P, yaw_offset_rad, inflation))
    vel = cov.upper_triangle(cov.velocity_covariance(P, inflation))
    return dialect().MAVLink_odometry_message(
        int(time_usec), MAV_FRAME_LOCAL_FRD, MAV_FRAME_BODY_FRD, *map(float, p),
        quaternion_wxyz(rpy), *map(float, x[6:12]), pose, vel,
        reset_counter=int(reset_counter) % 256, estimator_type=MAV_ESTIMATOR_TYPE_VIO,
        quality=int(quality),
    )  # fmt: skip


def vision_position_estimate(time_usec: int, x, P, *, yaw_offset_rad: float = 0.0,
                             inflation: float = 1.0, reset_counter: int = 0):  # fmt: skip
    """VISION_POSITION_ESTIMATE of the state (module docstring)."""
    p, rpy = autopilot_pose(x, yaw_offset_rad)
    pose = cov.upper_triangle(cov.pose_covariance(P, yaw_offset_rad, inflation))
    return dialect().MAVLink_vision_position_estimate_message(
        int(time_usec), *map(float, p), *rpy, pose, reset_counter=int(reset_counter) % 256
    )


def rotation_vector(R) -> np.ndarray:
    """Log(R): the axis-angle vector a (|a| = angle in [0, pi]) with Exp(a) = R, the inverse of
    Rodrigues' formula (a = th / (2 sin th) (R32 - R23, R13 - R31, R21 - R12), th = arccos((tr R
    - 1) / 2); near pi from the symmetric part, (R + R^T) / 2 = cos th I + (1 - cos th) n n^T)."""
    R = np.asarray(R, dtype=float)
    c = min(max((np.trace(R) - 1.0) / 2.0, -1.0), 1.0)
    th = math.acos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if th < 1e-7:
        return 0.5 * w  # (th / sin th -> 1)
    if math.pi - th > 1e-4:
        return th / (2.0 * math.sin(th)) * w
    # near pi, from the symmetric part: (R + R^T) / 2 = cos th I + (1 - cos th) n n^T
    B = ((R + R.T) / 2.0 - c * np.eye(3)) / (1.0 - c)
    k = int(np.argmax(np.diag(B)))
    n = B[:, k] / math.sqrt(max(B[k, k], 1e-300))
    n = n if float(np.dot(n, w)) >= 0 else -n  # (w = 2 sin th n fixes the sign)
    return th * n / np.linalg.norm(n)


def vision_position_delta(time_usec: int, dt_s: float, x_before, x_after, confidence: float):
    """VISION_POSITION_DELTA from ``x_before`` to ``x_after`` over ``dt_s`` (module
    docstring)."""
    xa = np.asarray(x_before, dtype=float)
    xb = np.asarray(x_after, dtype=float)
    angle = rotation_vector(rpy_to_matrix(xa[3:6]).T @ rpy_to_matrix(xb[3:6]))
    delta = xb[6:9] * float(dt_s)
    return dialect().MAVLink_vision_position_delta_message(
        int(time_usec), int(round(dt_s * 1e6)), [float(a) for a in angle],
        [float(d) for d in delta], float(confidence),
    )  # fmt: skip
