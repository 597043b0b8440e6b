"""Sensor models: statistics of long runs against the configured sigmas, closed forms."""

import numpy as np
import pytest
from scipy import stats

from undertow.log import G0
from undertow.sim import Scenario, load_scenario, simulate
from undertow.sim.motion import kinematics
from undertow.sim.simulate import build_motion, build_wave


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def scenario(name="calm", **over) -> Scenario:
    base = load_scenario(name).to_yaml_dict()
    base = _merge(base, {"ground_truth": {"rate_hz": 50.0}, "floor_cloud": {"spacing_m": 0.2}})
    return Scenario.model_validate(_merge(base, over))


def std_in_chi2_bounds(samples: np.ndarray, sigma: float, p: float = 1e-4, mean_known=True):
    """True if the sample std is inside the two-sided chi-square interval for sigma."""
    n = samples.size
    dof = n if mean_known else n - 1
    ss = np.sum(samples**2) if mean_known else np.sum((samples - samples.mean()) ** 2)
    lo, hi = stats.chi2.ppf([p / 2, 1 - p / 2], dof)
    return lo <= ss / sigma**2 <= hi


AT_REST = {
    "motion": {"carriage": {"hold_before_s": 300.0, "run_length_m": 0.5, "hold_after_s": 0.0}}
}


def test_dvl_velocity_noise_at_rest_matches_beam_geometry():
    s = scenario(**AT_REST, dvl={"beam_velocity_sigma": 0.01, "rate_hz": 10.0})
    dvl = simulate(s, seed=3).log.dvl
    v = dvl.velocity[dvl.t < 299.0]
    sb, tilt = 0.01, np.deg2rad(22.5)
    assert std_in_chi2_bounds(v[:, 0], sb / (np.sqrt(2) * np.sin(tilt)))
    assert std_in_chi2_bounds(v[:, 1], sb / (np.sqrt(2) * np.sin(tilt)))
    assert std_in_chi2_bounds(v[:, 2], sb / (2 * np.cos(tilt)))
    np.testing.assert_allclose(dvl.covariance[0], np.diag(np.diag(dvl.covariance[0])), atol=1e-12)


def _dvl_truth(s: Scenario, t: np.ndarray) -> np.ndarray:
    mount = s.mounting.to_mounting().dvl
    kin = kinematics(build_motion(s, build_wave(s)), t, mount.translation)
    R_wd = kin.R @ mount.rotation_matrix()
    return np.einsum("nji,nj->ni", R_wd, kin.velocity), kin.position


def test_dvl_wave_noise_scales_with_orbital_speed_at_sensor_depth():
    s = scenario("wave-a0.10-f0.75", **AT_REST, dvl={"beam_velocity_sigma": 0.002})
    dvl = simulate(s, seed=5).log.dvl
    true_v, pos = _dvl_truth(s, dvl.t)
    resid = (dvl.velocity - true_v)[dvl.t < 299.0]
    wave = build_wave(s)
    k, h, w, a = wave.k, 3.0, wave.omega, 0.1
    d = pos[0, 2]
    U = a * w * np.cosh(k * (h - d)) / np.sinh(k * h)  # closed form, kappa = 1 along x
    sb, tilt = 0.002, np.deg2rad(22.5)
    # the DVL frame is yawed 0.05 rad from the wave axis: project the along-wave variance
    var_wave = (U / np.sqrt(2)) ** 2
    var_x = (sb / (np.sqrt(2) * np.sin(tilt))) ** 2 + var_wave * np.cos(0.05) ** 2
    var_z = (sb / (2 * np.cos(tilt))) ** 2
    assert std_in_chi2_bounds(resid[:, 0], np.sqrt(var_x))
    assert std_in_chi2_bounds(resid[:, 2], np.sqrt(var_z))


def test_sound_speed_scales_velocity():
    s = scenario(dvl={"sound_speed_setting": 1500.0}, water={"sound_speed_m_s": 1470.0})
    dvl = simulate(s, seed=1).log.dvl
    true_v, _ = _dvl_truth(s, dvl.t)
    cruise = np.abs(true_v[:, 0]) > 0.9
    ratio = dvl.velocity[cruise, 0].sum() / true_v[cruise, 0].sum()
    assert ratio == pytest.approx(1500.0 / 1470.0, rel=5e-4)


def test_dvl_altitude_and_sonar_range_over_flat_floor():
    s = scenario(
        **AT_REST,
        dvl={"range_sigma": 0.004},
        sonar={"range_sigma": 0.01, "range_sigma_fraction": 0.0},
    )
    log = simulate(s, seed=2).log
    # both convert the echo's travel time with the sound speed they are set to (1500 m/s)
    k_dvl = s.dvl.sound_speed_setting / s.water.sound_speed_m_s
    k_sonar = s.sonar.sound_speed_setting / s.water.sound_speed_m_s
    z_dvl = 0.5 + 0.284
    alt = log.dvl.altitude[log.dvl.t < 299.0]
    # altitude = mean of 4 beams' r_i cos(tilt): noise sigma_r cos(tilt) / 2
    sigma = k_dvl * 0.004 * np.cos(np.deg2rad(22.5)) / 2
    assert std_in_chi2_bounds(alt - k_dvl * (3.0 - z_dvl), sigma)
    assert np.all(log.dvl.beam_valid)
    r = log.sonar.range[log.sonar.t < 299.0]
    # minimum slant range = vertical
    assert std_in_chi2_bounds(r - k_sonar * (3.0 - 0.5 - 0.306), k_sonar * 0.01)
    assert np.all((log.sonar.confidence >= 0) & (log.sonar.confidence <= 1))


def test_sonar_range_noise_grows_with_the_waves_as_the_dvls():
    """The Ping meets the acoustic path's wave disturbance the DVL's ranges do: its range
    noise is hypot(s_0, kappa_r a sinh(k (h - d)) / sinh(k h) / sqrt 2) at its depth d."""
    s = scenario(
        "wave-a0.10-f0.75", **AT_REST, sonar={"range_sigma": 0.004, "range_sigma_fraction": 0.0}
    )
    log = simulate(s, seed=4).log
    wave = build_wave(s)
    k, h, a, d = wave.k, s.water.depth_m, 0.1, 0.5 + 0.306
    zeta = a * np.sinh(k * (h - d)) / np.sinh(k * h) / np.sqrt(2)
    scale = s.sonar.sound_speed_setting / s.water.sound_speed_m_s
    r = log.sonar.range[log.sonar.t < 299.0]
    assert std_in_chi2_bounds(r - scale * (h - d), scale * np.hypot(0.004, zeta))
    calm = scenario(
        "wave-a0.10-f0.75",
        **AT_REST,
        sonar={
            "range_sigma": 0.004,
            "range_sigma_fraction": 0.0,
            "wave_range_noise_coefficient": 0.0,
        },
    )
    r = simulate(calm, seed=4).log.sonar.range[log.sonar.t < 299.0]
    assert std_in_chi2_bounds(r - scale * (h - d), scale * 0.004)


@pytest.mark.parametrize("setting", [1440.0, 1500.0])
def test_sound_speed_scales_the_ranges(setting):
    """A range is c_set t / 2 of the echo's travel time t: the ranges of one run in waters of
    two sound speeds differ by their ratio (same seed, same noise draws)."""
    ranges = {}
    for water in (1470.0, 1500.0):
        s = scenario(
            **AT_REST,
            dvl={"sound_speed_setting": setting},
            sonar={"sound_speed_setting": setting},
            water={"sound_speed_m_s": water},
        )
        log = simulate(s, seed=3).log
        ranges[water] = (log.dvl.beam_range, log.dvl.altitude, log.sonar.range)
    for slow, fast in zip(ranges[1470.0], ranges[1500.0], strict=True):
        ok = np.isfinite(slow) & np.isfinite(fast)
        assert ok.mean() > 0.9
        np.testing.assert_allclose(slow[ok], fast[ok] * 1500.0 / 1470.0, rtol=1e-12)


def test_sonar_sees_the_rock_top_first():
    s = scenario()
    log = simulate(s, seed=0).log
    rock = s.tank.rock
    gt = log.ground_truth
    x_sonar = np.interp(log.sonar.t, gt.t, gt.position[:, 0]) + 0.164
    over = np.abs(x_sonar - rock.center_x_m) < 0.2
    k = s.sonar.sound_speed_setting / s.water.sound_speed_m_s  # the Ping's sound speed
    expected = k * (3.0 - rock.height_m - (0.5 + 0.306))
    assert np.median(log.sonar.range[over]) == pytest.approx(expected, abs=0.03)


@pytest.mark.slow
def test_imu_gyro_white_noise_and_bias_walk_follow_the_densities():
    s = scenario(**AT_REST, imu={"gyro_bias_random_walk": 0.0, "gyro_initial_bias_sigma": 0.0})
    imu = simulate(s, seed=4).log.imu
    rest = imu.t < 299.0
    sd = s.imu.gyro_noise_density * np.sqrt(s.imu.rate_hz)
    assert std_in_chi2_bounds(imu.angular_velocity[rest].ravel(), sd)
    f = imu.linear_acceleration[rest]
    np.testing.assert_allclose(
        f.mean(axis=0), [0.0, 0.0, -G0], atol=5 * 2.9e-3 * 10 / np.sqrt(f.shape[0])
    )

    s = scenario(**AT_REST, imu={"gyro_noise_density": 0.0, "gyro_initial_bias_sigma": 0.0})
    imu = simulate(s, seed=4).log.imu
    steps = np.diff(imu.angular_velocity[imu.t < 299.0], axis=0)
    assert std_in_chi2_bounds(steps.ravel(), s.imu.gyro_bias_random_walk / np.sqrt(s.imu.rate_hz))


def test_dead_reckoning_yaw_drift_rate_matches_configured_bias():
    s = scenario(dead_reckoning={"yaw_drift_rate": 1e-3, "orientation_sigma": 1e-3})
    log = simulate(s, seed=6).log
    dr, gt = log.dead_reckoning, log.ground_truth
    err = dr.orientation[:, 2] - np.interp(dr.t, gt.t, gt.orientation[:, 2])
    fit = stats.linregress(dr.t, err)
    assert fit.slope == pytest.approx(1e-3, abs=5 * fit.stderr)


def test_dead_reckoning_without_errors_follows_ground_truth():
    s = scenario(
        dvl={"beam_velocity_sigma": 0.0, "sound_speed_setting": 1476.0, "rate_hz": 10.0},
        dead_reckoning={"yaw_drift_rate": 0.0, "orientation_sigma": 0.0},
    )
    log = simulate(s, seed=0).log
    gt, dr = log.ground_truth, log.dead_reckoning
    truth = np.stack([np.interp(dr.t, gt.t, gt.position[:, i]) for i in range(3)], 1)
    # forward Euler at 10 Hz over a 0.5 m/s^2 ramp: error below a dt * v_max
    assert np.max(np.abs(dr.position - truth)) < 0.1 * 1.0


def test_barometer_reads_hydrostatic_plus_dynamic_pressure():
    s = scenario("wave-a0.10-f1.00", **AT_REST)
    log = simulate(s, seed=8).log
    p = log.pressure
    gt = log.ground_truth
    x = np.interp(p.t, gt.t, gt.position[:, 0])
    d = np.interp(p.t, gt.t, gt.position[:, 2])
    wave = build_wave(s)
    k, w, rho, a = wave.k, wave.omega, 998.0, 0.1
    theta = k * (-x) - w * p.t  # heading 180 deg
    model = (
        101325.0
        + rho * G0 * d
        + rho * G0 * a * np.cosh(k * (3.0 - d)) / np.cosh(3.0 * k) * np.cos(theta)
    )
    assert std_in_chi2_bounds(p.pressure - model, s.barometer.noise_sigma_pa)


def test_wave_probe_reads_the_elevation_at_its_x():
    s = scenario("wave-a0.05-f0.75")
    probe = simulate(s, seed=9).log.wave_probe
    wave = build_wave(s)
    eta = 0.05 * np.cos(wave.k * (-s.wave_probe.x_m) - wave.omega * probe.t)
    assert std_in_chi2_bounds(probe.elevation - eta, s.wave_probe.noise_sigma)
    assert probe.x == s.wave_probe.x_m
