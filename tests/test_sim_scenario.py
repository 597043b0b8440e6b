"""Scenarios (loading, overrides, errors), determinism and the carriage experiment's geometry."""

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.log import STREAM_NAMES
from undertow.sim import Scenario, SimulationResult, list_scenarios, load_scenario, simulate

PAPER = ["calm", "wave-a0.10-f1.00", "wave-a0.10-f0.75", "wave-a0.05-f0.75"]


def test_builtins_are_listed_and_load():
    names = list_scenarios()
    assert set(PAPER + ["rock-survey"]) <= set(names)
    for name in PAPER:
        s = load_scenario(name)
        assert s.name == name and s.motion.kind == "carriage"
        assert s.motion.carriage.run_length_m == 36.6
    assert load_scenario("wave-a0.10-f0.75").wave.amplitude_m == 0.1
    assert load_scenario("wave-a0.05-f0.75").wave.frequency_hz == 0.75
    assert load_scenario("rock-survey").motion.kind == "survey"


def test_unknown_name_lists_the_builtins():
    with pytest.raises(ConfigError, match="calm.*rock-survey"):
        load_scenario("no-such-scenario")


def test_user_yaml_overrides_only_some_fields(tmp_path):
    f = tmp_path / "mine.yaml"
    f.write_text("base: wave-a0.10-f1.00\nname: mine\ndvl:\n  rate_hz: 5.0\n")
    s = load_scenario(f)
    assert s.name == "mine" and s.dvl.rate_hz == 5.0
    assert s.wave.amplitude_m == 0.1 and s.dvl.beam_tilt_deg == 22.5
    g = tmp_path / "plain.yaml"
    g.write_text("wave:\n  amplitude_m: 0.02\n")
    assert load_scenario(g) == Scenario(wave={"amplitude_m": 0.02})


def test_invalid_field_names_file_and_field(tmp_path):
    f = tmp_path / "bad.yaml"
    f.write_text("dvl:\n  rate_hz: -1\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: field dvl\.rate_hz"):
        load_scenario(f)
    f.write_text("dvl:\n  rat_hz: 3\n")
    with pytest.raises(ConfigError, match=r"field dvl\.rat_hz"):
        load_scenario(f)


def test_to_yaml_dict_round_trips():
    s = load_scenario("rock-survey")
    assert Scenario.model_validate(s.to_yaml_dict()) == s


def _short(**over) -> Scenario:
    s = load_scenario("wave-a0.10-f1.00").to_yaml_dict()
    s["motion"]["carriage"]["run_length_m"] = 4.0
    s["ground_truth"]["rate_hz"] = 100.0
    for key, value in over.items():
        s[key].update(value)
    return Scenario.model_validate(s)


def test_deterministic_for_a_seed_and_sensor_streams_independent():
    a, b, c = simulate(_short(), seed=7), simulate(_short(), seed=7), simulate(_short(), seed=8)
    assert isinstance(a, SimulationResult) and a.scenario.seed == 7
    for name in STREAM_NAMES:
        sa, sb = getattr(a.log, name), getattr(b.log, name)
        for field in (
            "t",
            "angular_velocity",
            "velocity",
            "pressure",
            "range",
            "elevation",
            "position",
        ):
            if hasattr(sa, field) and getattr(sa, field) is not None:
                np.testing.assert_array_equal(getattr(sa, field), getattr(sb, field))
    assert not np.array_equal(a.log.imu.angular_velocity, c.log.imu.angular_velocity)
    # changing one sensor's noise leaves the others' noise unchanged
    d = simulate(_short(dvl={"range_sigma": 0.05}), seed=7)
    np.testing.assert_array_equal(a.log.imu.angular_velocity, d.log.imu.angular_velocity)
    np.testing.assert_array_equal(a.log.pressure.pressure, d.log.pressure.pressure)
    assert not np.array_equal(a.log.dvl.beam_range, d.log.dvl.beam_range)


def test_carriage_run_is_36_6_m_along_x_with_trapezoid_speed():
    s = load_scenario("calm").to_yaml_dict()
    s["ground_truth"]["rate_hz"] = 200.0
    s = Scenario.model_validate(s)
    r = simulate(s, seed=0)
    gt = r.log.ground_truth
    c = s.motion.carriage
    assert gt.position[-1, 0] - gt.position[0, 0] == pytest.approx(36.6, abs=1e-9)
    np.testing.assert_allclose(gt.position[:, 1:], [[c.y_m, c.depth_m]] * len(gt), atol=1e-12)
    speed = gt.velocity[:, 0]
    assert speed.max() == pytest.approx(c.cruise_speed_m_s, abs=1e-6)
    assert speed[0] == pytest.approx(0.0, abs=1e-9) and speed[-1] == pytest.approx(0.0, abs=1e-9)
    T = c.hold_before_s + c.hold_after_s + 2 * c.cruise_speed_m_s / c.acceleration_m_s2
    T += (36.6 - c.cruise_speed_m_s**2 / c.acceleration_m_s2) / c.cruise_speed_m_s
    assert gt.t[-1] == pytest.approx(T, abs=1 / 200.0)
    meta = r.log.metadata
    assert meta["scenario"] == "calm" and meta["seed"] == 0
    assert meta["wave"] == {"amplitude_m": 0.0, "frequency_hz": 1.0}


def test_default_scenario_rates_and_floor_cloud():
    r = simulate(load_scenario("wave-a0.10-f1.00"), seed=0)
    log = r.log
    assert log.ground_truth.rate_hz == pytest.approx(2000.0)
    assert log.imu.rate_hz == pytest.approx(100.0)
    assert 5.0 - 1e-9 <= log.dvl.rate_hz <= 10.0 + 1e-9
    assert 5.0 - 1e-9 <= log.dead_reckoning.rate_hz <= 10.0 + 1e-9
    assert 10.0 - 1e-9 <= log.pressure.rate_hz <= 20.0 + 1e-9
    assert log.imu.orientation is None
    cloud = r.floor_cloud
    assert 1e5 < len(cloud) < 2e6
    gt = log.ground_truth.position
    assert cloud[:, 0].min() <= gt[:, 0].min() - 1.9 and cloud[:, 0].max() >= gt[:, 0].max() + 1.9
    rock = r.scenario.tank.rock
    assert cloud[:, 2].min() == pytest.approx(3.0 - rock.height_m)


def test_rock_survey_vehicle_moves_with_the_waves_over_the_rock():
    r = simulate(load_scenario("rock-survey"), seed=0)
    gt = r.log.ground_truth
    rock = r.scenario.tank.rock
    assert gt.position[:, 0].min() < rock.center_x_m < gt.position[:, 0].max()
    assert gt.position[:, 1].min() < rock.center_y_m < gt.position[:, 1].max()
    # heave: the depth oscillates with the vertical orbital displacement at the commanded depth
    from undertow.sim.simulate import build_wave

    wave = build_wave(r.scenario)
    _, W = wave.velocity_amplitude(r.scenario.motion.survey.depth_m)
    assert np.ptp(gt.position[:, 2]) == pytest.approx(2 * W / wave.omega, rel=0.02)
    assert np.all(np.abs(gt.orientation[:, :2]) < 0.1)
