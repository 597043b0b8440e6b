"""``inekf(log) -> Trajectory``: the invariant EKF on SE_2(3) (:mod:`.inekf_core`; Potokar,
Norman and Mangelson, RA-L 2021) on the UKF's sensors and noise (:func:`.inputs.peer_inputs`).

It reads what the paper's UKF reads, the same way (rows, envelopes, floors, the wave noise of
the noise profile added to the DVL's covariance for the variants that add it), except:

- it integrates the accelerometer (the UKF does not read it) and estimates its bias, so a log
  without ``Imu.linear_acceleration`` is refused;
- the DVL's dead-reckoning attitude, which the UKF fuses, is fused as an attitude
  observation (:func:`.inekf_core.update_attitude`) with the UKF's noise (rpy covariance
  mapped to a world rotation, N = E C E^T, E = R T(phi, theta)^-1) and the DR bias held at its
  initial value x0[12:15] (the UKF estimates it), unless ``dr_bias=True``: then three DR-bias
  states estimate what x0[12:15] leaves, as a world-frame rotation b_d (R_m = Exp(b_d) R), a
  random walk with the UKF's density and mean drift mapped by E_0 = R_0 T_0^-1 (the drift
  E_0 mu_b, the density the diagonal of E_0 diag(q_b) E_0^T: exact for a heading offset of a
  level vehicle, the UKF's (1e-7, 1e-7, 1e-6) unchanged by a turn), started at 0 with
  E_0 P0[DR] E_0^T, and written back as the UKF's rpy offset x0[12:15] + T R^T b_d (a
  world rotation Exp(b_d) R = R Exp(R^T b_d) changes rpy by T R^T b_d to first order).
  ``dr_attitude=False`` runs Potokar et al.'s
  filter as published (IMU, DVL, depth only): its heading is then the gyro's integral,
  observed only through the DVL's lever arm (the gyro bias), and drifts with the yaw-rate bias.

Conversions (e = (xi_R, xi_v, xi_p, db_g, db_a), X = exp(xi) X_hat; to first order
R = Exp(xi_R) R_hat, v = v_hat + xi_R x v_hat + xi_v, p = p_hat + xi_R x p_hat + xi_p):

- to the ordinary errors (d_theta world, dv world, dp world, db): d_theta = xi_R,
  dv = xi_v - [v_hat]x xi_R, dp = xi_p - [p_hat]x xi_R (:func:`ordinary_jacobian`); the pose,
  velocity and gyro-bias blocks of that covariance go to :func:`.inputs.to_trajectory`;
- from the UKF's initial covariance (position, roll pitch yaw, body velocity, gyro bias):
  xi_R = R_hat T(phi, theta)^-1 d(rpy) (T the Euler-rate matrix: a body-frame attitude error),
  xi_v = R_hat d(nu), xi_p = dp + [p_hat]x xi_R (:func:`initial_covariance`).

The IMU's white-noise densities are the per-sample variances times the sample period
(s = sigma^2 dt, the inverse of the discretization sigma^2 = s / dt).
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import MissingStreamError
from ..log import G0, Log
from ..robot import Mounting
from ..rotations import matrix_to_rpy, rpy_to_matrix
from ..trajectory import Trajectory
from .inekf_core import ATTITUDE, DEPTH, DVL, InekfModel, run_inekf
from .inputs import PeerInputs, euler_rate_matrix, peer_inputs, to_trajectory
from .lie import hat

ESTIMATOR = "inekf"


def inekf(log: Log, *, profile=None, wave=None, calibration=None, extrapolate: bool = False,
          gravity_m_s2: float = G0, dr_attitude: bool = True, dr_bias: bool = False,
          **params) -> Trajectory:  # fmt: skip
    """The InEKF's trajectory of ``log`` (options as :func:`.inputs.peer_inputs`: the noise
    profile, the wave, a calibration, LocalizerConfig fields, the accelerometer's settings);
    ``dr_attitude``: fuse the DVL's dead-reckoning attitude as the UKF does, ``dr_bias``:
    estimate its bias (three states, as the UKF; module doc); one row after every DVL, depth
    and attitude measurement."""
    inputs = peer_inputs(log, profile=profile, wave=wave, calibration=calibration,
                         extrapolate=extrapolate, **params)  # fmt: skip
    return run_on_inputs(inputs, gravity_m_s2=gravity_m_s2, dr_attitude=dr_attitude,
                         dr_bias=dr_bias)  # fmt: skip


def run_on_inputs(inputs: PeerInputs, gravity_m_s2: float = G0, dr_attitude: bool = True,
                  dr_bias: bool = False) -> Trajectory:  # fmt: skip
    """The filter on resolved :class:`.inputs.PeerInputs` (see :func:`inekf`)."""
    if not inputs.has_imu or not inputs.has_accelerometer:
        raise MissingStreamError(
            "inekf needs the IMU's gyro and accelerometer (imu.linear_acceleration); "
            f"the log {inputs.metadata.get('source') or ''} has "
            f"{'no IMU' if not inputs.has_imu else 'no accelerometer'}".replace("  ", " ")
        )
    if inputs.dvl_t.size + inputs.depth_t.size == 0:
        raise MissingStreamError("inekf needs a DVL or a depth stream; the log has neither")
    with_bias = bool(dr_bias and dr_attitude and inputs.dr_t.size)
    R0, v0, p0, b0 = initial_estimate(inputs, with_bias)
    model = inekf_model(inputs, gravity_m_s2, R0 if with_bias else None)
    P0 = initial_covariance(inputs, R0, p0, with_bias)
    start = time.process_time()
    out = run_inekf(
        inputs.imu_t, inputs.gyro_rad_s, inputs.accel_m_s2,
        inputs.dvl_t, inputs.dvl_velocity_m_s, inputs.dvl_covariance,
        inputs.depth_t, inputs.depth_m, inputs.depth_std_m**2,
        t0=inputs.t0, R0=R0, v0=v0, p0=p0, b0=b0, P0=P0, model=model,
        attitude=attitude_observations(inputs) if dr_attitude else None,
    )  # fmt: skip
    cpu_s = time.process_time() - start
    C = ordinary_covariance(out.P, out.v, out.p)
    pose = np.empty((len(out.t), 6, 6))
    pose[:, :3, :3], pose[:, :3, 3:] = C[:, 0:3, 0:3], C[:, 0:3, 6:9]
    pose[:, 3:, :3], pose[:, 3:, 3:] = C[:, 6:9, 0:3], C[:, 6:9, 6:9]
    dr = dr_bias_rpy(inputs, out.R, out.b, C) if with_bias else {}
    meta = {**_summary(out, cpu_s), "dr_attitude": bool(dr_attitude), "dr_bias": with_bias}
    return to_trajectory(
        inputs, out.t, out.R, out.p, out.v, out.b[:, 0:3], pose,
        estimator=ESTIMATOR, attitude_error="world",
        velocity_cov=C[:, 3:6, 3:6], gyro_bias_cov=C[:, 9:12, 9:12],
        metadata={"inekf": meta}, **dr,
    )  # fmt: skip


def dr_bias_rpy(inputs: PeerInputs, R: np.ndarray, b: np.ndarray, C: np.ndarray) -> dict:
    """The DR-bias states as the UKF's rpy offset: x0[12:15] + J b_d, covariance J C_dd J^T,
    J = T(phi, theta) R^T (module doc)."""
    J = euler_rate_matrix(matrix_to_rpy(R)) @ np.swapaxes(R, 1, 2)
    cov = J @ C[:, 15:18, 15:18] @ np.swapaxes(J, 1, 2)
    return {"dr_bias": inputs.x0[12:15] + np.einsum("nij,nj->ni", J, b[:, 6:9]),
            "dr_bias_cov": 0.5 * (cov + np.swapaxes(cov, 1, 2))}  # fmt: skip


def _summary(out, cpu_s: float) -> dict:
    """Counts, NIS means per sensor, the final accelerometer bias and the filter's CPU time."""
    summary = {"cpu_s": cpu_s}
    for kind, name in ((DVL, "dvl"), (DEPTH, "depth"), (ATTITUDE, "attitude")):
        rows = out.kind == kind
        applied = rows & out.applied
        summary[f"{name}_updates"] = int(applied.sum())
        summary[f"{name}_gated"] = int((rows & ~out.applied).sum())
        summary[f"{name}_mean_nis"] = float(out.nis[applied].mean()) if applied.any() else None
    if len(out.t):
        summary["accel_bias_m_s2"] = [float(v) for v in out.b[-1, 3:6]]
    return summary


def inekf_model(inputs: PeerInputs, gravity_m_s2: float = G0, R0=None) -> InekfModel:
    """The noise densities (s = sigma^2 dt at the IMU's median period), the DVL's lever arm
    (its velocity already in the body frame: R_d = I), the gates of the UKF's config; with
    ``R0`` the DR bias's walk and drift mapped to the world frame (module doc)."""
    dt = float(np.median(np.diff(inputs.imu_t))) if inputs.imu_t.size > 1 else 0.01
    gate = inputs.config.sensor_model(Mounting()).gate  # (the gates need no mounting)
    cfg = inputs.config
    return InekfModel(
        gyro_density=inputs.gyro_std_rad_s**2 * dt,
        accel_density=inputs.accel_std_m_s2**2 * dt,
        gyro_bias_walk=np.asarray(inputs.gyro_bias_walk_density, float),
        accel_bias_walk=np.asarray(inputs.accel_bias_walk_density, float),
        gyro_sample_var=inputs.gyro_std_rad_s**2,
        dvl_R=np.eye(3),
        dvl_r=np.asarray(inputs.dvl_lever_arm_m, float),
        baro_r=np.asarray(inputs.baro_lever_arm_m, float),
        gravity=float(gravity_m_s2),
        gate_dvl=float(gate[1]),
        gate_depth=float(gate[3]),
        gate_attitude=float(gate[2]),
        max_dt=float(cfg.max_dt_s),
        **({} if R0 is None else _dr_bias_noise(inputs, R0)),
    )


def _dr_bias_noise(inputs: PeerInputs, R0: np.ndarray) -> dict:
    E = R0 @ np.linalg.inv(euler_rate_matrix(inputs.x0[3:6])[0])
    walk = np.diag(E @ np.diag(inputs.dr_bias_walk_density) @ E.T)
    return {"dr_bias_walk": walk.copy(), "dr_bias_drift": E @ inputs.dr_bias_drift_rad_s}


def attitude_observations(inputs: PeerInputs):
    """(t, R_m, world covariance) of the DR attitude rows: R_m = R(z - b_dr0), N = E C E^T with
    E = R_m T(phi, theta)^-1 (an rpy error d maps to the world rotation xi = E d)."""
    if inputs.dr_t.size == 0:
        return None
    rpy = inputs.dr_rpy_rad - inputs.x0[12:15]
    Rm = rpy_to_matrix(rpy)
    E = Rm @ np.linalg.inv(euler_rate_matrix(rpy))
    N = E @ inputs.dr_covariance @ np.swapaxes(E, 1, 2)
    return inputs.dr_t, Rm, 0.5 * (N + np.swapaxes(N, 1, 2))


def initial_estimate(inputs: PeerInputs, dr_bias: bool = False):
    """(R0, v0 world, p0, b0 = (b_g, b_a = 0) or (b_g, b_a = 0, b_d = 0)) from the UKF's x0."""
    x0 = inputs.x0
    R0 = rpy_to_matrix(x0[3:6])
    b0 = np.zeros(9 if dr_bias else 6)
    b0[0:3] = x0[15:18]
    return R0, R0 @ x0[6:9], np.array(x0[0:3], float), b0


def initial_covariance(inputs: PeerInputs, R0: np.ndarray, p0: np.ndarray,
                       dr_bias: bool = False) -> np.ndarray:  # fmt: skip
    """P0 of e from the UKF's P0 blocks (position, rpy, body velocity, gyro bias, and the DR
    bias with ``dr_bias``) and the accelerometer's initial bias std (module doc)."""
    P = inputs.P0
    n = 18 if dr_bias else 15
    idx = np.r_[0:3, 3:6, 6:9, 15:18]
    Po = np.zeros((n, n))
    Po[:12, :12] = P[np.ix_(idx, idx)]
    Po[12:15, 12:15] = np.diag(np.asarray(inputs.accel_bias_std_m_s2, float) ** 2)
    if dr_bias:
        Po[15:18, 15:18] = P[12:15, 12:15]
    M = from_ordinary_jacobian(R0, p0, inputs.x0[3:6], n)
    return M @ Po @ M.T


def from_ordinary_jacobian(R: np.ndarray, p: np.ndarray, rpy: np.ndarray, n: int = 15
                           ) -> np.ndarray:  # fmt: skip
    """M (n, n): e = M (dp, d(rpy), d(nu body), db_g, db_a[, d(DR bias rpy)]), to first order
    (module doc; the DR bias maps as the attitude, b_d = R T^-1 d)."""
    T = euler_rate_matrix(np.asarray(rpy, float))[0]
    M = np.zeros((n, n))
    M[0:3, 3:6] = R @ np.linalg.inv(T)
    M[3:6, 6:9] = R
    M[6:9, 0:3] = np.eye(3)
    M[6:9, 3:6] = hat(np.asarray(p, float)) @ M[0:3, 3:6]
    M[9:15, 9:15] = np.eye(6)
    if n > 15:
        M[15:18, 15:18] = M[0:3, 3:6]
    return M


def ordinary_jacobian(v: np.ndarray, p: np.ndarray, size: int = 15) -> np.ndarray:
    """J (n, m, m): (d_theta, dv, dp, db_g, db_a[, db_d]) = J e, all world frame (module doc;
    m = 15, or 18 with the DR-bias states)."""
    n = v.shape[0]
    J = np.broadcast_to(np.eye(size), (n, size, size)).copy()
    J[:, 3:6, 0:3] = -_hats(v)
    J[:, 6:9, 0:3] = -_hats(p)
    return J


def ordinary_covariance(P: np.ndarray, v: np.ndarray, p: np.ndarray) -> np.ndarray:
    """J P J^T with J = :func:`ordinary_jacobian` (P of 15 or 18)."""
    J = ordinary_jacobian(v, p, P.shape[-1])
    C = J @ P @ np.swapaxes(J, 1, 2)
    return 0.5 * (C + np.swapaxes(C, 1, 2))


def _hats(w: np.ndarray) -> np.ndarray:
    W = np.zeros((w.shape[0], 3, 3))
    W[:, 0, 1], W[:, 0, 2], W[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    W[:, 1, 0], W[:, 2, 0], W[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return W
