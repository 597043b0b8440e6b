"""The rules of ArduSub's external navigation against closed forms and pymavlink's own
definitions (the MAVLink enums, message field types)."""

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from scipy.spatial.transform import Rotation

from undertow.sim.robot import autopilot_rules as rules


def test_the_frame_pair_is_mavlinks_local_frd_and_body_frd():
    assert rules.FRAME_LOCAL_FRD == mavlink2.MAV_FRAME_LOCAL_FRD
    assert rules.FRAME_BODY_FRD == mavlink2.MAV_FRAME_BODY_FRD


def test_status_flags_are_mavlinks_ekf_status_flags():
    for name in (
        "EKF_ATTITUDE",
        "EKF_VELOCITY_HORIZ",
        "EKF_VELOCITY_VERT",
        "EKF_POS_HORIZ_REL",
        "EKF_POS_HORIZ_ABS",
        "EKF_POS_VERT_ABS",
        "EKF_CONST_POS_MODE",
        "EKF_PRED_POS_HORIZ_REL",
        "EKF_PRED_POS_HORIZ_ABS",
        "EKF_UNINITIALIZED",
    ):
        assert getattr(rules, name) == getattr(mavlink2, name), name


@pytest.mark.parametrize("variances", [(0.25, 0.25, 0.25), (0.01, 0.04, 0.09), (2.0, 0.0, 1.0)])
def test_the_two_covariance_reductions(variances):
    cov = [0.0] * 21
    # the upper triangle of a 6x6 matrix, row-major: diagonal terms at 0, 6, 11, 15, 18, 20
    diag_index = [sum(6 - r for r in range(i)) for i in range(6)]
    assert diag_index == [0, 6, 11, 15, 18, 20]
    for i, v in zip(diag_index[:3], variances, strict=True):
        cov[i] = v
    for i in diag_index[3:]:
        cov[i] = 0.01
    a, b, c = variances
    pos, ang = rules.reduce_covariance(cov, "cbrt")
    assert pos == pytest.approx((a * a + b * b + c * c) ** (1 / 3))
    assert ang == pytest.approx((3 * 0.01**2) ** (1 / 3))
    pos, ang = rules.reduce_covariance(cov, "sqrt")
    assert pos == pytest.approx(math.sqrt(a + b + c))
    assert ang == pytest.approx(math.sqrt(0.03))


def test_a_nan_covariance_means_no_error_and_the_floors_apply():
    cov = [math.nan] * 21
    assert rules.reduce_covariance(cov, "cbrt") == (0.0, 0.0)
    assert rules.clamp_errors(0.0, 0.0, 0.2, 0.3) == (0.2, 0.3)
    assert rules.clamp_errors(500.0, 7.0, 0.2, 0.3) == (100.0, 1.5)
    assert rules.clamp_errors(0.7, 0.5, 0.2, 0.3) == (0.7, 0.5)
    with pytest.raises(ValueError):
        rules.reduce_covariance(cov, "cube")


@pytest.mark.parametrize("rule", rules.COVARIANCE_RULES)
@pytest.mark.parametrize("pos_err, ang_err", [(0.3, 0.05), (1.7, 0.4)])
def test_covariance_for_error_inverts_the_reduction(rule, pos_err, ang_err):
    cov = rules.covariance_for_error(pos_err, ang_err, rule)
    assert rules.reduce_covariance(cov, rule) == pytest.approx((pos_err, ang_err))


def test_body_odometry_error_interpolates_between_the_two_limits():
    assert rules.body_odometry_error(100, 0.1, 0.9) == pytest.approx(0.1)
    assert rules.body_odometry_error(0, 0.1, 0.9) == pytest.approx(0.9)
    assert rules.body_odometry_error(25, 0.1, 0.9) == pytest.approx(0.1 + 0.8 * 0.75)


def test_quaternion_rotate_matches_scipy():
    rng = np.random.default_rng(3)
    for _ in range(20):
        r = Rotation.random(random_state=rng)
        x, y, z, w = r.as_quat()
        v = rng.normal(size=3)
        assert rules.quaternion_rotate((w, x, y, z), v) == pytest.approx(r.apply(v), abs=1e-12)


def test_valid_origin():
    assert rules.valid_origin(470_000_000, 80_000_000, 0)
    assert not rules.valid_origin(910_000_000, 0, 0)
    assert not rules.valid_origin(0, 1_810_000_000, 0)
    assert not rules.valid_origin(0, 0, 0)
    assert not rules.valid_origin(10, 10, 90_000_000)


def test_param_values_are_stored_as_their_type():
    assert rules.param_value(2, 6.9) == 6.0
    assert rules.param_value(2, 300) == 127.0
    assert rules.param_value(4, -40000) == -32768.0
    assert rules.param_value(9, 0.1) == float(np.float32(0.1))


def test_the_parameter_table_uses_mavlinks_types():
    for name, spec in rules.PARAMS.items():
        assert len(name) <= 16, name
        assert spec.mav_type in (
            mavlink2.MAV_PARAM_TYPE_INT8,
            mavlink2.MAV_PARAM_TYPE_INT16,
            mavlink2.MAV_PARAM_TYPE_INT32,
            mavlink2.MAV_PARAM_TYPE_REAL32,
        )
