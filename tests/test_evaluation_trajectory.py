"""Trajectory metrics against closed forms and against evo's APE."""

import numpy as np
import pytest

from undertow.errors import DataError
from undertow.evaluation.trajectory import (
    ground_truth_velocity,
    pose_nees,
    trajectory_rmse,
)
from undertow.log import GroundTruth
from undertow.rotations import rpy_to_quaternion
from undertow.trajectory import Trajectory


def _carriage(rate=2000.0, duration=20.0, speed=0.8):
    t = np.arange(0.0, duration, 1.0 / rate)
    pos = np.column_stack([speed * t, np.zeros_like(t), np.full_like(t, 1.0)])
    return GroundTruth(t=t, position=pos, orientation=np.zeros((t.size, 3)))


def _estimate(gt, t, dpos=(0, 0, 0), dyaw=0.0, dvel=(0, 0, 0), sigma=0.1):
    x = np.zeros((t.size, 18))
    x[:, 0] = np.interp(t, gt.t, gt.position[:, 0]) + dpos[0]
    x[:, 1] = dpos[1]
    x[:, 2] = 1.0 + dpos[2]
    x[:, 5] = dyaw
    x[:, 6] = 0.8 + dvel[0]
    P = np.tile(np.eye(18) * sigma**2, (t.size, 1, 1))
    return Trajectory(t=t, x=x, P=P)


def test_constant_offsets_give_their_rmse():
    gt = _carriage()
    est = _estimate(
        gt, np.linspace(1, 19, 500), dpos=(0.3, -0.2, 0.01), dyaw=0.02, dvel=(0.05, 0, 0)
    )
    r = trajectory_rmse(est, gt).rmse
    assert r["x_m"] == pytest.approx(0.3, abs=1e-9)
    assert r["y_m"] == pytest.approx(0.2, abs=1e-9)
    assert r["z_m"] == pytest.approx(0.01, abs=1e-9)
    assert r["yaw_rad"] == pytest.approx(0.02, abs=1e-12)
    assert r["vx_mps"] == pytest.approx(0.05, abs=1e-6)


def test_angle_errors_wrap_across_pi():
    gt = _carriage()
    gt = GroundTruth(
        t=gt.t, position=gt.position, orientation=np.tile([0, 0, np.pi - 0.01], (gt.t.size, 1))
    )
    est = _estimate(gt, np.linspace(1, 19, 100), dyaw=-np.pi + 0.01)
    assert trajectory_rmse(est, gt).rmse["yaw_rad"] == pytest.approx(0.02, abs=1e-9)


def test_ground_truth_velocity_of_a_ramp_profile():
    t = np.arange(0, 10, 1 / 2000)
    x = np.where(t < 5, 0.1 * t**2, 2.5 + 1.0 * (t - 5))  # accelerate at 0.2 m/s^2, then 1 m/s
    gt = GroundTruth(
        t=t, position=np.column_stack([x, 0 * t, 0 * t]), orientation=np.zeros((t.size, 3))
    )
    v = ground_truth_velocity(gt, smoothing_s=0.05)
    steady = (t > 1) & (t < 4.9)
    np.testing.assert_allclose(v[steady, 0], 0.2 * t[steady], atol=1e-6)
    np.testing.assert_allclose(v[t > 5.1, 0], 1.0, atol=1e-6)


def test_nees_of_gaussian_errors_has_mean_dof():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(6, 6))
    P = A @ A.T + 6 * np.eye(6)
    e = rng.multivariate_normal(np.zeros(6), P, size=20000)
    nees = pose_nees(e, np.tile(P, (e.shape[0], 1, 1)))
    assert nees.mean() == pytest.approx(6.0, rel=0.03)


def test_translation_rmse_matches_evo_ape():
    from evo.core import metrics, sync
    from evo.core.trajectory import PoseTrajectory3D

    gt = _carriage()
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.5, 19.5, 400))
    est = _estimate(gt, t, dpos=(0.1, 0.0, 0.0))
    x = est.x.copy()
    x[:, :3] += rng.normal(scale=0.05, size=(t.size, 3))
    est = Trajectory(t=t, x=x, P=est.P)
    ours = trajectory_rmse(est, gt).rmse

    gt_pos = np.column_stack([np.interp(t, gt.t, gt.position[:, i]) for i in range(3)])
    q = rpy_to_quaternion(np.zeros((t.size, 3)))
    ref = PoseTrajectory3D(gt_pos, q[:, [3, 0, 1, 2]], t)
    traj = PoseTrajectory3D(x[:, :3], q[:, [3, 0, 1, 2]], t)
    ref, traj = sync.associate_trajectories(ref, traj)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, traj))
    evo_rmse = ape.get_statistic(metrics.StatisticsType.rmse)
    ours_3d = np.sqrt(ours["x_m"] ** 2 + ours["y_m"] ** 2 + ours["z_m"] ** 2)
    assert ours_3d == pytest.approx(evo_rmse, rel=1e-9)


def test_align_origin_removes_a_constant_offset():
    gt = _carriage()
    est = _estimate(gt, np.linspace(0, 19, 200), dpos=(1.0, 2.0, 0.5))
    assert trajectory_rmse(est, gt, align="origin").rmse["y_m"] == pytest.approx(0.0, abs=1e-9)


def test_no_overlap_is_a_clear_error():
    gt = _carriage(duration=5.0)
    est = _estimate(gt, np.linspace(10, 12, 5))
    with pytest.raises(DataError, match="does not overlap ground truth"):
        trajectory_rmse(est, gt)
