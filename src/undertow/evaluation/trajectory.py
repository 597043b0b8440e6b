"""Trajectory evaluation against ground truth: the paper's Table II metrics plus NEES.

- Ground truth is interpolated to the estimate times (linear in position, linear in unwrapped
  angles); estimates outside the ground-truth span are dropped (counted).
- Ground-truth velocity, as the paper: differentiate the (2000 Hz) positions and smooth by
  convolution with a normalized window of ``smoothing_s`` seconds; the world velocity is then
  expressed in the body frame with the true attitude, v^B = R(eta)^T v^W, to compare with the
  filter's nu = (u, v, w) (what the DVL measures).
- Ground truth with repeated timestamps (e.g. rounded to 0.01 s) or non-finite poses: those rows
  are dropped with one warning each (the first pose at a repeated time is kept); fewer than 3
  distinct poses left is a DataError.
- No alignment by default: a rigid (SE(3), Umeyama) alignment of a straight-line run is
  ill-posed (the rotation about the line is not observable) and would absorb the heading drift
  being measured (Zhang and Scaramuzza, "A Tutorial on Quantitative Trajectory Evaluation for
  Visual(-Inertial) Odometry", IROS 2018, discuss the alignment choices). ``align="origin"``
  moves the estimate rigidly so that its first pose equals the ground truth's (evo's
  ``--align_origin``), and moves the pose covariance with it: P' = J P J^T with
  J = diag(R_align, d rpy'/d rpy) (the latter by central differences; the first estimated pose
  is taken as exact).
- RMSE per axis: sqrt(mean(e_i^2)), angles wrapped to [-pi, pi).
- NEES of the pose: epsilon_k = e_k^T P_k^{-1} e_k over the 6 pose states; for a consistent filter
  its mean is 6 and 95 % of samples lie below chi2_6(0.95) = 12.59. Samples whose pose
  covariance is not positive definite (zero, non-finite, negative eigenvalues) have no NEES: they
  are left out with a warning (``nees_samples`` counts the others).
- A trajectory with no rows or non-finite times is refused (DataError); rows with a non-finite
  pose or velocity are dropped with a warning.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import asdict, dataclass, field

import numpy as np

from ..errors import DataError, ReaderError
from ..log import GroundTruth
from ..rotations import matrix_to_rpy, rpy_to_matrix, world_to_body, wrap_angle
from ..trajectory import Trajectory
from ..trajectory_chunks import CHUNK_STATES, npz_header, npz_rows

MIN_SAMPLES = 10  # estimates inside the ground truth needed for an RMSE
AXES = ("x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz")
UNITS = ("m", "m", "m", "rad", "rad", "rad", "m_s", "m_s", "m_s")


@dataclass(frozen=True, eq=False)
class PoseStates:
    """What the evaluation reads of a trajectory: times (N,), the pose and body velocity
    x[:, :9] and the pose covariance P[:, :6, :6], with the variant and metadata (a tenth of
    a state's numbers); :meth:`from_npz` reads a trajectory.npz chunk by chunk."""

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    variant: str = ""
    metadata: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def position(self) -> np.ndarray:
        return self.x[:, :3]

    def replace(self, **changes) -> PoseStates:
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_npz(cls, path, chunk: int = CHUNK_STATES) -> PoseStates:
        variant, metadata = npz_header(path)
        t = np.concatenate([*npz_rows(path, "t", chunk), np.empty(0)])
        x = np.concatenate([*(x[:, :9] for x in npz_rows(path, "x", chunk)), np.empty((0, 9))])
        P = [P[:, :6, :6] for P in npz_rows(path, "P", chunk)]
        P = np.concatenate([*P, np.empty((0, 6, 6))])
        if not (len(t) == len(x) == len(P)):
            raise ReaderError(f"{path}: t, x and P differ in length")
        return cls(t, x, P, variant, metadata)


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
    nees_samples: int = 0  # samples with a positive definite pose covariance

    def to_dict(self) -> dict:
        return asdict(self)


def _align_origin(pos: np.ndarray, rpy: np.ndarray, gt_pos0, gt_rpy0, P: np.ndarray):
    """Apply T = T_gt0 T_est0^{-1} to every estimated pose, and to the pose covariance P (N, 6, 6)
    through its Jacobian J = diag(R, d rpy'/d rpy) (central differences, wrapped)."""
    R_e0 = rpy_to_matrix(rpy[0])
    R = rpy_to_matrix(gt_rpy0) @ R_e0.T
    new_pos = (pos - pos[0]) @ R.T + gt_pos0
    new_rpy = matrix_to_rpy(R @ rpy_to_matrix(rpy))
    h = 1e-6
    J = np.zeros((rpy.shape[0], 6, 6))
    J[:, :3, :3] = R
    for i in range(3):
        step = np.zeros(3)
        step[i] = h
        plus = matrix_to_rpy(R @ rpy_to_matrix(rpy + step))
        minus = matrix_to_rpy(R @ rpy_to_matrix(rpy - step))
        J[:, 3:6, 3 + i] = wrap_angle(plus - minus) / (2 * h)
    new_P = J @ P @ np.swapaxes(J, 1, 2)
    return new_pos, new_rpy, new_P


def trajectory_rmse(
    est: Trajectory | PoseStates,
    gt: GroundTruth,
    align: str = "none",
    smoothing_s: float = 0.05,
    min_samples: int = MIN_SAMPLES,
) -> TrajectoryErrors:
    """RMSE per axis (x, y, z, roll, pitch, yaw, vx, vy, vz) of ``est`` against ``gt``, and NEES.

    Fewer than ``min_samples`` estimates inside the ground-truth span is a DataError; more than
    half of them outside it is a warning (the RMSE then describes a part of the run only)."""
    if align not in ("none", "origin"):
        raise DataError(f"align must be 'none' or 'origin', not {align!r}")
    est = _finite_samples(est)
    gt = gt.usable("evaluate trajectory")
    inside = (est.t >= gt.t[0]) & (est.t <= gt.t[-1])
    if not np.any(inside):
        raise DataError(
            f"trajectory [{est.t[0]:.3f}, {est.t[-1]:.3f}] s does not overlap ground truth "
            f"[{gt.t[0]:.3f}, {gt.t[-1]:.3f}] s"
        )
    _check_overlap(est.t, inside, gt, min_samples)
    t = est.t[inside]
    x = est.x[inside]
    P = est.P[inside][:, :6, :6]
    v_world = gt.differentiated_velocity(smoothing_s)
    gt_pos, gt_rpy, gt_vel = gt.interpolate(t, v_world)
    gt_vel_body = world_to_body(gt_rpy, gt_vel)
    pos, rpy = x[:, 0:3], x[:, 3:6]
    if align == "origin":
        pos, rpy, P = _align_origin(pos, rpy, gt_pos[0], gt_rpy[0], P)
    err = np.concatenate([pos - gt_pos, wrap_angle(rpy - gt_rpy), x[:, 6:9] - gt_vel_body], axis=1)
    rmse = {
        f"{a}_{u}": float(np.sqrt(np.mean(err[:, i] ** 2)))
        for i, (a, u) in enumerate(zip(AXES, UNITS, strict=True))
    }
    nees = _usable_nees(err[:, :6], P)
    from scipy.stats import chi2  # scipy.stats takes a second to import: only when evaluating

    return TrajectoryErrors(
        rmse=rmse,
        nees_mean=float(np.mean(nees)) if nees.size else float("nan"),
        nees_dof=6,
        nees_fraction_in_95=float(np.mean(nees <= chi2.ppf(0.95, 6)))
        if nees.size
        else float("nan"),
        samples=int(t.size),
        dropped_outside_ground_truth=int(np.sum(~inside)),
        align=align,
        nees_samples=int(nees.size),
    )


def _finite_samples(est: Trajectory) -> Trajectory:
    """``est`` without the samples whose pose or velocity is not finite (one warning); a
    trajectory with no samples, non-finite times or no finite sample is a DataError."""
    if len(est) == 0:
        raise DataError("trajectory has no samples (nothing to evaluate)")
    if not np.all(np.isfinite(est.t)):
        raise DataError(f"trajectory: {int(np.sum(~np.isfinite(est.t)))} non-finite times")
    finite = np.all(np.isfinite(est.x[:, :9]), axis=1)
    if finite.all():
        return est
    warnings.warn(
        f"trajectory: dropped {int(np.sum(~finite))} samples with a non-finite pose or velocity",
        RuntimeWarning,
        stacklevel=3,
    )
    if not finite.any():
        raise DataError("trajectory: no sample has a finite pose and velocity")
    return est.replace(t=est.t[finite], x=est.x[finite], P=est.P[finite])


def _usable_nees(err: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Pose NEES of the samples whose covariance is positive definite (one warning about the
    others, which have none)."""
    usable = positive_definite(P)
    if not usable.all():
        warnings.warn(
            f"trajectory: {int(np.sum(~usable))} of {usable.size} samples have a pose covariance "
            "that is not positive definite (zero, non-finite or negative); NEES leaves them out",
            RuntimeWarning,
            stacklevel=3,
        )
    return pose_nees(err[usable], P[usable])


def _check_overlap(t: np.ndarray, inside: np.ndarray, gt: GroundTruth, min_samples: int) -> None:
    used, dropped = int(inside.sum()), int(t.size - inside.sum())
    span = f"ground truth [{gt.t[0]:.3f}, {gt.t[-1]:.3f}] s"
    where = f"of the trajectory [{t[0]:.3f}, {t[-1]:.3f}] s"
    if used < min_samples:
        raise DataError(
            f"only {used} of {t.size} samples {where} lie inside the {span}; need at least "
            f"{min_samples} for an RMSE (is it the ground truth of this run?)"
        )
    if dropped > used:
        warnings.warn(
            f"{dropped} of {t.size} samples {where} lie outside the {span} and are dropped; "
            f"the RMSE covers the other {used} only",
            RuntimeWarning,
            stacklevel=3,
        )


def positive_definite(P: np.ndarray, rel_floor: float = 1e-12) -> np.ndarray:
    """Per matrix of P (N, d, d): finite, symmetric (to 1e-9 relative) and with every eigenvalue
    above ``rel_floor`` times the largest (so that its inverse means something)."""
    ok = np.all(np.isfinite(P), axis=(1, 2))
    out = np.zeros(P.shape[0], bool)
    if not ok.any():
        return out
    Q = P[ok]
    scale = np.max(np.abs(Q), axis=(1, 2))
    symmetric = np.all(np.abs(Q - np.swapaxes(Q, 1, 2)) <= 1e-9 * scale[:, None, None], axis=(1, 2))
    w = np.linalg.eigvalsh(0.5 * (Q + np.swapaxes(Q, 1, 2)))
    out[ok] = symmetric & (w[:, -1] > 0) & (w[:, 0] > rel_floor * w[:, -1])
    return out


def pose_nees(err: np.ndarray, P: np.ndarray) -> np.ndarray:
    """epsilon_k = e_k^T P_k^{-1} e_k for each k (solved, not inverted; P floored at 1e-12)."""
    d = err.shape[1]
    Pj = P + 1e-12 * np.eye(d)
    return np.einsum("ni,ni->n", err, np.linalg.solve(Pj, err[..., None])[..., 0])
