"""Wave characterization against closed forms: synthetic signals, and simulated runs whose
configured noise (DVL beams, wave term, barometer) is known in closed form."""

import numpy as np
import pytest

from undertow.estimation.characterize import characterize_run, estimate_waves, wave_noise
from undertow.log import Dvl, GroundTruth, Log, WaveProbe
from undertow.robot import Mounting


def test_sinusoid_amplitude_and_frequency():
    t = np.arange(0, 120, 0.01)
    probe = WaveProbe(t=t, elevation=0.1 * np.cos(2 * np.pi * 0.75 * t + 0.3))
    w = estimate_waves(probe)
    assert w.frequency_hz == pytest.approx(0.75, rel=2e-3)
    assert w.amplitude_m == pytest.approx(0.1, rel=1e-2)
    assert w.amplitude_zero_crossing_m == pytest.approx(0.1, rel=1e-2)


def test_dvl_noise_about_truth_excludes_motion_and_acceleration():
    sigma = np.array([0.03, 0.01, 0.003])
    run = characterize_run(_ramp_hold_ramp(4, sigma))
    n = run.dvl_samples
    assert 300 < n < 400  # only the constant-speed phase (~10 s..50 s at 10 Hz, edges trimmed)
    # the sample std of n normal draws has relative standard error 1/sqrt(2(n-1))
    np.testing.assert_allclose(run.dvl_std_m_s, sigma, rtol=4 / np.sqrt(2 * (n - 1)))


def test_quadrature_subtraction_of_calm_noise():
    from undertow.estimation.characterize import RunCharacterization

    calm = RunCharacterization("c", None, (0.006, 0.006, 0.002), 100, None, "gt")
    wavy = RunCharacterization("w", None, (0.010, 0.006, 0.001), 100, None, "gt")
    np.testing.assert_allclose(wave_noise(wavy, calm), [0.008, 0.0, 0.0], atol=1e-12)


@pytest.mark.slow
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
    np.testing.assert_allclose(run.dvl_std_m_s, expected, rtol=4 / np.sqrt(2 * (n - 1)))


def test_calm_probe_is_calm_not_a_random_spectral_peak():
    """Probe noise alone (white, 1 mm) has a flat spectrum whose highest bin is random: the run
    is calm and has no wave frequency. The same noise over a 5 cm wave is a wave."""
    rng = np.random.default_rng(7)
    t = np.arange(0, 50, 0.01)
    noise = rng.normal(0, 1e-3, t.size)
    calm = estimate_waves(WaveProbe(t=t, elevation=noise))
    assert calm.calm and calm.frequency_hz is None
    wave = estimate_waves(WaveProbe(t=t, elevation=0.05 * np.cos(2 * np.pi * 0.8 * t) + noise))
    assert not wave.calm and wave.frequency_hz == pytest.approx(0.8, rel=5e-3)


def _ramp_hold_ramp(seed, sigma, wave_probe=None):
    rng = np.random.default_rng(seed)
    t = np.arange(0, 60, 1 / 2000)
    speed = np.clip(t / 10, 0, 1) * np.clip((60 - t) / 10, 0, 1) * 1.0
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
    dvl = Dvl.from_velocity(td, v_true + rng.normal(size=v_true.shape) * sigma)
    return Log(dvl=dvl, ground_truth=gt, mounting=mounting, wave_probe=wave_probe)


def test_without_ground_truth_the_acceleration_phases_are_excluded():
    """Ramps of 0.1 m/s^2 over 10 s: about the DVL's own running mean, inside the constant-speed
    segment found from the DVL, the std is the configured one (a reference that followed the
    ramps badly, or residuals taken during them, would inflate it)."""
    sigma = np.array([0.03, 0.01, 0.003])
    run = characterize_run(_ramp_hold_ramp(4, sigma).replace(ground_truth=None))
    n = run.dvl_samples
    assert 250 < n < 400  # the 40 s plateau at 10 Hz, less one window
    np.testing.assert_allclose(run.dvl_std_m_s, sigma, rtol=4 / np.sqrt(2 * (n - 1)))
    assert any("no ground_truth" in note for note in run.notes)


@pytest.fixture(scope="module")
def simulated():
    from undertow.sim import load_scenario, simulate

    return {name: simulate(load_scenario(name), seed=5) for name in ("calm", "wave-a0.10-f0.75")}


@pytest.mark.slow
@pytest.mark.parametrize("name", ["calm", "wave-a0.10-f0.75"])
def test_without_ground_truth_agrees_with_ground_truth(simulated, name):
    """Hiding the ground truth changes the reference (the DVL's own running mean inside its
    constant-speed segment) but not the answer: within sampling error of the with-ground-truth
    numbers on the same run, for the calm run (whose probe noise must not be taken as a fast
    wave) and a wave run; the barometer's noise is measured too."""
    log = simulated[name].log
    with_gt = characterize_run(log)
    without = characterize_run(log.replace(ground_truth=None))
    assert without.calm == with_gt.calm == (name == "calm")
    n = min(with_gt.dvl_samples, without.dvl_samples)
    assert n > 200
    np.testing.assert_allclose(
        without.dvl_std_m_s, with_gt.dvl_std_m_s, rtol=3 / np.sqrt(2 * (n - 1))
    )
    assert without.depth_std_m == pytest.approx(with_gt.depth_std_m, rel=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["calm", "wave-a0.10-f0.75"])
def test_barometer_depth_noise_matches_its_closed_form(simulated, name):
    """The simulated barometer reads p = p_atm + rho g d + rho g a K_p(d) cos(theta) + n_p with
    K_p(d) = cosh(k(h - d)) / cosh(k h) (linear theory, k from the dispersion relation solved
    here by brentq) at a constant depth d on the carriage, so depth(p) computed with the
    characterization's density rho_c has std sqrt((rho/rho_c a K_p)^2 / 2 + (s_p/(rho_c g))^2),
    with and without ground truth."""
    from scipy.optimize import brentq

    sim = simulated[name]
    scenario, log = sim.scenario, sim.log
    a, f, h = scenario.wave.amplitude_m, scenario.wave.frequency_hz, scenario.water.depth_m
    g, rho, rho_c = scenario.water.gravity_m_s2, scenario.water.density_kg_m3, 997.0
    d = scenario.motion.carriage.depth_m + log.mounting.barometer.translation[2]
    omega = 2 * np.pi * f
    k = brentq(lambda k: g * k * np.tanh(k * h) - omega**2, 1e-6, 100.0)
    K_p = np.cosh(k * (h - d)) / np.cosh(k * h)
    expected = np.hypot(rho / rho_c * a * K_p / np.sqrt(2), scenario.barometer.noise_sigma_pa
                        / (rho_c * g))  # fmt: skip
    # pure noise: sampling error of a std (4 standard errors); a wave: the sinusoid's share
    # of the variance over a non-integer number of periods and the running mean's leak, < 3 %
    rel = 4 / np.sqrt(2 * len(log.pressure)) if a == 0 else 0.03
    assert characterize_run(log).depth_std_m == pytest.approx(expected, rel=rel)
    assert characterize_run(log.replace(ground_truth=None)).depth_std_m == pytest.approx(
        expected, rel=rel
    )


def test_a_run_without_a_constant_speed_segment_says_so():
    """A run whose speed keeps changing (as on a circle with manoeuvres) has plenty of valid DVL
    samples but no segment at constant speed: the error says that, not "too few samples"."""
    from undertow.errors import DataError

    td = np.arange(0.1, 60, 0.1)
    speed = 0.5 + 0.4 * np.sin(2 * np.pi * td / 6)  # never within 5 % of a cruise speed for 4 s
    dvl = Dvl.from_velocity(td, np.column_stack([speed, 0 * td, 0 * td]))
    with pytest.raises(DataError, match="no constant-speed segment") as info:
        characterize_run(Log(dvl=dvl, mounting=Mounting()))
    assert f"among its {td.size} valid DVL samples" in str(info.value)
    assert "fewer than 10" not in str(info.value)


@pytest.mark.slow
def test_characterize_without_a_calm_run_warns():
    from undertow.estimation.characterize import characterize

    with pytest.warns(UserWarning, match="no calm run among the logs"):
        t = np.arange(0, 60, 0.01)
        probe = WaveProbe(t=t, elevation=0.1 * np.cos(2 * np.pi * 0.75 * t))
        characterize([_ramp_hold_ramp(5, np.array([0.01, 0.01, 0.01]), wave_probe=probe)])


def test_without_a_probe_the_onboard_estimate_gives_the_condition(simulation):
    """A run with no wave probe (at sea) is characterized at the condition the onboard
    estimator infers from the barometer and DVL; with a probe, the probe is the reference and
    the onboard estimate is reported next to it. Both against the scenario's true condition."""
    from undertow.estimation.characterize import characterize

    log = simulation("wave-a0.10-f0.75").log
    a_true = log.metadata["wave"]["amplitude_m"]
    f_true = log.metadata["wave"]["frequency_hz"]
    with_probe = characterize_run(log)
    assert with_probe.wave.amplitude_m == pytest.approx(a_true, rel=0.05)  # the probe
    assert with_probe.onboard["amplitude_m"] == pytest.approx(a_true, rel=0.15)
    assert with_probe.onboard["frequency_hz"] == pytest.approx(f_true, rel=0.05)
    no_probe = characterize_run(log.replace(wave_probe=None))
    assert no_probe.wave.amplitude_m == no_probe.onboard["amplitude_m"]
    assert no_probe.wave.frequency_hz == pytest.approx(f_true, rel=0.05)
    assert any("estimated from the onboard sensors" in n for n in no_probe.notes)
    calm = simulation("calm").log.replace(wave_probe=None)
    result = characterize([calm, log.replace(wave_probe=None)])
    rows = result.table()
    assert rows[0]["calm"] and not rows[1]["calm"]
    wave = result.profile.conditions[1]
    assert wave.amplitude_m == pytest.approx(a_true, rel=0.15)
    assert wave.frequency_hz == pytest.approx(f_true, rel=0.05)
