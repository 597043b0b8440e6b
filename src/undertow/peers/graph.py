"""The factor graph of a run, keyframe by keyframe: states, factors and a causal initial guess.

Keyframes (:func:`keyframe_times`): the first measurement time, every DVL report, and fill-ins so
that no two are more than ``max_gap_s`` apart (a DVL outage). At keyframe k the states are the
pose X(k) = (R, p) (R_B^W, world position), the world velocity V(k), the IMU biases B(k)
(accelerometer, gyro) and, for the variants that estimate biases on a log with the DVL's dead
reckoning, the DR attitude bias D(k).

Factors added when keyframe k+1 arrives (:func:`KeyframeGraph.step`, so an incremental solver
sees only the past):

- ``CombinedImuFactor(X_k, V_k, X_k+1, V_k+1, B_k, B_k+1)`` of the IMU samples between the two
  keyframes (each held until the next sample; GTSAM's on-manifold preintegration, Forster et
  al., "On-Manifold Preintegration for Real-Time Visual-Inertial Odometry", T-RO 2017,
  gtsam/navigation/CombinedImuFactor.h): the gyro and the accelerometer with their bias random
  walks. The UKF reads the gyro only: the accelerometer is the peers' own sensor.
- the DVL factor at X_k+1, V_k+1 (the report that made the keyframe);
- the depth and DR factors of the reports in [t_k, t_k+1) at X_k (V_k for the depth), each
  moved by the time since the keyframe (:mod:`.gtsam_factors`);
- ``BetweenFactorVector(D_k, D_k+1)``: the DR bias walk, b_k+1 - b_k = mu_b dt + w,
  w ~ N(0, q_b dt) (eq:dynamics_model's b^g).

Priors on X(0), V(0), B(0), D(0) are the UKF's x0 and P0 moved to GTSAM's tangent spaces: with
T the Euler-rate matrix, d_theta = T^-1 d_rpy and d_t = R^T d_p, so the pose prior's covariance
is J P0[rpy, xyz] J^T with J = diag(T^-1, R^T); the velocity's R P0[uvw] R^T. The gyro bias
prior is x0's with P0's std for the variants that estimate biases, else held (a tiny std and
walk: the UKF's frozen bias states).
"""

from __future__ import annotations

import numpy as np

from ..rotations import matrix_to_rpy, rpy_to_matrix
from .gtsam_factors import (
    depth_factor,
    dr_factor,
    dvl_factor,
    gaussian,
    imu_params,
    require_gtsam,
    skew,
    so3_exp,
)
from .inputs import HELD_VARIANCE, PeerInputs, euler_rate_matrix

#: longest time between keyframes (s): fill-ins during a DVL outage
MAX_GAP_S = 1.0


def keyframe_times(inputs: PeerInputs, max_gap_s: float = MAX_GAP_S) -> np.ndarray:
    """t0, every DVL report, and fill-ins where two are more than ``max_gap_s`` apart, up to the
    last IMU sample (the preintegration needs IMU samples between keyframes)."""
    end = inputs.imu_t[-1]
    t = np.unique(
        np.r_[inputs.t0, inputs.dvl_t[(inputs.dvl_t >= inputs.t0) & (inputs.dvl_t <= end)]]
    )
    wide = np.flatnonzero(np.diff(t) > max_gap_s)
    extra = [np.arange(t[i] + max_gap_s, t[i + 1], max_gap_s) for i in wide]
    if end - t[-1] > max_gap_s:
        extra.append(np.arange(t[-1] + max_gap_s, end, max_gap_s))
    return np.unique(np.concatenate([t, *extra])) if extra else t


def imu_pieces(imu_t: np.ndarray, kf: np.ndarray):
    """(interval, sample, dt) of the zero-order-hold pieces between keyframes: the timeline cut
    at every IMU sample and keyframe, each piece integrated with the last sample at or before
    its start (the first sample before the first one), in interval order."""
    inside = imu_t[(imu_t > kf[0]) & (imu_t < kf[-1])]
    breaks = np.unique(np.r_[inside, kf])
    start = breaks[:-1]
    sample = np.clip(np.searchsorted(imu_t, start, side="right") - 1, 0, imu_t.size - 1)
    interval = np.searchsorted(kf, start, side="right") - 1
    return interval, sample, np.diff(breaks)


def _between(t: np.ndarray, kf: np.ndarray) -> np.ndarray:
    """The keyframe at or before each time (reports before the first go to it)."""
    return np.clip(np.searchsorted(kf, t, side="right") - 1, 0, kf.size - 1)


def pose_prior_cov(x0: np.ndarray, P0: np.ndarray) -> np.ndarray:
    """P0's pose block in GTSAM's Pose3 tangent (d_theta, d_t body): J P J^T, J = diag(T^-1, R^T)
    on (rpy, xyz) (module doc)."""
    order = np.r_[3:6, 0:3]
    P = P0[np.ix_(order, order)]
    J = np.zeros((6, 6))
    J[:3, :3] = np.linalg.inv(euler_rate_matrix(x0[3:6])[0])
    J[3:, 3:] = rpy_to_matrix(x0[3:6]).T
    C = J @ P @ J.T
    return 0.5 * (C + C.T) + np.eye(6) * HELD_VARIANCE


class KeyframeGraph:
    """The graph of one run grown keyframe by keyframe (module doc): :meth:`start` gives the
    priors, :meth:`step` the factors and initial values of each next keyframe."""

    def __init__(self, inputs: PeerInputs, max_gap_s: float = MAX_GAP_S):
        gtsam = require_gtsam()
        self.gtsam, self.inputs = gtsam, inputs
        self.X, self.V = gtsam.symbol_shorthand.X, gtsam.symbol_shorthand.V
        self.B, self.D = gtsam.symbol_shorthand.B, gtsam.symbol_shorthand.D
        self.kf = keyframe_times(inputs, max_gap_s)
        self.params = imu_params(inputs)
        self.pieces = imu_pieces(inputs.imu_t, self.kf)
        self.piece_bounds = np.searchsorted(self.pieces[0], np.arange(self.kf.size + 1))
        self.dvl_at = {int(k): i for i, k in enumerate(np.searchsorted(self.kf, inputs.dvl_t))
                       if k < self.kf.size and self.kf[k] == inputs.dvl_t[i]}  # fmt: skip
        self.depth_kf = _between(inputs.depth_t, self.kf)
        self.dr_kf = _between(inputs.dr_t, self.kf)
        self.has_dr_bias = inputs.estimates_bias and inputs.dr_t.size > 0
        self.b0_gyro = inputs.x0[15:18].copy()
        self.counts = {"imu": 0, "dvl": 0, "depth": 0, "dead_reckoning": 0}
        self._guess = None

    def __len__(self) -> int:
        return int(self.kf.size)

    def start(self):
        """(graph, values) of keyframe 0: the priors from the UKF's x0, P0 (module doc)."""
        gtsam, inp = self.gtsam, self.inputs
        x0, P0 = inp.x0, inp.P0
        R0 = rpy_to_matrix(x0[3:6])
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        pose = gtsam.Pose3(gtsam.Rot3(R0), x0[0:3])
        graph.add(gtsam.PriorFactorPose3(self.X(0), pose, gaussian(pose_prior_cov(x0, P0))))
        v0 = R0 @ x0[6:9]
        graph.add(gtsam.PriorFactorVector(self.V(0), v0, gaussian(R0 @ P0[6:9, 6:9] @ R0.T)))
        gyro_var = np.diag(P0)[15:18] if inp.estimates_bias else np.full(3, HELD_VARIANCE)
        bias = gtsam.imuBias.ConstantBias(np.zeros(3), x0[15:18])
        sigmas = np.sqrt(np.r_[inp.accel_bias_std_m_s2**2, np.maximum(gyro_var, HELD_VARIANCE)])
        sigma_model = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
        graph.add(gtsam.PriorFactorConstantBias(self.B(0), bias, sigma_model))
        values.insert(self.X(0), pose)
        values.insert(self.V(0), v0)
        values.insert(self.B(0), bias)
        if self.has_dr_bias:
            var = np.maximum(np.diag(P0)[12:15], HELD_VARIANCE)
            sigma_model = gtsam.noiseModel.Diagonal.Sigmas(np.sqrt(var))
            graph.add(gtsam.PriorFactorVector(self.D(0), x0[12:15], sigma_model))
            values.insert(self.D(0), x0[12:15].copy())
        self._guess = (R0, x0[0:3].copy(), v0)
        return graph, values

    def step(self, k: int):
        """(graph, values) that keyframe k (>= 1) brings: the IMU factor k-1 -> k, the DVL factor
        at k, the depth and DR factors of [t_k-1, t_k) at k-1, the DR bias walk; and the new
        states' initial values (causal: :meth:`_initial`)."""
        gtsam = self.gtsam
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        pim = self._preintegrated(k - 1)
        graph.add(gtsam.CombinedImuFactor(self.X(k - 1), self.V(k - 1), self.X(k), self.V(k),
                                          self.B(k - 1), self.B(k), pim))  # fmt: skip
        self.counts["imu"] += 1
        self._sensor_factors(graph, k - 1)
        if k in self.dvl_at:
            graph.add(self._dvl(k, self.dvl_at[k]))
            self.counts["dvl"] += 1
        dt = self.kf[k] - self.kf[k - 1]
        if self.has_dr_bias:
            inp = self.inputs
            noise = gtsam.noiseModel.Diagonal.Sigmas(np.sqrt(inp.dr_bias_walk_density * dt))
            graph.add(gtsam.BetweenFactorVector(self.D(k - 1), self.D(k),
                                                inp.dr_bias_drift_rad_s * dt, noise))  # fmt: skip
        self._initial(k, pim, values)
        return graph, values

    def finish(self):
        """The depth and DR factors of the reports at or after the last keyframe."""
        graph = self.gtsam.NonlinearFactorGraph()
        self._sensor_factors(graph, self.kf.size - 1)
        return graph

    def _preintegrated(self, j: int):
        """The IMU samples of [t_j, t_j+1) preintegrated at the initial gyro bias."""
        gtsam, inp = self.gtsam, self.inputs
        bias = gtsam.imuBias.ConstantBias(np.zeros(3), self.b0_gyro)
        pim = gtsam.PreintegratedCombinedMeasurements(self.params, bias)
        _, sample, dt = self.pieces
        for i in range(self.piece_bounds[j], self.piece_bounds[j + 1]):
            s = sample[i]
            pim.integrateMeasurement(inp.accel_m_s2[s], inp.gyro_rad_s[s], dt[i])
        return pim

    def _omega(self, t: float) -> np.ndarray:
        """The gyro at t (interpolated between its two samples around t, held outside them)
        minus the initial gyro bias."""
        imu_t, w = self.inputs.imu_t, self.inputs.gyro_rad_s
        i = int(np.searchsorted(imu_t, t, side="right"))
        near = slice(max(i - 1, 0), i + 1)  # np.interp of the whole log costs O(samples)
        return np.array([np.interp(t, imu_t[near], w[near, j]) for j in range(3)]) - self.b0_gyro

    def _dvl(self, k: int, i: int):
        inp = self.inputs
        omega = inp.dvl_gyro_rad_s[i] - self.b0_gyro
        u = inp.dvl_velocity_m_s[i] - np.cross(omega, inp.dvl_lever_arm_m)
        return dvl_factor(self.X(k), self.V(k), u, inp.dvl_covariance[i])

    def _sensor_factors(self, graph, j: int) -> None:
        """The depth and DR factors of the reports attached to keyframe j."""
        inp, t_j = self.inputs, self.kf[j]
        for i in _attached(self.depth_kf, j):
            graph.add(depth_factor(self.X(j), self.V(j), inp.depth_m[i], inp.depth_std_m[i],
                                   inp.baro_lever_arm_m, inp.depth_t[i] - t_j))  # fmt: skip
            self.counts["depth"] += 1
        for i in _attached(self.dr_kf, j):
            E = so3_exp(self._omega(inp.dr_t[i]) * (inp.dr_t[i] - t_j))
            d_key = self.D(j) if self.has_dr_bias else None
            graph.add(dr_factor(self.X(j), d_key, inp.dr_rpy_rad[i], inp.dr_covariance[i], E,
                                held_bias=inp.x0[12:15]))  # fmt: skip
            self.counts["dead_reckoning"] += 1

    def _initial(self, k: int, pim, values) -> None:
        """Causal initial values of keyframe k: the attitude of the gyro's preintegrated rotation
        (reset to the last DR report's when there is one, its bias removed), the velocity R u of
        the DVL report at k (else the previous), the position integrated with the mean
        velocity and its z from the last depth; biases carried over."""
        gtsam, inp = self.gtsam, self.inputs
        R_prev, p_prev, v_prev = self._guess
        R = R_prev @ pim.deltaRij().matrix()
        dr = _last_within(inp.dr_t, self.kf[k], 0.5)
        if dr is not None:
            R = rpy_to_matrix(inp.dr_rpy_rad[dr] - inp.x0[12:15])
        R = _orthonormal(R)
        v = v_prev
        if k in self.dvl_at:
            i = self.dvl_at[k]
            v = R @ (inp.dvl_velocity_m_s[i] - skew(self._omega(self.kf[k])) @ inp.dvl_lever_arm_m)
        p = p_prev + 0.5 * (v_prev + v) * (self.kf[k] - self.kf[k - 1])
        dp = _last_within(inp.depth_t, self.kf[k], 0.5)
        if dp is not None:
            p[2] = inp.depth_m[dp] - (R @ inp.baro_lever_arm_m)[2]
        values.insert(self.X(k), gtsam.Pose3(gtsam.Rot3(R), p))
        values.insert(self.V(k), v)
        values.insert(self.B(k), gtsam.imuBias.ConstantBias(np.zeros(3), self.b0_gyro))
        if self.has_dr_bias:
            values.insert(self.D(k), inp.x0[12:15].copy())
        self._guess = (R, p, v)


def _attached(keyframe_of: np.ndarray, j: int) -> range:
    """The reports attached to keyframe j (``keyframe_of`` is non-decreasing)."""
    return range(int(np.searchsorted(keyframe_of, j, side="left")),
                 int(np.searchsorted(keyframe_of, j, side="right")))  # fmt: skip


def _last_within(t: np.ndarray, at: float, window: float) -> int | None:
    """The index of the last report at or before ``at`` and less than ``window`` before it."""
    i = int(np.searchsorted(t, at, side="right")) - 1
    return i if i >= 0 and t[i] > at - window else None


def _orthonormal(R: np.ndarray) -> np.ndarray:
    """The nearest rotation (re-orthonormalized by way of its roll, pitch, yaw)."""
    return rpy_to_matrix(matrix_to_rpy(R))
