"""`undertow check` on the shared real recordings, as a new user walks it: check, the written
config, localize, the drift against the DVL's own dead reckoning. Independent references: the
recordings' README (which topic is what, their quirks), the vehicle's own depth topic, the A50's
own dead reckoning."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from conftest import REAL_DATA, one_error_line
from typer.testing import CliRunner

from undertow.cli import app
from undertow.commands.check import check_file, depth_agreement
from undertow.commands.common import load_log
from undertow.io.topic_guess import propose_topics
from undertow.settings import Settings
from undertow.trajectory import Trajectory

COUG = REAL_DATA / "coug_a50_imu_ros2"
BIN = REAL_DATA / "ardusub_small.BIN"
CIRCLE = REAL_DATA / "a50_ros1_circle.bag"
pytestmark = pytest.mark.realdata
runner = CliRunner()

#: what the recordings' README says each topic of the AUV bag is
README_TOPICS = {
    "dvl": "/coug2/dvl/data",
    "dead_reckoning": "/coug2/dvl/position",
    "imu": "/coug2/modem_imu",
    "pressure": "/coug2/pressure/data",
    "depth": "/coug2/depth_data",
    "gps": "/coug2/fix",
}


@pytest.fixture(scope="module")
def checked(tmp_path_factory):
    folder = tmp_path_factory.mktemp("check")
    config = folder / "robot.yaml"
    result = runner.invoke(app, ["check", str(COUG), "--write-config", str(config)])
    return result, config, folder


def test_check_names_the_streams_the_clock_the_units_and_the_surface(checked):
    result, config, _ = checked
    assert result.exit_code == 0, result.output
    out = result.output
    for topic in README_TOPICS.values():
        if topic != "/coug2/fix":  # no valid fix in the excerpt: dropped and counted
            assert topic in out
    assert "time base: record (receive) time" in out and "/coug2/modem_imu" in out
    assert "gyro unit deg/s" in out and "converted" in out
    assert "surface pressure 85," in out
    assert "ready to localize" in out


def test_topics_proposed_by_type_and_name_are_the_readmes():
    from undertow.io.rosbag import bag_topics

    types = {t: m for t, (m, _) in bag_topics(COUG).items()}
    proposed = {s: c.topic for s, c in propose_topics(types).items()}
    assert {s: proposed.get(s) for s in README_TOPICS} == README_TOPICS


def test_the_written_config_loads_and_pins_what_was_found(checked):
    _, config, _ = checked
    data = yaml.safe_load(config.read_text())
    settings = Settings.model_validate(data)
    assert settings.topics.dvl == [README_TOPICS["dvl"]]
    assert settings.log.time == "record" and settings.log.imu_units == "deg/s"
    assert isinstance(settings.log.surface_pressure_pa, float)


def test_depth_from_pressure_agrees_with_the_vehicles_own(checked):
    _, config, _ = checked
    log = load_log(COUG, settings=Settings.from_yaml(config))
    rms = depth_agreement(log)
    assert rms is not None and rms < 0.1


def test_localize_with_the_written_config_ends_near_the_a50s_own_dead_reckoning(checked):
    _, config, folder = checked
    out = folder / "run"
    result = runner.invoke(app, ["localize", str(COUG), "--config", str(config), "--out",
                                 str(out)])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "consistency:" in result.output
    trajectory = Trajectory.load_npz(out)
    log = load_log(COUG, settings=Settings.from_yaml(config))
    dr = log.dead_reckoning
    p = np.asarray(trajectory.x)[:, :3]
    ref = np.column_stack([np.interp(trajectory.t, dr.t, dr.position[:, k]) for k in range(3)])
    travelled = np.sum(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1))
    end = np.linalg.norm((p[-1] - p[0])[:2] - (ref[-1] - ref[0])[:2])
    assert travelled > 5.0 and end < 0.10 * travelled
    evaluated = runner.invoke(app, ["evaluate", "trajectory", str(out), str(COUG), "--reference",
                                    "dvl-dr", "--config", str(config)])  # fmt: skip
    assert evaluated.exit_code == 0, evaluated.output
    assert "final drift" in evaluated.output and "% of" in evaluated.output


def test_check_json_and_its_config_record_the_time_base(checked):
    _, config, _ = checked
    result = runner.invoke(app, ["check", str(COUG), "--config", str(config), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["ready"] and data["time_base"]["base"] == "record"
    assert {s["stream"] for s in data["streams"]} >= {"dvl", "imu", "pressure", "depth"}


def test_a_log_that_cannot_be_localized_exits_1_with_the_reason():
    result = runner.invoke(app, ["check", str(CIRCLE)])
    assert result.exit_code == 1
    assert "not ready:" in result.output and "orientation source" in result.output
    assert "missing: localize: no orientation source" in result.output


def test_the_dataflash_log_says_what_a_localization_would_lack():
    result = check_file(BIN)
    assert not result.ready and "DVL velocity" in result.reason
    assert {"imu", "pressure", "autopilot"} <= {s.stream for s in result.streams}
    assert any("no DVL velocity" in line for line in result.missing)
    runner_result = runner.invoke(app, ["check", str(BIN)])
    assert runner_result.exit_code == 1


def test_a_bad_time_option_is_one_line(tmp_path):
    result = runner.invoke(app, ["check", str(COUG), "--time", "gps"])
    assert "auto, header or record" in one_error_line(result)
