"""The filter's consistency report (undertow.estimation.consistency): the statistics against
their distributions (white Gaussian innovations are consistent about 95 % of the time, the
bands agree with scipy.stats.chi2), the whitened innovations the filter records against the
closed form of a linear update and against its own NIS accumulators, a simulated run with the
simulator's own noise in the filter (consistent) and with a noise understated or overstated
(flagged), and the commands that write and print the report."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest
from scipy.stats import chi2
from typer.testing import CliRunner

from undertow.estimation import model
from undertow.estimation.consistency import (
    CONSISTENT,
    OVERCONFIDENT,
    PESSIMISTIC,
    ConsistencyReport,
    innovation_consistency,
    sensor_consistency,
)
from undertow.estimation.localizer import localize
from undertow.estimation.ukf import update_linear

runner = CliRunner()


def test_white_gaussian_innovations_are_consistent_and_the_bands_are_chi_square():
    rng = np.random.default_rng(0)
    w = rng.standard_normal((20000, 3))
    s = sensor_consistency("dvl", w)
    assert s.verdict == CONSISTENT and s.white and s.share_as_expected
    assert s.share_outside == pytest.approx(0.05, abs=0.005)
    assert s.share_below == pytest.approx(0.025, abs=0.004)
    k = s.effective_count
    assert k == pytest.approx(20000, rel=0.03)  # no correlation: K' ~ K
    assert s.nis_band_low == pytest.approx(chi2.ppf(0.025, 3 * k) / k, rel=1e-9)
    assert s.nis_band_high == pytest.approx(chi2.ppf(0.975, 3 * k) / k, rel=1e-9)
    assert s.autocorrelation_band == pytest.approx(1.959964 / np.sqrt(19999 * 3), rel=1e-6)
    assert sensor_consistency("dvl", 2.0 * w).verdict == OVERCONFIDENT  # S 4x too small
    assert sensor_consistency("dvl", 0.5 * w).verdict == PESSIMISTIC  # S 4x too large


def test_the_mean_band_covers_95_percent_of_consistent_runs():
    """Over 400 runs of 100 white innovations the mean NIS falls in its 95 % band about 95 %
    of the time, and |rho_1| within its band about as often (tolerances off: 100 samples)."""
    import undertow.estimation.consistency as c

    rng = np.random.default_rng(1)
    inside = white = 0
    for _ in range(400):
        s = sensor_consistency("imu", rng.standard_normal((100, 3)))
        inside += s.nis_band_low <= s.nis_mean <= s.nis_band_high
        white += abs(s.autocorrelation_lag1) <= s.autocorrelation_band
    assert 0.92 <= inside / 400 <= 0.99
    assert 0.92 <= white / 400 <= 0.98
    assert c.NIS_TOLERANCE * 3 < 1.0  # the practical tolerance is narrower than the 100-band


def test_correlated_innovations_are_flagged_and_widen_the_band():
    """AR(1) innovations w_k = a w_{k-1} + sqrt(1 - a^2) e_k: rho_1 ~ a; the NIS series then
    correlates by a^2, so K' ~ K (1 - a^2) / (1 + a^2)."""
    rng = np.random.default_rng(2)
    a, n = 0.6, 20000
    e = rng.standard_normal((n, 3))
    w = np.empty_like(e)
    w[0] = e[0]
    for k in range(1, n):
        w[k] = a * w[k - 1] + np.sqrt(1 - a * a) * e[k]
    s = sensor_consistency("dvl", w)
    assert s.autocorrelation_lag1 == pytest.approx(a, abs=0.02) and s.white is False
    assert s.effective_count == pytest.approx(n * (1 - a * a) / (1 + a * a), rel=0.1)
    assert s.verdict == CONSISTENT  # right variance, wrong whiteness


def test_no_innovations_and_the_round_trip():
    kind = np.array([model.DVL, model.DVL, model.IMU])
    w = np.array([[0.1, -0.2, 0.3], [np.nan] * 3, [1.0, 0.5, -0.5]])
    report = innovation_consistency(kind, w)
    by = {s.sensor: s for s in report.sensors}
    assert by["dvl"].count == 1 and by["imu"].count == 1 and by["pressure"].count == 0
    assert by["pressure"].verdict == "no innovations" and by["dvl"].autocorrelation_lag1 is None
    data = json.loads(json.dumps(report.to_dict()))
    assert ConsistencyReport.from_dict(data).to_dict() == data
    assert report.summary().startswith("NIS mean/expected: imu")


def test_the_update_leaves_the_whitened_innovation():
    """For a linear update, w = L_S^-1 (z - H x) with S = H P H^T + R = L_S L_S^T, and
    w^T w is the NIS the update returns (numpy's Cholesky as the reference)."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(18, 18))
    P = A @ A.T / 18 + np.eye(18) * 0.1
    x = rng.normal(size=18)
    H = rng.normal(size=(3, 18))
    R = np.diag([0.2, 0.3, 0.4])
    z = rng.normal(size=3)
    S = H @ P @ H.T + R
    expected = np.linalg.solve(np.linalg.cholesky(S), z - H @ x)
    w = np.full(3, np.nan)
    no_angles = np.zeros(18, dtype=np.bool_)
    status, nis = update_linear(x.copy(), P.copy(), H, z, R, no_angles, no_angles[:3], np.inf, w)
    assert status == 0
    np.testing.assert_allclose(w, expected, rtol=1e-10)
    assert nis == pytest.approx(float(w @ w), rel=1e-12)


def _simulators_noise(scenario) -> dict:
    """The filter's noise set to what the simulator draws (tests/conftest.py's "calm"): the
    gyro's white noise per sample sigma_c sqrt(rate) and its bias walk sigma_bc^2, the DR's
    orientation noise and yaw drift mu_b (a constant drift: a negligible walk), the barometer's
    noise in depth sigma_p / (rho g); the DVL's covariance is the log's own. The carriage
    holds the robot: only x accelerates (the filter's white-acceleration model, 1e-3 (m/s^2)^2
    /Hz), nothing rotates."""
    imu, dr, baro, water = scenario.imu, scenario.dead_reckoning, scenario.barometer, scenario.water
    return {
        "variant": "proposed",
        "imu_gyro_std_rad_s": (imu.gyro_noise_density * np.sqrt(imu.rate_hz),) * 3,
        "gyro_bias_walk_density": (imu.gyro_bias_random_walk**2,) * 3,
        "dr_orientation_std_rad": (dr.orientation_sigma,) * 3,
        "dr_bias_drift_rad_s": (*dr.roll_pitch_drift_rate, dr.yaw_drift_rate),
        "dr_bias_walk_density": (1e-9,) * 3,
        "depth_std_m": baro.noise_sigma_pa / (water.density_kg_m3 * water.gravity_m_s2),
        "accel_density": (1e-3, 1e-6, 1e-6),
        "angular_accel_density": (1e-8,) * 3,
    }


@pytest.fixture(scope="module")
def calm(simulation):
    from undertow.sim import load_scenario

    return simulation("calm"), _simulators_noise(load_scenario("calm"))


def _report(log, **params) -> tuple[ConsistencyReport, dict]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        trajectory = localize(log, **params)
    meta = trajectory.metadata
    return ConsistencyReport.from_dict(meta["consistency"]), meta


def test_the_simulators_own_noise_is_consistent(calm):
    """IMU, DR and barometer: mean NIS within the band (or 10 %), about 5 % outside, white.
    The DVL's innovations are flagged as correlated: the carriage accelerates by ramps, not by
    the white acceleration the filter's constant-velocity model assumes."""
    sim, noise = calm
    report, meta = _report(sim.log, **noise)
    by = {s.sensor: s for s in report.sensors}
    for name in ("imu", "dead_reckoning", "pressure"):
        s = by[name]
        assert s.verdict == CONSISTENT, s
        assert abs(s.nis_mean / s.dof - 1) < 0.1, s
        assert s.share_outside == pytest.approx(0.05, abs=0.035), s
        assert s.white, s
    assert by["dvl"].white is False and by["dvl"].autocorrelation_lag1 > 0.3
    # the recorded innovations agree with the filter's own NIS accumulators
    for name, s in by.items():
        assert s.count == meta["nis"][name]["count"]
        assert s.nis_mean == pytest.approx(meta["nis"][name]["mean"], rel=1e-5)


def test_understated_and_overstated_noise_are_flagged(calm):
    sim, noise = calm
    report, _ = _report(sim.log, **{**noise, "imu_gyro_std_rad_s": (1.75e-4,) * 3})
    imu = {s.sensor: s for s in report.sensors}["imu"]
    assert imu.verdict == OVERCONFIDENT and imu.nis_mean > 50 and imu.share_above > 0.9
    assert "imu" in report.summary() and "too large" in report.summary()
    report, _ = _report(sim.log, **{**noise, "depth_std_m": 0.02})
    pressure = {s.sensor: s for s in report.sensors}["pressure"]
    assert pressure.verdict == PESSIMISTIC and pressure.nis_mean < 0.1
    assert pressure.share_below > 0.2  # expected 0.025
    # the DVL without its covariance, told it is ten times better than it is
    no_cov = dataclasses.replace(sim.log.dvl, covariance=np.full((len(sim.log.dvl), 3, 3), np.nan))
    report, _ = _report(
        sim.log.replace(dvl=no_cov),
        **{**noise, "dvl_velocity_std_m_s": (2e-4,) * 3, "dvl_std_floor_m_s": 1e-5,
           "accel_density": (1e-5, 1e-6, 1e-6)},
    )  # fmt: skip
    dvl = {s.sensor: s for s in report.sensors}["dvl"]
    assert dvl.verdict == OVERCONFIDENT and dvl.share_above > 0.5


def test_localize_writes_the_report_and_evaluate_prints_it(simulated_run, tmp_path):
    from conftest import one_error_line

    from undertow.cli import app
    from undertow.trajectory import Trajectory

    log = simulated_run("calm", 0) / "log"
    r = runner.invoke(app, ["localize", str(log), "--out", str(tmp_path / "est")])
    assert r.exit_code == 0, r.output
    (line,) = [ln for ln in r.output.splitlines() if ln.startswith("consistency: ")]
    assert "imu" in line and "dvl" in line and "undertow evaluate trajectory" in line
    config = __import__("yaml").safe_load((tmp_path / "est" / "config.yaml").read_text())
    assert set(config["consistency"]["sensors"]) == {"imu", "dvl", "dead_reckoning", "pressure"}
    r = runner.invoke(app, ["evaluate", "trajectory", str(tmp_path / "est")])
    assert r.exit_code == 0, r.output
    assert "Consistency of the filter's innovations" in r.output and "pressure" in r.output
    assert "too small (pessimistic): innovations smaller than the filter" in r.output
    j = runner.invoke(app, ["evaluate", "trajectory", str(tmp_path / "est"), "--json"])
    assert json.loads(j.stdout) == {"consistency": config["consistency"]}
    # a trajectory without a report, and no reference: one line
    old = Trajectory.load_npz(tmp_path / "est")
    old.replace(metadata={}).save_npz(tmp_path / "old.npz")
    line = one_error_line(runner.invoke(app, ["evaluate", "trajectory", str(tmp_path / "old.npz")]))
    assert "no consistency report" in line and "REFERENCE" in line
