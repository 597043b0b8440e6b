"""Solving a graph of Python ``CustomFactor``s in time linear in its size: GTSAM's
Levenberg-Marquardt driven from Python, iSAM2 with its linearization point held, and the batch
solution's marginal covariances from an iSAM2 Bayes tree.

Why: a ``CustomFactor``'s Python error function receives the ``Values`` it is evaluated at, and
pybind11 hands a C++ object over by copy unless a Python object already wraps it
(``type_caster_generic::cast``: ``find_registered_python_instance``, else the ``copy`` policy of
an lvalue argument; pybind11/detail/type_caster_base.h). Inside
``LevenbergMarquardtOptimizer.iterate()`` the Values are the optimizer's own, wrapped by no Python
object, so every callback copies all of them: O(keyframes) per factor, O(keyframes^2) per
iteration (on a 120 s log, 960 keyframes: 3.5 s of CPU per ``iterate()``, where the same
linearize + solve + retract + error from Python take 0.13 s). Values a Python object wraps are
passed as they are. Hence:

- :func:`levenberg_marquardt`: GTSAM's algorithm (gtsam/nonlinear/LevenbergMarquardtOptimizer.cpp,
  ``tryLambda`` with ``useFixedLambdaFactor`` and no diagonal damping) on Python-owned Values.
  Each iteration linearizes at x, solves the damped normal equations
  (J^T J + lambda I) delta = -J^T r, i.e. the linear graph plus sqrt(lambda) I delta = 0 on every
  variable, retracts x' = x (+) delta, and accepts the step when the model fidelity
  rho = (f(x) - f(x')) / (L(0) - L(delta)) exceeds ``min_model_fidelity`` (lambda /= factor),
  else raises lambda (lambda *= factor) and solves again; it stops when the error decreases by
  less than ``relative_tol`` of itself or ``absolute_tol`` (NonlinearOptimizer::checkConvergence).
- :func:`isam2_solver`: iSAM2 and its ``getLinearizationPoint()``, which wraps iSAM2's own
  Values by reference (the same object on each call): kept alive by the caller, iSAM2's callbacks
  receive it uncopied.
- :func:`bayes_tree_marginals`: the marginal covariance of each variable at the solution from an
  iSAM2 Bayes tree eliminated by QR (one update at the solution), as ``gtsam.Marginals`` computes
  them (the inverse of the marginal information), in time linear in the graph: the Cholesky of
  ``gtsam.Marginals`` finds the Hessian of a long log (8 minutes here) indeterminate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gtsam_factors import require_gtsam

#: GTSAM's LevenbergMarquardtParams defaults (lambdaInitial, lambdaFactor, lambdaUpperBound,
#: minModelFidelity) and NonlinearOptimizerParams' absoluteErrorTol
LAMBDA_INITIAL = 1e-5
LAMBDA_FACTOR = 10.0
LAMBDA_UPPER_BOUND = 1e5
MIN_MODEL_FIDELITY = 1e-3
ABSOLUTE_TOLERANCE = 1e-5


@dataclass
class Solution:
    """The optimized values, the iterations done, and the graph's error before and after."""

    values: object
    iterations: int
    initial_error: float
    final_error: float


def levenberg_marquardt(graph, values, *, max_iterations: int = 50,
                        relative_tol: float = 1e-5, absolute_tol: float = ABSOLUTE_TOLERANCE,
                        lambda_initial: float = LAMBDA_INITIAL) -> Solution:  # fmt: skip
    """GTSAM's Levenberg-Marquardt (module doc) of ``graph`` from ``values`` (a gtsam.Values,
    not modified), COLAMD ordering; the linear solves as GTSAM's default (multifrontal,
    Cholesky where it can)."""
    gtsam = require_gtsam()
    ordering = graph.orderingCOLAMD()
    zero = values.zeroVectors()
    dims = [(key, zero.at(key).size) for key in values.keys()]
    x, error = values, graph.error(values)
    initial, lam, iterations = error, lambda_initial, 0
    while iterations < max_iterations and error > 0.0:
        linear = graph.linearize(x)
        x_new, error_new, lam = _try_lambdas(
            gtsam, graph, linear, x, error, lam, ordering, dims, relative_tol
        )
        iterations += 1
        decrease = error - error_new
        x, error, previous = x_new, error_new, error
        if decrease <= relative_tol * previous or decrease <= absolute_tol:
            break
    return Solution(x, iterations, float(initial), float(error))


def _try_lambdas(
    gtsam, graph, linear, x, error: float, lam: float, ordering, dims, relative_tol: float
):
    """One LM iteration's inner loop (LevenbergMarquardtOptimizer::tryLambda): (x', f(x'),
    lambda'), x' = x when no lambda up to the upper bound decreases the error; the search also
    stops at a change below ``relative_tol`` of the error."""
    zero = x.zeroVectors()
    linear_error0 = linear.error(zero)
    while True:
        damped = gtsam.GaussianFactorGraph()
        damped.push_back(linear)
        sqrt_lam = np.sqrt(lam)
        for key, d in dims:
            damped.push_back(gtsam.JacobianFactor(key, sqrt_lam * np.eye(d), np.zeros(d),
                                                  gtsam.noiseModel.Unit.Create(d)))  # fmt: skip
        stop, accepted = False, False
        try:
            delta = damped.optimize(ordering)
        except RuntimeError:  # gtsam's IndeterminantLinearSystemException: more damping
            delta = None
        if delta is not None:
            linear_change = linear_error0 - linear.error(delta)
            if linear_change >= 0.0:
                x_new = x.retract(delta)
                error_new = graph.error(x_new)
                change = error - error_new
                if linear_change > np.finfo(float).eps * linear_error0:
                    accepted = change / linear_change > MIN_MODEL_FIDELITY
                else:
                    accepted = True
                stop = abs(change) < relative_tol * error
        if accepted:
            return x_new, error_new, lam / LAMBDA_FACTOR
        if stop or lam * LAMBDA_FACTOR >= LAMBDA_UPPER_BOUND:
            return x, error, lam
        lam *= LAMBDA_FACTOR


def isam2_solver(params):
    """(iSAM2 of ``params``, its linearization point): keep the second alive as long as the
    solver is updated (module doc)."""
    solver = require_gtsam().ISAM2(params)
    return solver, solver.getLinearizationPoint()


def bayes_tree_marginals(graph, values):
    """An object whose ``marginalCovariance(key)`` is the marginal covariance of ``key`` in
    ``graph`` linearized at ``values`` (module doc: an iSAM2 Bayes tree, QR)."""
    gtsam = require_gtsam()
    params = gtsam.ISAM2Params()
    params.setFactorization("QR")
    solver, point = isam2_solver(params)
    solver.update(graph, values)
    del point
    return solver
