"""Rotations: the ZYX convention against closed forms and scipy."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from undertow.rotations import (
    matrix_to_quaternion_scalar,
    matrix_to_rpy,
    quaternion_to_rpy,
    quaternion_to_rpy_one,
    rpy_to_matrix,
    rpy_to_quaternion,
    rpy_to_quaternion_scalar,
    wrap_angle,
)

RNG = np.random.default_rng(1)
RPY = np.column_stack(
    [RNG.uniform(-3, 3, 200), RNG.uniform(-1.5, 1.5, 200), RNG.uniform(-3.1, 3.1, 200)]
)


def test_matrix_agrees_with_scipy_extrinsic_xyz():
    expected = Rotation.from_euler("ZYX", RPY[:, ::-1]).as_matrix()
    np.testing.assert_allclose(rpy_to_matrix(RPY), expected, atol=1e-12)


def test_quaternion_agrees_with_scipy_xyzw():
    q = rpy_to_quaternion(RPY)
    ref = Rotation.from_euler("ZYX", RPY[:, ::-1]).as_quat()
    ref = np.where(ref[:, 3:4] < 0, -ref, ref)
    np.testing.assert_allclose(q, ref, atol=1e-12)


def test_scalar_forms_agree_with_scipy():
    """The one-at-a-time forms (live messages): rpy -> quaternion and matrix -> quaternion
    (Shepperd's four branches: rotations near 180 degrees about each axis included) against
    scipy, w >= 0."""
    flips = [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    mats = [*rpy_to_matrix(RPY), *flips, *(f @ rpy_to_matrix([1e-3, -2e-3, 3e-3]) for f in flips)]
    for R in mats:
        ref = Rotation.from_matrix(R).as_quat()
        ref = -ref if ref[3] < 0 else ref
        q = np.array(matrix_to_quaternion_scalar(R))
        assert q[3] >= 0
        # at w = 0 (a half turn) q and -q are both w >= 0: compare the rotations
        np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), R, atol=1e-12)
        if ref[3] > 1e-6:
            np.testing.assert_allclose(q, ref, atol=1e-12)
    for rpy in RPY:
        np.testing.assert_allclose(rpy_to_quaternion_scalar(*rpy), rpy_to_quaternion(rpy),
                                   atol=1e-15)  # fmt: skip


def test_round_trips():
    np.testing.assert_allclose(matrix_to_rpy(rpy_to_matrix(RPY)), RPY, atol=1e-9)
    np.testing.assert_allclose(quaternion_to_rpy(rpy_to_quaternion(RPY)), RPY, atol=1e-9)


def test_yaw_rotates_forward_into_right():
    np.testing.assert_allclose(rpy_to_matrix([0, 0, np.pi / 2]) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_wrap_angle_range():
    a = wrap_angle(np.linspace(-20, 20, 1001))
    assert np.all(a >= -np.pi) and np.all(a < np.pi)
    np.testing.assert_allclose(np.sin(a), np.sin(np.linspace(-20, 20, 1001)), atol=1e-12)


def _bits(a) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    return np.where(np.isnan(a), np.nan, a).view(np.uint64)  # one NaN; signed zeros kept


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # numpy on NaN, infinities, 0 / 0
def test_one_at_a_time_forms_are_numpys_bits():
    """The live recorder writes a quaternion and reads its attitude back one message at a
    time; a replay converts the whole stream with numpy: the scalar forms must give numpy's
    bits, special values included (NaN, infinities, zero and underflowing quaternions)."""
    rng = np.random.default_rng(4)
    q = rng.normal(size=(20000, 4))
    q[::97] = 0.0
    q[::101, 1] = np.nan
    q[::103, 2] = np.inf
    q[::107] *= 1e-200  # squares underflow: numpy divides by a zero norm
    q[::109] *= 1e200
    q[::113, 0] = -0.0
    one = np.array([quaternion_to_rpy_one(row) for row in q])
    assert np.array_equal(_bits(one), _bits(quaternion_to_rpy(q)))
    rpy = rng.uniform(-7.0, 7.0, (20000, 3))
    rpy[::97, 0] = np.nan
    rpy[::89, 2] = -0.0
    scalar = np.array([rpy_to_quaternion_scalar(*row) for row in rpy])
    assert np.array_equal(scalar.view(np.uint64), rpy_to_quaternion(rpy).view(np.uint64))
