"""Localizer on synthetic logs generated here from a known truth (closed-form kinematics)."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import ConfigError, MissingStreamError
from undertow.estimation import Localizer
from undertow.log import G0, P_ATM, DeadReckoning, Dvl, Imu, Log, Pressure
from undertow.robot import Mounting
from undertow.rotations import rpy_to_matrix, wrap_angle

RHO = 997.0


def truth(t, u=0.0, r=0.0, psi0=0.0, depth=1.0):
    """Level vehicle, body velocity (u, 0, 0), yaw rate r: closed-form pose (circle or line)."""
    psi = psi0 + r * t
    if abs(r) > 0:
        x = u / r * (np.sin(psi) - np.sin(psi0))
        y = -u / r * (np.cos(psi) - np.cos(psi0))
    else:
        x, y = u * t * np.cos(psi0), u * t * np.sin(psi0)
    pos = np.stack([x, y, np.full_like(t, depth)], axis=1)
    rpy = np.stack([np.zeros_like(t), np.zeros_like(t), wrap_angle(psi)], axis=1)
    return pos, rpy


def make_log(duration=30.0, u=0.0, r=0.0, psi0=0.0, depth=1.0, imu_bias=(0, 0, 0),
             dr_bias_rate=(0, 0, 0), seed=0, mounting=None):  # fmt: skip
    """IMU 100 Hz, DVL 8 Hz, DR 5 Hz, baro 10 Hz following the paper's measurement models."""
    rng = np.random.default_rng(seed)
    mounting = mounting or Mounting()
    omega = np.array([0.0, 0.0, r])
    v = np.array([u, 0.0, 0.0])
    ti = np.arange(0, duration, 0.01)
    imu = Imu(ti, omega + np.asarray(imu_bias) + rng.normal(0, 0.003, (ti.size, 3)))
    td = np.arange(0, duration, 0.125)
    Rd = mounting.dvl.rotation_matrix()
    v_dvl = Rd.T @ (v + np.cross(omega, mounting.dvl.translation))
    dvl = Dvl.from_velocity(td, v_dvl + rng.normal(0, 0.005, (td.size, 3)))
    tr = np.arange(0, duration, 0.2)
    _, rpy = truth(tr, u, r, psi0, depth)
    meas = rpy + np.outer(tr, dr_bias_rate) + rng.normal(0, 0.003, (tr.size, 3))
    dr = DeadReckoning(tr, np.zeros((tr.size, 3)), wrap_angle(meas))
    tp = np.arange(0, duration, 0.1)
    pos, rpy_p = truth(tp, u, r, psi0, depth)
    z_bar = pos[:, 2] + (rpy_to_matrix(rpy_p) @ np.asarray(mounting.barometer.translation))[:, 2]
    p = P_ATM + RHO * G0 * (z_bar + rng.normal(0, 0.005, tp.size))
    return Log(imu=imu, dvl=dvl, dead_reckoning=dr, pressure=Pressure(tp, p), mounting=mounting)


def test_static_vehicle_converges():
    log = make_log(duration=20.0, depth=2.0)
    loc = Localizer("proposed")
    traj = loc.run(log)
    assert np.all(np.isfinite(traj.x)) and np.all(np.isfinite(traj.P))
    var0, var1 = np.square(loc.config.initial_std), np.diagonal(traj.P[-1])
    assert np.all(var1[2:12] < var0[2:12])  # x, y are not observed: they may only grow
    err = traj.x[-1, :12] - np.r_[0, 0, 2.0, 0, 0, 0, np.zeros(6)]
    assert np.all(np.abs(err[2:]) < 3 * np.sqrt(var1[2:12]) + 1e-3)
    assert np.linalg.norm(traj.x[-1, 6:9]) < 0.01
    assert traj.metadata["counts"]["used_dvl"] == len(log.dvl)


def test_yaw_crosses_pi_continuously():
    psi0, r, u = np.pi - 0.3, 0.1, 0.3
    log = make_log(duration=8.0, u=u, r=r, psi0=psi0)
    traj = Localizer("proposed").run(log)
    pos, rpy = truth(traj.t, u, r, psi0)
    yaw_err = wrap_angle(traj.x[:, 5] - rpy[:, 2])
    assert np.max(np.abs(yaw_err)) < 0.03
    assert np.max(np.abs(wrap_angle(np.diff(traj.x[:, 5])))) < 0.02  # no jumps at the cut
    assert np.any(traj.x[:, 5] < -2.9) and np.any(traj.x[:, 5] > 2.9)  # really crossed
    assert np.max(np.linalg.norm(traj.x[:, :2] - pos[:, :2], axis=1)) < 0.1


def test_gyro_bias_recovered_within_3_sigma():
    b = np.array([0.01, -0.008, 0.015])
    traj = Localizer("be").run(make_log(duration=60.0, u=0.2, imu_bias=b))
    est, sd = traj.x[-1, 15:18], np.sqrt(np.diagonal(traj.P[-1])[15:18])
    assert np.all(np.abs(est - b) < 3 * sd)
    assert np.all(np.abs(est - b) < 0.003)


def test_dr_yaw_bias_drift_recovered_and_baseline_is_not():
    d = np.array([0.0, 0.0, 0.002])  # rad/s drift of the DR yaw (the DVL gyro's bias)
    log = make_log(duration=60.0, u=0.2, dr_bias_rate=d)
    std = [0.01] * 3 + [0.05] * 3 + [0.1] * 3 + [0.05] * 3 + [0.005] * 3 + [1e-4] * 3
    be = Localizer("be", initial_std=std, dr_bias_drift_rad_s=tuple(d)).run(log)
    base = Localizer("baseline", initial_std=std, dr_bias_drift_rad_s=tuple(d)).run(log)
    est, sd = be.x[-1, 14], np.sqrt(be.P[-1, 14, 14])
    assert abs(est - d[2] * be.t[-1]) < 3 * sd
    assert abs(be.x[-1, 5]) < 0.02  # true yaw is 0
    assert abs(base.x[-1, 5]) > 0.08  # the baseline follows the drifting DR yaw
    assert np.all(base.x[:, 12:18] == 0.0)


def test_variants_differ_as_designed():
    log = make_log(duration=10.0, u=0.3, imu_bias=(0, 0, 0.01))
    runs = {v: Localizer(v, wave="wave-a0.10-f0.75").run(log) for v in ("baseline", "be", "an",
                                                                         "proposed")}  # fmt: skip
    for v in ("baseline", "an"):
        assert np.all(runs[v].x[:, 12:18] == 0.0)
    assert np.any(runs["be"].x[:, 17] != 0.0)
    assert runs["baseline"].metadata["wave_noise"] is None
    assert runs["an"].metadata["wave_noise"]["dvl_std"] == [0.040, 0.010, 0.003]
    # added noise weighs the DVL less: larger velocity variance
    assert runs["an"].P[-1, 6, 6] > runs["baseline"].P[-1, 6, 6]
    assert runs["proposed"].P[-1, 6, 6] > runs["be"].P[-1, 6, 6]


def test_adversarial_run_never_nan():
    log = make_log(duration=30.0, u=0.3, r=0.05)
    rng = np.random.default_rng(3)
    gap = {n: s.select((s.t < 10) | (s.t > 20)) for n, s in log.streams().items()}  # 10 s gap
    log = log.replace(**gap)
    imu, dvl, dr = log.imu, log.dvl, log.dead_reckoning
    w = np.array(imu.angular_velocity)
    w[rng.integers(0, w.shape[0], 50)] = np.nan
    w[rng.integers(0, w.shape[0], 50)] = 1e6
    v = np.array(dvl.velocity)
    v[::7] = np.nan
    v[::11] = -1e5
    valid = np.ones(len(dvl), bool)
    valid[::5] = False
    cov = np.tile(np.eye(3) * 1e-30, (len(dvl), 1, 1))  # tiny R
    o = np.array(dr.orientation)
    o[::3] = np.nan
    o[::4] = 1e9
    bad = Log(
        imu=Imu(imu.t, w),
        dvl=Dvl.from_velocity(dvl.t, v, valid=valid, covariance=cov),
        dead_reckoning=DeadReckoning(dr.t, dr.position, o),
        pressure=Pressure(log.pressure.t[log.pressure.t < 25], log.pressure.pressure[
            log.pressure.t < 25]),
    )  # fmt: skip
    no_envelope = {"gyro_max_rate_rad_s": None, "dvl_max_speed_m_s": None}
    for gate in (None, 0.999):
        traj = Localizer("proposed", gate_probability=gate, max_dt_s=0.5, **no_envelope).run(bad)
        assert np.all(np.isfinite(traj.x)) and np.all(np.isfinite(traj.P))
        c = traj.metadata["counts"]
        assert c["rejected_imu"] > 0 and c["rejected_dvl_invalid"] > 0
        assert c["rejected_dvl_nonfinite"] > 0 and c["rejected_dead_reckoning"] > 0
        assert c["dt_capped"] > 0
        assert np.all(np.diagonal(traj.P, axis1=1, axis2=2) > 0)
    assert c["gated_imu"] > 0 and c["gated_dvl"] > 0
    # by default the envelopes reject the spikes before the filter: 50 rows at 1e6 rad/s
    c = Localizer("proposed", max_dt_s=0.5).run(bad).metadata["counts"]
    assert 0 < c["rejected_imu_range"] <= 50 and c["rejected_dvl_speed"] > 0


def test_output_rate_missing_stream_and_bad_config():
    log = make_log(duration=5.0)
    traj = Localizer("baseline", output_rate_hz=2.0).run(log)
    np.testing.assert_allclose(traj.t, np.arange(0, 5.0, 0.5))
    with pytest.raises(MissingStreamError):  # no orientation source: neither IMU nor DR
        Localizer().run(log.replace(imu=None, dead_reckoning=None))
    with pytest.raises(ConfigError):
        Localizer(variant="fancy")
    with pytest.raises(ConfigError):
        Localizer(alpha=1e-3)


def test_dvl_scale_factor_and_wave_from_log_metadata():
    log = make_log(duration=10.0, u=0.3).replace(metadata={"wave": "wave-a0.10-f1.00"})
    traj = Localizer("proposed", dvl_scale_factor=1.5).run(log)
    assert abs(traj.x[-1, 6] - 0.2) < 0.02  # v_used = v_measured / scale
    assert traj.metadata["wave_noise"]["condition"] == "wave-a0.10-f1.00"


def test_dr_orientation_in_the_dvl_frame_is_rotated_through_the_mounting():
    """DR reports the DVL's attitude, R_dr = R_body R_mount. For a level vehicle at yaw psi and a
    DVL mounted at pitch b, yaw a: R_dr = Rz(psi) Rz(a) Ry(b), i.e. DR (roll, pitch, yaw) =
    (0, b, psi + a) in closed form; dr_orientation_frame="dvl" must give back (0, 0, psi)."""
    a, b = 0.3, 0.1
    mounting = Mounting().updated({"dvl": {"rotation": [0.0, b, a]}})
    psi0, r = 2.8, 0.05
    log = make_log(duration=20.0, u=0.2, r=r, psi0=psi0, mounting=mounting)
    dr = log.dead_reckoning
    rpy_dvl = np.array(dr.orientation) + [0.0, b, a]  # the truth's (0, 0, psi) + noise, moved
    log = log.replace(dead_reckoning=DeadReckoning(dr.t, dr.position, wrap_angle(rpy_dvl)))
    traj = Localizer("baseline", dr_orientation_frame="dvl").run(log)
    _, rpy = truth(traj.t, 0.2, r, psi0)
    err = wrap_angle(traj.x[:, 3:6] - rpy)
    assert np.max(np.abs(err[:, :2])) < 0.01
    assert np.max(np.abs(err[:, 2])) < 0.02  # yaw crosses pi on the way
    np.testing.assert_allclose(wrap_angle(traj.x[0, 3:6] - [0, 0, psi0]), 0, atol=0.01)
    body = Localizer("baseline").run(log)  # read as body attitude: off by the mounting
    assert abs(wrap_angle(body.x[-1, 4] - b)) < 0.02  # the mount pitch taken as attitude


def test_calibrated_gyro_bias_is_the_initial_bias_state():
    """`undertow calibrate`'s IMU gyro bias starts the bias state of be / proposed: with a
    tight initial bias std and no DR, the yaw rate is then right from the start; the baseline
    has no bias states (the paper's definition) and ignores it."""
    from undertow.estimation import localize
    from undertow.estimation.calibration import Calibration

    bias = np.array([0.002, -0.003, 0.02])
    log = make_log(duration=3.0, u=0.2, imu_bias=bias).replace(dead_reckoning=None)
    std = [0.01] * 3 + [0.05] * 3 + [0.1] * 3 + [0.05] * 3 + [0.005] * 3 + [1e-4] * 3
    cal = Calibration(gyro_bias_rad_s=tuple(bias))
    with_cal = localize(log, "be", calibration=cal, initial_std=std)
    without = localize(log, "be", initial_std=std)
    assert with_cal.metadata["config"]["gyro_bias_rad_s"] == pytest.approx(bias)
    np.testing.assert_allclose(with_cal.x[:, 15:18] - bias, 0, atol=3e-4)
    assert abs(np.mean(with_cal.x[10:, 11])) < 0.002  # true yaw rate 0
    assert abs(np.mean(without.x[10:, 11]) - bias[2]) < 0.002  # the bias taken as rotation
    base = localize(log, "baseline", calibration=cal)
    assert np.all(base.x[:, 12:18] == 0.0)
    assert list(base.metadata["config"]["gyro_bias_rad_s"]) == [0.0, 0.0, 0.0]


def test_wave_condition_and_where_it_came_from_are_recorded():
    """Without a wave condition the log's recorded one is used, else calm; config says which."""
    from undertow.estimation.localizer import wave_condition

    log = make_log(duration=3.0)
    assert wave_condition(None, log) == ("calm", "default")
    assert wave_condition("wave-a0.10-f1.00", log) == ("wave-a0.10-f1.00", "given")
    recorded = log.replace(metadata={"wave": {"amplitude_m": 0.1, "frequency_hz": 1.0}})
    assert wave_condition(None, recorded)[1] == "the log's metadata"
    bag = log.replace(metadata={"wave": "wave-a0.10-f1.00", "format": "rosbag", "recorded": {}})
    assert wave_condition(None, bag) == ("wave-a0.10-f1.00", "the bag's sidecar undertow.yaml")
    traj = Localizer("baseline").run(log)
    assert (traj.metadata["wave_condition"], traj.metadata["wave_condition_source"]) == (
        "calm",
        "default",
    )


def test_smoothing_a_decimated_run_is_refused_before_filtering():
    """An empty log would fail in the filter: the option clash must be found first."""
    from undertow.estimation import localize

    with pytest.raises(ConfigError, match="smoothing .* needs the filter output at every"):
        localize(Log(), smooth=True, output_rate_hz=1.0)


def test_calibration_applies_only_what_was_estimated_and_says_so():
    from undertow.estimation import LocalizerConfig
    from undertow.estimation.calibration import Calibration
    from undertow.estimation.localizer import calibration_fields

    cal = Calibration(
        dr_bias_drift_rad_s=(0.0, 0.0, 1e-4),
        dvl_scale_factor=1.02,
        estimated=("dr_bias_drift_rad_s", "dvl_scale_factor"),
        left_at_default={"gyro_bias_rad_s": "the log has no imu stream"},
    )
    with pytest.warns(RuntimeWarning, match=r"gyro_bias_rad_s \(the log has no imu"):
        fields = calibration_fields(cal, LocalizerConfig(variant="proposed"))
    assert fields == {"dvl_scale_factor": 1.02, "dr_bias_drift_rad_s": (0.0, 0.0, 1e-4)}
    # baseline uses no bias parameter: nothing to say
    assert calibration_fields(cal, LocalizerConfig(variant="baseline")) == {
        "dvl_scale_factor": 1.02
    }


def test_explicit_settings_win_over_the_log_and_the_calibration():
    """localize() fills a field from the log or the calibration only when the caller left it
    unset: an explicit start position, scale or density is used as given."""
    from undertow.estimation import localize
    from undertow.estimation.calibration import Calibration
    from undertow.log import GroundTruth

    log = make_log(duration=2.0, u=0.2)
    t = log.imu.t
    gt = GroundTruth(t=t, position=np.tile([5.0, -2.0, 1.0], (t.size, 1)),
                     orientation=np.zeros((t.size, 3)))  # fmt: skip
    log = log.replace(ground_truth=gt, metadata={"water_density_kg_m3": 1025.0})
    cal = Calibration(dvl_scale_factor=1.1)
    filled = localize(log, "baseline", calibration=cal).metadata["config"]
    assert filled["initial_position"] == (5.0, -2.0, 1.0)
    assert filled["water_density_kg_m3"] == 1025.0 and filled["dvl_scale_factor"] == 1.1
    explicit = {"initial_position": (0.0, 0.0, 1.0), "water_density_kg_m3": 997.0,
                "dvl_scale_factor": 1.0}  # fmt: skip
    given = localize(log, "baseline", calibration=cal, **explicit).metadata["config"]
    assert given["initial_position"] == (0.0, 0.0, 1.0)
    assert given["water_density_kg_m3"] == 997.0 and given["dvl_scale_factor"] == 1.0
    origin = localize(log, "baseline", initial_position=None).metadata["config"]
    assert origin["initial_position"] is None


def test_measurement_rows_noise_in_closed_form():
    """The DVL rows' R: the log's covariance scaled by 1 / s^2 and symmetrized (or the
    configured diagonal without one), its diagonal floored at dvl_std_floor_m_s^2, plus the
    wave noise gamma_DVL^2 (proposed); every row's diagonal at least std_floor^2 after the merge,
    the off-diagonal entries untouched."""
    from undertow.estimation.config import LocalizerConfig
    from undertow.estimation.noise import WaveNoise
    from undertow.estimation.rows import dvl_rows, merged_rows

    cfg = LocalizerConfig(variant="proposed", dvl_scale_factor=2.0, dvl_std_floor_m_s=0.01,
                          std_floor=0.05)  # fmt: skip
    t = np.arange(3.0)
    cov = np.array([[[4e-6, 1e-6, 0.0], [3e-6, 1e-2, 0.0], [0.0, 0.0, 1.0]]] * 3)
    cov[2] = np.nan  # no covariance: the configured diagonal
    dvl = Dvl.from_velocity(t, np.zeros((3, 3)), covariance=cov)
    gamma = np.array([0.02, 0.03, 0.04])
    noise = WaveNoise("test", 0.1, 1.0, dvl_std=gamma, dr_std=np.zeros(3), how="node")
    _, kind, z, R, ok = dvl_rows(Log(dvl=dvl), cfg, noise, {}, warn=False)
    scaled = cov[0] / 4.0
    expect = 0.5 * (scaled + scaled.T)
    np.fill_diagonal(expect, np.maximum(np.diag(expect), 0.01**2) + gamma**2)
    np.testing.assert_allclose(R[0], expect, rtol=1e-15, atol=0)
    configured = np.maximum(np.asarray(cfg.dvl_velocity_std_m_s), cfg.std_floor) ** 2
    np.testing.assert_allclose(np.diag(R[2]), np.maximum(configured, 0.01**2) + gamma**2)
    assert ok.all() and np.all(R[2] == np.diag(np.diag(R[2])))
    rows, _ = merged_rows([(t, kind, z, R)], cfg.std_floor**2)
    diagonal = np.einsum("nii->ni", rows["R"])
    np.testing.assert_array_equal(diagonal, np.maximum(np.einsum("nii->ni", R), 0.05**2))
    off = ~np.eye(3, dtype=bool)
    np.testing.assert_array_equal(rows["R"][:, off], R[:, off])
