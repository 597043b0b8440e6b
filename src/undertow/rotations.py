"""Rotations in the robotics (ZYX, roll-pitch-yaw) convention, vectorized over leading axes.

R(phi, theta, psi) = Rz(psi) Ry(theta) Rx(phi) maps body vectors to the world frame.
Quaternions are stored (x, y, z, w) as in ROS and TUM files.
"""

from __future__ import annotations

import math

import numpy as np


def wrap_angle(a):
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def rpy_to_matrix(rpy) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from roll, pitch, yaw (..., 3): Rz(psi) Ry(theta) Rx(phi)."""
    rpy = np.asarray(rpy, dtype=float)
    cr, sr = np.cos(rpy[..., 0]), np.sin(rpy[..., 0])
    cp, sp = np.cos(rpy[..., 1]), np.sin(rpy[..., 1])
    cy, sy = np.cos(rpy[..., 2]), np.sin(rpy[..., 2])
    R = np.empty(rpy.shape[:-1] + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def world_to_body(rpy, v_world) -> np.ndarray:
    """v^B = R(eta)^T v^W for rows of attitudes ``rpy`` (N, 3) and world vectors (N, 3)."""
    return np.einsum("nji,nj->ni", rpy_to_matrix(rpy), v_world)


def matrix_to_rpy(R) -> np.ndarray:
    """Roll, pitch, yaw (..., 3) of rotation matrices (..., 3, 3) (inverse of rpy_to_matrix)."""
    R = np.asarray(R, dtype=float)
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def rpy_to_quaternion(rpy) -> np.ndarray:
    """Quaternions (..., 4) as (x, y, z, w) from roll, pitch, yaw (..., 3), w >= 0."""
    rpy = np.asarray(rpy, dtype=float)
    hr, hp, hy = rpy[..., 0] / 2, rpy[..., 1] / 2, rpy[..., 2] / 2
    cr, sr, cp, sp, cy, sy = np.cos(hr), np.sin(hr), np.cos(hp), np.sin(hp), np.cos(hy), np.sin(hy)
    q = np.stack(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ],
        axis=-1,
    )
    return np.where(q[..., 3:4] < 0, -q, q)


def rpy_to_quaternion_scalar(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """(x, y, z, w), w >= 0, of one (roll, pitch, yaw): :func:`rpy_to_quaternion` in scalar
    arithmetic, for one message at a time (a few times faster than numpy on one row)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    q = (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )
    return (-q[0], -q[1], -q[2], -q[3]) if q[3] < 0 else q  # (as numpy's where: NaN kept)


def matrix_to_quaternion_scalar(R) -> tuple[float, float, float, float]:
    """(x, y, z, w), w >= 0, of one rotation matrix, by the largest of the four squared
    components (Shepperd, "Quaternion from rotation matrix", J. Guidance and Control 1(3),
    1978): 4 w^2 = 1 + tr R, 4 x^2 = 1 + R00 - R11 - R22, ...; the others from the
    off-diagonal sums and differences."""
    rows = R.tolist() if isinstance(R, np.ndarray) else R
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = ([float(v) for v in row] for row in rows)
    tr = r00 + r11 + r22
    if tr >= max(r00, r11, r22):
        s = 2.0 * math.sqrt(max(1.0 + tr, 0.0))
        q = ((r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s, s / 4.0)
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r00 - r11 - r22, 0.0))
        q = (s / 4.0, (r01 + r10) / s, (r02 + r20) / s, (r21 - r12) / s)
    elif r11 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r11 - r00 - r22, 0.0))
        q = ((r01 + r10) / s, s / 4.0, (r12 + r21) / s, (r02 - r20) / s)
    else:
        s = 2.0 * math.sqrt(max(1.0 + r22 - r00 - r11, 0.0))
        q = ((r02 + r20) / s, (r12 + r21) / s, s / 4.0, (r10 - r01) / s)
    return q if q[3] >= 0 else (-q[0], -q[1], -q[2], -q[3])


def quaternion_to_rpy_one(q) -> tuple[float, float, float]:
    """:func:`quaternion_to_rpy` of one quaternion (x, y, z, w), bit for bit: the arithmetic in
    scalars (the same operations in the same order; the norm as numpy sums four squares), the
    arc functions from numpy, whose vectorized forms may round differently from libm's."""
    x, y, z, w = (float(v) for v in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n == 0.0:  # (squares that underflow) numpy's division by zero: +-inf, 0 / 0 NaN
        x, y, z, w = (math.copysign(math.inf, v) if v else math.nan for v in (x, y, z, w))
    else:
        x, y, z, w = x / n, y / n, z / n, w / n
    s = 2 * (w * y - z * x)
    s = min(max(s, -1.0), 1.0) if s == s else s  # np.clip (NaN kept)
    roll, yaw = np.arctan2([2 * (w * x + y * z), 2 * (w * z + x * y)],
                           [1 - 2 * (x * x + y * y), 1 - 2 * (y * y + z * z)]).tolist()  # fmt: skip
    return roll, float(np.arcsin(s)), yaw


def quaternion_to_rpy(q) -> np.ndarray:
    """Roll, pitch, yaw (..., 3) of quaternions (..., 4) stored (x, y, z, w); normalizes first."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)
