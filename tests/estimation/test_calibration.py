"""Calibration recovers parameters planted in synthetic data within their sampling error."""

import numpy as np
import pytest

from undertow.errors import DataError, MissingStreamError
from undertow.estimation.calibration import Calibration, calibrate
from undertow.log import (
    FRESH_WATER_DENSITY,
    G0,
    P_ATM,
    DeadReckoning,
    Dvl,
    GroundTruth,
    Imu,
    Log,
    Pressure,
)
from undertow.robot import Mounting, SensorMount
from undertow.rotations import rpy_to_matrix

BAR30_PA = 20.0  # the MS5837-30BA's resolution at OSR 8192: 0.2 mbar


def _run(drift=(0.0, 0.0, 2e-4), gyro_bias=(0.01, -0.02, 0.005), scale=1.02, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0, 1 / 2000)
    speed = np.clip(t / 10, 0, 1) * 0.8  # accelerate for 10 s, then 0.8 m/s
    x = np.cumsum(speed) / 2000
    gt = GroundTruth(
        t=t,
        position=np.column_stack([x, 0 * t, 0 * t + 0.5]),
        orientation=np.column_stack([0 * t, 0 * t, 0 * t + 0.3]),
    )
    mounting = Mounting()
    td = np.arange(0.5, 59.5, 0.125)
    v_world = np.column_stack([np.interp(td, t, speed), 0 * td, 0 * td])
    v_body = v_world @ rpy_to_matrix([0, 0, 0.3])  # R^T v for each row
    v_dvl = v_body @ mounting.dvl.rotation_matrix()
    dvl = Dvl.from_velocity(td, scale * v_dvl + rng.normal(scale=0.005, size=v_dvl.shape))
    tr = np.arange(0.5, 59.5, 0.2)
    dr = DeadReckoning(
        t=tr,
        position=np.zeros((tr.size, 3)),
        orientation=np.array([0, 0, 0.3])
        + np.outer(tr, drift)
        + rng.normal(scale=1e-3, size=(tr.size, 3)),
    )
    ti = np.arange(0.5, 59.5, 0.01)
    imu = Imu(
        t=ti, angular_velocity=np.array(gyro_bias) + rng.normal(scale=0.002, size=(ti.size, 3))
    )
    tp = np.arange(0.5, 59.5, 0.1)
    rho_g = FRESH_WATER_DENSITY * G0
    p = P_ATM + rho_g * 0.5 + rng.normal(scale=BAR30_PA, size=tp.size)
    return Log(imu=imu, dvl=dvl, dead_reckoning=dr, ground_truth=gt, mounting=mounting,
               pressure=Pressure(t=tp, pressure=p))  # fmt: skip


def test_recovers_planted_parameters():
    cal = calibrate(_run())
    # slope standard error: sigma / (sqrt(n) std(t)) = 1e-3 / (sqrt(295) * 17) ~ 3.4e-6
    np.testing.assert_allclose(cal.dr_bias_drift_rad_s, [0, 0, 2e-4], atol=2e-5)
    np.testing.assert_allclose(cal.gyro_bias_rad_s, [0.01, -0.02, 0.005], atol=3e-4)
    assert cal.dvl_scale_factor == pytest.approx(1.02, abs=5 * cal.dvl_scale_factor_std)
    assert cal.dvl_scale_factor_std < 1e-3


def test_yaml_round_trip(tmp_path):
    cal = calibrate(_run())
    back = Calibration.from_yaml(cal.save_yaml(tmp_path / "cal.yaml"))
    assert back.dvl_scale_factor == cal.dvl_scale_factor
    assert back.dr_bias_drift_rad_s == pytest.approx(cal.dr_bias_drift_rad_s)


def test_needs_ground_truth():
    log = _run()
    with pytest.raises(MissingStreamError, match="calibrate needs stream.s. ground_truth"):
        calibrate(log.replace(ground_truth=None))


def test_ground_truth_with_rounded_times_is_deduplicated_with_a_warning():
    """Ground truth at 2000 Hz with its times rounded to 0.01 s repeats each time 20 times: the
    repeats are dropped (one warning) and the planted parameters are still found."""
    log = _run()
    gt = log.ground_truth
    rounded = GroundTruth(t=np.round(gt.t, 2), position=gt.position, orientation=gt.orientation)
    with pytest.warns(RuntimeWarning, match="repeats 113999 timestamps"):
        cal = calibrate(log.replace(ground_truth=rounded))
    np.testing.assert_allclose(cal.dr_bias_drift_rad_s, [0, 0, 2e-4], atol=2e-5)
    np.testing.assert_allclose(cal.gyro_bias_rad_s, [0.01, -0.02, 0.005], atol=3e-4)
    assert cal.dvl_scale_factor == pytest.approx(1.02, abs=2e-3)
    same = GroundTruth(t=np.zeros(5), position=np.zeros((5, 3)), orientation=np.zeros((5, 3)))
    with (
        pytest.warns(RuntimeWarning, match="repeats 4"),
        pytest.raises(DataError, match="1 usable poses at distinct times; need at least 3"),
    ):
        calibrate(log.replace(ground_truth=same))


def test_too_little_overlap_is_an_error_not_a_calibration():
    """Four ground-truth poses (2 ms at 2000 Hz) overlap one IMU sample at most: refused."""
    log = _run()
    gt = log.ground_truth.select(
        np.isin(np.arange(len(log.ground_truth)), [1000, 1001, 1002, 1003])
    )
    with pytest.raises(DataError, match=r"overlaps .*1 samples for gyro_bias_rad_s.*need at least"):
        calibrate(log.replace(ground_truth=gt))


def test_a_parameter_with_too_few_samples_keeps_its_default_and_says_so():
    """3 s of ground truth: 300 IMU samples and 24 DVL, but DR at 5 Hz gives only 15."""
    log = _run()
    gt = log.ground_truth.select((log.ground_truth.t >= 10.0) & (log.ground_truth.t <= 12.9))
    with pytest.warns(RuntimeWarning, match="dr_bias_drift_rad_s .*left at the default"):
        cal = calibrate(log.replace(ground_truth=gt))
    assert cal.dr_bias_drift_rad_s == (0.0, 0.0, 0.0)
    assert "dead_reckoning" not in cal.samples and cal.samples["imu"] >= 290
    np.testing.assert_allclose(cal.gyro_bias_rad_s, [0.01, -0.02, 0.005], atol=1e-3)


@pytest.mark.parametrize(
    ("stream", "parameter"),
    [("imu", "gyro_bias_rad_s"), ("dead_reckoning", "dr_bias_drift_rad_s")],
)
def test_a_missing_stream_leaves_its_parameter_at_the_default_with_a_warning(
    tmp_path, stream, parameter
):
    with pytest.warns(RuntimeWarning, match=f"{parameter} left at the default .*no {stream} str"):
        cal = calibrate(_run().replace(**{stream: None}))
    assert parameter not in cal.estimated and "dvl_scale_factor" in cal.estimated
    assert cal.left_at_default == {parameter: f"the log has no {stream} stream"}
    back = Calibration.from_yaml(cal.save_yaml(tmp_path / "cal.yaml"))
    assert back.estimated == cal.estimated and back.left_at_default == cal.left_at_default
    assert set(calibrate(_run()).estimated) == {
        "dr_bias_drift_rad_s",
        "gyro_bias_rad_s",
        "dvl_scale_factor",
        "depth_std_m",
    }


def _pitching_barometer(seed=0, lever=(0.3, 0.0, -0.1), offset_pa=150.0):
    """A barometer 0.3 m ahead of the origin on a vehicle pitching +-0.2 rad at 0.2 Hz while
    it heaves, read at 50 Hz with the Bar30's noise and a surface-pressure offset."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0, 0.005)
    pitch = 0.2 * np.sin(2 * np.pi * 0.2 * t)
    z = 2.0 + 0.3 * np.sin(2 * np.pi * 0.05 * t)
    rpy = np.column_stack([0 * t, pitch, 0 * t + 0.4])
    gt = GroundTruth(t=t, position=np.column_stack([0 * t, 0 * t, z]), orientation=rpy)
    mounting = Mounting(barometer=SensorMount(translation=lever))
    tp = np.arange(0.5, 59.5, 0.02)
    idx = np.searchsorted(t, tp)
    d = z[idx] + (rpy_to_matrix(rpy[idx]) @ np.asarray(lever))[:, 2]
    p = P_ATM + offset_pa + FRESH_WATER_DENSITY * G0 * d + rng.normal(scale=BAR30_PA, size=tp.size)
    return Log(ground_truth=gt, mounting=mounting, pressure=Pressure(t=tp, pressure=p))


def test_the_barometer_noise_is_its_spread_about_the_truth_at_the_sensor():
    """The Bar30's 20 Pa (2.04 mm of fresh water) recovered within its sampling error
    (std / sqrt(2 n) = 0.9 % for n = 2950) through a lever arm on a pitching vehicle and a
    surface-pressure offset; without the lever arm the pitch would add 6 cm."""
    with pytest.warns(RuntimeWarning, match="left at the default"):  # no IMU, DVL or DR
        cal = calibrate(_pitching_barometer())
    sigma = BAR30_PA / (FRESH_WATER_DENSITY * G0)
    assert cal.depth_std_m == pytest.approx(sigma, rel=0.04)
    assert "depth_std_m" in cal.estimated and cal.samples["pressure"] == 2950
    with pytest.warns(RuntimeWarning, match="left at the default"):
        moved = calibrate(_pitching_barometer().replace(mounting=Mounting()))
    assert moved.depth_std_m > 10 * sigma  # the lever arm matters: the fit uses it


def test_the_barometer_noise_is_not_calibrated_in_waves():
    """A log whose metadata records a swell: the barometer's spread holds the swell's pressure
    too, so depth_std_m keeps its default and the warning says why."""
    log = _run().replace(metadata={"wave": {"amplitude_m": 0.1, "frequency_hz": 1.0}})
    with pytest.warns(RuntimeWarning, match="depth_std_m left at the default 0.01: the log "
                      "records waves"):  # fmt: skip
        cal = calibrate(log)
    assert "depth_std_m" not in cal.estimated and cal.depth_std_m == 0.01
    calm = log.replace(metadata={"wave": {"amplitude_m": 0.0, "frequency_hz": None}})
    assert "depth_std_m" in calibrate(calm).estimated
    track = {"t": [0.0, 30.0], "amplitude_m": [0.0, 0.05], "frequency_hz": [0.8, 0.8]}
    for wave in (track, "wave-a0.10-f1.00"):  # a sea that changes, a condition by name
        with pytest.warns(RuntimeWarning, match="depth_std_m left at the default"):
            assert "depth_std_m" not in calibrate(log.replace(metadata={"wave": wave})).estimated
