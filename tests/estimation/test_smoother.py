"""Unscented RTS smoother: closed-form RTS on a linear model, covariance and error invariants on
logs drawn from the filter's own model (see test_estimation_nis.simulate)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_nis import PARAMS, simulate

from undertow._util.plain import to_plain
from undertow.errors import ConfigError, DataError
from undertow.estimation import Localizer, LocalizerConfig, ukf
from undertow.estimation.smoother import _rts_step, _rts_workspace, smooth, smooth_store
from undertow.log import Imu
from undertow.rotations import wrap_angle
from undertow.trajectory import Trajectory
from undertow.trajectory_chunks import TrajectoryStore


def test_linear_gaussian_equals_closed_form_rts():
    """Same kernels (sigma points, predict moments, _rts_step) on x' = F x + w, z = H x + v:
    the unscented transform is exact, so URTS = RTS (state 1 flagged as an angle, kept small)."""
    rng = np.random.default_rng(4)
    n, N, dt = 4, 30, 0.1
    F = np.eye(n) + np.diag([dt, dt], 2)
    Q = np.diag([1e-4, 2e-4, 1e-2, 1e-2])
    H = rng.normal(size=(2, n)) * 0.5
    Rz = np.diag([0.1, 0.2])
    angles = np.array([False, True, False, False])
    x, P = np.array([0.5, 0.1, 0.2, -0.1]), np.diag([0.05, 0.02, 0.05, 0.05])
    xf, Pf = [], []
    for _ in range(N):  # Kalman filter (forward, closed form)
        x, P = F @ x, F @ P @ F.T + Q
        S = H @ P @ H.T + Rz
        K = P @ H.T @ np.linalg.inv(S)
        z = H @ x + rng.normal(0, 0.1, 2)
        x, P = x + K @ (z - H @ x), P - K @ S @ K.T
        xf.append(x)
        Pf.append(P)
    xs_ref, Ps_ref = [xf[-1]], [Pf[-1]]
    for k in range(N - 2, -1, -1):  # RTS (closed form)
        Pp = F @ Pf[k] @ F.T + Q
        G = Pf[k] @ F.T @ np.linalg.inv(Pp)
        xs_ref.insert(0, xf[k] + G @ (xs_ref[0] - F @ xf[k]))
        Ps_ref.insert(0, Pf[k] + G @ (Ps_ref[0] - Pp) @ G.T)
    assert np.max(np.abs(np.array(xs_ref)[:, 1])) < 1.0  # the angle never wraps
    wm, wc, lam = ukf.weights(n, 0.8, 2.0, 0.0)
    L, chi, D = np.zeros((n, n)), np.empty((2 * n + 1, n)), np.empty((n, 2 * n + 1))
    ws = _rts_workspace(n)
    xs, Ps = xf[-1].copy(), Pf[-1].copy()
    for k in range(N - 2, -1, -1):
        x, P = xf[k].copy(), Pf[k].copy()
        ukf.sigma_points(x, P, lam, angles, L, chi)
        m, Pm = np.empty(n), np.empty((n, n))
        ukf.predict_moments(np.ascontiguousarray(chi @ F.T), wm, wc, Q, angles, m, Pm, D)
        assert _rts_step(x, P, chi, D, m, Pm, xs, Ps, wc, angles, ws) == 0
        np.testing.assert_allclose(x, xs_ref[k], rtol=0, atol=1e-10)
        np.testing.assert_allclose(P, Ps_ref[k], rtol=0, atol=1e-12)
        xs, Ps = x, P


def errors(traj, grid, truth):
    err = traj.x - truth[np.searchsorted(grid, traj.t)]
    err[:, 3:6] = wrap_angle(err[:, 3:6])
    return err


# truth without biases: the model the baseline variant (biases frozen at 0) assumes
NO_BIAS = dict(PARAMS, dr_bias_walk_density=(0.0,) * 3, gyro_bias_walk_density=(0.0,) * 3,
               initial_std=PARAMS["initial_std"][:12] + [0.0] * 6)  # fmt: skip


@pytest.mark.parametrize("variant", ["be", "baseline"])
def test_smoothed_covariance_never_larger(variant):
    cfg = LocalizerConfig(variant=variant, **(PARAMS if variant == "be" else NO_BIAS))
    log, _, _ = simulate(cfg, duration=20.0, seed=5)
    filt = Localizer(**cfg.model_dump()).run(log)
    sm = smooth(filt)
    assert sm.metadata["smoothed"] is True and "smoothed" not in filt.metadata
    assert sm.metadata["smoother_counts"]["nonfinite_kept_filtered"] == 0
    assert np.all(np.isfinite(sm.x)) and np.all(np.isfinite(sm.P))
    np.testing.assert_array_equal(sm.t, filt.t)
    np.testing.assert_array_equal(sm.x[-1], filt.x[-1])  # the last step has no future data
    df = np.diagonal(filt.P, axis1=1, axis2=2)
    ds = np.diagonal(sm.P, axis1=1, axis2=2)
    assert np.all(ds <= df * (1 + 1e-9) + 1e-18)  # each diagonal, at every time
    assert np.all(ds.sum(1) <= df.sum(1) * (1 + 1e-12))  # trace
    assert np.all(np.linalg.eigvalsh(sm.P) > 0)
    np.testing.assert_array_equal(sm.P, np.swapaxes(sm.P, 1, 2))
    assert np.mean(ds[:-1, 6:12] / df[:-1, 6:12]) < 0.8  # and it really helps
    if variant == "baseline":
        assert np.all(sm.x[:, 12:] == 0.0)
        np.testing.assert_allclose(ds[:, 12:], 1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["be", "baseline"])
def test_smoothed_error_not_larger_monte_carlo(variant):
    """Mean squared error over 12 runs drawn from the filter's model: the smoother (the
    conditional mean given all data) is never worse than the filter, group by group."""
    cfg = LocalizerConfig(variant=variant, **(PARAMS if variant == "be" else NO_BIAS))
    mse_f = mse_s = 0.0
    for seed in range(12):
        log, grid, truth = simulate(cfg, duration=10.0, seed=100 + seed)
        filt = Localizer(**cfg.model_dump()).run(log)
        mse_f = mse_f + np.mean(errors(filt, grid, truth) ** 2, axis=0)
        mse_s = mse_s + np.mean(errors(smooth(filt), grid, truth) ** 2, axis=0)
    groups = [slice(2, 3), slice(3, 6), slice(6, 9), slice(9, 12)]
    groups += [slice(12, 18)] if variant == "be" else []
    for g in groups:  # depth (m), angles (rad), velocities (m/s), rates (rad/s), biases
        assert mse_s[g].sum() < mse_f[g].sum(), (g, mse_s[g], mse_f[g])
    assert mse_s[6:12].sum() < 0.7 * mse_f[6:12].sum()
    # x, y are not observed (integrated velocity): smoothing barely changes them
    assert mse_s[0:2].sum() < 1.05 * mse_f[0:2].sum()


def test_smoother_never_nan_on_adversarial_log():
    cfg = LocalizerConfig(variant="proposed", max_dt_s=0.5, **PARAMS)
    log, _, _ = simulate(cfg, duration=20.0, seed=6)
    gap = {n: s.select((s.t < 6) | (s.t > 12)) for n, s in log.streams().items()}
    log = log.replace(**gap)
    w = np.array(log.imu.angular_velocity)
    w[::37] = 1e3
    log = log.replace(imu=Imu(log.imu.t, w))
    filt = Localizer(**cfg.model_dump()).run(log)
    sm = smooth(filt)
    assert np.all(np.isfinite(sm.x)) and np.all(np.isfinite(sm.P))
    assert np.all(np.diagonal(sm.P, axis1=1, axis2=2) > 0)


def test_smoother_refuses_decimated_or_unknown_input():
    cfg = LocalizerConfig(variant="be", **PARAMS)
    log, _, _ = simulate(cfg, duration=3.0)
    dec = Localizer(**{**cfg.model_dump(), "output_rate_hz": 10.0}).run(log)
    with pytest.raises(ConfigError, match="decimated"):
        smooth(dec)
    filt = Localizer(**cfg.model_dump()).run(log)
    with pytest.raises(ConfigError, match="already smoothed"):
        smooth(smooth(filt))
    bare = filt.replace(metadata={})
    with pytest.raises(ConfigError, match="no filter config"):
        smooth(bare)
    np.testing.assert_array_equal(smooth(bare, cfg).x, smooth(filt).x)
    with pytest.raises(DataError):
        smooth(filt.replace(t=filt.t[::-1].copy()), cfg)


def test_saved_trajectory_keeps_its_metadata_and_can_be_smoothed(tmp_path):
    """trajectory.npz stores the metadata (as JSON), so smooth() runs on a loaded file with
    the filter's own config and gives what it gives on the trajectory in memory."""
    cfg = LocalizerConfig(**PARAMS, variant="proposed")
    log, _, _ = simulate(cfg, duration=3.0)
    traj = Localizer(**cfg.model_dump()).run(log)
    back = Trajectory.load_npz(traj.save_npz(tmp_path / "trajectory.npz"))
    assert back.metadata["config"] == json.loads(json.dumps(to_plain(traj.metadata["config"])))
    assert back.metadata["counts"] == traj.metadata["counts"] and back.variant == "proposed"
    np.testing.assert_array_equal(back.P, traj.P)
    a, b = smooth(traj), smooth(back)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)
    assert b.metadata["smoothed"] is True
    with pytest.raises(ConfigError, match="already smoothed"):  # and that survives a save too
        smooth(Trajectory.load_npz(b.save_npz(tmp_path / "smoothed.npz")))


def test_npz_without_metadata_still_loads(tmp_path):
    path = tmp_path / "old.npz"
    np.savez(path, t=np.arange(3.0), x=np.zeros((3, 18)), P=np.tile(np.eye(18), (3, 1, 1)),
             variant=np.array("be"))  # fmt: skip
    old = Trajectory.load_npz(path)
    assert old.metadata == {} and old.variant == "be"
    with pytest.raises(ConfigError, match="carries no filter config"):
        smooth(old)


@pytest.mark.parametrize("variant", ["be", "baseline"])
def test_smoothing_a_store_backward_in_chunks_is_the_whole_smoother_bit_for_bit(tmp_path, variant):
    """The filter writing its states to disk every 7 rows and the smoother rewriting them
    backward in chunks of 3 states (chunks of 1 and of all too) give exactly the arrays and
    metadata of the in-memory run and smoother."""
    cfg = LocalizerConfig(variant=variant, **(PARAMS if variant == "be" else NO_BIAS))
    log, _, _ = simulate(cfg, duration=3.0, seed=2)
    localizer = Localizer(**cfg.model_dump())
    whole = localizer.run(log)
    ref = smooth(whole)
    for chunk in (1, 3, len(whole) + 5):
        store = TrajectoryStore(tmp_path / f"s{chunk}")
        stored = localizer.run(log, store=store, store_rows=7)
        assert stored.metadata == whole.metadata
        filtered = store.trajectory()
        for name in "txP":
            np.testing.assert_array_equal(getattr(filtered, name), getattr(whole, name))
        meta = smooth_store(store, stored.metadata, chunk=chunk)
        assert meta == ref.metadata
        back = store.trajectory()
        np.testing.assert_array_equal(back.x, ref.x)
        np.testing.assert_array_equal(back.P, ref.P)
    with pytest.raises(ConfigError, match="already smoothed"):
        smooth_store(store, meta)
