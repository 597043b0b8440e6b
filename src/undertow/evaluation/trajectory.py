"""Trajectory evaluation against ground truth: the paper's Table II metrics plus NEES.

- Ground truth is interpolated to the estimate times (linear in position, linear in unwrapped
  angles); estimates outside the ground-truth span are dropped (counted).
- Ground-truth velocity, as the paper: differentiate the (2000 Hz) positions and smooth by
  convolution with a normalized window of ``smoothing_s`` seconds; the world velocity is then
  expressed in the body frame with the true attitude, v^B = R(eta)^T v^W, to compare with the
  filter's nu = (u, v, w) (what the DVL measures).
- No alignment by default (NOTES.md section 3: alignment on a straight line is ill-posed and
  hides the heading drift being measured); ``align="origin"`` moves the estimate rigidly so that
  its first pose equals the ground truth's (evo's ``--align_origin``).
- RMSE per axis: sqrt(mean(e_i^2)), angles wrapped to [-pi, pi).
- NEES of the pose: epsilon_k = e_k^T P_k^{-1} e_k over the 6 pose states; for a consistent filter
  its mean is 6 and 95 % of samples lie below chi2_6(0.95) = 12.59.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.stats import chi2

from ..errors import DataError
from ..log import GroundTruth
from ..rotations import matrix_to_rpy, rpy_to_matrix, wrap_angle
from ..trajectory import Trajectory

AXES = ("x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz")
UNITS = ("m", "m", "m", "rad", "rad", "rad", "mps", "mps", "mps")


@dataclass(frozen=True)
class TrajectoryErrors:
    """Per-axis RMSE (units in the key names) and pose NEES statistics."""

    rmse: dict[str, float]
    nees_mean: float
    nees_dof: int
    nees_fraction_in_95: float
    samples: int
    dropped_outside_ground_truth: int
    align: str

    def to_dict(self) -> dict:
        return asdict(self)


def ground_truth_velocity(gt: GroundTruth, smoothing_s: float = 0.05) -> np.ndarray:
    """World-frame velocity (N, 3) by differentiating positions and convolution smoothing.

    v_k = sum_j w_j (dp/dt)_{k-j}, with w a normalized Hann window spanning ``smoothing_s``.
    """
    if len(gt) < 3:
        raise DataError("ground_truth: need at least 3 poses to differentiate")
    v = np.gradient(gt.position, gt.t, axis=0)
    dt = float(np.median(np.diff(gt.t)))
    n = max(int(round(smoothing_s / dt)), 1) | 1  # odd, so the window is centred (no delay)
    if n < 3:
        return v
    w = np.hanning(n + 2)[1:-1]
    w /= w.sum()
    pad = n // 2
    padded = np.pad(v, ((pad, n - 1 - pad), (0, 0)), mode="edge")
    return np.stack([np.convolve(padded[:, i], w, mode="valid") for i in range(3)], axis=1)


def interpolate_ground_truth(gt: GroundTruth, t: np.ndarray, velocity: np.ndarray | None = None):
    """Ground-truth position, attitude (and velocity) at times ``t`` (inside the GT span)."""
    pos = np.stack([np.interp(t, gt.t, gt.position[:, i]) for i in range(3)], axis=1)
    unwrapped = np.unwrap(gt.orientation, axis=0)
    rpy = wrap_angle(np.stack([np.interp(t, gt.t, unwrapped[:, i]) for i in range(3)], axis=1))
    vel = None
    if velocity is not None:
        vel = np.stack([np.interp(t, gt.t, velocity[:, i]) for i in range(3)], axis=1)
    return pos, rpy, vel


def _align_origin(pos: np.ndarray, rpy: np.ndarray, gt_pos0, gt_rpy0):
    """Apply T = T_gt0 T_est0^{-1} to every estimated pose."""
    R_e0 = rpy_to_matrix(rpy[0])
    R = rpy_to_matrix(gt_rpy0) @ R_e0.T
    new_pos = (pos - pos[0]) @ R.T + gt_pos0
    new_rpy = matrix_to_rpy(R @ rpy_to_matrix(rpy))
    return new_pos, new_rpy


def trajectory_rmse(
    est: Trajectory,
    gt: GroundTruth,
    align: str = "none",
    smoothing_s: float = 0.05,
) -> TrajectoryErrors:
    """RMSE per axis (x, y, z, roll, pitch, yaw, vx, vy, vz) of ``est`` against ``gt``, and NEES."""
    if align not in ("none", "origin"):
        raise DataError(f"align must be 'none' or 'origin', not {align!r}")
    inside = (est.t >= gt.t[0]) & (est.t <= gt.t[-1])
    if not np.any(inside):
        raise DataError(
            f"trajectory [{est.t[0]:.3f}, {est.t[-1]:.3f}] s does not overlap ground truth "
            f"[{gt.t[0]:.3f}, {gt.t[-1]:.3f}] s"
        )
    t = est.t[inside]
    x = est.x[inside]
    P = est.P[inside]
    v_world = ground_truth_velocity(gt, smoothing_s)
    gt_pos, gt_rpy, gt_vel = interpolate_ground_truth(gt, t, v_world)
    gt_vel_body = np.einsum("nji,nj->ni", rpy_to_matrix(gt_rpy), gt_vel)
    pos, rpy = x[:, 0:3], x[:, 3:6]
    if align == "origin":
        pos, rpy = _align_origin(pos, rpy, gt_pos[0], gt_rpy[0])
    err = np.concatenate([pos - gt_pos, wrap_angle(rpy - gt_rpy), x[:, 6:9] - gt_vel_body], axis=1)
    rmse = {
        f"{a}_{u}": float(np.sqrt(np.mean(err[:, i] ** 2)))
        for i, (a, u) in enumerate(zip(AXES, UNITS, strict=True))
    }
    nees = pose_nees(err[:, :6], P[:, :6, :6])
    return TrajectoryErrors(
        rmse=rmse,
        nees_mean=float(np.mean(nees)),
        nees_dof=6,
        nees_fraction_in_95=float(np.mean(nees <= chi2.ppf(0.95, 6))),
        samples=int(t.size),
        dropped_outside_ground_truth=int(np.sum(~inside)),
        align=align,
    )


def pose_nees(err: np.ndarray, P: np.ndarray) -> np.ndarray:
    """epsilon_k = e_k^T P_k^{-1} e_k for each k (solved, not inverted; P floored at 1e-12)."""
    d = err.shape[1]
    Pj = P + 1e-12 * np.eye(d)
    return np.einsum("ni,ni->n", err, np.linalg.solve(Pj, err[..., None])[..., 0])
