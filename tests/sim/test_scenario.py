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
    # a list where the DVL's model name goes (found by the fuzz campaign: was a TypeError)
    f.write_text("dvl:\n  model: [1]\n")
    with pytest.raises(ConfigError, match=r"field dvl\.model"):
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


def test_default_scenario_rates_and_floor_cloud(simulation):
    r = simulation("wave-a0.10-f1.00", 0)
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


def test_rock_survey_vehicle_moves_with_the_waves_over_the_rock(simulation):
    r = simulation("rock-survey", 0)
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


# -- user mistakes: one clear error naming the file and the field, never a traceback ----------


def test_negative_seed_is_rejected_by_the_scenario_and_by_simulate(tmp_path):
    f = tmp_path / "neg.yaml"
    f.write_text("base: calm\nseed: -1\n")
    with pytest.raises(ConfigError, match=r"neg\.yaml: field seed: .*greater than or equal to 0"):
        load_scenario(f)
    with pytest.raises(ConfigError, match="seed -1: must be a non-negative integer"):
        simulate(load_scenario("calm"), seed=-1)


def test_binary_and_empty_files_name_the_file(tmp_path):
    binary = tmp_path / "scan.ply"
    binary.write_bytes(b"ply\nformat binary_little_endian 1.0\n\xff\xfe\x00\x89")
    with pytest.raises(ConfigError, match=r"scan\.ply: not a scenario YAML file \(binary"):
        load_scenario(binary)
    for text in ("", "# only a comment\n"):
        empty = tmp_path / "empty.yaml"
        empty.write_text(text)
        with pytest.raises(ConfigError, match=r"empty\.yaml: empty scenario file.*base: calm"):
            load_scenario(empty)


def test_error_from_a_base_scenario_names_the_users_file(tmp_path):
    """The floor-scan budget is checked at load time, so the error names the user's file, not
    the built-in it starts from; the budget matches the points the simulator makes."""
    f = tmp_path / "fine.yaml"
    f.write_text("base: calm\nfloor_cloud: {spacing_m: 0.001}\n")
    with pytest.raises(ConfigError, match=r"^\S*fine\.yaml: field floor_cloud\.spacing_m: "):
        load_scenario(f)
    f.write_text("base: calmm\n")
    with pytest.raises(ConfigError, match=r"^\S*fine\.yaml: field base: unknown scenario 'calmm'"):
        load_scenario(f)
    # the check's count is the simulator's: a budget of exactly the scan's size passes
    s = load_scenario("calm").to_yaml_dict()
    s["motion"]["carriage"]["run_length_m"] = 2.0
    s["floor_cloud"]["spacing_m"] = 0.1
    n = len(simulate(Scenario.model_validate(s)).floor_cloud)
    s["floor_cloud"]["max_points"] = n
    Scenario.model_validate(s)
    s["floor_cloud"]["max_points"] = n - 1
    with pytest.raises(ValueError, match="floor_cloud.max_points"):
        Scenario.model_validate(s)


# -- physically impossible scenarios: rejected at the field, naming the limit ----------------

IMPOSSIBLE = [
    # robot below the 3 m floor (and its sensors 0.3 m lower still)
    ({"motion": {"carriage": {"depth_m": 5.0}}}, r"motion\.carriage\.depth_m: .*floor"),
    # robot in the air; in waves it must stay below the trough (a = 0.1 m)
    ({"motion": {"carriage": {"depth_m": -1.0}}}, r"motion\.carriage\.depth_m: .*out of the"),
    (
        {"motion": {"carriage": {"depth_m": 0.08}}},
        r"motion\.carriage\.depth_m: .*below the wave trough at 0\.1",
    ),
    # 100 m + 36.6 m run leaves the 110 m tank
    (
        {"motion": {"carriage": {"start_x_m": 100.0}}},
        r"motion\.carriage\.start_x_m: .*136\.\d+ m.*0 to 110 m",
    ),
    ({"motion": {"carriage": {"y_m": 3.3}}}, r"motion\.carriage\.y_m: .*outside the tank"),
    ({"dvl": {"min_range": 60.0}}, r"dvl\.min_range: 60\.0 m is not below dvl\.max_range"),
    ({"sonar": {"min_range": 2.0, "max_range": 1.0}}, r"sonar\.min_range"),
    ({"tank": {"rock": {"height_m": 3.5}}}, r"tank\.rock\.height_m: .*under water"),
    ({"tank": {"rock": {"center_x_m": 109.8}}}, r"tank\.rock\.center_x_m: .*inside the tank"),
    ({"wave_probe": {"x_m": 120.0}}, r"wave_probe\.x_m: .*outside the tank"),
]


@pytest.mark.parametrize(("over", "message"), IMPOSSIBLE)
def test_physically_impossible_carriage_scenarios_are_rejected(tmp_path, over, message):
    import yaml

    f = tmp_path / "mine.yaml"
    f.write_text(yaml.safe_dump({"base": "wave-a0.10-f1.00", **over}))
    with pytest.raises(ConfigError, match=r"mine\.yaml: field " + message):
        load_scenario(f)


def test_breaking_limit_is_h_over_lambda_one_seventh_with_the_dispersion_relation():
    """a_max = lambda / 14 with lambda = 2 pi / k, k solving omega^2 = g k tanh(k h) (solved
    here with scipy, independently of the simulator): just below passes, just above fails."""
    from scipy.optimize import brentq

    g, h, f = 9.80665, 3.0, 1.0
    omega = 2 * np.pi * f
    k = brentq(lambda k: g * k * np.tanh(k * h) - omega**2, 1e-6, 100.0, xtol=1e-14)
    a_max = 2 * np.pi / k / 14
    assert a_max == pytest.approx(0.111, abs=1e-3)  # lambda = 2 pi / k = 1.56 m at 1 Hz in 3 m
    Scenario(wave={"amplitude_m": a_max * (1 - 1e-6), "frequency_hz": f})
    with pytest.raises(ValueError, match=r"breaking wave: steepness .* 1/7") as info:
        Scenario(wave={"amplitude_m": a_max * (1 + 1e-6), "frequency_hz": f})
    assert info.value.errors()[0]["loc"] == ("wave", "amplitude_m")
    # the paper's three conditions are well below the limit
    for name in PAPER[1:]:
        load_scenario(name)


def test_survey_path_stays_inside_the_tank_and_the_water():
    survey = load_scenario("rock-survey").to_yaml_dict()

    def with_survey(**over):
        s = {**survey, "motion": {**survey["motion"], "survey": {**survey["motion"]["survey"]}}}
        s["motion"]["survey"].update(over)
        return s

    for over, message in (
        ({"first_pass_y_m": 2.9}, r"survey path covers y = .* outside the tank"),
        ({"passes": 12}, r"survey path covers y = .* outside the tank"),
        ({"start_x_m": 106.0}, r"survey path covers x = .* outside the tank"),
        ({"depth_m": 2.4}, r"lowest sensor .* floor at 2\.6 m \(the rock's top"),
        ({"depth_m": 0.04}, r"out of the water"),
    ):
        with pytest.raises(ValueError, match=message):
            Scenario.model_validate(with_survey(**over))
    # the free vehicle's simulated path (turns and orbital excursion included) stays in the box
    # the check allows: the check is not looser than the motion
    from undertow.sim.scenario.checks import path_extent

    s = Scenario.model_validate(with_survey(first_pass_y_m=-3.0, passes=2, pass_length_m=2.0))
    box = path_extent(s)
    gt = simulate(s).log.ground_truth.position
    assert box.x_min <= gt[:, 0].min() and gt[:, 0].max() <= box.x_max
    assert box.y_min <= gt[:, 1].min() and gt[:, 1].max() <= box.y_max
    assert gt[:, 1].min() > -s.tank.width_m / 2
