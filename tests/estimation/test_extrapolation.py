"""Wave conditions outside the noise profile: extrapolated by the orbital velocity at the DVL.

The scaling function is checked against the closed-form limits of linear (Airy) wave theory and
against the simulator's own implementation; the extrapolated gamma against the wave-induced DVL
noise the simulator actually produces at conditions outside the profile (an amplitude, a
frequency and a depth), measured as characterize does: DVL velocity minus the true velocity in
the DVL frame during the constant-speed phase, with the calm run's noise removed in quadrature.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import yaml
from scipy.ndimage import uniform_filter1d
from typer.testing import CliRunner

from undertow.cli import app
from undertow.errors import ConfigError
from undertow.estimation.characterize import characterize
from undertow.estimation.localizer import Localizer
from undertow.estimation.noise import NoiseProfile
from undertow.estimation.noise_physics import (
    ASSUMED_SENSOR_DEPTH_M,
    ASSUMED_WATER_DEPTH_M,
    SensorSite,
    orbital_velocity_amplitude,
    sensor_site,
)
from undertow.log import G0
from undertow.sim import Scenario, load_scenario, simulate, write_simulation
from undertow.sim.waves import LinearWave

PAPER_NODES = [(0.10, 1.00), (0.10, 0.75), (0.05, 0.75)]  # the profile's (a, f), Table I
# conditions outside the profile's (a in [0, 0.1] m, f in [0.75, 1] Hz at the DVL's 0.784 m):
# (a, f, body depth of the carriage)
OUTSIDE = {
    "amplitude": (0.18, 0.75, 0.5),
    "frequency": (0.10, 0.50, 0.5),
    "depth": (0.18, 0.75, 1.5),
}
# Each std is measured from ~1060 DVL samples (relative standard error 1/sqrt(2 n) ~ 2.2 %); the
# extrapolation carries the node's error too: ~3 % together, so 10 % is over three sigma.
TOLERANCE = 0.10


# ---- the scaling function: closed forms ------------------------------------------------------


@pytest.mark.parametrize("f", [0.3, 0.75, 1.5])
def test_deep_water_limit_is_a_omega_exp_minus_k_d(f):
    """k h -> inf: U = a omega e^{-k d}, k = omega^2 / g."""
    a, omega = 0.2, 2 * np.pi * f
    k = omega**2 / G0
    d = np.array([0.0, 0.5, 2.0, 5.0])
    expected = a * omega * np.exp(-k * d)
    np.testing.assert_allclose(orbital_velocity_amplitude(a, f, d, math.inf), expected, rtol=1e-12)
    # a finite depth where tanh(k h) = 1 to double precision is the same
    np.testing.assert_allclose(orbital_velocity_amplitude(a, f, d, 400.0), expected, rtol=1e-9)


def test_shallow_water_limit_is_a_sqrt_g_over_h_at_every_depth():
    """k h -> 0: omega = k sqrt(g h), cosh -> 1, sinh(k h) -> k h, so U = a omega / (k h) =
    a sqrt(g / h), the same from the surface to the floor."""
    a, h, f = 0.05, 0.2, 0.01  # k h ~ 0.0045
    d = np.array([0.0, 0.1, 0.2])
    np.testing.assert_allclose(
        orbital_velocity_amplitude(a, f, d, h), a * np.sqrt(G0 / h), rtol=1e-4
    )


def test_matches_the_simulators_airy_wave():
    """The same U as the simulator's LinearWave (its own Newton solver and exponential forms)."""
    for a, f, h in [(0.1, 1.0, 3.0), (0.18, 0.75, 3.0), (0.1, 0.5, 3.0), (0.3, 0.2, 10.0)]:
        d = np.linspace(0.0, h, 7)
        U_sim, _ = LinearWave(a, f, h).velocity_amplitude(d)
        np.testing.assert_allclose(orbital_velocity_amplitude(a, f, d, h), U_sim, rtol=1e-9)


# ---- the policies on the paper's profile -----------------------------------------------------


def test_physics_policy_scales_the_nearest_node_and_states_it():
    prof = NoiseProfile.paper()
    out = prof.noise((0.2, 1.0), extrapolate="physics")
    # same f, same depth: U is linear in a, so exactly twice the node (0.1, 1.0)
    np.testing.assert_allclose(out.dvl_std, [0.05, 0.02, 0.006], rtol=1e-12)
    assert out.how == "extrapolated"
    record = out.to_dict()["extrapolation"]
    assert record["from"] == "wave-a0.10-f1.00" and record["ratio"] == pytest.approx(2.0)
    assert "outside the profile's conditions; its noise extrapolated by the orbital velocity at " \
        "the DVL's depth" in record["statement"]  # fmt: skip
    assert "assumed" in record["statement"]  # the paper's profile records no depth
    # deep water: moving the DVL from d0 to d multiplies U by e^{-k (d - d0)}
    deep = NoiseProfile.from_dict({**prof.to_dict(), "sensor_depth_m": 0.5})
    site = SensorSite(1.5, math.inf, "test")
    out = deep.noise((0.3, 0.75), extrapolate="physics", site=site)
    k = (2 * np.pi * 0.75) ** 2 / G0
    np.testing.assert_allclose(out.dvl_std, np.array([0.040, 0.010, 0.003]) * 3 * np.exp(-k))


def test_inside_the_profile_nothing_changes_and_other_policies_stay():
    """Inside the (a, f) nodes the profile is used as characterized, whatever the depth; the
    library's default still refuses a condition outside, True still takes the nearest as is."""
    prof = NoiseProfile.paper()
    far = SensorSite(2.5, 3.0, "test")
    for wave in [(0.10, 1.00), (0.10, 0.875), (0.025, 0.75), "calm"]:
        here = prof.noise(wave, extrapolate="physics", site=far)
        assert here.to_dict() == prof.noise(wave).to_dict()
        assert here.how in ("node", "interpolated", "calm")
    with pytest.raises(ConfigError, match="outside the characterized conditions"):
        prof.noise((0.2, 1.0))
    assert prof.noise((0.2, 1.0), extrapolate=True).how == "nearest"
    with pytest.raises(ConfigError, match="extrapolate 'sideways': expected one of"):
        prof.noise((0.2, 1.0), extrapolate="sideways")


def test_the_profile_site_is_recorded_or_assumed(tmp_path):
    prof = NoiseProfile.from_dict(
        {**NoiseProfile.paper().to_dict(), "sensor_depth_m": 1.2, "water_depth_m": 8.0}
    )
    back = NoiseProfile.from_yaml(prof.to_yaml(tmp_path / "p.yaml"))
    assert (back.sensor_depth_m, back.water_depth_m) == (1.2, 8.0)
    assert back.site().source == "recorded in the profile"
    (tmp_path / "bad.yaml").write_text(
        "sensor_depth_m: 5\nwater_depth_m: 3\nconditions: [{amplitude_m: 0, dvl_std: [0, 0, 0]}]"
    )
    with pytest.raises(ConfigError, match=r"bad\.yaml: noise profile field sensor_depth_m"):
        NoiseProfile.from_yaml(tmp_path / "bad.yaml")
    # without a record: the paper's carriage runs as the simulator builds them
    s = load_scenario("wave-a0.10-f1.00")
    dvl_depth = s.motion.carriage.depth_m + s.mounting.dvl.translation[2]
    site = NoiseProfile.paper().site()
    assert site.sensor_depth_m == pytest.approx(dvl_depth) == ASSUMED_SENSOR_DEPTH_M
    assert site.water_depth_m == s.water.depth_m == ASSUMED_WATER_DEPTH_M


# ---- against the simulator ---------------------------------------------------------------------


def _carriage(a: float, f: float, depth: float = 0.5) -> Scenario:
    """The paper's carriage run with a wave (a, f) at body depth ``depth``, made cheap and
    long enough: 30 m at 1 m/s, ground truth at 100 Hz, DVL at 40 Hz (the wave noise of each
    report is independent of the rate; more reports, a tighter std)."""
    s = load_scenario("wave-a0.10-f1.00").to_yaml_dict()
    s["motion"]["carriage"].update(run_length_m=30.0, depth_m=depth)
    s["ground_truth"]["rate_hz"] = 100.0
    s["dvl"]["rate_hz"] = 40.0
    s["wave"].update(amplitude_m=a, frequency_hz=f)
    return Scenario.model_validate(s)


def _dvl_std(log) -> np.ndarray:
    """Std of DVL velocity - true velocity (DVL frame) at cruise: smoothed speed (2 s) within 1 %
    of its maximum, so the acceleration phases are left out."""
    gt, dvl = log.ground_truth, log.dvl
    speed = uniform_filter1d(np.linalg.norm(gt.velocity, axis=1), int(2 * gt.rate_hz))
    keep = dvl.valid & (np.interp(dvl.t, gt.t, speed) > 0.99 * speed.max())
    truth = gt.body_velocity(dvl.t[keep], gt.velocity) @ log.mounting.dvl.rotation_matrix()
    return np.std(dvl.velocity[keep] - truth, axis=0, ddof=1)


@pytest.fixture(scope="module")
def simulated():
    """A profile characterized on the simulator at the paper's three conditions (extra noise
    over a calm run, at the DVL depth the scenario puts it), and logs at conditions outside."""
    calm = _dvl_std(simulate(_carriage(0.0, 1.0), seed=1).log)
    conditions = [{"amplitude_m": 0.0, "dvl_std": [0.0] * 3}]
    for i, (a, f) in enumerate(PAPER_NODES):
        total = _dvl_std(simulate(_carriage(a, f), seed=2 + i).log)
        extra = np.sqrt(np.maximum(total**2 - calm**2, 0.0))
        conditions.append({"amplitude_m": a, "frequency_hz": f, "dvl_std": extra.tolist()})
    s = _carriage(0.1, 1.0)
    profile = NoiseProfile.from_dict({
        "name": "simulated", "conditions": conditions, "water_depth_m": s.water.depth_m,
        "sensor_depth_m": s.motion.carriage.depth_m + s.mounting.dvl.translation[2],
    })  # fmt: skip
    logs = {name: simulate(_carriage(*case), seed=10).log for name, case in OUTSIDE.items()}
    return profile, calm, logs


@pytest.mark.parametrize("case", list(OUTSIDE))
def test_extrapolated_gamma_matches_the_simulated_noise(simulated, case):
    profile, calm, logs = simulated
    a, f, _ = OUTSIDE[case]
    log = logs[case]
    total = _dvl_std(log)
    # the along-wave axis (DVL x, 0.05 rad off the wave): the simulator's wave noise is there
    true_gamma = math.sqrt(max(total[0] ** 2 - calm[0] ** 2, 0.0))
    site = sensor_site(
        log, log.metadata["water_density_kg_m3"], log.metadata["surface_pressure_pa"]
    )
    extrapolated = profile.noise((a, f), extrapolate="physics", site=site)
    snapped = profile.noise((a, f), extrapolate=True)
    assert extrapolated.how == "extrapolated" and snapped.how == "nearest"
    error = abs(extrapolated.dvl_std[0] / true_gamma - 1.0)
    snap_error = abs(snapped.dvl_std[0] / true_gamma - 1.0)
    assert error < TOLERANCE, (case, extrapolated.dvl_std[0], true_gamma)
    assert snap_error > 0.4 and snap_error > 4 * error, (case, snapped.dvl_std[0], true_gamma)
    if case == "depth":  # the depth matters: the same (a, f) at the profile's depth is far off
        at_profile_depth = profile.noise((a, f), extrapolate="physics").dvl_std[0]
        assert at_profile_depth / true_gamma > 5


def test_the_dvl_site_comes_from_the_log(simulated):
    _, _, logs = simulated
    log = logs["depth"]
    s = _carriage(*OUTSIDE["depth"])
    expected = s.motion.carriage.depth_m + s.mounting.dvl.translation[2]
    site = sensor_site(log)
    assert site.sensor_depth_m == pytest.approx(expected, abs=0.01)
    assert site.water_depth_m == s.water.depth_m and "barometer" in site.source
    # without the barometer: the ground truth; without the recorded water depth: the altitude
    bare = log.replace(pressure=None, metadata={})
    site = sensor_site(bare)
    assert site.sensor_depth_m == pytest.approx(expected, abs=1e-9)
    assert site.water_depth_m == pytest.approx(s.water.depth_m, abs=0.02)
    assert "ground truth" in site.source and "altitude" in site.source
    # nothing at all: the profile's own site, said so
    default = SensorSite(0.784, 3.0, "profile")
    unknown = sensor_site(bare.replace(ground_truth=None), default=default)
    assert unknown.sensor_depth_m == 0.784 and "DVL depth unknown" in unknown.source


def test_characterize_records_the_depth_it_characterized_at():
    """A profile from `undertow characterize` records its wave runs' DVL and water depth (so
    extrapolating from it needs no assumption)."""
    s = _carriage(0.1, 0.75, depth=1.0)
    logs = [simulate(_carriage(0.0, 1.0, depth=1.0), seed=1).log, simulate(s, seed=2).log]
    profile = characterize(logs).profile
    dvl_depth = s.motion.carriage.depth_m + s.mounting.dvl.translation[2]
    assert profile.sensor_depth_m == pytest.approx(dvl_depth, abs=0.01)
    assert profile.water_depth_m == s.water.depth_m
    assert profile.site().source == "recorded in the profile"


def test_the_localizer_states_and_records_the_extrapolation(simulated):
    profile, _, logs = simulated
    log = logs["depth"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = Localizer("an", profile=profile, wave=(0.18, 0.75)).run(log)
    lines = [str(w.message) for w in caught if "outside the profile's conditions" in str(w.message)]
    assert len(lines) == 1 and "\n" not in lines[0]
    assert "wave a=0.18 m, f=0.75 Hz is outside the profile's conditions; its noise extrapolated " \
        "by the orbital velocity at the DVL's depth" in lines[0]  # fmt: skip
    used = run.metadata["wave_noise"]
    site = sensor_site(
        log, log.metadata["water_density_kg_m3"], log.metadata["surface_pressure_pa"]
    )
    expected = profile.noise((0.18, 0.75), extrapolate="physics", site=site)
    assert used["how"] == "extrapolated" and used["dvl_std"] == expected.to_dict()["dvl_std"]
    assert used["extrapolation"]["site"]["sensor_depth_m"] == pytest.approx(1.784, abs=0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # asked for: the nearest as is, no warning
        nearest = Localizer("an", profile=profile, wave=(0.18, 0.75), extrapolate=True).run(log)
    assert nearest.metadata["wave_noise"]["how"] == "nearest"


def test_localize_command_extrapolates_and_writes_it_to_config_yaml(simulated, tmp_path):
    profile, _, logs = simulated
    s = _carriage(*OUTSIDE["depth"])
    run_dir = write_simulation(simulate(s, seed=10), tmp_path / "run")
    profile_path = profile.to_yaml(tmp_path / "profile.yaml")
    runner = CliRunner()
    common = ["localize", str(run_dir / "log"), "--profile", str(profile_path), "--variant", "an",
              "--wave-amplitude", "0.18", "--wave-frequency", "0.75"]  # fmt: skip
    r = runner.invoke(app, [*common, "--out", str(tmp_path / "physics")])
    assert r.exit_code == 0, r.output
    assert "outside the profile's conditions" in r.output
    used = yaml.safe_load((tmp_path / "physics" / "config.yaml").read_text())["wave_noise"]
    assert used["how"] == "extrapolated" and used["extrapolation"]["from"] == "wave-a0.10-f0.75"
    assert used["extrapolation"]["site"]["sensor_depth_m"] == pytest.approx(1.784, abs=0.02)
    r = runner.invoke(app, [*common, "--extrapolate", "--out", str(tmp_path / "nearest")])
    assert r.exit_code == 0, r.output
    used = yaml.safe_load((tmp_path / "nearest" / "config.yaml").read_text())["wave_noise"]
    assert used["how"] == "nearest"
