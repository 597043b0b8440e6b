"""Onboard sea-state estimate: transfer functions against the simulator's Airy closed forms,
encounter frequency, platform choice, held-out accuracy against the simulated truth, calm logs,
sensor subsets, a changing sea, and one-line errors.

The truth comes from the simulator (scenario fields and log.metadata["wave"]), never from the
estimator; the held-out conditions are not among the built-in scenarios."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

from undertow.errors import ConfigError, DataError, UndertowError
from undertow.io import LogOptions
from undertow.io.sound_speed import correct_sound_speed
from undertow.log import Log
from undertow.seastate import SeaStateEstimate, WaveWindow, estimate_sea_state
from undertow.sim import load_scenario, simulate
from undertow.sim.waves import (
    LinearWave,
    depth_factors,
    encounter_frequency,
    intrinsic_from_encounter,
    solve_wavenumber,
    wavenumber,
)
from undertow.wavetrack import WaveTrack

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from bench_waves import scenario  # noqa: E402  (the held-out scenarios: one definition)

A_TOL, F_TOL = 0.15, 0.05  # the accuracy target per stationary window
REAL_BAG = Path("/work/shared/data/real/a50_ros1_circle.bag")


@pytest.fixture(scope="module")
def sims():
    cache = {}

    def get(kind, a, f, seed=1, heading=180.0):
        key = (kind, a, f, seed, heading)
        if key not in cache:
            cache[key] = simulate(scenario(kind, a, f, heading), seed=seed)
        return cache[key]

    return get


# --------------------------------------------------------- transfer functions (closed forms)


@pytest.mark.parametrize("f", [0.3, 0.65, 1.0, 2.0])
@pytest.mark.parametrize("h", [0.8, 3.0, 40.0])
def test_transfer_functions_match_the_simulators_airy_wave(f, h):
    wave = LinearWave(a=0.1, f=f, h=h, beta=0.7, phi_0=0.3)
    k = wavenumber(wave.omega, h)
    assert k == pytest.approx(solve_wavenumber(wave.omega, h, wave.g), rel=1e-10)
    assert k == pytest.approx(wave.k, rel=1e-10)
    for d in (0.0, 0.3 * h, 0.9 * h):
        k_h, k_s, k_p = depth_factors(k, h, d)
        U, W = wave.velocity_amplitude(d)
        assert U == pytest.approx(wave.a * wave.omega * k_h, rel=1e-9)
        assert W == pytest.approx(wave.a * wave.omega * k_s, rel=1e-9, abs=1e-15)
        # dynamic pressure and displacement amplitudes over one period at a fixed point
        t = np.linspace(0, 1 / f, 257)
        p = wave.dynamic_pressure(0.0, 0.0, d, t)
        assert np.max(np.abs(p)) == pytest.approx(wave.rho * wave.g * wave.a * k_p, rel=1e-3)
        xi = wave.particle_displacement(0.0, 0.0, d, t)
        assert np.max(np.hypot(xi[:, 0], xi[:, 1])) == pytest.approx(wave.a * k_h, rel=1e-3)
        assert np.max(np.abs(xi[:, 2])) == pytest.approx(wave.a * k_s, rel=1e-3, abs=1e-12)


def test_deep_water_limits():
    w = 2 * np.pi * 1.3
    k = wavenumber(w, np.inf)
    assert k == pytest.approx(w * w / 9.80665)
    assert wavenumber(w, 60.0) == pytest.approx(k, rel=1e-9)  # tanh(kh) = 1
    for factor in depth_factors(k, np.inf, 0.7):
        assert factor == pytest.approx(np.exp(-k * 0.7))
    assert np.allclose(depth_factors(k, 60.0, 0.7), depth_factors(k, np.inf, 0.7), rtol=1e-9)


@pytest.mark.parametrize("h", [3.0, np.inf])
@pytest.mark.parametrize("u", [-1.0, -0.3, 0.0, 0.2, 0.4])
def test_intrinsic_frequency_inverts_the_encounter_frequency(h, u):
    omega = 2 * np.pi * np.array([0.6, 0.9, 1.2])
    k = wavenumber(omega, h)
    # u > 0: following seas; these waves' group speed exceeds u (slower vehicle)
    we = encounter_frequency(omega, k, abs(u), 0.0 if u >= 0 else np.pi, 0.0)
    assert np.allclose(we, omega - k * u)
    assert np.allclose(intrinsic_from_encounter(we, u, h), omega, rtol=1e-10)


def test_a_vehicle_faster_than_the_waves_has_no_solution():
    # deep water: omega - omega^2 U / g peaks at g / 4U; above it no slower wave matches
    u = 1.5
    peak = 9.80665 / (4 * u)
    assert np.isnan(intrinsic_from_encounter(1.1 * peak, u, np.inf))
    assert np.isfinite(intrinsic_from_encounter(0.9 * peak, u, np.inf))
    assert np.isnan(intrinsic_from_encounter(-1.0, 0.0, 3.0))


# ------------------------------------------------------------------ the estimator on simulated logs


def _truth(log: Log) -> tuple[float, float]:
    w = log.metadata["wave"]
    return w["amplitude_m"], w["frequency_hz"]


def _assert_accurate(est: SeaStateEstimate, a: float, f: float) -> None:
    for w in est.windows:
        assert w.frequency_hz is not None, f"window {w.t_start:.1f} s calm in waves: {w.notes}"
        assert w.amplitude_m == pytest.approx(a, rel=A_TOL), (w.t_start, w.notes)
        assert w.frequency_hz == pytest.approx(f, rel=F_TOL), (w.t_start, w.notes)
        assert w.significant_height_m == pytest.approx(2 * np.sqrt(2) * w.amplitude_m)


@pytest.mark.parametrize("kind", ["carriage", "survey"])
def test_held_out_condition_every_window_within_target(sims, kind):
    log = sims(kind, 0.07, 0.9).log
    est = estimate_sea_state(log)
    assert len(est.windows) >= 3
    _assert_accurate(est, *_truth(log))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize(
    "kind, a, f",
    [
        ("carriage", 0.07, 0.9), ("carriage", 0.04, 0.65), ("carriage", 0.12, 0.8),
        ("survey", 0.07, 0.9), ("survey", 0.04, 0.65), ("survey", 0.12, 0.8),
        ("survey", 0.06, 1.2),
    ],
)  # fmt: skip
def test_held_out_conditions_two_seeds(sims, kind, a, f, seed):
    # carriage at (0.06 m, 1.2 Hz) misses the amplitude target (docs/waves.md: 32 Pa of wave
    # under 20 Pa of barometer noise, a ~ e^{k d}); its frequency is checked below
    log = sims(kind, a, f, seed).log
    _assert_accurate(estimate_sea_state(log), a, f)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_weak_carriage_signal_keeps_the_frequency(sims, seed):
    log = sims("carriage", 0.06, 1.2, seed).log
    for w in estimate_sea_state(log).windows:
        assert w.frequency_hz == pytest.approx(1.2, rel=F_TOL)
        assert w.amplitude_m == pytest.approx(0.06, rel=0.5)


def test_encounter_frequency_of_the_cruising_carriage(sims):
    res = sims("carriage", 0.07, 0.9)
    c = res.scenario.motion.carriage
    run = c.run_length_m / c.cruise_speed_m_s
    cruise = (c.hold_before_s + c.cruise_speed_m_s / c.acceleration_m_s2,
              c.hold_before_s + run)  # fmt: skip
    wave = LinearWave(0.07, 0.9, res.scenario.water.depth_m)
    expected = (wave.omega + wave.k * c.cruise_speed_m_s) / (2 * np.pi)  # oncoming waves
    est = estimate_sea_state(res.log)
    inside = [w for w in est.windows if w.t_start >= cruise[0] and w.t_end <= cruise[1]]
    assert inside
    for w in inside:
        assert w.encounter_frequency_hz == pytest.approx(expected, rel=0.02)
        assert w.frequency_hz == pytest.approx(0.9, rel=F_TOL)


def test_rigid_on_the_carriage_free_in_the_survey(sims):
    carriage = estimate_sea_state(sims("carriage", 0.07, 0.9).log)
    survey = estimate_sea_state(sims("survey", 0.07, 0.9).log)
    assert {w.platform for w in carriage.windows} == {"rigid"}
    assert {w.platform for w in survey.windows} == {"free"}
    # the free vehicle's direction comes from its orbital velocity: waves toward -x (180 deg)
    for w in survey.windows:
        assert w.direction_deg is not None
        assert abs((w.direction_deg - 180.0 + 180) % 360 - 180) < 20.0


def test_forced_platform_is_reported(sims):
    log = sims("carriage", 0.07, 0.9).log
    est = estimate_sea_state(log, platform="rigid")
    assert {w.platform for w in est.windows} == {"rigid"}


@pytest.mark.parametrize("name", ["calm", "rock-survey"])
def test_calm_logs_give_calm(name):
    s = load_scenario(name)
    data = s.to_yaml_dict()
    data["wave"]["amplitude_m"] = 0.0
    log = simulate(type(s).model_validate(data), seed=4).log
    est = estimate_sea_state(log)
    for w in est.windows:
        assert w.amplitude_m == 0.0 and w.frequency_hz is None and w.encounter_frequency_hz is None
        assert w.direction_deg is None and w.significant_height_m == 0.0
    track = est.track()
    assert np.all(track.amplitude_m == 0) and np.all(np.isnan(track.frequency_hz))


def test_dvl_only_log_body_frame(sims):
    log = sims("survey", 0.07, 0.9).log
    bare = log.replace(pressure=None, dead_reckoning=None, imu=None)
    est = estimate_sea_state(bare, water_depth_m=3.0)
    assert any("body frame" in n for n in est.notes)
    good = [w for w in est.windows if w.frequency_hz is not None]
    assert len(good) >= len(est.windows) - 1
    for w in good:
        assert w.sensors == ("dvl",) and w.platform == "free"
        assert w.direction_deg is None  # no orientation: only relative to the vehicle
    f = np.median([w.frequency_hz for w in good])
    assert f == pytest.approx(0.9, rel=F_TOL)


def test_dvl_with_gyro_gives_relative_direction(sims):
    sim = sims("survey", 0.07, 0.9)
    # without a barometer the DVL's depth is the water's less its altitude: read as a user who
    # set the water's sound speed would (the DVL converts with 1500 m/s, 1.6 % long here)
    water = LogOptions(sound_speed_m_s=sim.scenario.water.sound_speed_m_s)
    log = correct_sound_speed(sim.log, water, state=False)
    est = estimate_sea_state(log.replace(pressure=None, dead_reckoning=None))
    first = est.windows[0]  # first leg along +x: waves from ahead, relative direction 180
    assert first.direction_deg is None and first.relative_direction_deg is not None
    assert abs(abs(first.relative_direction_deg) - 180.0) < 20.0
    assert first.amplitude_m == pytest.approx(0.07, rel=A_TOL)


def test_barometer_only_carriage_is_rigid_without_direction(sims):
    log = sims("carriage", 0.07, 0.9).log
    est = estimate_sea_state(log.replace(dvl=None, dead_reckoning=None, imu=None))
    assert any("barometer only" in n for n in est.notes)
    for w in est.windows:
        assert w.platform == "rigid" and w.direction_deg is None and w.sensors == ("pressure",)
        assert w.frequency_hz is not None
    # at rest (first hold) the encounter frequency is the wave frequency itself
    assert est.windows[0].encounter_frequency_hz == pytest.approx(
        est.windows[0].frequency_hz, rel=1e-9
    )


def test_outputs_are_plain_and_track_follows_windows(sims):
    est = estimate_sea_state(sims("survey", 0.07, 0.9).log)
    track = est.track()
    assert isinstance(track, WaveTrack) and track.source == "estimated"
    centres = [0.5 * (w.t_start + w.t_end) for w in est.windows]
    assert np.allclose(track.t, centres)
    assert np.allclose(track.amplitude_m, [w.amplitude_m for w in est.windows])
    rows = est.to_table_rows()
    assert len(rows) == len(est.windows)
    assert all(isinstance(v, (int, float, str, type(None))) for r in rows for v in r.values())
    d = est.to_dict()
    assert d["windows"][0]["sensors"] == list(est.windows[0].sensors)
    assert isinstance(est.windows[0], WaveWindow)
    with pytest.raises(dataclasses.FrozenInstanceError):
        est.windows[0].amplitude_m = 1.0


def test_short_log_gives_one_window(sims):
    log = sims("carriage", 0.07, 0.9).log
    est = estimate_sea_state(log, t_start=0.0, t_end=5.0)  # the first hold: ~4.5 periods
    assert len(est.windows) == 1
    w = est.windows[0]
    assert w.amplitude_m == pytest.approx(0.07, rel=A_TOL)
    assert w.frequency_hz == pytest.approx(0.9, rel=F_TOL)


# ------------------------------------------------------------------ a changing sea


def _held(track: dict) -> list[tuple[float, float, float, float]]:
    """(start, end, a, f) of the schedule's held segments (equal consecutive nodes)."""
    t, a, f = track["t"], track["amplitude_m"], track["frequency_hz"]
    return [(t[i], t[i + 1], a[i], f[i]) for i in range(len(t) - 1)
            if a[i] == a[i + 1] and f[i] == f[i + 1]]  # fmt: skip


@pytest.mark.slow
def test_changing_sea_on_the_carriage_is_followed():
    log = simulate(load_scenario("changing-sea-carriage"), seed=1).log
    est = estimate_sea_state(log)
    for start, end, a, f in _held(log.metadata["wave"]):
        inside = [w for w in est.windows if w.t_start > start - 0.01 and w.t_end < end + 0.01]
        assert inside, (start, end)
        # every window wholly inside a held condition (so at most two windows after the change)
        for w in inside:
            if a == 0:
                assert w.amplitude_m == 0.0
            else:
                assert w.amplitude_m == pytest.approx(a, rel=A_TOL)
                assert w.frequency_hz == pytest.approx(f, rel=F_TOL)


@pytest.mark.slow
def test_changing_sea_survey_median_per_condition():
    log = simulate(load_scenario("changing-sea-survey"), seed=1).log
    est = estimate_sea_state(log)
    for start, end, a, f in _held(log.metadata["wave"]):
        inside = [w for w in est.windows if w.t_start > start - 0.01 and w.t_end < end + 0.01]
        assert inside, (start, end)
        if a == 0:
            assert all(w.amplitude_m == 0.0 for w in inside)
            continue
        assert np.median([w.amplitude_m for w in inside]) == pytest.approx(a, rel=A_TOL)
        fs = [w.frequency_hz or 0.0 for w in inside]
        assert np.median(fs) == pytest.approx(f, rel=F_TOL)


# ------------------------------------------------------------------ errors and real data


def _one_line(exc: BaseException) -> None:
    assert "\n" not in str(exc) and str(exc)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"platform": "floating"},
        {"window_periods": float("nan")},
        {"window_periods": 1.0},
        {"step_fraction": 0.0},
        {"step_fraction": 2.0},
        {"water_depth_m": -1.0},
        {"water_density_kg_m3": float("inf")},
        {"t_start": "soon"},
    ],
)
def test_bad_options_are_one_line_config_errors(sims, kwargs):
    with pytest.raises(ConfigError) as err:
        estimate_sea_state(sims("carriage", 0.07, 0.9).log, **kwargs)
    _one_line(err.value)


def test_missing_streams_and_short_logs_are_one_line_data_errors(sims):
    log = sims("carriage", 0.07, 0.9).log
    with pytest.raises(DataError) as err:
        estimate_sea_state(log.replace(pressure=None, dvl=None))
    _one_line(err.value)
    assert "pressure" in str(err.value) and "dvl" in str(err.value)
    with pytest.raises(DataError) as err:
        estimate_sea_state(log, t_start=0.0, t_end=2.0)
    _one_line(err.value)
    with pytest.raises(DataError) as err:
        estimate_sea_state(log.replace(dvl=None), platform="rigid", t_start=0, t_end=0.5)
    _one_line(err.value)
    with pytest.raises(DataError) as err:  # the rigid model needs the barometer
        estimate_sea_state(log.replace(pressure=None), platform="rigid")
    _one_line(err.value)
    with pytest.raises(ConfigError):
        estimate_sea_state("not a log")


@pytest.mark.realdata
def test_real_dvl_only_tank_recording_is_calm_or_a_clear_error():
    from undertow.io import read_log

    log = read_log(REAL_BAG)
    try:
        est = estimate_sea_state(log)
    except UndertowError as exc:
        _one_line(exc)
        return
    assert all(w.amplitude_m == 0.0 for w in est.windows), est.to_table_rows()
