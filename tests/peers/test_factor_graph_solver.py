"""The factor graph's solvers (undertow.peers.gtsam_solve) against GTSAM's own: the Python-driven
Levenberg-Marquardt reaches gtsam.LevenbergMarquardtOptimizer's optimum in as many iterations,
the Bayes-tree marginals are gtsam.Marginals', and no Python factor is handed a copy of the
Values (the copies made GTSAM's loop quadratic in the log)."""

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from undertow.peers.gtsam_factors import depth_factor, dr_factor, dvl_factor  # noqa: E402
from undertow.peers.gtsam_solve import (  # noqa: E402
    bayes_tree_marginals,
    isam2_solver,
    levenberg_marquardt,
)
from undertow.rotations import rpy_to_matrix  # noqa: E402

X, V = gtsam.symbol_shorthand.X, gtsam.symbol_shorthand.V
N = 15


def _graph(seed=0):
    """A turning vehicle: DVL, depth and DR factors at each keyframe, odometry between them, a
    prior on the first; the initial values off by about 0.2 rad and 0.3 m."""
    rng = np.random.default_rng(seed)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    unit = gtsam.noiseModel.Isotropic.Sigma
    poses = [gtsam.Pose3(gtsam.Rot3(rpy_to_matrix([0.0, 0.0, 0.2 * k])), [0.5 * k, 0.1 * k, 1.0])
             for k in range(N)]  # fmt: skip
    for k, pose in enumerate(poses):
        R = pose.rotation().matrix()
        factors = [
            dvl_factor(X(k), V(k), [0.5, 0.0, 0.0] + rng.normal(0, 0.01, 3), 1e-4 * np.eye(3)),
            depth_factor(X(k), V(k), 0.8 + rng.normal(0, 0.01), 0.01, [0.1, 0.0, -0.2], 0.05),
            dr_factor(X(k), None, [0.0, 0.0, 0.2 * k] + rng.normal(0, 0.01, 3),
                      1e-4 * np.eye(3), np.eye(3)),
        ]  # fmt: skip
        for factor in factors:
            graph.add(factor)
        if k:
            graph.add(gtsam.BetweenFactorPose3(X(k - 1), X(k), poses[k - 1].between(pose),
                                               unit(6, 0.05)))  # fmt: skip
        off = gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(0, 0.2, 3)), rng.normal(0, 0.3, 3))
        values.insert(X(k), pose.compose(off))
        values.insert(V(k), R @ [0.5, 0.0, 0.0] + rng.normal(0, 0.1, 3))
    graph.add(gtsam.PriorFactorPose3(X(0), poses[0], unit(6, 0.01)))
    return graph, values


def _spy(seen, k):
    """A Python factor (a weak prior on V(k)) keeping each Values it is evaluated at."""

    def error(this, values, H):
        seen.append(values)
        if H is not None:
            H[0] = np.eye(3)
        return np.asarray(values.atVector(V(k))) - [0.5, 0.0, 0.0]

    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(3, 10.0), [V(k)], error)


def test_levenberg_marquardt_reaches_gtsams_optimum_in_as_many_iterations():
    graph, values = _graph()
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-6)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    expected = optimizer.optimize()
    solution = levenberg_marquardt(graph, values, relative_tol=1e-6)
    assert solution.iterations == optimizer.iterations() > 1
    assert solution.initial_error == pytest.approx(graph.error(values))
    assert solution.final_error == pytest.approx(graph.error(expected), rel=1e-9)
    assert solution.final_error < 1e-2 * solution.initial_error
    for k in range(N):
        assert solution.values.atPose3(X(k)).equals(expected.atPose3(X(k)), 1e-9)
        np.testing.assert_allclose(solution.values.atVector(V(k)), expected.atVector(V(k)),
                                   atol=1e-9)  # fmt: skip


def test_the_bayes_tree_marginals_are_gtsams():
    graph, values = _graph()
    solution = levenberg_marquardt(graph, values).values
    marginals, tree = gtsam.Marginals(graph, solution), bayes_tree_marginals(graph, solution)
    for key in (X(0), X(N // 2), X(N - 1), V(0), V(N - 1)):
        expected = marginals.marginalCovariance(key)
        np.testing.assert_allclose(tree.marginalCovariance(key), expected,
                                   rtol=1e-7, atol=1e-9 * np.abs(expected).max())  # fmt: skip


def test_no_python_factor_is_handed_a_copy_of_the_values():
    seen = []
    graph, values = _graph()
    for k in range(N):
        graph.add(_spy(seen, k))
    solution = levenberg_marquardt(graph, values)
    # one Values per point the loop evaluates (the start, each step tried): not one per call
    # (the objects are kept alive in ``seen``, so copies would all be distinct)
    distinct = len({id(v) for v in seen})
    assert distinct <= 2 + 2 * solution.iterations
    assert len(seen) >= N * distinct
    seen.clear()
    solver, point = isam2_solver(gtsam.ISAM2Params())
    solver.update(graph, values)
    solver.update()
    assert seen and all(v is point for v in seen)
