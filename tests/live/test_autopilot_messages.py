"""The messages undertow sends, packed and parsed back by pymavlink (the peer library), checked
against the state they come from: frames, quaternion order, the frame turn, the covariance
layout, and VISION_POSITION_DELTA integrated by undertow's own MAVLink reader (and scipy's
rotation vectors) back into the attitude change."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as m
from scipy.spatial.transform import Rotation

from undertow.io.mavlink import MavlinkMapper
from undertow.live.autopilot import covariance as cov
from undertow.live.autopilot import messages
from undertow.rotations import rpy_to_matrix


def _roundtrip(msg):
    sender = m.MAVLink(None, srcSystem=255, srcComponent=197)
    parser = m.MAVLink(None)
    (out,) = parser.parse_buffer(bytes(msg.pack(sender)))
    assert out.get_srcComponent() == 197
    return out


def _state(seed: int = 0):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=18)
    x[3:5] *= 0.2  # moderate roll and pitch
    A = rng.normal(size=(18, 18)) * 0.1
    return x, A @ A.T + 0.01 * np.eye(18)


def test_odometry_frames_pose_and_covariances():
    x, P = _state()
    dpsi, k = 0.4, 2.0
    msg = _roundtrip(messages.odometry(123_456_789, x, P, yaw_offset_rad=dpsi, inflation=k,
                                       reset_counter=258, quality=77))  # fmt: skip
    assert (msg.frame_id, msg.child_frame_id) == (20, 12)  # MAV_FRAME_LOCAL_FRD, BODY_FRD
    assert msg.time_usec == 123_456_789 and msg.reset_counter == 2 and msg.quality == 77
    assert msg.estimator_type == m.MAV_ESTIMATOR_TYPE_VIO
    c, s = math.cos(dpsi), math.sin(dpsi)
    turned = [c * x[0] - s * x[1], s * x[0] + c * x[1], x[2]]
    np.testing.assert_allclose([msg.x, msg.y, msg.z], turned, rtol=1e-6)
    # q = (w, x, y, z); scipy's quaternion is (x, y, z, w) of the same rotation
    expected = Rotation.from_euler("ZYX", [x[5] + dpsi, x[4], x[3]]).as_quat()
    q = np.array(msg.q)
    assert abs(abs(np.dot(q, np.roll(expected, 1))) - 1.0) < 1e-6
    np.testing.assert_allclose([msg.vx, msg.vy, msg.vz, msg.rollspeed, msg.pitchspeed,
                                msg.yawspeed], x[6:12], rtol=1e-6)  # fmt: skip
    C = cov.from_upper_triangle(msg.pose_covariance)
    np.testing.assert_allclose(C, cov.pose_covariance(P, dpsi, k), rtol=1e-6, atol=1e-9)
    V = cov.from_upper_triangle(msg.velocity_covariance)
    np.testing.assert_allclose(V, k * P[6:12, 6:12], rtol=1e-6, atol=1e-9)


def test_vision_position_estimate_carries_the_same_content():
    x, P = _state(1)
    msg = _roundtrip(messages.vision_position_estimate(5, x, P, yaw_offset_rad=-1.0,
                                                       inflation=3.0, reset_counter=9))  # fmt: skip
    odo = messages.odometry(5, x, P, yaw_offset_rad=-1.0, inflation=3.0)
    assert (msg.usec, msg.reset_counter) == (5, 9)
    np.testing.assert_allclose([msg.x, msg.y, msg.z], [odo.x, odo.y, odo.z], rtol=1e-6)
    assert msg.yaw == pytest.approx(math.remainder(x[5] - 1.0, 2 * math.pi), abs=1e-6)
    np.testing.assert_allclose(msg.covariance, odo.pose_covariance, rtol=1e-6)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 0.3, 2.0, math.pi - 1e-6, math.pi])
def test_rotation_vector_is_scipys(angle):
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    R = Rotation.from_rotvec(angle * axis).as_matrix()
    a = messages.rotation_vector(R)
    np.testing.assert_allclose(Rotation.from_rotvec(a).as_matrix(), R, atol=1e-7)
    assert np.linalg.norm(a) == pytest.approx(angle, abs=1e-7)


def test_position_delta_integrates_back_into_the_attitude_change():
    xa, P = _state(2)
    xb = xa.copy()
    xb[3:6] += [0.05, -0.03, 0.4]  # the body turned between the two states
    dt = 0.1
    msg = _roundtrip(messages.vision_position_delta(7, dt, xa, xb, 88.0))
    assert msg.time_delta_usec == 100_000 and msg.confidence == pytest.approx(88.0)
    np.testing.assert_allclose(msg.position_delta, xb[6:9] * dt, rtol=1e-6)
    # undertow's reader composes R_k = R_(k-1) Exp(angle_delta) from the first message's frame
    mapper = MavlinkMapper()
    (_, dr) = mapper.records(msg, 1.0)
    R = rpy_to_matrix(dr.data["orientation"])
    np.testing.assert_allclose(rpy_to_matrix(xa[3:6]) @ R, rpy_to_matrix(xb[3:6]), atol=1e-6)


def test_autopilot_pose_turns_only_the_yaw():
    x = np.zeros(18)
    x[:6] = [1.0, 0.0, 2.0, 0.1, 0.2, 3.0]
    p, rpy = messages.autopilot_pose(x, 0.5)
    np.testing.assert_allclose(p, [math.cos(0.5), math.sin(0.5), 2.0])
    R = rpy_to_matrix(np.array(rpy))
    np.testing.assert_allclose(R, cov.rotate_z(0.5) @ rpy_to_matrix(x[3:6]), atol=1e-12)
