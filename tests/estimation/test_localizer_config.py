"""Filter parameters and calibration files: invalid values are refused by name, and a run that
the filter cannot follow says so instead of returning a frozen track."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import yaml
from test_localize import make_log

from undertow.errors import ConfigError
from undertow.estimation import Localizer, LocalizerConfig
from undertow.estimation.calibration import Calibration
from undertow.log import Dvl, Imu

NAN = float("nan")


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("beta", NAN, "finite"),
        ("alpha", NAN, "finite"),
        ("kappa", -16.0, "greater than or equal to 0"),  # Julier's 3 - n: big negative W_0
        ("alpha", 1e-3, "greater than or equal to 0.5"),  # W^m_0 ~ -1e6 for n = 18
        ("dr_bias_drift_rad_s", (NAN, 0.0, 0.0), "finite"),
        ("accel_density", (-0.01, 0.01, 0.01), "greater than 0"),
        ("angular_accel_density", (0.0, 0.01, 0.01), "greater than 0"),
        ("gyro_bias_walk_density", (-1e-9, 0.0, 0.0), "greater than or equal to 0"),
        ("imu_gyro_std_rad_s", (NAN, 0.005, 0.005), "finite"),
        ("dvl_velocity_std_m_s", (0.0, 0.01, 0.01), "greater than 0"),
        ("depth_std_m", float("inf"), "finite"),
        ("dvl_scale_factor", NAN, "finite"),
        ("max_dt_s", float("inf"), "finite"),
        ("initial_position", (0.0, NAN, 0.0), "finite"),
        ("initial_std", [0.1] * 17, "18 values"),
        ("initial_state", [0.0] * 17 + [NAN], "finite"),
        ("gate_probability", NAN, "finite"),
        ("swell_damping", 1.0, "less than 1"),  # the band's transition needs 0 < lambda < 1
        ("swell_damping", 0.0, "greater than 0"),
        ("wave_heading_deg", NAN, "finite"),
    ],
)
def test_invalid_parameters_are_refused_by_name(field, value, message):
    with pytest.raises(ConfigError, match=rf"Localizer: {field}[.\d]*: .*{message}"):
        Localizer(**{field: value})


def test_zero_bias_walk_is_allowed_and_defaults_validate():
    LocalizerConfig(dr_bias_walk_density=(0.0, 0.0, 0.0), gyro_bias_walk_density=(0, 0, 0))
    cfg = LocalizerConfig()
    assert LocalizerConfig(**cfg.model_dump()) == cfg  # what config.yaml holds reads back


def test_a_run_that_gates_almost_everything_warns_once_per_sensor():
    """A chi-square quantile of 1e-9 is below any real innovation's NIS: nearly every
    measurement is gated and the track would be frozen at the start: one line per sensor."""
    log = make_log(duration=5.0, u=0.3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        Localizer("proposed", gate_probability=1e-9).run(log)
    lines = [str(w.message) for w in caught if "barely uses" in str(w.message)]
    for sensor in ("imu", "dvl"):
        mine = [m for m in lines if m.startswith(f"{sensor}: ")]
        assert len(mine) == 1 and "\n" not in mine[0] and "gated" in mine[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # and a sound run says nothing
        Localizer("proposed", gate_probability=0.999).run(log)


def test_a_run_whose_every_update_overflows_warns():
    """Finite but absurd measurements (1e300): rejected by the envelopes by default; without
    them they overflow every update, each is reverted, and each sensor says so."""
    log = make_log(duration=3.0)
    imu = Imu(log.imu.t, np.full_like(log.imu.angular_velocity, 1e300))
    dvl = Dvl.from_velocity(log.dvl.t, np.full_like(log.dvl.velocity, 1e300))
    absurd = log.replace(imu=imu, dvl=dvl)
    with pytest.warns(RuntimeWarning, match="reverted steps .* frozen"):
        traj = Localizer("proposed", gyro_max_rate_rad_s=None, dvl_max_speed_m_s=None).run(absurd)
    assert np.all(np.isfinite(traj.x))
    with pytest.warns(RuntimeWarning, match="imu: 100 % .* beyond the gyro's range"):
        traj = Localizer("proposed").run(absurd)
    c = traj.metadata["counts"]
    assert c["rejected_imu_range"] == len(imu) and c["rejected_dvl_speed"] == len(dvl)


# --- calibration files -------------------------------------------------------------------------


def _write(tmp_path, text, name="cal.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "dr_bias_drift_rad_s: [.nan, 0, 0]\n",
            "dr_bias_drift_rad_s.0: .*finite",
        ),
        ("gyro_bias_rad_s: [0, .inf, 0]\n", "gyro_bias_rad_s.1: .*finite"),
        ("dvl_scale_factor: -1.0\n", "dvl_scale_factor: .*greater than 0"),
        ("dr_bias_drift_rad_s: [0, 0]\n", "dr_bias_drift_rad_s"),
        ("[1, 2]\n", "not a calibration file .*got a list"),
        ("name: paper\nconditions: []\n", "unknown keys conditions, name"),
        ("dvl_scale_factr: 1.01\n", "unknown keys dvl_scale_factr"),
        ("a: [1\n", "invalid YAML in calibration file at line 2"),
    ],
)
def test_bad_calibration_files_are_refused(tmp_path, text, message):
    with pytest.raises(ConfigError, match=message):
        Calibration.from_yaml(_write(tmp_path, text))


def test_the_shipped_noise_profile_is_not_a_calibration():
    from importlib import resources

    path = resources.files("undertow") / "data" / "noise_profile_paper.yaml"
    with pytest.raises(ConfigError, match="unknown keys conditions, name"):
        Calibration.from_yaml(path)


def test_calibration_file_round_trip_keeps_nan_std(tmp_path):
    cal = Calibration(dr_bias_drift_rad_s=(0.0, 0.0, 1e-4), dvl_scale_factor=1.016)
    back = Calibration.from_yaml(cal.save_yaml(tmp_path / "c.yaml"))
    assert back.dr_bias_drift_rad_s == cal.dr_bias_drift_rad_s
    assert back.dvl_scale_factor == 1.016 and np.isnan(back.dvl_scale_factor_std)
    assert yaml.safe_load((tmp_path / "c.yaml").read_text())["source"] == ""
    empty = Calibration.from_yaml(_write(tmp_path, "", "empty.yaml"))
    assert empty.dvl_scale_factor == 1.0
