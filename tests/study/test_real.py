"""The peers on the real AUV recording (undertow.study.real): read as `undertow localize
--config` reads it, and the agreement with the A50's dead reckoning as `undertow evaluate
trajectory --reference dvl-dr` reports it."""

import dataclasses
import json

import numpy as np
import pytest
from conftest import REAL_DATA
from typer.testing import CliRunner

from undertow.study import real

# the settings `undertow check coug_a50_imu_ros2 --write-config` proposes (docs/your-robot.md)
SETTINGS = """\
topics: {dvl: /coug2/dvl/data, dead_reckoning: /coug2/dvl/position, imu: /coug2/modem_imu,
         pressure: /coug2/pressure/data, depth: /coug2/depth_data, gps: /coug2/fix}
log: {time: record, imu_units: deg/s, surface_pressure_pa: 85221.0, water: fresh}
mounting:
  imu: {rotation: [3.141592653589793, 0.0, 0.0]}
localizer:
  dr_bias_rad: [0.0, 0.2215, 0.0]
  dr_orientation_std_rad: [0.0207, 0.0207, 0.01]
"""

pytestmark = [pytest.mark.realdata, pytest.mark.slow]


@pytest.fixture(scope="module")
def settings(tmp_path_factory):
    path = tmp_path_factory.mktemp("real") / "robot.yaml"
    path.write_text(SETTINGS)
    return path


def test_the_proposed_filters_drift_is_what_evaluate_trajectory_reports(settings, tmp_path):
    from undertow.cli import app

    bag = REAL_DATA / "coug_a50_imu_ros2"
    result = real.real_peers(bag, settings, estimators=("proposed",))
    runner = CliRunner()
    out = tmp_path / "est"
    r = runner.invoke(app, ["localize", str(bag), "--config", str(settings), "--out", str(out),
                            "-q"])  # fmt: skip
    assert r.exit_code == 0, r.output
    args = ["evaluate", "trajectory", str(out), str(bag), "--reference", "dvl-dr", "--config",
            str(settings), "--json"]  # fmt: skip
    data = json.loads(runner.invoke(app, args).stdout)
    proposed = result["estimators"]["proposed"]
    assert proposed["final_drift_m"] == pytest.approx(data["final_drift_m"], rel=1e-6)
    assert proposed["consistency"]["dvl"]["dof"] == 3
    assert "proposed" in real.real_markdown(result)


def test_without_an_accelerometer_the_peers_say_why(settings, monkeypatch):
    log, params = real.load_real_log(REAL_DATA / "coug_a50_imu_ros2", settings)
    imu = dataclasses.replace(log.imu, linear_acceleration=np.full_like(
        log.imu.linear_acceleration, np.nan))  # fmt: skip
    monkeypatch.setattr(real, "load_real_log", lambda *a: (log.replace(imu=imu), params))
    result = real.real_peers("coug", estimators=("baseline", "inekf"))
    assert result["accelerometer"] is False
    assert "no accelerometer" in result["estimators"]["inekf"]["status"]
    assert "final_drift_m" in result["estimators"]["baseline"]
