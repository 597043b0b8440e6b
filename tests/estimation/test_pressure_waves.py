"""The swell's pressure head in the barometer's noise (``pressure_wave_noise``): the physics
against the simulator's own wave and barometer, the rows, and the filter it makes consistent."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from undertow.cli import app
from undertow.estimation.config import LocalizerConfig
from undertow.estimation.localizer import localize
from undertow.estimation.noise import NoiseProfile, TrackNoise
from undertow.estimation.noise_physics import pressure_head_variance
from undertow.estimation.rows import pressure_rows
from undertow.estimation.wave_schedule import schedule_noise
from undertow.log import FRESH_WATER_DENSITY, G0
from undertow.sim import Scenario, load_scenario, simulate
from undertow.sim.waves import depth_factors, wavenumber
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
    assert "the barometer's swell is tracked by two wave-model states" in r.output
    config = yaml.safe_load((tmp_path / "on" / "config.yaml").read_text())
    assert config["config"]["pressure_wave_noise"] is True
    r = runner.invoke(app, [*args, str(tmp_path / "be"), "--variant", "be"])
    assert r.exit_code == 0, r.output
    assert "wave-model states" not in r.output
