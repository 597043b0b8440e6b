"""The invariant EKF on SE_2(3) with IMU biases, on plain arrays (numba): propagation with the
IMU, DVL body-velocity and depth updates, after Potokar, Norman and Mangelson, "Invariant
extended Kalman filtering for underwater navigation", IEEE RA-L 6(3), 2021, with the
right-invariant IMU propagation of Barrau and Bonnabel, "The invariant extended Kalman filter as
a stable observer", IEEE TAC 62(4), 2017, and the bias augmentation ("imperfect IEKF") of
Hartley et al., "Contact-aided invariant extended Kalman filtering for robot state
estimation", IJRR 39(4), 2020, section V.

Frames (undertow's, :mod:`undertow.log`): world x north / along the tank, y right, z DOWN;
body forward-right-down. Gravity is therefore g = (0, 0, +g) in the world, and an
accelerometer at rest reads the specific force f = R^T (a - g) = (0, 0, -g) when level.

State: X = (R, v, p) in SE_2(3) (:mod:`undertow.peers.lie`; R body to world, v and p the
body origin's velocity and position in the world) and the biases b = (b_g, b_a) (gyro rad/s,
accelerometer m/s^2, body frame). Error (15 entries, right-invariant on X, linear on b):

    X = exp(xi) X_hat,   b = b_hat + db,   e = (xi_R, xi_v, xi_p, db_g, db_a),   P = Cov(e).

IMU propagation (gyro omega_m and accelerometer f_m in the body frame; UNLIKE the paper's UKF,
which uses the gyro only, this filter integrates the accelerometer as Potokar et al. do):

    R' = R Exp((omega_m - b_g) dt)
    v' = v + (R (f_m - b_a) + g) dt
    p' = p + v dt + (R (f_m - b_a) + g) dt^2 / 2

and the error obeys de/dt = A e + [Ad_X, 0; 0, I] w (Hartley et al. 2020, eq. 50, up to the
sign of the error, which flips both A's bias columns and xi, so A is the same):

    A = [[0,     0, 0, -R,      0 ],
         [[g]x,  0, 0, -[v]x R, -R],
         [0,     I, 0, -[p]x R, 0 ],
         [0,     0, 0, 0,       0 ],
         [0,     0, 0, 0,       0 ]]

A is nilpotent (bias -> attitude -> velocity -> position, A^4 = 0), so the transition over a step
with X held is exactly Phi = I + A dt + (A dt)^2/2 + (A dt)^3/6; the discrete noise is
Q_d = Phi Q_c Phi^T dt with Q_c = blockdiag(Ad_X diag(s_g, s_a, 0) Ad_X^T, diag(q_bg, q_ba))
(s: white-noise densities, q: bias random-walk densities), and P' = Phi P Phi^T + Q_d.

DVL (velocity y in the DVL frame, mounting R_d body <- DVL, lever arm r, body):

    y = R_d^T (R^T v + omega x r) + n,    omega = omega_m - b_g - n_g.

With y_b = R_d y - (omega_m - b_g_hat) x r the reading has the form Y = X^-1 (y_b, -1, 0),
which Barrau and Bonnabel (and Hartley et al.) call a right-invariant observation (other
texts name it after the body frame it is expressed in, "left-invariant"): its innovation
in the world, z = R_hat y_b - v_hat, depends on the error alone,

    z = xi_v + R_hat [r]x db_g + R_hat (R_d n + [r]x n_g),   H = [0, I, 0, R_hat [r]x, 0],

so its Jacobian does not depend on the estimate's attitude or velocity (the lever arm couples
the gyro bias). N = R_hat (R_d Sigma_dvl R_d^T + [r]x Sigma_g [r]x^T) R_hat^T.

Depth (barometer at lever arm r_b, body): d = p_z + e_3^T R r_b + n. A world-frame position
Y = X (0, 0, 1) is a left-invariant observation, and depth measures one of its components: as
Potokar et al. do, the update runs in the left-invariant error X = X_hat exp(xi_l), to which
the covariance is switched by the adjoint (xi_l = Ad_{X_hat^-1} xi),

    z = d - p_hat_z - e_3^T R_hat r_b,   H_l = [-e_3^T R_hat [r_b]x, 0, e_3^T R_hat, 0, 0],

the correction applied on the right (X_hat <- X_hat exp(K z)) and the covariance switched back
with the updated estimate's adjoint. This scalar row is the limit of their pseudo-measurement
(x_hat, y_hat, d) whose x and y variances grow without bound.

Attitude (optional; the DVL's dead-reckoning attitude the paper's UKF fuses): a reported
R_m = Exp(n) R with n a world-frame rotation noise, z = Log(R_m R_hat^T) = xi_R + n, so
H = [I, 0, 0, 0, 0], again independent of the estimate.

DR-bias states (optional, as the paper's UKF estimates b^g): a world-frame rotation b_d
between the DR attitude and the vehicle's, R_m = Exp(n) Exp(b_d) R, a random walk
b_d' = b_d + mu_d dt + w (density q_d) appended to the error (e has 18 entries, db_d linear as
the IMU biases; it enters no propagation, so A's columns for it are zero). The attitude
innovation is then z = Log(Exp(-b_d_hat) R_m R_hat^T) = xi_R + db_d + n to first order,
H = [I, 0, 0, 0, 0, I] (exact for rotations about one axis, e.g. a heading offset of a level
vehicle). Without them (15 entries) the DR bias is whatever the caller removed from R_m.

Updates are the Kalman gain K = P H^T S^-1, S = H P H^T + N, the Joseph form for P, and a gate
on the normalized innovation squared (NIS = z^T S^-1 z; an innovation above the gate is
counted and not applied).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .lie import hat, se23_adjoint, se23_exp, se23_inverse, so3_exp, so3_log

N_ERR = 15  # without the DR-bias states; 18 with them (the size of P decides)
DVL, DEPTH, ATTITUDE = 1, 2, 3


class InekfModel(NamedTuple):
    """The noise densities, the sensors' mounting and the gates (arrays float64)."""

    gyro_density: np.ndarray  # (3,) white-noise density s_g, (rad/s)^2/Hz
    accel_density: np.ndarray  # (3,) s_a, (m/s^2)^2/Hz
    gyro_bias_walk: np.ndarray  # (3,) q_bg, (rad/s)^2/s
    accel_bias_walk: np.ndarray  # (3,) q_ba, (m/s^2)^2/s
    gyro_sample_var: np.ndarray  # (3,) Sigma_g of one gyro sample, (rad/s)^2 (lever-arm term)
    dvl_R: np.ndarray  # (3, 3) R_d, DVL frame to body
    dvl_r: np.ndarray  # (3,) DVL lever arm, body, m
    baro_r: np.ndarray  # (3,) barometer lever arm, body, m
    gravity: float  # g, m/s^2 (world +z, down)
    gate_dvl: float  # largest NIS applied (inf: no gate)
    gate_depth: float
    gate_attitude: float
    max_dt: float  # longest propagation step, s
    dr_bias_walk: np.ndarray = np.zeros(3)  # (3,) q_d, rad^2/s (used with the DR-bias states)
    dr_bias_drift: np.ndarray = np.zeros(3)  # (3,) mu_d, rad/s, world frame


@njit(cache=True)
def transition(R, v, p, dt, g, n=N_ERR):
    """Phi = exp(A dt) = I + A dt + (A dt)^2/2 + (A dt)^3/6 (A nilpotent), at X = (R, v, p);
    ``n`` the error's size (18: the DR-bias states, whose rows and columns of A are 0)."""
    A = np.zeros((n, n))
    A[0:3, 9:12] = -R
    A[3:6, 0:3] = hat(np.array([0.0, 0.0, g]))
    A[3:6, 9:12] = -(hat(v) @ R)
    A[3:6, 12:15] = -R
    A[6:9, 3:6] = np.eye(3)
    A[6:9, 9:12] = -(hat(p) @ R)
    Ad = A * dt
    Ad2 = Ad @ Ad
    return np.eye(n) + Ad + 0.5 * Ad2 + (Ad2 @ Ad) / 6.0


@njit(cache=True)
def process_noise(R, v, p, dt, model, n=N_ERR):
    """Q_d = Phi Q_c Phi^T dt (Hartley et al. 2020, section V-B), and Phi (q_d on the DR-bias
    states when n = 18)."""
    Phi = transition(R, v, p, dt, model.gravity, n)
    Qc = np.zeros((n, n))
    Ad = se23_adjoint(R, v, p)
    s = np.zeros(9)
    s[0:3] = model.gyro_density
    s[3:6] = model.accel_density
    Qc[0:9, 0:9] = (Ad * s) @ Ad.T
    for i in range(3):
        Qc[9 + i, 9 + i] = model.gyro_bias_walk[i]
        Qc[12 + i, 12 + i] = model.accel_bias_walk[i]
        if n > N_ERR:
            Qc[15 + i, 15 + i] = model.dr_bias_walk[i]
    return Phi, Phi @ Qc @ Phi.T * dt


@njit(cache=True)
def propagate(R, v, p, b, P, omega_m, f_m, dt, model):
    """One IMU step of length dt: the mean (R, v, p) and P, returned (b is constant; the DR
    bias's drift is :func:`_advance`'s)."""
    Phi, Qd = process_noise(R, v, p, dt, model, P.shape[0])
    P = Phi @ P @ Phi.T + Qd
    P = 0.5 * (P + P.T)
    acc = R @ (f_m - b[3:6])
    acc[2] += model.gravity
    p = p + v * dt + 0.5 * acc * dt * dt
    v = v + acc * dt
    R = R @ so3_exp((omega_m - b[0:3]) * dt)
    return R, v, p, P


@njit(cache=True)
def dvl_innovation(R, v, b, y, cov, omega_m, model):
    """(z, H, N) of a DVL reading y (DVL frame) with covariance cov: see the module doc."""
    Rd, r = model.dvl_R, model.dvl_r
    omega = omega_m - b[0:3]
    y_b = Rd @ y - np.cross(omega, r)
    z = R @ y_b - v
    H = np.zeros((3, 9 + b.size))
    H[0:3, 3:6] = np.eye(3)
    rx = hat(r)
    H[0:3, 9:12] = R @ rx
    Nb = Rd @ cov @ Rd.T + (rx * model.gyro_sample_var) @ rx.T
    return z, H, R @ Nb @ R.T


@njit(cache=True)
def depth_innovation(R, p, d, model, n=N_ERR):
    """(z, H_l) of a depth d: the scalar row in the left-invariant error (module doc)."""
    r = model.baro_r
    z = np.empty(1)
    z[0] = d - p[2] - (R[2, 0] * r[0] + R[2, 1] * r[1] + R[2, 2] * r[2])
    H = np.zeros((1, n))
    e3R = R[2, :].copy()
    H[0, 0:3] = -(e3R @ hat(r))
    H[0, 6:9] = e3R
    return z, H


@njit(cache=True)
def kalman(P, z, H, N, gate):
    """(correction K z, P+ in the same error coordinates, NIS, applied): Joseph form."""
    S = H @ P @ H.T + N
    S = 0.5 * (S + S.T)
    Si = np.linalg.inv(S)
    nis = z @ Si @ z
    if not nis <= gate:
        return np.zeros(P.shape[0]), P, nis, False
    K = P @ H.T @ Si
    IKH = np.eye(P.shape[0]) - K @ H
    P = IKH @ P @ IKH.T + K @ N @ K.T
    return K @ z, 0.5 * (P + P.T), nis, True


@njit(cache=True)
def error_frame(R, v, p, n=N_ERR):
    """T = blockdiag(Ad_X, I): xi_right = T xi_left (left to right-invariant error)."""
    T = np.eye(n)
    T[0:9, 0:9] = se23_adjoint(R, v, p)
    return T


@njit(cache=True)
def right_correct(R, v, p, b, dx):
    """X <- exp(dxi) X, b <- b + db: a right-invariant correction dx = (dxi (9), db (6 or 9))."""
    dR, dv, dp = se23_exp(dx[0:9].copy())
    return dR @ R, dR @ v + dv, dR @ p + dp, b + dx[9:]


@njit(cache=True)
def update_dvl(R, v, p, b, P, y, cov, omega_m, model):
    """A DVL update (right-invariant): X <- exp(dxi) X, b <- b + db; returns the NIS too."""
    z, H, N = dvl_innovation(R, v, b, y, cov, omega_m, model)
    dx, P, nis, ok = kalman(P, z, H, N, model.gate_dvl)
    if ok:
        R, v, p, b = right_correct(R, v, p, b, dx)
    return R, v, p, b, P, nis, ok


@njit(cache=True)
def update_attitude(R, v, p, b, P, Rm, cov, model):
    """An attitude update (right-invariant): Rm = Exp(n) R, n ~ N(0, cov) in the world frame,
    z = Log(Rm R_hat^T) = xi_R + n, H = [I, 0, 0, 0, 0]; with the DR-bias states (b of 9)
    Rm = Exp(n) Exp(b_d) R, z = Log(Exp(-b_d_hat) Rm R_hat^T), H = [I, 0, 0, 0, 0, I]."""
    H = np.zeros((3, P.shape[0]))
    H[0:3, 0:3] = np.eye(3)
    if b.size > 6:
        z = so3_log(so3_exp(-b[6:9]) @ Rm @ R.T)
        H[0:3, 15:18] = np.eye(3)
    else:
        z = so3_log(Rm @ R.T)
    dx, P, nis, ok = kalman(P, z, H, cov, model.gate_attitude)
    if ok:
        R, v, p, b = right_correct(R, v, p, b, dx)
    return R, v, p, b, P, nis, ok


@njit(cache=True)
def update_depth(R, v, p, b, P, d, var, model):
    """A depth update in the left-invariant error (module doc): X <- X exp(dxi)."""
    Ri, vi, pi = se23_inverse(R, v, p)
    n = P.shape[0]
    Tl = error_frame(Ri, vi, pi, n)  # right -> left
    Pl = Tl @ P @ Tl.T
    z, H = depth_innovation(R, p, d, model, n)
    N = np.full((1, 1), var)
    dx, Pl, nis, ok = kalman(Pl, z, H, N, model.gate_depth)
    if ok:
        dR, dv, dp = se23_exp(dx[0:9].copy())
        R, v, p = R @ dR, R @ dv + v, R @ dp + p
        b = b + dx[9:]
    Tr = error_frame(R, v, p, n)  # left -> right, at the updated estimate
    P = Tr @ Pl @ Tr.T
    return R, v, p, b, 0.5 * (P + P.T), nis, ok


class InekfRun(NamedTuple):
    """The filter's output after every DVL and depth measurement (M rows)."""

    t: np.ndarray  # (M,) s
    kind: np.ndarray  # (M,) DVL or DEPTH
    R: np.ndarray  # (M, 3, 3) body to world
    v: np.ndarray  # (M, 3) world velocity, m/s
    p: np.ndarray  # (M, 3) world position, m
    b: np.ndarray  # (M, 6 or 9) gyro bias rad/s, accelerometer bias m/s^2 (, DR bias rad)
    P: np.ndarray  # (M, 15 or 18, ...) covariance of the invariant error e
    omega: np.ndarray  # (M, 3) the held gyro reading less the bias, rad/s (body)
    nis: np.ndarray  # (M,) normalized innovation squared
    applied: np.ndarray  # (M,) bool: the update passed the gate


@njit(cache=True)
def _advance(R, v, p, b, P, t, t_end, omega_m, f_m, model):
    """Propagate from t to t_end with the held IMU reading, in steps of at most max_dt (the DR
    bias, when b has it, moves by its mean drift mu_d dt)."""
    if b.size > 6 and t_end > t:
        b = b.copy()
        b[6:9] += model.dr_bias_drift * (t_end - t)
    while t_end - t > 1e-12:
        dt = min(t_end - t, model.max_dt)
        R, v, p, P = propagate(R, v, p, b, P, omega_m, f_m, dt, model)
        t += dt
    return R, v, p, b, P, t_end


@njit(cache=True)
def _first_at_or_after(times, t0):
    i = 0
    while i < times.size and times[i] < t0:
        i += 1
    return i


@njit(cache=True)
def run_kernel(imu_t, gyro, accel, dvl_t, dvl_y, dvl_cov, dep_t, dep_d, dep_var, att_t, att_R,
               att_cov, t0, R, v, p, b, P, model):  # fmt: skip
    """Walk the IMU, DVL, depth and attitude streams in time order from t0 (see run_inekf)."""
    m = dvl_t.size + dep_t.size + att_t.size
    o_t, o_k = np.empty(m), np.empty(m, np.int64)
    o_R, o_v, o_p = np.empty((m, 3, 3)), np.empty((m, 3)), np.empty((m, 3))
    o_b, o_P, o_w = np.empty((m, b.size)), np.empty((m, P.shape[0], P.shape[0])), np.empty((m, 3))
    o_nis, o_ok = np.empty(m), np.zeros(m, np.bool_)
    i = max(_first_at_or_after(imu_t, t0) - 1, 0)  # the reading held at t0
    omega_m, f_m = gyro[i].copy(), accel[i].copy()
    i += 1 if imu_t[i] <= t0 else 0
    j, k = _first_at_or_after(dvl_t, t0), _first_at_or_after(dep_t, t0)
    q, n, t, big = _first_at_or_after(att_t, t0), 0, t0, np.inf
    while j < dvl_t.size or k < dep_t.size or q < att_t.size:
        ti = imu_t[i] if i < imu_t.size else big
        tj = dvl_t[j] if j < dvl_t.size else big
        tk = dep_t[k] if k < dep_t.size else big
        tq = att_t[q] if q < att_t.size else big
        te = min(min(ti, tj), min(tk, tq))
        R, v, p, b, P, t = _advance(R, v, p, b, P, t, te, omega_m, f_m, model)
        if ti == te:  # a new IMU reading (a non-finite one keeps the previous)
            if np.all(np.isfinite(gyro[i])) and np.all(np.isfinite(accel[i])):
                omega_m, f_m = gyro[i].copy(), accel[i].copy()
            i += 1
            continue
        if tj == te:
            y, cov = dvl_y[j].copy(), dvl_cov[j].copy()
            j += 1
            if not (np.all(np.isfinite(y)) and np.all(np.isfinite(cov))):
                continue
            R, v, p, b, P, nis, ok = update_dvl(R, v, p, b, P, y, cov, omega_m, model)
            o_k[n] = DVL
        elif tk == te:
            d, var = dep_d[k], dep_var[k]
            k += 1
            if not (np.isfinite(d) and np.isfinite(var)):
                continue
            R, v, p, b, P, nis, ok = update_depth(R, v, p, b, P, d, var, model)
            o_k[n] = DEPTH
        else:
            Rm, cov = att_R[q].copy(), att_cov[q].copy()
            q += 1
            if not (np.all(np.isfinite(Rm)) and np.all(np.isfinite(cov))):
                continue
            R, v, p, b, P, nis, ok = update_attitude(R, v, p, b, P, Rm, cov, model)
            o_k[n] = ATTITUDE
        o_t[n], o_R[n], o_v[n], o_p[n], o_b[n], o_P[n] = t, R, v, p, b, P
        o_w[n], o_nis[n], o_ok[n] = omega_m - b[0:3], nis, ok
        n += 1
    return (o_t[:n], o_k[:n], o_R[:n], o_v[:n], o_p[:n], o_b[:n], o_P[:n], o_w[:n], o_nis[:n],
            o_ok[:n])  # fmt: skip


def run_inekf(imu_t, gyro, accel, dvl_t, dvl_y, dvl_cov, depth_t, depth, depth_var, *,
              t0, R0, v0, p0, b0, P0, model: InekfModel, attitude=None) -> InekfRun:  # fmt: skip
    """The filter over whole streams (plain arrays, time-ordered; body-frame IMU, DVL-frame
    velocities with their (3, 3) covariances, depths with their variances, optionally
    ``attitude`` = (t, R (m, 3, 3) body to world, world-frame covariance (m, 3, 3))), started at
    t0 from X0 = (R0, v0, p0), b0 = (b_g, b_a) and the invariant-error covariance P0 (15, 15);
    with b0 = (b_g, b_a, b_d) and P0 (18, 18) the DR-bias states run too (module doc).

    Between readings the last IMU sample is held (zero-order hold); a measurement time between
    two IMU samples is reached by a partial step. Rows with non-finite values are skipped; the
    filter stops at the last aiding measurement. Needs at least one IMU sample."""
    f64 = np.float64
    if attitude is None:
        attitude = (np.zeros(0), np.zeros((0, 3, 3)), np.zeros((0, 3, 3)))
    arrays = [np.ascontiguousarray(a, dtype=f64) for a in (imu_t, gyro, accel, dvl_t, dvl_y,
              dvl_cov, depth_t, depth, depth_var, *attitude)]  # fmt: skip
    if arrays[0].size == 0:
        raise ValueError("run_inekf: no IMU samples")
    state = [np.ascontiguousarray(a, dtype=f64) for a in (R0, v0, p0, b0, P0)]
    out = run_kernel(*arrays, float(t0), *state, model)
    return InekfRun(*out)
