"""A sea state that changes during a run (wave.schedule) and the way-point free vehicle, against
closed forms: the schedule's amplitude and frequency where it is exact (the wave probe) and in
the barometer's dynamic pressure, a continuous phase, the constant wave as a one-segment
schedule, one-line validation errors, and the Doppler-shifted encounter frequency
omega_e = |omega - k V cos(beta - psi)| of a vehicle on legs at several headings to the waves.

Wavenumbers are recomputed here from the dispersion relation by scipy's brentq, independently of
``sim/waves.py``; frequencies and amplitudes are fitted by least squares (a cos + b sin + c)."""

import numpy as np
import pytest
import yaml
from scipy.optimize import brentq, minimize_scalar

from undertow.errors import ConfigError
from undertow.sim import Scenario, load_scenario, simulate, write_simulation
from undertow.sim.seastate import build_wave, wave_track
from undertow.sim.waves import LinearWave
from undertow.wavetrack import WaveTrack

G = 9.80665


def _k(f, h):
    omega = 2 * np.pi * f
    return brentq(lambda k: G * k * np.tanh(k * h) - omega**2, 1e-6, 100.0, xtol=1e-14)


def _fit(t, x, f_lo=0.2, f_hi=3.0):
    """(f, amplitude) of the best least-squares sinusoid a cos(2 pi f t) + b sin(..) + c: the
    periodogram's peak (zero-padded), refined by minimizing the residual."""
    x = x - x.mean()
    n = 16 * t.size
    spec = np.abs(np.fft.rfft(x * np.hanning(t.size), n))
    freqs = np.fft.rfftfreq(n, t[1] - t[0])
    band = (freqs >= f_lo) & (freqs <= f_hi)
    f0 = freqs[band][np.argmax(spec[band])]

    def solve(f):
        A = np.stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t), np.ones_like(t)], 1)
        coef, *_ = np.linalg.lstsq(A, x, rcond=None)
        return coef, np.sum((A @ coef - x) ** 2)

    df = 2.0 / (t[-1] - t[0])
    f = minimize_scalar(lambda f: solve(f)[1], bounds=(f0 - df, f0 + df), method="bounded",
                        options={"xatol": 1e-7}).x  # fmt: skip
    coef, _ = solve(f)
    return f, float(np.hypot(coef[0], coef[1]))


SCHEDULE = [
    {"amplitude_m": 0.0, "until_s": 10.0},
    {"ramp_s": 4.0, "amplitude_m": 0.08, "frequency_hz": 1.0, "until_s": 36.0},
    {"ramp_s": 8.0, "amplitude_m": 0.05, "frequency_hz": 0.75},
]
HELD = [(14.0, 36.0, 0.08, 1.0), (44.0, 70.0, 0.05, 0.75)]  # (from, to, a, f)


def _station(schedule=SCHEDULE, duration=70.0, **wave) -> Scenario:
    """The carriage at rest at x = 48 m for ``duration``, the probe 2 m up-wave."""
    return Scenario.model_validate({
        "name": "station",
        "wave": {"heading_deg": 180.0, "schedule": schedule, **wave},
        "motion": {"kind": "carriage", "carriage": {
            "start_x_m": 48.0, "run_length_m": 0.0, "hold_before_s": duration,
            "hold_after_s": 0.0}},
        "wave_probe": {"x_m": 50.0, "y_m": 0.0},
        "ground_truth": {"rate_hz": 50.0},
    })  # fmt: skip


@pytest.fixture(scope="module")
def station():
    return simulate(_station(), seed=1)


def test_probe_and_barometer_follow_each_held_condition(station):
    """Probe: eta = a cos(.) at f; barometer: rho g a cosh(k(h-d))/cosh(kh) at f, per segment."""
    log, h = station.log, 3.0
    depth = station.scenario.motion.carriage.depth_m
    for t0, t1, a, f in HELD:
        p = log.wave_probe.select((log.wave_probe.t >= t0) & (log.wave_probe.t <= t1))
        f_fit, a_fit = _fit(p.t, p.elevation)
        assert f_fit == pytest.approx(f, abs=2e-4)
        assert a_fit == pytest.approx(a, rel=5e-3)
        b = log.pressure.select((log.pressure.t >= t0) & (log.pressure.t <= t1))
        f_fit, p_fit = _fit(b.t, b.pressure)
        k = _k(f, h)
        expected = 998.0 * G * a * np.cosh(k * (h - depth)) / np.cosh(k * h)
        assert f_fit == pytest.approx(f, abs=3e-3)
        assert p_fit == pytest.approx(expected, rel=0.05)
    calm = log.wave_probe.t < 10.0
    assert np.std(log.wave_probe.elevation[calm]) < 2e-3  # the probe's own noise (1 mm)


def test_dvl_wave_noise_follows_the_orbital_speed_of_each_segment(station):
    """At rest the DVL's along-wave error is white with sigma^2 = (kappa U(d)/sqrt2)^2 plus
    the beam noise; U(d) = a omega cosh(k(h-d))/sinh(kh) of the segment at the DVL's depth."""
    log, h = station.log, 3.0
    d_dvl = station.scenario.motion.carriage.depth_m + 0.284  # DVL lever arm z
    for t0, t1, a, f in HELD:
        sel = (log.dvl.t >= t0) & (log.dvl.t <= t1)
        k, omega = _k(f, h), 2 * np.pi * f
        U = a * omega * np.cosh(k * (h - d_dvl)) / np.sinh(k * h)
        std = np.std(log.dvl.velocity[sel, 0])  # DVL x ~ world -x = along the heading
        assert std == pytest.approx(U / np.sqrt(2), rel=0.2)


def test_phase_is_continuous_and_exact_at_the_probe_through_the_ramps():
    s = _station()
    wave = build_wave(s)
    t = np.arange(0.0, 70.0, 1e-3)
    eta = wave.elevation(50.0, 0.0, t)
    # |d eta/dt| <= a omega + |da/dt| everywhere: no jump at a ramp's ends
    bound = (0.08 * 2 * np.pi * 1.0 + 0.08 / 4.0) * 1e-3
    assert np.max(np.abs(np.diff(eta))) <= 1.01 * bound
    # at the probe the instantaneous frequency -d theta/dt is the schedule's, linear in ramps
    theta = wave.phase(50.0, 0.0, t)
    f_inst = -np.gradient(theta, t) / (2 * np.pi)
    f_sched = np.interp(t, [36.0, 44.0], [1.0, 0.75])  # the first wave's f from t = 0 (calm)
    inner = (t > 0.01) & (t < 69.99)
    np.testing.assert_allclose(f_inst[inner], f_sched[inner], atol=2e-5)  # kinks: f' dt / 4
    # amplitude envelope: linear in the ramp from calm, 0.08 -> 0.05 in the second
    np.testing.assert_allclose(wave.amplitude_at([10.0, 12.0, 14.0, 40.0, 44.0]),
                               [0.0, 0.04, 0.08, 0.065, 0.05], atol=1e-15)  # fmt: skip


def test_one_segment_schedule_is_the_constant_wave():
    base = load_scenario("wave-a0.10-f1.00").to_yaml_dict()
    base["motion"]["carriage"]["run_length_m"] = 4.0
    base["ground_truth"]["rate_hz"] = 100.0
    const = Scenario.model_validate(base)
    base["wave"]["schedule"] = [{"amplitude_m": 0.1, "frequency_hz": 1.0}]
    base["wave"]["amplitude_m"] = 0.0
    sched = Scenario.model_validate(base)
    lw, wf = build_wave(const), build_wave(sched)
    assert isinstance(lw, LinearWave)
    x, t = np.linspace(20.0, 60.0, 401), np.linspace(0.0, 30.0, 401)
    for name in ("elevation", "phase"):
        np.testing.assert_allclose(getattr(wf, name)(x, 0.1, t), getattr(lw, name)(x, 0.1, t),
                                   atol=1e-9)  # fmt: skip
    for name in ("orbital_velocity", "orbital_acceleration", "particle_displacement",
                 "dynamic_pressure", "orbital_slope"):  # fmt: skip
        np.testing.assert_allclose(getattr(wf, name)(x, 0.1, 0.7, t),
                                   getattr(lw, name)(x, 0.1, 0.7, t), atol=1e-8)  # fmt: skip
    a, b = simulate(const, seed=3).log, simulate(sched, seed=3).log
    for stream, field in (("wave_probe", "elevation"), ("pressure", "pressure"),
                          ("dvl", "velocity"), ("imu", "linear_acceleration"),
                          ("ground_truth", "position")):  # fmt: skip
        np.testing.assert_allclose(getattr(getattr(b, stream), field),
                                   getattr(getattr(a, stream), field), atol=1e-7)  # fmt: skip
    assert WaveTrack.from_dict(b.metadata["wave"]).at(5.0) == (0.1, 1.0)


def test_wave_track_and_metadata():
    s = _station()
    track = wave_track(s, 70.0)
    np.testing.assert_array_equal(track.t, [0, 10, 14, 36, 44, 70])
    np.testing.assert_array_equal(track.amplitude_m, [0, 0, 0.08, 0.08, 0.05, 0.05])
    assert track.source == "scenario" and np.all(track.direction_deg == 180.0)
    const = wave_track(load_scenario("wave-a0.05-f0.75"))
    assert len(const) == 1 and const.at(100.0) == (0.05, 0.75)
    assert np.isnan(wave_track(load_scenario("calm")).frequency_hz[0])
    meta = simulate(load_scenario("wave-a0.05-f0.75"), seed=0).log.metadata
    assert meta["wave"] == {"amplitude_m": 0.05, "frequency_hz": 0.75}
    assert meta["wave_heading_deg"] == 180.0 and meta["water_depth_m"] == 3.0


def test_changing_sea_metadata_survives_the_bag(station, tmp_path):
    from undertow.io import read_log

    write_simulation(station, tmp_path / "run")
    back = read_log(tmp_path / "run" / "log")
    truth = WaveTrack.from_dict(station.log.metadata["wave"])
    again = WaveTrack.from_dict(back.metadata["wave"])
    t = np.linspace(0.0, 70.0, 141)
    np.testing.assert_array_equal(np.stack(again.at(t)), np.stack(truth.at(t)))
    assert back.metadata["wave_heading_deg"] == 180.0 and back.metadata["water_depth_m"] == 3.0


def _bad(tmp_path, wave: dict, motion: dict | None = None) -> str:
    f = tmp_path / "bad.yaml"
    doc = {"base": "changing-sea-carriage", "wave": wave}
    if motion:
        doc["motion"] = motion
    f.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as info:
        load_scenario(f)
    message = str(info.value)
    assert "\n" not in message and "bad.yaml: field " in message
    return message


@pytest.mark.parametrize(
    ("change", "field", "words"),
    [
        ({1: {"until_s": 50.0}}, "wave.schedule.1.until_s", "time order"),
        ({1: {"ramp_s": -1.0}}, "wave.schedule.1.ramp_s", "greater than or equal to 0"),
        ({1: {"ramp_s": 1.0}}, "wave.schedule.1.ramp_s", "2 wave periods"),
        ({1: {"amplitude_m": 0.2}}, "wave.schedule.1.amplitude_m", "breaking"),
        ({1: {"until_s": None}}, "wave.schedule.1.until_s", "required"),
        ({2: {"typo": 1}}, "wave.schedule.2.typo", "Extra inputs"),
    ],
)
def test_schedule_errors_are_one_line_naming_the_field(tmp_path, change, field, words):
    schedule = [dict(seg) for seg in load_scenario("changing-sea-carriage").to_yaml_dict()
                ["wave"]["schedule"]]  # fmt: skip
    for i, over in change.items():
        schedule[i].update(over)
    message = _bad(tmp_path, {"schedule": schedule})
    assert f"field {field}:" in message and words in message


def test_schedule_needs_zero_amplitude_and_slow_ramps_far_from_the_probe(tmp_path):
    assert "field wave.amplitude_m:" in _bad(tmp_path, {"amplitude_m": 0.1})
    message = _bad(tmp_path, {}, {"carriage": {"start_x_m": 10.0}})  # 40 m from the probe
    assert "field wave.schedule.2.ramp_s:" in message and "local frequency" in message


def test_waypoint_errors_name_the_field(tmp_path):
    s = load_scenario("changing-sea-survey").to_yaml_dict()
    for over, field in (
        ({"turn_radius_m": 9.0}, "turn_radius_m"),
        ({"points": [[26.0, 0.0], [34.0, 0.0], [26.0, 0.0]]}, "points"),
        ({"points": [[26.0, 0.0], [26.0, 0.0], [30.0, 0.0]]}, "points"),
        ({"points": [[26.0, 0.0], [90.0, 0.0]]}, "points"),
    ):
        doc = {**s, "motion": {**s["motion"], "waypoints": {**s["motion"]["waypoints"], **over}}}
        with pytest.raises(ConfigError, match=rf"field motion\.waypoints\.{field}:"):
            from undertow._util.validate import validate

            validate(Scenario, doc, "x.yaml: field ")


# legs of a hexagon (10 m at 0.5 m/s) heading 0, 60, ..., 300 deg, in waves toward -x
HEXAGON = [[25.0 + 10 * np.cos(a), 10 * np.sin(a)] for a in np.deg2rad([-120, -60, 0, 60, 120,
                                                                        180, -120])]  # fmt: skip


@pytest.fixture(scope="module")
def hexagon():
    s = Scenario.model_validate({
        "water": {"depth_m": 10.0},
        "wave": {"amplitude_m": 0.05, "frequency_hz": 0.75, "heading_deg": 180.0},
        "tank": {"length_m": 50.0, "width_m": 50.0, "rock": {"center_x_m": 25.0,
                                                             "center_y_m": 0.0}},
        "motion": {"kind": "waypoints", "waypoints": {
            "points": [[float(x), float(y)] for x, y in HEXAGON], "turn_radius_m": 1.0,
            "depth_m": 1.0, "speed_m_s": 0.5, "ramp_s": 2.0}},
        "wave_probe": {"x_m": 25.0, "y_m": 0.0},
        "ground_truth": {"rate_hz": 50.0},
        "floor_cloud": {"spacing_m": 0.25},
    })  # fmt: skip
    return simulate(s, seed=0)


def test_free_vehicle_heaves_at_the_encounter_frequency_of_each_leg(hexagon):
    """On a leg at heading psi the vertical velocity is W omega_e / omega sin(.) with
    omega_e = |omega - k V cos(beta - psi)| (k from the dispersion relation in 10 m)."""
    gt, s = hexagon.log.ground_truth, hexagon.scenario
    v = s.motion.waypoints
    f, beta, V = 0.75, np.pi, v.speed_m_s
    omega, k = 2 * np.pi * f, _k(f, 10.0)
    W = 0.05 * omega * np.sinh(k * (10.0 - v.depth_m)) / np.sinh(k * 10.0)
    found = set()
    for psi_deg in (0, 60, 120, 180, 240, 300):
        psi = np.deg2rad(psi_deg)
        on_leg = np.abs(np.angle(np.exp(1j * (gt.orientation[:, 2] - psi)))) < 1e-9
        on_leg &= (gt.t > v.hold_before_s + v.ramp_s) & (gt.t < gt.t[-1] - 6.0)
        assert on_leg.sum() > 10.0 * 50  # >= 10 s of straight leg
        t, w = gt.t[on_leg], gt.velocity[on_leg, 2]
        omega_e = abs(omega - k * V * np.cos(beta - psi))
        f_fit, amp = _fit(t, w)
        assert f_fit == pytest.approx(omega_e / (2 * np.pi), abs=2e-3)
        assert amp == pytest.approx(W * omega_e / omega, rel=0.02)
        found.add(round(omega_e, 3))
    assert len(found) == 4  # cos(beta - psi) = -1, -1/2, 1/2, 1: four encounter frequencies


def test_way_point_corners_have_the_turn_rate_v_over_r(hexagon):
    gt = hexagon.log.ground_truth
    yaw_rate = np.gradient(np.unwrap(gt.orientation[:, 2]), gt.t)
    v = hexagon.scenario.motion.waypoints
    assert np.max(yaw_rate) == pytest.approx(v.speed_m_s / v.turn_radius_m, rel=0.02)
    assert np.min(yaw_rate) > -1e-6  # a hexagon counter-clockwise: left turns only
    # the gyro sees the same (bias and noise aside)
    gyro = hexagon.log.imu.angular_velocity[:, 2]
    assert np.max(gyro) == pytest.approx(v.speed_m_s / v.turn_radius_m, rel=0.05)


def test_builtin_changing_sea_scenarios_load_with_long_held_conditions():
    from undertow.sim.simulate import build_motion

    for name in ("changing-sea-carriage", "changing-sea-survey"):
        s = load_scenario(name)
        assert s.description and s.wave.schedule is not None
        track = wave_track(s, build_motion(s, build_wave(s)).duration)
        # held conditions: consecutive nodes with the same (a, f)
        a, f = track.amplitude_m, np.nan_to_num(track.frequency_hz)
        for i in range(len(track) - 1):
            if a[i] == a[i + 1] and f[i] == f[i + 1] and a[i] > 0:
                assert track.t[i + 1] - track.t[i] >= 2.5 * 20 / f[i]
