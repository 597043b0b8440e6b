"""The joined settings file: defaults with no file, partial files, one-line errors, CLI use."""

import pytest
from typer.testing import CliRunner

from undertow.cli import app
from undertow.errors import ConfigError
from undertow.estimation import LocalizerConfig
from undertow.mapping.config import MappingConfig
from undertow.settings import Settings


def test_no_file_gives_every_stage_default():
    s = Settings.from_yaml(None)
    assert s.mapping == MappingConfig() and s.localizer == LocalizerConfig()
    assert s.localizer_params() == {}


def test_partial_file_sets_only_what_it_names(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("localizer: {variant: be}\nmapping: {method: csm}\ntopics: {imu: [/my/imu]}\n")
    s = Settings.from_yaml(path)
    assert s.localizer_params() == {"variant": "be"}
    assert s.mapping.method == "csm" and s.mapping.resolution == 0.1
    assert s.topics.imu == ["/my/imu"]


@pytest.mark.parametrize(
    "text, where",
    [
        ("mapping: {resolution: -1}", "mapping.resolution"),
        ("localise: {}", "localise"),
        ("- 1", "mapping"),
    ],
)
def test_errors_name_file_and_field(tmp_path, text, where):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=f"bad.yaml: .*{where}"):
        Settings.from_yaml(path)


def test_cli_reports_a_bad_settings_file_in_one_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("localizer: {variant: nope}\n")
    result = CliRunner().invoke(
        app, ["localize", "x.bag", "--config", str(path), "--out", str(tmp_path / "o")]
    )
    assert result.exit_code == 1 and "localizer.variant" in result.output
    assert "Traceback" not in result.output


def test_mounting_override_keeps_fields_it_does_not_name(tmp_path):
    from undertow.robot import Mounting

    m = Mounting().updated({"dvl": {"rotation": [0, 0, 0.1]}})
    assert m.dvl.rotation == (0.0, 0.0, 0.1)
    assert m.dvl.translation == Mounting().dvl.translation  # the BlueROV2 lever arm stays
    path = tmp_path / "bad.yaml"
    path.write_text("mounting: {gps: {rotation: [0, 0, 0]}}\n")
    with pytest.raises(ConfigError, match="bad.yaml: mounting.gps: unknown sensor"):
        Settings.from_yaml(path)


@pytest.mark.slow
def test_imu_logged_in_ros_flu_is_fixed_by_a_mounting_rotation(tmp_path):
    """REP-103 IMUs (e.g. mavros) report rates in forward-left-up: p, -q, -r of our FRD body.
    Declaring the IMU frame rolled by pi gives the same estimate as the FRD log."""
    import numpy as np

    from undertow.estimation import localize
    from undertow.evaluation.trajectory import trajectory_rmse
    from undertow.log import Imu
    from undertow.sim import load_scenario, simulate

    log = simulate(load_scenario("rock-survey"), seed=4).log  # turns: yaw rates matter
    w = log.imu.angular_velocity * np.array([1.0, -1.0, -1.0])
    flu = log.replace(imu=Imu(t=log.imu.t, angular_velocity=w))
    path = tmp_path / "s.yaml"
    path.write_text("mounting: {imu: {rotation: [3.141592653589793, 0, 0]}}\n")
    fixed = Settings.from_yaml(path).apply_mounting(flu)
    reference = localize(log, "proposed")
    corrected = localize(fixed, "proposed")
    # the same estimate; the gyro bias is a state of the IMU frame, so its y and z flip sign
    np.testing.assert_allclose(corrected.x[:, :15], reference.x[:, :15], atol=1e-9)
    flip = np.array([1.0, -1.0, -1.0])
    np.testing.assert_allclose(corrected.x[:, 15:] * flip, reference.x[:, 15:], atol=1e-9)
    gt = log.ground_truth
    wrong = trajectory_rmse(localize(flu, "proposed"), gt).rmse
    assert wrong["yaw_rad"] > 5 * trajectory_rmse(reference, gt).rmse["yaw_rad"]


@pytest.mark.parametrize(
    "text, old, new",
    [
        (
            "localizer: {initial_gyro_bias_rad_s: [0, 0, 0]}\n",
            "initial_gyro_bias_rad_s",
            "gyro_bias_rad_s",
        ),  # fmt: skip
        (
            "localizer: {dead_reckoning_drift_rad_per_s: [0, 0, 0]}\n",
            "dead_reckoning_drift_rad_per_s",
            "dr_bias_drift_rad_s",
        ),  # fmt: skip
    ],
)
def test_a_renamed_setting_is_refused_naming_its_new_name(tmp_path, text, old, new):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=rf"localizer\.{old}: renamed, use '{new}'"):
        Settings.from_yaml(path)


def test_a_calibration_file_with_an_old_name_is_refused(tmp_path):
    from undertow.estimation.calibration import Calibration

    path = tmp_path / "cal.yaml"
    path.write_text("imu_gyro_bias_rad_per_s: [0, 0, 0]\ndvl_scale_factor: 1.0\n")
    with pytest.raises(ConfigError, match=r"imu_gyro_bias_rad_per_s: renamed, use 'gyro_bias"):
        Calibration.from_yaml(path)
