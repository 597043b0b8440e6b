"""The swell's pressure head at the barometer (``pressure_wave_noise``): the physics against the
simulator's own wave and barometer, the rows (white noise for the peers, the swell states' model
for the UKF), the band at the encounter frequency, and the filter it makes consistent."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from undertow.cli import app
from undertow.estimation import model
from undertow.estimation.calibration import Calibration
from undertow.estimation.config import LocalizerConfig
from undertow.estimation.localizer import calibration_fields, localize, with_log_heading
from undertow.estimation.noise import NoiseProfile, TrackNoise
from undertow.estimation.noise_physics import pressure_head_variance
from undertow.estimation.rows import filter_pressure_rows, pressure_rows
from undertow.estimation.wave_schedule import schedule_noise
from undertow.log import FRESH_WATER_DENSITY, G0
from undertow.rotations import rpy_to_matrix
from undertow.sim import Scenario, load_scenario, simulate
from undertow.sim.waves import depth_factors, encounter_frequency, wavenumber
from undertow.wavetrack import WaveTrack


def test_deep_water_is_the_pressure_factor_exp_minus_k_d():
    """The closed form a^2 e^{-2 omega^2 d / g} / 2 (deep-water dispersion k = omega^2 / g)."""
    a, f = 0.1, 0.5
    d = np.linspace(0.0, 20.0, 9)
    closed = a**2 * np.exp(-2 * (2 * np.pi * f) ** 2 / G0 * d) / 2
    np.testing.assert_allclose(pressure_head_variance(a, f, d), closed, rtol=1e-12)


@pytest.mark.parametrize(("f", "h"), [(1.0, 3.03), (0.33, 6.07), (0.2, 8.0), (0.1, 20.0)])
def test_within_eight_percent_of_the_finite_depth_factor_above_mid_depth(f, h):
    """The simulator's finite-depth K_p (its own dispersion solver) against the deep-water
    form: never above it, and at most 8 % below it down to mid-depth."""
    k = wavenumber(2 * np.pi * f, h)
    d = np.linspace(0.0, h, 21)
    _, _, k_p = depth_factors(k, h, d)
    deep = np.sqrt(2 * pressure_head_variance(1.0, f, d))
    assert np.all(deep <= k_p * (1 + 1e-12))
    upper = d <= h / 2
    assert np.all(deep[upper] >= 0.92 * k_p[upper])


def test_nothing_for_calm_or_unknown_frequency():
    assert np.all(pressure_head_variance([0.0, 0.1, 0.1], [1.0, np.nan, 1.0],
                                         [1.0, 1.0, np.nan]) == 0.0)  # fmt: skip


@pytest.fixture(scope="module")
def basin():
    """The basin's carriage run in its waves (a = 0.1 m, f = 1 Hz; k h = 12: deep water)."""
    return simulate(load_scenario("mhl-basin"), seed=3).log


def test_the_simulated_barometer_reads_the_swell_with_this_variance(basin):
    """The simulator's barometer (p = rho g d + the wave's dynamic pressure + its noise, through
    its own LinearWave) minus the true depth: variance a^2 K_p^2 / 2 + its noise^2, within
    10 %."""
    log = basin
    meta = log.metadata
    rho_g = float(meta["water_density_kg_m3"]) * G0
    p, gt = log.pressure, log.ground_truth
    t = p.t[(p.t > gt.t[0]) & (p.t < gt.t[-1])]
    depth = np.interp(t, gt.t, gt.position[:, 2])
    read = (np.interp(t, p.t, p.pressure) - meta["surface_pressure_pa"]) / rho_g
    noise = 20.0 / rho_g  # BarometerModel.noise_sigma_pa
    a, f = meta["wave"]["amplitude_m"], meta["wave"]["frequency_hz"]
    expected = np.mean(pressure_head_variance(a, f, depth)) + noise**2
    assert np.var(read - depth) == pytest.approx(expected, rel=0.1)


def test_the_wave_variants_add_it_to_the_barometers_rows(basin):
    log = basin
    a, f = log.metadata["wave"]["amplitude_m"], log.metadata["wave"]["frequency_hz"]
    noise = NoiseProfile.paper().noise((a, f), extrapolate=True)
    rows = {}
    for name, cfg in {"proposed": LocalizerConfig(variant="proposed"),
                      "an": LocalizerConfig(variant="an"),
                      "be": LocalizerConfig(variant="be"),
                      "off": LocalizerConfig(variant="proposed", pressure_wave_noise=False),
                      }.items():  # fmt: skip
        t, _, z, R, ok = pressure_rows(log, cfg, noise, {})
        rows[name] = R[:, 0, 0]
    added = pressure_head_variance(a, f, z[:, 0])
    assert added[ok].min() > 0
    np.testing.assert_allclose(rows["proposed"] - rows["be"], added, rtol=1e-12, atol=1e-18)
    np.testing.assert_array_equal(rows["an"], rows["proposed"])
    np.testing.assert_array_equal(rows["off"], rows["be"])
    assert np.all(rows["be"] == 0.01**2)
    calm = NoiseProfile.paper().noise("calm")
    _, _, _, R, _ = pressure_rows(log, LocalizerConfig(variant="proposed"), calm, {})
    assert np.all(R[:, 0, 0] == 0.01**2)


def test_the_filter_rows_carry_the_swell_and_the_sensor_noise_alone(basin):
    """The UKF's barometer rows: R of the sensor alone, and per row (omega_0, sigma^2, cos beta,
    sin beta) with sigma^2 the variance the white-noise rows add; none for a variant without."""
    log = basin
    a, f = log.metadata["wave"]["amplitude_m"], log.metadata["wave"]["frequency_hz"]
    noise = NoiseProfile.paper().noise((a, f), extrapolate=True)
    cfg = LocalizerConfig(variant="proposed", wave_heading_deg=150.0)
    t, _, z, R, ok, swell = filter_pressure_rows(log, cfg, noise, {})
    assert np.all(R[:, 0, 0] == cfg.depth_std_m**2)
    np.testing.assert_allclose(swell[:, 1], pressure_head_variance(a, f, z[:, 0]), rtol=1e-12)
    np.testing.assert_allclose(swell[:, 0], 2 * np.pi * f)
    beta = np.radians(150.0)
    assert np.all(swell[:, 2] == np.cos(beta)) and np.all(swell[:, 3] == np.sin(beta))
    unknown = filter_pressure_rows(log, cfg.model_copy(update={"wave_heading_deg": None}),
                                   noise, {})[5]  # fmt: skip
    assert np.isnan(unknown[:, 2:]).all()
    for off in (
        LocalizerConfig(variant="be"),
        cfg.model_copy(update={"pressure_wave_noise": False}),
    ):
        held = filter_pressure_rows(log, off, noise, {})[5]
        assert np.all(held[:, 1] == 0.0) and np.isnan(held[:, 0]).all()


def test_the_band_sits_at_the_encounter_frequency():
    """model.encounter against the simulator's encounter_frequency (omega - k V cos(beta - psi),
    its own code) for random attitudes, body velocities and wave directions; with the direction
    unknown the band stays at omega_0 and its half-width lambda_e omega_0 covers every encounter
    frequency the speed allows."""
    rng = np.random.default_rng(3)
    R = np.empty((3, 3))
    for _ in range(200):
        x = np.zeros(20)
        x[3:6] = rng.uniform([-0.2, -0.2, -np.pi], [0.2, 0.2, np.pi])
        x[6:9] = rng.normal(0.0, 0.4, 3)
        omega0, beta = 2 * np.pi * rng.uniform(0.2, 1.0), rng.uniform(-np.pi, np.pi)
        k0 = omega0**2 / G0
        v = rpy_to_matrix(x[3:6]) @ x[6:9]
        speed, course = np.hypot(v[0], v[1]), np.arctan2(v[1], v[0])
        expected = encounter_frequency(omega0, k0, speed, course, beta)
        we, lam = model.encounter(x, omega0, np.cos(beta), np.sin(beta), 0.1, R)
        assert lam == 0.1
        assert we == pytest.approx(max(abs(float(expected)), 0.1 * omega0), rel=1e-12)
        w0, lam_e = model.encounter(x, omega0, np.nan, np.nan, 0.1, R)
        assert w0 == omega0 and lam_e == pytest.approx(min(max(0.1, k0 * speed / omega0), 0.9))
        if lam_e < 0.9:
            assert abs(float(expected) - omega0) <= lam_e * omega0 * (1 + 1e-12)


def test_the_log_s_wave_direction_is_used_and_recorded(basin):
    """A simulated log records its waves' direction (metadata wave_heading_deg): the swell
    variants take it into their config (and config.yaml), a given one wins, the others ignore it."""
    assert basin.metadata["wave_heading_deg"] == 180.0
    cfg = LocalizerConfig(variant="proposed")
    assert with_log_heading(cfg, basin).wave_heading_deg == 180.0
    given = cfg.model_copy(update={"wave_heading_deg": 90.0})
    assert with_log_heading(given, basin).wave_heading_deg == 90.0
    assert with_log_heading(LocalizerConfig(variant="be"), basin).wave_heading_deg is None
    assert with_log_heading(cfg, basin.replace(metadata={})).wave_heading_deg is None


def test_the_calibrated_barometer_noise_goes_to_the_variants_that_carry_the_swell():
    cal = Calibration(depth_std_m=0.002, estimated=("dvl_scale_factor", "depth_std_m"))
    assert calibration_fields(cal, LocalizerConfig(variant="proposed"))["depth_std_m"] == 0.002
    assert calibration_fields(cal, LocalizerConfig(variant="an"))["depth_std_m"] == 0.002
    for other in (LocalizerConfig(variant="be"), LocalizerConfig(variant="baseline"),
                  LocalizerConfig(variant="proposed", pressure_wave_noise=False)):  # fmt: skip
        assert "depth_std_m" not in calibration_fields(cal, other)


def test_each_kind_of_wave_noise_says_its_wave_over_time():
    profile = NoiseProfile.paper()
    t = np.array([0.0, 5.0, 10.0, 20.0])
    a, f = profile.noise((0.1, 0.75)).wave_at(t)
    np.testing.assert_array_equal(a, 0.1)
    np.testing.assert_array_equal(f, 0.75)
    a, f = profile.noise("calm").wave_at(t)
    assert np.all(a == 0) and np.all(np.isnan(f))
    track = WaveTrack(t=[0.0, 10.0, 20.0], amplitude_m=[0.0, 0.1, 0.05],
                      frequency_hz=[np.nan, 1.0, 0.75])  # fmt: skip
    a, f = TrackNoise(track, [profile.noise("calm")] * 3).wave_at(t)
    np.testing.assert_allclose(a, [0.0, 0.05, 0.1, 0.05])
    np.testing.assert_allclose(
        f, [1.0, 1.0, 1.0, 0.75]
    )  # the calm node's frequency: its neighbour's
    steps = schedule_noise(profile, [{"from_t": 8.0, "condition": [0.1, 1.0]}], "nearest")
    a, f = steps.wave_at(t)
    np.testing.assert_array_equal(a, [0.0, 0.0, 0.1, 0.1])
    assert np.isnan(f[:2]).all() and np.all(f[2:] == 1.0)


@pytest.mark.slow
def test_a_free_vehicle_in_a_swell_gets_a_consistent_depth():
    """Half the field survey (a = 0.15 m, f = 0.33 Hz swell at 3 m), the filter told the
    barometer's own noise (the simulated Bar30's 20 Pa, what `undertow calibrate` measures in
    calm water): with the swell states the depth error is 10 times smaller and the filter is not
    overconfident (pressure NIS and the depth error against its std at most about 1; both are
    below 1 because the swell model's band, lambda = 0.1, is wider than the simulator's single
    wave); the paper's model (the barometer's noise alone, swell unmodelled) is overconfident
    in both by more than 3."""
    scenario = load_scenario("field-survey")
    data = scenario.to_yaml_dict()
    data["motion"]["waypoints"]["points"] = data["motion"]["waypoints"]["points"][:8]
    log = simulate(Scenario.model_validate(data), seed=0).log
    a, f = log.metadata["wave"]["amplitude_m"], log.metadata["wave"]["frequency_hz"]
    bar30 = scenario.barometer.noise_sigma_pa / (FRESH_WATER_DENSITY * G0)
    gt = log.ground_truth
    out = {}
    for carried in (True, False):
        traj = localize(log, "proposed", wave=(a, f), pressure_wave_noise=carried,
                        depth_std_m=bar30)  # fmt: skip
        ok = (traj.t > gt.t[0]) & (traj.t < gt.t[-1])
        e = traj.position[ok, 2] - np.interp(traj.t[ok], gt.t, gt.position[:, 2])
        ratio = np.sqrt(np.mean(e**2) / np.mean(traj.P[ok, 2, 2]))
        out[carried] = (traj.metadata["nis"]["pressure"]["mean"], ratio, np.sqrt(np.mean(e**2)))
    assert out[True][0] < 1.3 and out[True][1] < 1.3
    assert out[False][0] > 3.0 and out[False][1] > 3.0
    assert out[True][2] < out[False][2] / 10


def test_localize_says_so_and_config_yaml_records_it(simulated_run, tmp_path):
    run_dir = simulated_run("wave-a0.10-f1.00")
    runner = CliRunner()
    args = ["localize", str(run_dir / "log"), "--wave", "wave-a0.10-f1.00", "--out"]
    r = runner.invoke(app, [*args, str(tmp_path / "on")])
    assert r.exit_code == 0, r.output
    assert ("the barometer's swell is tracked by two wave-model states at the encounter "
            "frequency of waves toward 180 deg") in " ".join(r.output.split())  # fmt: skip
    config = yaml.safe_load((tmp_path / "on" / "config.yaml").read_text())
    assert config["config"]["pressure_wave_noise"] is True
    assert config["config"]["wave_heading_deg"] == 180.0  # the simulated log records it
    r = runner.invoke(app, [*args, str(tmp_path / "be"), "--variant", "be"])
    assert r.exit_code == 0, r.output
    assert "wave-model states" not in r.output
