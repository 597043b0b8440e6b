"""Wave characterization against closed forms on synthetic signals (the simulator tests are in
test_experiments)."""

import numpy as np
import pytest

from undertow.characterize import characterize_run, estimate_waves, wave_noise
from undertow.log import Dvl, GroundTruth, Log, Mounting, WaveProbe


def test_sinusoid_amplitude_and_frequency():
    t = np.arange(0, 120, 0.01)
    probe = WaveProbe(t=t, elevation=0.1 * np.cos(2 * np.pi * 0.75 * t + 0.3))
    w = estimate_waves(probe)
    assert w.frequency_hz == pytest.approx(0.75, rel=2e-3)
    assert w.amplitude_m == pytest.approx(0.1, rel=1e-2)
    assert w.amplitude_zero_crossing_m == pytest.approx(0.1, rel=1e-2)


def test_dvl_noise_about_truth_excludes_motion_and_acceleration():
    rng = np.random.default_rng(4)
    t = np.arange(0, 60, 1 / 2000)
    speed = np.clip(t / 10, 0, 1) * np.clip((60 - t) / 10, 0, 1) * 1.0  # ramp up, hold, down
    gt = GroundTruth(
        t=t,
        position=np.column_stack([np.cumsum(speed) / 2000, 0 * t, 0 * t]),
        orientation=np.zeros((t.size, 3)),
    )
    mounting = Mounting()
    td = np.arange(0.1, 59.9, 0.1)
    v_true = (
        np.column_stack([np.interp(td, t, speed), 0 * td, 0 * td]) @ mounting.dvl.rotation_matrix()
    )
    sigma = np.array([0.03, 0.01, 0.003])
    dvl = Dvl.from_velocity(td, v_true + rng.normal(size=v_true.shape) * sigma)
    run = characterize_run(Log(dvl=dvl, ground_truth=gt, mounting=mounting))
    n = run.dvl_samples
    assert 300 < n < 400  # only the constant-speed phase (~10 s..50 s at 10 Hz, edges trimmed)
    # the sample std of n normal draws has relative standard error 1/sqrt(2(n-1))
    np.testing.assert_allclose(run.dvl_std_mps, sigma, rtol=4 / np.sqrt(2 * (n - 1)))


def test_quadrature_subtraction_of_calm_noise():
    from undertow.characterize import RunCharacterization

    calm = RunCharacterization("c", None, (0.006, 0.006, 0.002), 100, None, "gt")
    wavy = RunCharacterization("w", None, (0.010, 0.006, 0.001), 100, None, "gt")
    np.testing.assert_allclose(wave_noise(wavy, calm), [0.008, 0.0, 0.0], atol=1e-12)


def test_recovers_the_simulators_waves_and_noise():
    """Characterize a simulated carriage run: wave amplitude and frequency within a few percent
    of the scenario, DVL sigmas within sampling error of the configured ones (base beam noise
    through the A50 geometry plus the wave term kappa U(d) / sqrt2, U from linear theory)."""
    from scipy.optimize import brentq

    from undertow.sim import load_scenario, simulate

    scenario = load_scenario("wave-a0.10-f0.75")
    log = simulate(scenario, seed=5).log
    run = characterize_run(log)
    a, f, h = scenario.wave.amplitude_m, scenario.wave.frequency_hz, scenario.water.depth_m
    assert run.wave.amplitude_m == pytest.approx(a, rel=0.03)
    assert run.wave.frequency_hz == pytest.approx(f, rel=0.01)

    g, omega = scenario.water.gravity_m_s2, 2 * np.pi * f
    k = brentq(lambda k: g * k * np.tanh(k * h) - omega**2, 1e-6, 100.0)
    d = scenario.motion.carriage.depth_m + log.mounting.dvl.translation[2]
    U = a * omega * np.cosh(k * (h - d)) / np.sinh(k * h)
    kappa = scenario.dvl.wave_noise_coefficient
    sigma_b, tilt = scenario.dvl.beam_velocity_sigma, np.deg2rad(scenario.dvl.beam_tilt_deg)
    base = np.array([1 / (np.sqrt(2) * np.sin(tilt))] * 2 + [1 / (2 * np.cos(tilt))]) * sigma_b
    yaw = log.mounting.dvl.rotation[2]  # waves along world x, seen in the DVL frame
    wave_x = kappa[0] * U / np.sqrt(2)
    expected = np.sqrt(base**2 + np.array([np.cos(yaw), np.sin(yaw), 0.0]) ** 2 * wave_x**2)
    n = run.dvl_samples
    np.testing.assert_allclose(run.dvl_std_mps, expected, rtol=4 / np.sqrt(2 * (n - 1)))
