"""SO(3) / SE_2(3) closed forms against independent references: scipy's rotation vectors, the
5x5 matrix exponential and logarithm, and the adjoint's defining identity."""

import math

import numpy as np
import pytest
from scipy.linalg import expm, logm
from scipy.spatial.transform import Rotation

from undertow.peers.lie import (
    hat,
    se23_adjoint,
    se23_compose,
    se23_exp,
    se23_inverse,
    se23_log,
    se23_matrix,
    so3_exp,
    so3_left_jacobian,
    so3_left_jacobian_inv,
    so3_log,
)


def _wedge(xi):
    """The 5x5 Lie algebra matrix of xi = (phi, nu, rho)."""
    M = np.zeros((5, 5))
    M[:3, :3] = hat(xi[:3])
    M[:3, 3] = xi[3:6]
    M[:3, 4] = xi[6:9]
    return M


@pytest.mark.parametrize("scale", [1e-9, 1e-3, 0.5, 2.0, np.pi - 1e-6])
def test_so3_exp_and_log_match_scipy_rotation_vectors(scale):
    rng = np.random.default_rng(1)
    for _ in range(5):
        axis = rng.normal(size=3)
        phi = scale * axis / np.linalg.norm(axis)
        R = so3_exp(phi)
        assert np.allclose(R, Rotation.from_rotvec(phi).as_matrix(), atol=1e-12)
        assert np.allclose(so3_log(R), Rotation.from_matrix(R).as_rotvec(), atol=1e-7)


@pytest.mark.parametrize("scale", [1e-8, 0.3, 2.5])
def test_se23_exp_is_the_matrix_exponential_and_log_inverts_it(scale):
    rng = np.random.default_rng(2)
    for _ in range(5):
        xi = rng.normal(size=9) * scale
        xi[:3] *= min(1.0, 3.0 / np.linalg.norm(xi[:3]))  # |phi| < pi: log's principal branch
        R, v, p = se23_exp(xi)
        assert np.allclose(se23_matrix(R, v, p), expm(_wedge(xi)), atol=1e-12)
        assert np.allclose(se23_log(R, v, p), xi, atol=1e-9 * max(scale, 1.0))
    xi = rng.normal(size=9) * 0.3  # and log against the matrix logarithm
    assert np.allclose(_wedge(se23_log(*se23_exp(xi))), np.real(logm(expm(_wedge(xi)))), atol=1e-9)


def test_left_jacobian_and_its_inverse_are_inverses_and_match_the_series():
    rng = np.random.default_rng(3)
    for scale in (1e-8, 0.1, 1.5):
        phi = rng.normal(size=3) * scale
        J = so3_left_jacobian(phi)
        assert np.allclose(J @ so3_left_jacobian_inv(phi), np.eye(3), atol=1e-12)
        # J = sum_k W^k / (k + 1)!
        W, S, term = hat(phi), np.zeros((3, 3)), np.eye(3)
        for k in range(30):
            S += term / math.factorial(k + 1)
            term = term @ W
        assert np.allclose(J, S, atol=1e-12)


def test_adjoint_satisfies_its_defining_identity_and_inverse_compose():
    rng = np.random.default_rng(4)
    X = se23_exp(rng.normal(size=9))
    xi = rng.normal(size=9) * 0.7
    Xm = se23_matrix(*X)
    left = Xm @ se23_matrix(*se23_exp(xi)) @ np.linalg.inv(Xm)
    right = se23_matrix(*se23_exp(se23_adjoint(*X) @ xi))
    assert np.allclose(left, right, atol=1e-12)
    assert np.allclose(se23_matrix(*se23_inverse(*X)), np.linalg.inv(Xm), atol=1e-12)
    Y = se23_exp(rng.normal(size=9))
    assert np.allclose(se23_matrix(*se23_compose(*X, *Y)), Xm @ se23_matrix(*Y), atol=1e-12)
    Xi = se23_inverse(*X)
    assert np.allclose(se23_adjoint(*Xi), np.linalg.inv(se23_adjoint(*X)), atol=1e-12)
