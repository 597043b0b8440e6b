"""Trajectory metrics against closed forms and against evo's APE."""

import numpy as np
import pytest

from undertow.errors import DataError
from undertow.evaluation.trajectory import (
    PoseStates,
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
    assert r["vx_m_s"] == pytest.approx(0.05, abs=1e-6)


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
    v = gt.differentiated_velocity(smoothing_s=0.05)
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


def test_empty_or_nan_time_trajectories_are_refused():
    gt = _carriage(duration=5.0)
    empty = Trajectory(t=np.zeros(0), x=np.zeros((0, 18)), P=np.zeros((0, 18, 18)))
    with pytest.raises(DataError, match="no samples"):
        trajectory_rmse(empty, gt)
    est = _estimate(gt, np.linspace(1, 4, 10))
    t = est.t.copy()
    t[3] = np.nan
    with pytest.raises(DataError, match="1 non-finite times"):
        trajectory_rmse(est.replace(t=t), gt)


def test_nan_states_are_dropped_with_a_warning():
    gt = _carriage()
    est = _estimate(gt, np.linspace(1, 19, 100), dpos=(0.3, 0, 0))
    x = est.x.copy()
    x[::10, 0] = np.nan
    with pytest.warns(RuntimeWarning, match="dropped 10 samples"):
        r = trajectory_rmse(est.replace(x=x), gt)
    assert r.samples == 90 and r.rmse["x_m"] == pytest.approx(0.3, abs=1e-9)


def test_unusable_covariances_are_left_out_of_nees():
    """A zero or indefinite pose covariance has no NEES (it used to give ~1e14 through a
    1e-12 floor); the others keep theirs: sigma = 0.1 and errors (0.1, 0, ...) give 1."""
    gt = _carriage()
    est = _estimate(gt, np.linspace(1, 19, 100), dpos=(0.1, 0, 0))
    P = est.P.copy()
    P[:40] = 0.0
    P[40:50, 2, 2] = -1.0
    with pytest.warns(RuntimeWarning, match="50 of 100 samples .* not positive definite"):
        r = trajectory_rmse(est.replace(P=P), gt)
    assert r.nees_samples == 50 and r.samples == 100
    assert r.nees_mean == pytest.approx(1.0, rel=1e-6)
    with pytest.warns(RuntimeWarning):
        none = trajectory_rmse(est.replace(P=np.zeros_like(P)), gt)
    assert none.nees_samples == 0 and np.isnan(none.nees_mean)
    assert none.rmse["x_m"] == pytest.approx(0.1, abs=1e-9)


def test_ground_truth_with_repeated_times_is_deduplicated():
    """Times rounded to 0.01 s (20 poses per time at 2000 Hz): the first pose per time is kept,
    one warning; a constant offset still gives its RMSE, velocities stay right."""
    gt = _carriage()
    est = _estimate(gt, np.linspace(1, 19, 300), dpos=(0.0, 0.2, 0.0))
    rounded = GroundTruth(t=np.round(gt.t, 2), position=gt.position, orientation=gt.orientation)
    with pytest.warns(RuntimeWarning, match="repeats .* timestamps"):
        r = trajectory_rmse(est, rounded)
    assert r.rmse["y_m"] == pytest.approx(0.2, abs=1e-9)
    assert r.rmse["x_m"] < 0.8 * 0.005 + 1e-9  # the kept pose is at most 5 ms early
    assert r.rmse["vx_m_s"] < 0.005  # the kept poses are 0-0.5 ms irregular: small jitter


def test_align_origin_rotates_the_covariance_with_the_estimate():
    """An estimate expressed in a frame turned by 90 deg, with errors drawn from an anisotropic
    P in that frame: after origin alignment the errors have covariance R P R^T, so the NEES mean
    is 6 (chi-square, 6 dof) only if P is rotated too (unrotated it is far off)."""
    rng = np.random.default_rng(5)
    gt = _carriage(duration=20.0)
    t = np.linspace(0.0, 19.0, 6000)
    a = np.pi / 2
    Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    gt_pos = np.column_stack([np.interp(t, gt.t, gt.position[:, i]) for i in range(3)])
    sd = np.array([0.01, 0.2, 0.05, 0.002, 0.003, 0.02])  # std along the estimate's own axes
    e = rng.normal(size=(t.size, 6)) * sd
    e[0] = 0.0  # the first pose is what the alignment takes as exact
    x = np.zeros((t.size, 18))
    x[:, :3] = (gt_pos - gt_pos[0]) @ Rz.T + e[:, :3]  # the run seen in the turned frame
    x[:, 3:6] = e[:, 3:6] + [0.0, 0.0, a]
    x[:, 6] = 0.8
    P = np.zeros((t.size, 18, 18))
    P[:, :6, :6] = np.diag(sd**2)
    P[:, 6:, 6:] = np.eye(12)
    r = trajectory_rmse(Trajectory(t=t, x=x, P=P), gt, align="origin")
    assert r.nees_mean == pytest.approx(6.0, rel=0.06)
    assert r.rmse["y_m"] == pytest.approx(0.01, rel=0.05)  # the 0.01 along-x std, now along y
    assert r.rmse["x_m"] == pytest.approx(0.2, rel=0.05)
    unrotated = pose_nees(e[1:], np.tile(np.diag(sd**2), (t.size - 1, 1, 1)))  # sanity: 6
    assert unrotated.mean() == pytest.approx(6.0, rel=0.06)


def test_too_few_samples_inside_the_ground_truth_is_an_error():
    gt = _carriage(duration=5.0)
    est = _estimate(gt, np.linspace(4.0, 60.0, 200))  # 4 samples in [4, 5) s
    with pytest.raises(DataError, match="only 4 of 200 samples .* need at least 10"):
        trajectory_rmse(est, gt)


def test_most_of_the_estimate_outside_the_ground_truth_warns_with_the_counts():
    gt = _carriage(duration=5.0)
    est = _estimate(gt, np.linspace(0.0, 19.9, 200))  # 50 of 200 samples inside [0, 5) s
    with pytest.warns(RuntimeWarning, match="150 of 200 samples .* outside the ground truth"):
        result = trajectory_rmse(est, gt)
    assert (result.samples, result.dropped_outside_ground_truth) == (50, 150)


def test_a_tum_file_is_not_a_trajectory_npz(tmp_path):
    from undertow.errors import ReaderError

    tum = tmp_path / "trajectory.tum"
    tum.write_text("# t x y z qx qy qz qw\n0.0 0 0 0 0 0 0 1\n")
    with pytest.raises(ReaderError, match="not a trajectory.npz written by `undertow localize`"):
        Trajectory.load_npz(tum)
    with pytest.raises(ReaderError, match="TUM file has poses only, no covariances"):
        Trajectory.load_npz(tum)
    (tmp_path / "junk.npz").write_bytes(b"\x00\x01binary")
    with pytest.raises(ReaderError, match="not a trajectory.npz") as info:
        Trajectory.load_npz(tmp_path / "junk.npz")
    assert "pickled" not in str(info.value)


@pytest.mark.parametrize("align", ["none", "origin"])
def test_the_pose_states_read_in_chunks_give_the_metrics_of_the_whole_trajectory(tmp_path, align):
    """PoseStates.from_npz (t, x[:, :9], P[:, :6, :6], read 7 states at a time) gives exactly
    the errors of the whole Trajectory, non-finite rows dropped alike."""
    gt = _carriage()
    est = _estimate(gt, np.linspace(1, 19, 120), dpos=(0.3, -0.1, 0.05), dyaw=0.02)
    rng = np.random.default_rng(1)
    A = rng.normal(size=(len(est), 18, 18)) * 0.05
    x = est.x + rng.normal(size=est.x.shape) * 0.01
    x[5, 0] = np.nan
    est = est.replace(x=x, P=A @ np.swapaxes(A, 1, 2) + est.P)
    est.save_npz(tmp_path / "trajectory.npz")
    states = PoseStates.from_npz(tmp_path, chunk=7)
    np.testing.assert_array_equal(states.P, est.P[:, :6, :6])
    with pytest.warns(RuntimeWarning, match="dropped 1 samples"):
        whole = trajectory_rmse(est, gt, align=align)
    with pytest.warns(RuntimeWarning, match="dropped 1 samples"):
        assert trajectory_rmse(states, gt, align=align) == whole
