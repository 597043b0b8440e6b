"""The swell's pressure in a trajectory's depth (mapping/depth_wave.py): the first-order gain
against its closed forms, a recursion run on a sinusoid, and the filter's own depth on
simulated swell; where R and Delta come from."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import csd, welch

from undertow.estimation.localizer import localize
from undertow.mapping.depth_wave import (
    depth_wave_terms,
    swell_variances,
    trajectory_depth_noise,
)
from undertow.sim import Scenario, load_scenario, simulate
from undertow.trajectory import Trajectory


def _gain2(var_z, frequency, interval, std):
    """|H|^2: swell_variances of a = sqrt 2 and K_p = 1."""
    terms = depth_wave_terms((math.sqrt(2.0), frequency, std, interval))
    return swell_variances(np.atleast_1d(np.asarray(var_z, float)), np.ones(np.size(var_z)),
                           *terms)  # fmt: skip


def test_the_gain_passes_a_steady_depth_and_averages_white_noise_to_k_over_2_minus_k():
    """|H(0)| = 1; the mean of |H|^2 over (0, pi / Delta) is the white-noise variance gain of
    the recursion, sum_n K^2 (1 - K)^(2n) = K / (2 - K) (Parseval); K = 1 passes everything."""
    std, interval = 0.01, 0.1
    for gain in (0.05, 0.3, 0.8):
        var_z = gain * std**2
        assert _gain2(var_z, 0.0, interval, std)[0] == pytest.approx(1.0, rel=1e-12)
        f = np.linspace(0.0, 0.5 / interval, 20001)
        mean = np.mean([_gain2(var_z, fi, interval, std)[0] for fi in f])
        assert mean == pytest.approx(gain / (2 - gain), rel=1e-3)
    assert _gain2(4 * std**2, 1.3, interval, std)[0] == pytest.approx(1.0)
    assert _gain2(0.0, 1.3, interval, std)[0] == 0.0


def test_the_gain_is_the_recursions_on_a_sinusoid():
    """x_n = (1 - K) x_{n-1} + K cos(omega n Delta): its steady amplitude is |H|."""
    std, interval, frequency, gain = 0.01, 0.1, 0.33, 0.2
    n = np.arange(4000)
    z = np.cos(2 * np.pi * frequency * n * interval)
    x = np.zeros(n.size)
    for i in range(1, n.size):
        x[i] = (1 - gain) * x[i - 1] + gain * z[i]
    amplitude = np.sqrt(2 * np.mean(x[2000:] ** 2))
    assert amplitude == pytest.approx(np.sqrt(_gain2(gain * std**2, frequency, interval, std)[0]),
                                      rel=1e-3)  # fmt: skip


def test_the_swell_share_is_the_filters_depth_error_within_a_third():
    """On simulated swell the filter's depth error at the wave's frequency, over the
    barometer's (the cross-spectrum's gain), is the first-order |H| within 30 % (it leaves
    out the velocity the filter also corrects from the barometer)."""
    for wave in ({"amplitude_m": 0.15, "frequency_hz": 0.33}, {}):
        data = load_scenario("mhl-basin").to_yaml_dict()
        data["wave"].update(wave)
        log = simulate(Scenario.model_validate(data), seed=1).log
        a, f = log.metadata["wave"]["amplitude_m"], log.metadata["wave"]["frequency_hz"]
        # the paper's barometer model: the swell left out of the depth noise
        trajectory = localize(log, "proposed", wave=(a, f), pressure_wave_noise=False)
        gt, p = log.ground_truth, log.pressure
        keep = (p.t > gt.t[0] + 5) & (p.t < min(gt.t[-1], trajectory.t[-1]))
        t = p.t[keep]
        depth = np.interp(t, gt.t, gt.position[:, 2])
        rho_g = float(log.metadata["water_density_kg_m3"]) * 9.80665
        baro = (p.pressure[keep] - log.metadata["surface_pressure_pa"]) / rho_g - depth
        error = np.interp(t, trajectory.t, trajectory.position[:, 2]) - depth
        freq, cross = csd(baro, error, fs=10.0, nperseg=256)
        _, power = welch(baro, fs=10.0, nperseg=256)
        i = int(np.argmin(np.abs(freq - f)))
        measured = abs(cross[i - 1 : i + 2].sum() / power[i - 1 : i + 2].sum())
        std, interval = trajectory_depth_noise(trajectory)
        var_z = np.interp(t, trajectory.t, trajectory.P[:, 2, 2])
        predicted = np.sqrt(np.mean(_gain2(var_z, f, interval, std)))
        assert 0.1 < measured < 0.9  # the filter neither passes nor removes the swell whole
        assert predicted == pytest.approx(measured, rel=0.3)


def test_the_filters_depth_noise_comes_from_the_trajectory():
    t = np.linspace(0.0, 10.0, 11)
    traj = Trajectory(t, np.zeros((11, 18)), np.zeros((11, 18, 18)))
    assert trajectory_depth_noise(traj) is None  # another estimator's: it does not say
    traj.metadata["config"] = {"depth_std_m": 0.02}
    assert trajectory_depth_noise(traj) is None  # no barometer
    traj.metadata["sensors"] = {"pressure": {"used": 51}}
    assert trajectory_depth_noise(traj) == (0.02, 0.2)
    traj.metadata["sensors"] = {"pressure": {"used": 1}}
    assert trajectory_depth_noise(traj) is None


def test_a_filter_that_carried_the_swell_gets_nothing_added():
    t = np.linspace(0.0, 10.0, 11)
    traj = Trajectory(t, np.zeros((11, 18)), np.zeros((11, 18, 18)))
    traj.metadata.update(config={"depth_std_m": 0.02, "pressure_wave_noise": True},
                         sensors={"pressure": {"used": 51}})  # fmt: skip
    assert trajectory_depth_noise(traj) == (0.02, 0.2)  # no wave noise added (be, baseline)
    traj.metadata["wave_noise"] = {"condition": "wave-a0.15-f0.33"}
    assert trajectory_depth_noise(traj) is None  # its depth covariance holds the swell
    traj.metadata["config"]["pressure_wave_noise"] = False
    assert trajectory_depth_noise(traj) == (0.02, 0.2)
