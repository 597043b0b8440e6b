"""NIS consistency diagnostics on logs drawn from the filter's own model (closed-form invariant:
for a consistent filter NIS = nu^T S^-1 nu ~ chi2(dim z), so E[NIS] = dim z)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from undertow.estimation import Localizer, LocalizerConfig, filter_loop, model
from undertow.log import G0, P_ATM, DeadReckoning, Dvl, Imu, Log, Pressure
from undertow.robot import Mounting
from undertow.rotations import rpy_to_matrix, wrap_angle

RHO = 997.0
X0 = np.r_[0.0, 0.0, 2.0, 0.05, -0.03, 0.5, 0.2, 0.0, 0.0, 0.0, 0.0, 0.02, np.zeros(6)]
STD0 = [0.01] * 3 + [0.02] * 3 + [0.05] * 3 + [0.005] * 3 + [0.005] * 3 + [0.005] * 3
PARAMS = dict(
    accel_density=(1e-3, 1e-3, 1e-3), angular_accel_density=(1e-5, 1e-5, 1e-5),
    initial_state=X0.tolist(), initial_std=STD0,
)  # fmt: skip


def euler_rate(phi, theta):
    return np.array([
        [1, np.sin(phi) * np.tan(theta), np.cos(phi) * np.tan(theta)],
        [0, np.cos(phi), -np.sin(phi)],
        [0, np.sin(phi) / np.cos(theta), np.cos(phi) / np.cos(theta)],
    ])  # fmt: skip


def simulate(cfg: LocalizerConfig, duration=40.0, seed=0, noise_scale=1.0):
    """A log and its truth drawn from the model the filter assumes (model.py docstring):
    x0 ~ N(x0_cfg, diag(std0^2)); eta += J (nu dt + a dt^2/2), nu += a dt, a ~ N(0, q/dt);
    biases random walks of density q_b; measurements h(x) + N(0, (noise_scale sigma)^2)."""
    rng = np.random.default_rng(seed)
    mount = Mounting()
    ms = {"imu": 10, "dvl": 125, "dr": 200, "baro": 100}
    times = {k: np.arange(0, int(duration * 1000), v) for k, v in ms.items()}
    grid = np.unique(np.concatenate(list(times.values())))
    q_acc = np.r_[cfg.accel_density, cfg.angular_accel_density]
    q_b = np.r_[cfg.dr_bias_walk_density, cfg.gyro_bias_walk_density]
    x = np.asarray(cfg.initial_state) + rng.normal(0, 1, 18) * np.asarray(cfg.initial_std)
    truth = np.empty((grid.size, 18))
    truth[0] = x
    for j in range(1, grid.size):
        dt = (grid[j] - grid[j - 1]) / 1000.0
        R, T = rpy_to_matrix(x[3:6]), euler_rate(x[3], x[4])
        a = rng.normal(0, 1, 6) * np.sqrt(q_acc / dt)
        x = x.copy()
        x[0:3] += R @ (x[6:9] * dt + a[:3] * dt**2 / 2)
        x[3:6] = wrap_angle(x[3:6] + T @ (x[9:12] * dt + a[3:] * dt**2 / 2))
        x[6:12] += a * dt
        x[12:18] += rng.normal(0, 1, 6) * np.sqrt(q_b * dt)
        truth[j] = x
    at = {k: truth[np.searchsorted(grid, v)] for k, v in times.items()}
    sec = {k: v / 1000.0 for k, v in times.items()}
    s = noise_scale
    xi = at["imu"]
    imu = xi[:, 9:12] @ mount.imu.rotation_matrix() + xi[:, 15:18]
    imu += rng.normal(0, 1, imu.shape) * s * np.asarray(cfg.imu_gyro_std_rad_s)
    xd = at["dvl"]
    v_b = xd[:, 6:9] + np.cross(xd[:, 9:12], np.asarray(mount.dvl.translation))
    dvl = v_b @ mount.dvl.rotation_matrix()
    dvl += rng.normal(0, 1, dvl.shape) * s * np.asarray(cfg.dvl_velocity_std_m_s)
    xr = at["dr"]
    dr = xr[:, 3:6] + xr[:, 12:15]
    dr = wrap_angle(dr + rng.normal(0, 1, dr.shape) * s * np.asarray(cfg.dr_orientation_std_rad))
    xp = at["baro"]
    lever = rpy_to_matrix(xp[:, 3:6]) @ np.asarray(mount.barometer.translation)
    depth = xp[:, 2] + lever[:, 2] + rng.normal(0, 1, xp.shape[0]) * s * cfg.depth_std_m
    log = Log(
        imu=Imu(sec["imu"], imu),
        dvl=Dvl.from_velocity(sec["dvl"], dvl),
        dead_reckoning=DeadReckoning(sec["dr"], np.zeros_like(dr), dr),
        pressure=Pressure(sec["baro"], P_ATM + RHO * G0 * depth),
        mounting=mount,
    )
    return log, grid / 1000.0, truth


@pytest.mark.slow
def test_nis_mean_matches_dimension_when_data_follow_the_model():
    # the model's depth is a random walk with no surface: no physical depth envelope
    cfg = LocalizerConfig(variant="be", min_depth_m=None, max_depth_m=None, **PARAMS)
    for seed in (0, 1):
        log, _, _ = simulate(cfg, seed=seed)
        nis = Localizer(**cfg.model_dump()).run(log).metadata["nis"]
        assert set(nis) == set(model.KIND_NAMES)
        for name, dim in zip(model.KIND_NAMES, model.KIND_DIM, strict=True):
            s = nis[name]
            n = s["count"]
            assert s["dof"] == dim and n == len(log.streams()[name])
            # mean of n independent chi2(dim) draws: sd sqrt(2 dim / n); 4 sd
            assert abs(s["mean"] - dim) < 4 * np.sqrt(2 * dim / n), (name, s)
            assert abs(s["fraction_in_95"] - 0.95) < 4 * np.sqrt(0.95 * 0.05 / n), (name, s)


def test_nis_large_when_noise_is_underestimated():
    cfg = LocalizerConfig(variant="be", **PARAMS)
    log, _, _ = simulate(cfg, seed=2, noise_scale=4.0)
    nis = Localizer(**cfg.model_dump()).run(log).metadata["nis"]
    for name, dim in zip(model.KIND_NAMES, model.KIND_DIM, strict=True):
        assert nis[name]["mean"] > 3 * dim, (name, nis[name])
        assert nis[name]["fraction_in_95"] < 0.8


def test_chi2_bounds_and_no_nis_without_stream():
    np.testing.assert_allclose(filter_loop.CHI2_95, chi2.ppf(0.95, model.KIND_DIM), rtol=1e-12)
    cfg = LocalizerConfig(variant="be", **PARAMS)
    log, _, _ = simulate(cfg, duration=3.0)
    nis = Localizer(**cfg.model_dump()).run(log.replace(pressure=None)).metadata["nis"]
    assert nis["pressure"] == {"mean": None, "dof": 1, "fraction_in_95": None, "count": 0}
    assert nis["imu"]["count"] == len(log.imu)
