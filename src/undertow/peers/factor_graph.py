"""Factor-graph peers on GTSAM: a batch smoother (Levenberg-Marquardt over the whole log) and the
same graph solved incrementally (iSAM2, Kaess et al., "iSAM2: Incremental smoothing and mapping
using the Bayes tree", IJRR 2012), the design of TURTLMap (Song et al., IROS 2024: GTSAM, IMU
preintegration and a DVL factor on a BlueROV2 with an A50).

Both read the UKF's sensors and noise (:func:`undertow.peers.inputs.peer_inputs`: the same
config, calibration, wave noise and initial state) plus **the accelerometer**, which the UKF does
not use (IMU preintegration needs it; a log without it is refused). The graph, its factors and
their equations: :mod:`undertow.peers.graph` and :mod:`undertow.peers.gtsam_factors`.

- :func:`factor_graph`: the whole graph optimized by GTSAM's Levenberg-Marquardt from a causal
  initial guess; each keyframe's marginal covariances (the pose's 6 x 6, the velocity's and the
  biases') from the solution's Bayes tree: a smoother, every state informed by the whole log.
  Both in time linear in the log (:mod:`.gtsam_solve`: GTSAM's own optimizer loop would copy
  all the Values at each Python factor's call).
- :func:`isam2`: iSAM2 updated once per keyframe; each keyframe's state and marginals are
  recorded when it is the newest (``calculateEstimate``, ``marginalCovariance``), the online
  estimate a vehicle would have had: the comparison for the UKF's own (online) output.

Output: a :class:`~undertow.trajectory.Trajectory` at the keyframes
(:func:`undertow.peers.inputs.to_trajectory`: pose marginal moved to roll-pitch-yaw and world
position; the angular velocity is the gyro minus the bias estimate).
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import ConfigError, DataError
from ..log import Log
from ..trajectory import Trajectory
from .graph import MAX_GAP_S, KeyframeGraph
from .gtsam_solve import bayes_tree_marginals, isam2_solver, levenberg_marquardt
from .inputs import PeerInputs, peer_inputs, to_trajectory

#: Levenberg-Marquardt's iteration limit and relative error decrease at which it stops
MAX_ITERATIONS = 50
RELATIVE_TOLERANCE = 1e-6


def factor_graph(log: Log, *, max_gap_s: float = MAX_GAP_S, **kw) -> Trajectory:
    """The batch factor-graph smoother of ``log`` (module doc); ``kw`` as
    :func:`~undertow.peers.inputs.peer_inputs` takes them."""
    inputs = _checked_inputs(log, kw, "factor-graph")
    start = time.process_time()
    kg = KeyframeGraph(inputs, max_gap_s)
    graph, values = kg.start()
    for k in range(1, len(kg)):
        g, v = kg.step(k)
        graph.push_back(g)
        values.insert(v)
    graph.push_back(kg.finish())
    solution = levenberg_marquardt(graph, values, max_iterations=MAX_ITERATIONS,
                                   relative_tol=RELATIVE_TOLERANCE)  # fmt: skip
    try:
        marginals = bayes_tree_marginals(graph, solution.values)
        states = _states(kg, range(len(kg)), solution.values, marginals)
    except RuntimeError as exc:  # gtsam's IndeterminateLinearSystemException, one line
        first = str(exc).strip().splitlines()[0]
        raise DataError(f"factor-graph: the covariance could not be computed ({first})") from None
    meta = {
        "optimizer": "Levenberg-Marquardt (gtsam's, driven from Python)",
        "iterations": solution.iterations,
        "initial_error": solution.initial_error,
        "final_error": solution.final_error,
        "online": False,
    }
    return _trajectory(kg, states, "factor-graph", meta, time.process_time() - start)


def isam2(log: Log, *, max_gap_s: float = MAX_GAP_S, relinearize_threshold: float = 0.1,
          relinearize_skip: int = 1, **kw) -> Trajectory:  # fmt: skip
    """The factor graph solved incrementally by iSAM2, one update per keyframe; each keyframe's
    estimate and marginals taken when it is the newest (the online estimate; module doc)."""
    inputs = _checked_inputs(log, kw, "isam2")
    start = time.process_time()
    kg = KeyframeGraph(inputs, max_gap_s)
    gtsam = kg.gtsam
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(relinearize_threshold)
    params.relinearizeSkip = relinearize_skip
    params.setFactorization("QR")  # Cholesky finds a long log's marginals indeterminate
    solver, _point = isam2_solver(params)  # _point held: its callbacks then copy no Values
    graph, values = kg.start()
    solver.update(graph, values)
    rows = [_state(kg, 0, _IsamView(solver))]
    for k in range(1, len(kg)):
        g, v = kg.step(k)
        if k == len(kg) - 1:
            g.push_back(kg.finish())
        solver.update(g, v)
        rows.append(_state(kg, k, _IsamView(solver)))
    states = [np.stack(col) for col in zip(*rows, strict=True)]
    meta = {
        "optimizer": "iSAM2 (gtsam), one update per keyframe",
        "relinearize_threshold": relinearize_threshold,
        "relinearize_skip": relinearize_skip,
        "online": True,
    }
    return _trajectory(kg, states, "isam2", meta, time.process_time() - start)


def _checked_inputs(log: Log, kw: dict, name: str) -> PeerInputs:
    """The run's inputs; a log without an IMU accelerometer is one ConfigError line."""
    inputs = peer_inputs(log, **kw)
    if not inputs.has_accelerometer:
        where = f" ({log.source})" if log.source else ""
        what = "no IMU" if not inputs.has_imu else "no accelerometer (imu linear_acceleration)"
        raise ConfigError(
            f"estimator {name}: the log{where} has {what}: IMU preintegration needs the gyro "
            "and the accelerometer (use the UKF, --estimator ukf)"
        )
    return inputs


class _IsamView:
    """iSAM2's current estimate and marginals with the accessors of Values and Marginals."""

    def __init__(self, solver):
        self.solver = solver

    def atPose3(self, key):
        return self.solver.calculateEstimatePose3(key)

    def atVector(self, key):
        return self.solver.calculateEstimateVector(key)

    def atConstantBias(self, key):
        return self.solver.calculateEstimateConstantBias(key)

    def marginalCovariance(self, key):
        return self.solver.marginalCovariance(key)


def _state(kg: KeyframeGraph, k: int, values, marginals=None):
    """(R, p, v, gyro bias, DR bias, pose cov, velocity cov, gyro bias cov, DR bias cov) of
    keyframe k; ``marginals`` None: ``values`` gives them too (iSAM2)."""
    marginals = values if marginals is None else marginals
    pose = values.atPose3(kg.X(k))
    R = pose.rotation().matrix()
    C = np.array(marginals.marginalCovariance(kg.X(k)))
    J = np.eye(6)
    J[3:, 3:] = R  # d_p (world) = R d_t (body)
    bias = values.atConstantBias(kg.B(k))
    C_b = np.array(marginals.marginalCovariance(kg.B(k)))
    dr, C_d = np.zeros(3), np.zeros((3, 3))
    if kg.has_dr_bias:
        dr = np.asarray(values.atVector(kg.D(k)), float)
        C_d = np.array(marginals.marginalCovariance(kg.D(k)))
    return (R, np.asarray(pose.translation(), float), np.asarray(values.atVector(kg.V(k)), float),
            np.asarray(bias.gyroscope(), float), dr, J @ C @ J.T,
            np.array(marginals.marginalCovariance(kg.V(k))), C_b[3:, 3:], C_d)  # fmt: skip


def _states(kg: KeyframeGraph, keys, values, marginals):
    rows = [_state(kg, k, values, marginals) for k in keys]
    return [np.stack(col) for col in zip(*rows, strict=True)]


def _trajectory(kg: KeyframeGraph, states, name: str, meta: dict, cpu_s: float) -> Trajectory:
    R, p, v, bg, dr, C_pose, C_v, C_bg, C_dr = states
    meta = {
        **meta,
        "keyframes": len(kg),
        "factors": dict(kg.counts),
        "cpu_s": round(cpu_s, 3),
        "sensors": ["imu gyro", "imu accelerometer (not used by the UKF)", "dvl velocity",
                    "pressure depth", "dead-reckoning attitude"],
    }  # fmt: skip
    has_dr = kg.has_dr_bias
    return to_trajectory(
        kg.inputs, kg.kf, R, p, v, bg, C_pose, estimator=name, velocity_cov=C_v,
        gyro_bias_cov=C_bg, dr_bias=dr if has_dr else None, dr_bias_cov=C_dr if has_dr else None,
        metadata=meta,
    )  # fmt: skip
