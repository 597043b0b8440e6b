"""The factor graph's custom factors: each analytic Jacobian (what GTSAM linearizes with) against
central differences of the factor's own error on GTSAM's manifold (Values.retract), at random
states; and the factors' errors against their equations at a known state."""

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from undertow.peers.gtsam_factors import (  # noqa: E402
    depth_factor,
    dr_factor,
    dvl_factor,
    so3_exp,
)
from undertow.rotations import matrix_to_rpy, rpy_to_matrix  # noqa: E402

X, V, D = gtsam.symbol_shorthand.X, gtsam.symbol_shorthand.V, gtsam.symbol_shorthand.D


def _values(rng, rpy=None):
    values = gtsam.Values()
    rpy = rng.uniform(-0.6, 0.6, 3) if rpy is None else rpy
    R = gtsam.Rot3(rpy_to_matrix(rpy))
    values.insert(X(0), gtsam.Pose3(R, rng.normal(0, 3, 3)))
    values.insert(V(0), rng.normal(0, 0.5, 3))
    values.insert(D(0), rng.normal(0, 0.05, 3))
    return values


def _dims(values, keys):
    return [6 if k == X(0) else 3 for k in keys]


def _numerical_jacobian(factor, values, step=1e-6):
    """d(whitened error)/d(tangent) by central differences, columns in the factor's key order."""
    keys = list(factor.keys())
    cols = []
    for key, dim in zip(keys, _dims(values, keys), strict=True):
        for j in range(dim):
            errors = []
            for sign in (1.0, -1.0):
                delta = gtsam.VectorValues()
                for k, d in zip(keys, _dims(values, keys), strict=True):
                    v = np.zeros(d)
                    if k == key:
                        v[j] = sign * step
                    delta.insert(k, v)
                errors.append(factor.whitenedError(values.retract(delta)))
            cols.append((errors[0] - errors[1]) / (2 * step))
    return np.column_stack(cols)


def _check(factor, values):
    A, b = factor.linearize(values).jacobian()
    np.testing.assert_allclose(A, _numerical_jacobian(factor, values), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(-b, factor.whitenedError(values), atol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_the_dvl_factor_jacobians_match_numerical_derivatives(seed):
    rng = np.random.default_rng(seed)
    cov = np.diag(rng.uniform(1e-4, 4e-4, 3))
    _check(dvl_factor(X(0), V(0), rng.normal(0, 0.3, 3), cov), _values(rng))


@pytest.mark.parametrize("seed", range(3))
def test_the_depth_factor_jacobians_match_numerical_derivatives(seed):
    rng = np.random.default_rng(seed)
    factor = depth_factor(X(0), V(0), 2.0, 0.01, rng.normal(0, 0.3, 3), rng.uniform(-0.1, 0.1))
    _check(factor, _values(rng))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("with_bias", [True, False])
def test_the_dr_factor_jacobians_match_numerical_derivatives(seed, with_bias):
    rng = np.random.default_rng(seed)
    E = so3_exp(rng.normal(0, 0.02, 3))
    values = _values(rng)
    z = matrix_to_rpy(values.atPose3(X(0)).rotation().matrix()) + rng.normal(0, 0.01, 3)
    factor = dr_factor(X(0), D(0) if with_bias else None, z, np.eye(3) * 1e-4, E,
                       held_bias=np.full(3, 0.01))  # fmt: skip
    _check(factor, values)


def test_the_factors_errors_follow_their_equations():
    """At a known state: DVL R^T v - u, depth z + v_z dt + (R r)_z - d, DR rpy(R E) + b - z."""
    rng = np.random.default_rng(7)
    rpy = np.array([0.1, -0.2, 2.0])
    values = _values(rng, rpy)
    R = rpy_to_matrix(rpy)
    p, v, b = values.atPose3(X(0)).translation(), values.atVector(V(0)), values.atVector(D(0))
    u, r = np.array([0.3, 0.0, 0.1]), np.array([0.1, 0.2, 0.3])
    e = dvl_factor(X(0), V(0), u, np.eye(3)).unwhitenedError(values)
    np.testing.assert_allclose(e, R.T @ v - u, atol=1e-12)
    e = depth_factor(X(0), V(0), 1.5, 1.0, r, 0.05).unwhitenedError(values)
    np.testing.assert_allclose(e, [p[2] + 0.05 * v[2] + (R @ r)[2] - 1.5], atol=1e-12)
    e = dr_factor(X(0), D(0), rpy, np.eye(3), np.eye(3)).unwhitenedError(values)
    np.testing.assert_allclose(e, b, atol=1e-12)
