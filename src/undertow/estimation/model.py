"""The paper's 18-state underwater model (eq:state .. eq:dr_meas_model) and its filter loop.

State (eq:state, eq:eta, eq:nu, eq:gyro_bias), layout of :mod:`undertow.trajectory`:

    x = [eta^W (x, y, z, phi, theta, psi), nu^B (u, v, w, p, q, r), b^g (3), b-bar^g (3)]

The paper names b^g the dead-reckoning (DVL) bias and b-bar^g the IMU gyro bias (eq:gyro_bias)
but eq:imu_meas_model / eq:dr_meas_model attach them the other way round. We resolve it by
sensor: the IMU measurement uses the IMU gyro bias b-bar^g = x[15:18] (rad/s) and the DR
orientation uses the DR bias b^g = x[12:15] (rad, an orientation offset whose mean drift mu_b is
the DVL gyro's bias in rad/s).

Motion (eq:dynamics_model), constant velocity by forward Euler, acceleration omega_t as noise:

    eta_t = eta + J(eta) (nu dt + omega_t dt^2 / 2),   nu_t = nu + omega_t dt,
    b_t = b + mu_b dt + omega^b_t,   b-bar_t = b-bar + mu-bar_b dt + omega-bar^b_t

J(eta) = diag(R_B^W(phi, theta, psi), T(phi, theta)): the paper writes R_B^W for both parts;
we use the rotation for the linear velocity and the Euler-rate transform T for the angular
velocity (the standard 6-DOF kinematics, Fossen), so that rpy-rates are correct off level.
Process noise convention: Gamma = diag(q) / dt with q the continuous-time acceleration
white-noise density ((m/s^2)^2/Hz, (rad/s^2)^2/Hz), entering through G = [J dt^2/2; I dt], so
Q = G Gamma G^T gives velocity variance q dt per step (independent of the measurement rate),
position variance J q J^T dt^3/4 and cross terms J q dt^2/2. Bias walks: Gamma_b dt with
Gamma_b a density (rad^2/s for b^g, (rad/s)^2/s for b-bar^g).

Measurements (eq:bar_meas_model .. eq:dr_meas_model), additive Gaussian noise:

    IMU  (kind 0):  z = R_imu^T omega + b-bar^g                         (rad/s, IMU frame)
    DVL  (kind 1):  z = R_dvl^T (v + omega x r_dvl) + gamma_DVL         (m/s, DVL frame)
    DR   (kind 2):  z = (phi, theta, psi) + b^g + gamma_DR              (rad, wrapped)
    Baro (kind 3):  z = z + e_3^T R_B^W r_bar                           (m, depth)

The wave noise gamma enters as extra variance in R (eq:dvl_meas_model). The IMU, DVL and DR
models are linear in the state, h(x) = H x (the paper writes all four as H x), and for a linear
h the unscented update is exact in closed form (ukf._update_linear): those three update without
drawing sigma points, with H read off _h itself (:func:`_jacobians`). The barometer's lever arm
makes its model nonlinear in the angles: it updates through sigma points drawn again from the
predicted (x, P). The loop :func:`_run_filter` walks a merged, time-sorted measurement array: it
predicts to each measurement's time (no prediction when dt <= 0, dt capped at dt_max) and
updates; see :mod:`undertow.estimation.localizer` for the Python side.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .ukf import (
    _cholesky_repair,
    _predict_moments,
    _sigma_points,
    _spread,
    _update,
    _update_linear,
    _wrap,
)

N_STATE = 18
IMU, DVL, DR, BARO = 0, 1, 2, 3
KIND_NAMES = ("imu", "dvl", "dead_reckoning", "pressure")
KIND_DIM = (3, 3, 3, 1)
STATE_ANGLES = np.zeros(N_STATE, dtype=np.bool_)
STATE_ANGLES[3:6] = True
# counters returned by _run_filter (after 4 "used" and 4 "gated" counters, one per kind)
COUNT_NAMES = (
    "used_imu", "used_dvl", "used_dead_reckoning", "used_pressure",
    "gated_imu", "gated_dvl", "gated_dead_reckoning", "gated_pressure",
    "nonfinite_rejected", "dt_capped", "no_predict_dt_nonpositive", "cholesky_repairs",
    "numerical_reverts",
)  # fmt: skip
# NIS accumulators (optional last argument of _run_filter), one row per kind:
# [sum of nu^T S^-1 nu, innovations evaluated, innovations with nis <= CHI2_95[kind]]
NIS_FIELDS = ("nis_sum", "count", "in_95")
CHI2_95 = np.array([7.814727903251179, 7.814727903251179, 7.814727903251179, 3.841458820694124])


@njit(cache=True)
def _rotation(phi, theta, psi, R):
    """R_B^W = Rz(psi) Ry(theta) Rx(phi)."""
    cr, sr = np.cos(phi), np.sin(phi)
    cp, sp = np.cos(theta), np.sin(theta)
    cy, sy = np.cos(psi), np.sin(psi)
    R[0, 0] = cy * cp
    R[0, 1] = cy * sp * sr - sy * cr
    R[0, 2] = cy * sp * cr + sy * sr
    R[1, 0] = sy * cp
    R[1, 1] = sy * sp * sr + cy * cr
    R[1, 2] = sy * sp * cr - cy * sr
    R[2, 0] = -sp
    R[2, 1] = cp * sr
    R[2, 2] = cp * cr


@njit(cache=True)
def _euler_rate(phi, theta, T):
    """T(phi, theta): (phi, theta, psi)-rates = T omega (cos theta kept away from 0)."""
    cr, sr = np.cos(phi), np.sin(phi)
    cp, sp = np.cos(theta), np.sin(theta)
    if abs(cp) < 1e-6:
        cp = 1e-6 if cp >= 0 else -1e-6
    T[0, 0] = 1.0
    T[0, 1] = sr * sp / cp
    T[0, 2] = cr * sp / cp
    T[1, 0] = 0.0
    T[1, 1] = cr
    T[1, 2] = -sr
    T[2, 0] = 0.0
    T[2, 1] = sr / cp
    T[2, 2] = cr / cp


@njit(cache=True)
def _f(x, dt, mu_bias, out, R, T):
    """Mean of eq:dynamics_model for one state x (noise-free part), given R = R_B^W(eta) and
    T = T(phi, theta) already evaluated at x's angles."""
    for i in range(3):
        out[i] = x[i] + dt * (R[i, 0] * x[6] + R[i, 1] * x[7] + R[i, 2] * x[8])
        out[3 + i] = _wrap(x[3 + i] + dt * (T[i, 0] * x[9] + T[i, 1] * x[10] + T[i, 2] * x[11]))
    for i in range(6, 12):
        out[i] = x[i]
    for i in range(6):
        out[12 + i] = x[12 + i] + mu_bias[i] * dt


@njit(cache=True)
def _process_noise(x, dt, q_acc, q_bias, Q, R, T):
    """Q = G diag(q_acc)/dt G^T (G = [J dt^2/2; I dt]) plus diag(q_bias) dt, J at the mean."""
    Q[:, :] = 0.0
    _rotation(x[3], x[4], x[5], R)
    _euler_rate(x[3], x[4], T)
    for blk in range(2):
        J = R if blk == 0 else T
        o = 3 * blk
        q = q_acc[o : o + 3]
        for i in range(3):
            for j in range(3):
                s = 0.0
                for k in range(3):
                    s += J[i, k] * q[k] * J[j, k]
                Q[o + i, o + j] = s * dt**3 / 4.0
            for k in range(3):
                c = J[i, k] * q[k] * dt**2 / 2.0
                Q[o + i, 6 + o + k] = c
                Q[6 + o + k, o + i] = c
            Q[6 + o + i, 6 + o + i] = q[i] * dt
    for i in range(6):
        Q[12 + i, 12 + i] = q_bias[i] * dt


@njit(cache=True)
def _h(kind, x, imu_Rt, dvl_Rt, dvl_r, baro_r, out, R):
    """Measurement functions eq:imu_meas_model, eq:dvl_meas_model, eq:dr_meas_model,
    eq:bar_meas_model for one state x (noise-free part)."""
    if kind == IMU:
        for i in range(3):
            out[i] = imu_Rt[i, 0] * x[9] + imu_Rt[i, 1] * x[10] + imu_Rt[i, 2] * x[11] + x[15 + i]
    elif kind == DVL:
        p, q, r = x[9], x[10], x[11]
        v0 = x[6] + q * dvl_r[2] - r * dvl_r[1]
        v1 = x[7] + r * dvl_r[0] - p * dvl_r[2]
        v2 = x[8] + p * dvl_r[1] - q * dvl_r[0]
        for i in range(3):
            out[i] = dvl_Rt[i, 0] * v0 + dvl_Rt[i, 1] * v1 + dvl_Rt[i, 2] * v2
    elif kind == DR:
        for i in range(3):
            out[i] = _wrap(x[3 + i] + x[12 + i])
    else:
        _rotation(x[3], x[4], x[5], R)
        out[0] = x[2] + R[2, 0] * baro_r[0] + R[2, 1] * baro_r[1] + R[2, 2] * baro_r[2]


@njit(cache=True)
def _all_finite(a):
    """No NaN or infinity in a (a sum propagates either; a finite overflow to inf also counts
    as not finite, which is what the callers want)."""
    return np.isfinite(a.sum())


@njit(cache=True)
def _jacobians(imu_Rt, dvl_Rt, dvl_r, baro_r):
    """H (3, 18) of the linear models IMU, DVL, DR, column j = h(e_j): (3, 3, 18), indexed by
    kind (the barometer's row is unused: it is not linear)."""
    H = np.zeros((3, 3, N_STATE))
    e = np.zeros(N_STATE)
    col = np.empty(3)
    R = np.empty((3, 3))
    for kd in (IMU, DVL, DR):
        for j in range(N_STATE):
            e[j] = 1.0
            _h(kd, e, imu_Rt, dvl_Rt, dvl_r, baro_r, col, R)
            e[j] = 0.0
            for a in range(3):
                H[kd, a, j] = col[a]
    return H


@njit(cache=True)
def _freeze_bias(x, P):
    """Baseline / AN variants: bias states held at 0 with a tiny variance and no correlation."""
    for i in range(12, 18):
        x[i] = 0.0
        for j in range(18):
            P[i, j] = 0.0
            P[j, i] = 0.0
        P[i, i] = 1e-12


@njit(cache=True)
def _predict(x, P, dt, wm, wc, lam, q_acc, q_bias, mu_bias, ws, factored=False):
    """Unscented prediction of (x, P) over dt through eq:dynamics_model, in place.

    ``factored``: the workspace's L already holds the Cholesky factor of P (skip factorizing)."""
    chi, chi_f, D, L, Q, R, T, xi = ws
    if factored:
        status = 0
        _spread(x, L, lam, STATE_ANGLES, chi)
    else:
        status = _sigma_points(x, P, lam, STATE_ANGLES, L, chi)
    # L is lower triangular, so most sigma points share chi_0's angles: trig only when they change
    a0, a1, a2 = np.nan, np.nan, np.nan
    for i in range(chi.shape[0]):
        if not (chi[i, 3] == a0 and chi[i, 4] == a1 and chi[i, 5] == a2):
            a0, a1, a2 = chi[i, 3], chi[i, 4], chi[i, 5]
            _rotation(a0, a1, a2, R)
            _euler_rate(a0, a1, T)
        _f(chi[i], dt, mu_bias, chi_f[i], R, T)
    _process_noise(x, dt, q_acc, q_bias, Q, R, T)
    _predict_moments(chi_f, wm, wc, Q, STATE_ANGLES, x, P, D)
    return status


@njit(cache=True)
def _run_filter(
    t, kind, z, Rm, x0, P0, t0, wm, wc, lam, q_acc, q_bias, mu_bias,
    imu_Rt, dvl_Rt, dvl_r, baro_r, dt_max, gate, freeze, out_times, record_all, out_n,
    nis_stats=None,
):  # fmt: skip
    """Walk the merged measurements (t, kind, z (N, 3), Rm (N, 3, 3)) in order: predict to each
    measurement time (none if dt <= 0, dt capped at dt_max), redraw sigma points, update.

    Records (x, P) after the last update at each distinct time (record_all) or, otherwise, at
    ``out_times`` (the filter predicted to that time; the filter itself is not changed). A
    recorded P that is not positive definite (rounding after extreme updates) is repaired
    first, as the next sigma-point draw would do, so every emitted covariance is SPD.
    Returns (out_t, out_x, out_P, counts) with counts as in COUNT_NAMES.

    ``nis_stats`` (optional, (4, 3) float, zeroed by the caller) accumulates per kind the
    normalized innovation squared NIS = nu^T S^-1 nu of every innovation evaluated (applied or
    gated; not when S cannot be factorized): rows as in NIS_FIELDS. For a consistent filter
    E[NIS] = dim z (KIND_DIM) and NIS <= CHI2_95[kind] with probability 0.95.
    """
    n = N_STATE
    npts = 2 * n + 1
    x = x0.copy()
    P = P0.copy()
    if freeze:
        _freeze_bias(x, P)
    counts = np.zeros(len(COUNT_NAMES), dtype=np.int64)
    out_t = np.empty(out_n)
    out_x = np.empty((out_n, n))
    out_P = np.empty((out_n, n, n))
    ws = (
        np.empty((npts, n)), np.empty((npts, n)), np.empty((n, npts)), np.zeros((n, n)),
        np.empty((n, n)), np.empty((3, 3)), np.empty((3, 3)), np.empty(n),
    )  # fmt: skip
    chi, L, R = ws[0], ws[3], ws[5]
    H = _jacobians(imu_Rt, dvl_Rt, dvl_r, baro_r)
    Zs1 = np.empty((npts, 1))
    zk3 = np.empty(3)
    zk1 = np.empty(1)
    Rk3 = np.empty((3, 3))
    Rk1 = np.empty((1, 1))
    zi = np.empty(3)
    zmask_angle = np.ones(3, dtype=np.bool_)
    zmask_lin = np.zeros(3, dtype=np.bool_)
    zmask_lin1 = np.zeros(1, dtype=np.bool_)
    no_mu = np.zeros(6)
    mu = no_mu if freeze else mu_bias
    xb = np.empty(n)
    Pb = np.empty((n, n))
    t_cur = t0
    factored = False  # L holds the Cholesky factor of the current P
    k_out = 0
    j_out = 0
    N = t.size
    for k in range(N + 1):
        tk = t[k] if k < N else np.inf
        while not record_all and j_out < out_times.size and out_times[j_out] < tk:
            if k_out < out_n:
                xb[:] = x
                Pb[:, :] = P
                dt = min(out_times[j_out] - t_cur, dt_max)
                if dt > 0:
                    counts[11] += max(_predict(xb, Pb, dt, wm, wc, lam, q_acc, q_bias, mu, ws), 0)
                counts[11] += max(_cholesky_repair(Pb, L), 0)  # emit only a PD covariance
                factored = False  # L now belongs to Pb
                out_t[k_out] = out_times[j_out]
                out_x[k_out] = xb
                out_P[k_out] = Pb
                k_out += 1
            j_out += 1
        if k == N:
            break
        kd = kind[k]
        m = 1 if kd == BARO else 3
        zk = zk1 if m == 1 else zk3
        Rk = Rk1 if m == 1 else Rk3
        for a in range(m):
            zk[a] = z[k, a]
            for b in range(m):
                Rk[a, b] = Rm[k, a, b]
        if not (_all_finite(zk) and _all_finite(Rk)):
            counts[8] += 1
        else:
            dt = tk - t_cur
            if dt > 0:
                if dt > dt_max:
                    dt = dt_max
                    counts[9] += 1
                xb[:] = x
                Pb[:, :] = P
                counts[11] += max(
                    _predict(x, P, dt, wm, wc, lam, q_acc, q_bias, mu, ws, factored), 0
                )
                if not (_all_finite(x) and _all_finite(P)):
                    x[:] = xb
                    P[:, :] = Pb
                    counts[12] += 1
                if freeze:
                    _freeze_bias(x, P)
                t_cur = tk
            else:
                counts[10] += 1
            factored = False
            xb[:] = x
            Pb[:, :] = P
            zmask = zmask_angle if kd == DR else (zmask_lin1 if m == 1 else zmask_lin)
            if kd == BARO:
                counts[11] += max(_sigma_points(x, P, lam, STATE_ANGLES, L, chi), 0)
                for i in range(npts):
                    _h(kd, chi[i], imu_Rt, dvl_Rt, dvl_r, baro_r, zi, R)
                    Zs1[i, 0] = zi[0]
                status, nis = _update(x, P, chi, Zs1, zk, Rk, wm, wc, STATE_ANGLES, zmask, gate[kd])
            else:
                status, nis = _update_linear(x, P, H[kd], zk, Rk, STATE_ANGLES, zmask, gate[kd])
            if nis_stats is not None and status < 2 and np.isfinite(nis):
                nis_stats[kd, 0] += nis
                nis_stats[kd, 1] += 1.0
                if nis <= CHI2_95[kd]:
                    nis_stats[kd, 2] += 1.0
            if status == 0 and _all_finite(x) and _all_finite(P):
                counts[kd] += 1
            else:
                if status == 1:
                    counts[4 + kd] += 1
                else:
                    counts[12] += 1
                x[:] = xb
                P[:, :] = Pb
            if freeze:
                _freeze_bias(x, P)
        if record_all and k_out < out_n and (k == N - 1 or t[k + 1] != tk):
            # the repair the next sigma-point draw would make, done now: every emitted
            # covariance is symmetric positive definite (the next draw then needs none)
            counts[11] += max(_cholesky_repair(P, L), 0)
            factored = True
            out_t[k_out] = tk
            out_x[k_out] = x
            out_P[k_out] = P
            k_out += 1
    return out_t[:k_out], out_x[:k_out], out_P[:k_out], counts
