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
h the unscented update is exact in closed form (ukf.update_linear): those three update without
drawing sigma points, with H read off h itself (:func:`jacobians`). The barometer's lever arm
makes its model nonlinear in the angles: it updates through sigma points drawn again from the
predicted (x, P).

Bias states no sensor informs are held at 0 with a tiny variance and no correlation: all six
for the variants without bias estimation (``ProcessModel.freeze_bias``), the DR bias b^g for a
log without DR, the IMU gyro bias b-bar^g for one without IMU (``hold_dr_bias``,
``hold_gyro_bias``); the held states are one contiguous range (:func:`held_range`).

The variant ``adaptive-r`` (``SensorModel.adapt_r``) replaces the rows' R of the DVL and DR by
a running estimate per kind, updated after each applied update (:func:`adapt_r`; Akhlaghi,
Zhou and Huang 2017):

    eps_k = z_k - h(x_k^+),   R_k = alpha R_{k-1} + (1 - alpha) (eps_k eps_k^T + H P_k^+ H^T)

starting from the first row's (nominal) R. The other variants take the same path as before
(the branch is off), bit for bit.

The swell in the barometer (beyond the paper, ``LocalizerConfig.pressure_wave_noise``): the
wave's dynamic pressure reaches the barometer as a depth error xi, a narrow-band oscillation
at the wave's frequency, not white noise. Two more states carry it, x[18:20] = (y, xi), the
linear wave model of dynamic positioning (Fossen, "Handbook of Marine Craft Hydrodynamics and
Motion Control", Wiley 2011, ch. 8, the linear wave response approximation):

    y'' + 2 lambda omega_0 y' + omega_0^2 y = w,   xi = y',

whose transfer function from w to xi, s / (s^2 + 2 lambda omega_0 s + omega_0^2), passes
nothing at zero frequency, so the swell cannot take the place of a slow depth change:

    Baro (kind 3):  z = z + e_3^T R_B^W r_bar + xi

The pair moves by the exact transition Phi(dt) = exp(A dt), A = [[0, 1], [-omega_0^2,
-2 lambda omega_0]] (:func:`swell_transition`), with the noise that keeps the stationary
covariance P_inf = diag(sigma^2 / omega_0^2, sigma^2) (for this model var(y') = omega_0^2
var(y) and cov(y, y') = 0): Q_s = P_inf - Phi P_inf Phi^T, exact for any dt. sigma^2 = a^2
K_p^2 / 2 is the swell's pressure head variance at the barometer's depth
(:func:`~undertow.estimation.noise_physics.pressure_head_variance`); the rows carry it with the
wave's frequency omega_0 = 2 pi f and its direction beta (:mod:`undertow.estimation.rows`). A
vehicle moving at v over ground meets the waves at the encounter frequency (:func:`encounter`,
at each step's mean; linear wave theory, e.g. Fossen 2011 ch. 8 and the simulator's
``undertow.sim.waves.encounter_frequency``):

    omega_e = | omega_0 - k_0 (v_x cos beta + v_y sin beta) |,   k_0 = omega_0^2 / g,

at which the band is centred when beta is known; when it is not, the band stays at omega_0 and
widens to the Doppler range any direction allows, lambda_e = max(lambda, k_0 |v_h| / omega_0)
(the band's half-power half-width is lambda omega_0). Without a swell (calm, or a variant
without it) the pair is held at 0 like the bias states. The trajectory holds the 18 states of
the paper (:data:`N_POSE`); the swell states are the filter's own.

The filter loop that walks the measurements with these models is
:mod:`undertow.estimation.filter_loop`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..log import G0
from .ukf import predict_moments, sigma_points, spread, wrap

N_POSE = 18  # the paper's states, what a trajectory holds
SWELL = 18  # first of the two swell states (y, xi), module doc
N_STATE = N_POSE + 2
N_SIGMA = 2 * N_STATE + 1
IMU, DVL, DR, BARO = 0, 1, 2, 3
KIND_NAMES = ("imu", "dvl", "dead_reckoning", "pressure")
KIND_DIM = (3, 3, 3, 1)
STATE_ANGLES = np.zeros(N_STATE, dtype=np.bool_)
STATE_ANGLES[3:6] = True
Z_ANGLES = np.ones(3, dtype=np.bool_)  # the DR measurement: three angles, wrapped
Z_LINEAR = np.zeros(3, dtype=np.bool_)  # IMU, DVL and (first entry) barometer


class ProcessModel(NamedTuple):
    """eq:dynamics_model's parameters and the unscented transform's weights, one record."""

    wm: np.ndarray  # (2n+1,) mean weights W^m
    wc: np.ndarray  # (2n+1,) covariance weights W^c
    lam: float  # lambda = alpha^2 (n + kappa) - n
    q_acc: np.ndarray  # (6,) acceleration densities: linear (m/s^2)^2/Hz, angular (rad/s^2)^2/Hz
    q_bias: np.ndarray  # (6,) bias-walk densities Gamma_b: b^g rad^2/s, b-bar^g (rad/s)^2/s
    mu_bias: np.ndarray  # (6,) mean bias drifts (mu_b, mu-bar_b); zeros when freeze_bias
    dt_max: float  # longest prediction step, s
    freeze_bias: bool  # no bias states: held at 0 with a tiny variance and no correlation
    # held like freeze_bias, one group each, when no sensor informs it (a log without the DR
    # orientation holds b^g = x[12:15], one without the IMU gyro b-bar^g = x[15:18])
    hold_dr_bias: bool = False
    hold_gyro_bias: bool = False
    # the swell model's relative damping lambda (module doc)
    swell_damping: float = 0.1


class SensorModel(NamedTuple):
    """Mounting of the sensors (eq:imu_meas_model .. eq:bar_meas_model) and the gates."""

    imu_Rt: np.ndarray  # (3, 3) R_imu^T, body -> IMU frame
    dvl_Rt: np.ndarray  # (3, 3) R_dvl^T, body -> DVL frame
    dvl_r: np.ndarray  # (3,) DVL lever arm r_dvl, body frame, m
    baro_r: np.ndarray  # (3,) barometer lever arm r_bar, body frame, m
    gate: np.ndarray  # (4,) per kind: largest NIS applied (inf: no gate)
    # innovation-based adaptive R of the DVL and DR (variant adaptive-r, :func:`adapt_r`):
    # on/off and the forgetting factor alpha
    adapt_r: bool = False
    adapt_alpha: float = 1.0


@njit(cache=True)
def rotation(phi, theta, psi, R):
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
def euler_rate(phi, theta, T):
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
def swell_transition(dt, omega, lam, Phi):
    """Phi = exp(A dt) of the swell model, A = [[0, 1], [-omega^2, -2 lambda omega]] (module
    doc), 0 < lambda < 1: with omega_d = omega sqrt(1 - lambda^2), c = cos(omega_d dt),
    s = sin(omega_d dt), e = exp(-lambda omega dt),

        Phi = e [[c + (lambda omega / omega_d) s, s / omega_d],
                 [-(omega^2 / omega_d) s,         c - (lambda omega / omega_d) s]]

    (the damped oscillator's free response). The identity when omega is not finite or 0 (no
    swell: the pair held)."""
    if not (omega > 0.0) or not np.isfinite(omega):
        Phi[0, 0], Phi[0, 1], Phi[1, 0], Phi[1, 1] = 1.0, 0.0, 0.0, 1.0
        return
    wd = omega * np.sqrt(1.0 - lam * lam)
    e = np.exp(-lam * omega * dt)
    c, s = np.cos(wd * dt), np.sin(wd * dt)
    r = lam * omega / wd
    Phi[0, 0] = e * (c + r * s)
    Phi[0, 1] = e * s / wd
    Phi[1, 0] = -e * omega * omega / wd * s
    Phi[1, 1] = e * (c - r * s)


@njit(cache=True)
def encounter(x, omega0, cos_beta, sin_beta, damping, R):
    """(omega_e, lambda_e) of the swell band at the state x (module doc): the encounter frequency
    of the vehicle's velocity over ground v = R_B^W nu (its horizontal part) with waves of
    frequency omega_0 travelling toward beta (cos beta NaN: unknown, the band at omega_0 widened
    to the Doppler range); omega_e at least 0.1 omega_0 (a vehicle riding at the waves' phase
    speed), lambda_e at most 0.9. ``R`` a (3, 3) scratch."""
    rotation(x[3], x[4], x[5], R)
    vx = R[0, 0] * x[6] + R[0, 1] * x[7] + R[0, 2] * x[8]
    vy = R[1, 0] * x[6] + R[1, 1] * x[7] + R[1, 2] * x[8]
    k0 = omega0 * omega0 / G0
    if np.isfinite(cos_beta):
        return max(abs(omega0 - k0 * (vx * cos_beta + vy * sin_beta)), 0.1 * omega0), damping
    return omega0, min(max(damping, k0 * np.sqrt(vx * vx + vy * vy) / omega0), 0.9)


@njit(cache=True)
def swell_noise(Phi, omega, var, Q):
    """Q_s = P_inf - Phi P_inf Phi^T into Q[18:20, 18:20], P_inf = diag(var / omega^2, var)
    (module doc): the noise that keeps the swell's stationary covariance over the step."""
    p_inf = (var / (omega * omega), var)
    for a in range(2):
        for b in range(2):
            v = Phi[a, 0] * p_inf[0] * Phi[b, 0] + Phi[a, 1] * p_inf[1] * Phi[b, 1]
            Q[SWELL + a, SWELL + b] = (p_inf[a] if a == b else 0.0) - v


@njit(cache=True)
def f(x, dt, mu_bias, out, R, T, Phi):
    """Mean of eq:dynamics_model for one state x (noise-free part), given R = R_B^W(eta) and
    T = T(phi, theta) already evaluated at x's angles; the swell states move by ``Phi``
    (:func:`swell_transition`)."""
    for i in range(3):
        out[i] = x[i] + dt * (R[i, 0] * x[6] + R[i, 1] * x[7] + R[i, 2] * x[8])
        out[3 + i] = wrap(x[3 + i] + dt * (T[i, 0] * x[9] + T[i, 1] * x[10] + T[i, 2] * x[11]))
    for i in range(6, 12):
        out[i] = x[i]
    for i in range(6):
        out[12 + i] = x[12 + i] + mu_bias[i] * dt
    y, xi = x[SWELL], x[SWELL + 1]
    out[SWELL] = Phi[0, 0] * y + Phi[0, 1] * xi
    out[SWELL + 1] = Phi[1, 0] * y + Phi[1, 1] * xi


@njit(cache=True)
def process_noise(x, dt, q_acc, q_bias, Q, R, T):
    """Q = G diag(q_acc)/dt G^T (G = [J dt^2/2; I dt]) plus diag(q_bias) dt, J at the mean
    (the swell's block is :func:`swell_noise`'s)."""
    Q[:, :] = 0.0
    rotation(x[3], x[4], x[5], R)
    euler_rate(x[3], x[4], T)
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
def h(kind, x, sensors, out, R):
    """Measurement functions eq:imu_meas_model, eq:dvl_meas_model, eq:dr_meas_model,
    eq:bar_meas_model for one state x (noise-free part)."""
    if kind == IMU:
        Rt = sensors.imu_Rt
        for i in range(3):
            out[i] = Rt[i, 0] * x[9] + Rt[i, 1] * x[10] + Rt[i, 2] * x[11] + x[15 + i]
    elif kind == DVL:
        Rt, r_dvl = sensors.dvl_Rt, sensors.dvl_r
        p, q, r = x[9], x[10], x[11]
        v0 = x[6] + q * r_dvl[2] - r * r_dvl[1]
        v1 = x[7] + r * r_dvl[0] - p * r_dvl[2]
        v2 = x[8] + p * r_dvl[1] - q * r_dvl[0]
        for i in range(3):
            out[i] = Rt[i, 0] * v0 + Rt[i, 1] * v1 + Rt[i, 2] * v2
    elif kind == DR:
        for i in range(3):
            out[i] = wrap(x[3 + i] + x[12 + i])
    else:
        r_bar = sensors.baro_r
        rotation(x[3], x[4], x[5], R)
        out[0] = x[2] + R[2, 0] * r_bar[0] + R[2, 1] * r_bar[1] + R[2, 2] * r_bar[2] + x[SWELL + 1]


@njit(cache=True)
def jacobians(sensors):
    """H (3, n) of the linear models IMU, DVL, DR, column j = h(e_j): (3, 3, n), indexed by
    kind (the barometer's row is unused: it is not linear)."""
    H = np.zeros((3, 3, N_STATE))
    e = np.zeros(N_STATE)
    col = np.empty(3)
    R = np.empty((3, 3))
    for kd in (IMU, DVL, DR):
        for j in range(N_STATE):
            e[j] = 1.0
            h(kd, e, sensors, col, R)
            e[j] = 0.0
            for a in range(3):
                H[kd, a, j] = col[a]
    return H


@njit(cache=True)
def freeze_states(x, P, first=12, last=18):
    """Baseline / AN variants: bias states held at 0 with a tiny variance and no correlation
    (states first..last-1: all six, or one group a log without its sensor cannot inform; the
    swell pair 18..19 when there is no swell)."""
    for i in range(first, last):
        x[i] = 0.0
        for j in range(x.size):
            P[i, j] = 0.0
            P[j, i] = 0.0
        P[i, i] = 1e-12


@njit(cache=True)
def held_range(freeze_bias, hold_dr, hold_gyro):
    """The held bias states as a range first..last-1 (empty: first == last): all six when the
    variant has no bias states, else b^g (12:15) and/or b-bar^g (15:18) when held."""
    first = 12 if (freeze_bias or hold_dr) else 15
    last = 18 if (freeze_bias or hold_gyro) else 15
    if last < first:
        last = first
    return first, last


@njit(cache=True)
def predict_workspace():
    """Scratch arrays of :func:`predict`: chi, f(chi), residuals, L, Q, R, T, a state, the
    swell's Phi."""
    n, npts = N_STATE, N_SIGMA
    return (
        np.empty((npts, n)), np.empty((npts, n)), np.empty((n, npts)), np.zeros((n, n)),
        np.empty((n, n)), np.empty((3, 3)), np.empty((3, 3)), np.empty(n), np.eye(2),
    )  # fmt: skip


@njit(cache=True)
def predict(x, P, dt, wm, wc, lam, q_acc, q_bias, mu_bias, ws, factored=False,
            swell=(np.nan, 0.0, 0.1)):  # fmt: skip
    """Unscented prediction of (x, P) over dt through eq:dynamics_model, in place:
    x = mean_i f(chi_i, dt), P = sum_i W^c_i (f(chi_i) - x)(f(chi_i) - x)^T + Q(x, dt), with
    the fields of :class:`ProcessModel` as arguments. ``swell`` = (omega rad/s, sigma^2 m^2,
    lambda) of the swell states' band (module doc); with sigma^2 = 0 they keep Phi = I and no
    noise (the caller holds them).

    ``factored``: the workspace's L already holds the Cholesky factor of P (skip factorizing)."""
    chi, chi_f, D, L, Q, R, T, xi, Phi = ws
    omega, var, damping = swell
    active = var > 0.0 and omega > 0.0
    swell_transition(dt, omega if active else np.nan, damping, Phi)
    if factored:
        status = 0
        spread(x, L, lam, STATE_ANGLES, chi)
    else:
        status = sigma_points(x, P, lam, STATE_ANGLES, L, chi)
    # L is lower triangular, so most sigma points share chi_0's angles: trig only when they change
    a0, a1, a2 = np.nan, np.nan, np.nan
    for i in range(chi.shape[0]):
        if not (chi[i, 3] == a0 and chi[i, 4] == a1 and chi[i, 5] == a2):
            a0, a1, a2 = chi[i, 3], chi[i, 4], chi[i, 5]
            rotation(a0, a1, a2, R)
            euler_rate(a0, a1, T)
        f(chi[i], dt, mu_bias, chi_f[i], R, T, Phi)
    process_noise(x, dt, q_acc, q_bias, Q, R, T)
    if active:
        swell_noise(Phi, omega, var, Q)
    predict_moments(chi_f, wm, wc, Q, STATE_ANGLES, x, P, D)
    return status


@njit(cache=True)
def adapt_r(Ra, alpha, z, x, P, H, angles):
    """Innovation-based adaptive R (Akhlaghi, Zhou and Huang, "Adaptive adjustment of noise
    covariance in Kalman filter for dynamic state estimation", IEEE PES General Meeting 2017,
    eq. 12; after Mehra 1970 and Sage and Husa 1969), in place, after an applied update:

        eps_k = z_k - h(x_k^+)                 (the residual after the update, angles wrapped)
        R_k   = alpha R_{k-1} + (1 - alpha) (eps_k eps_k^T + H P_k^+ H^T)

    For a linear h, eps = R S^-1 nu, so E[eps eps^T] + H P^+ H^T = R S^-1 R + (S - R)
    - (S - R) S^-1 (S - R) = R: the update is unbiased when R is right, and drifts to the
    residuals' actual spread when it is not. The result is symmetrized."""
    m = 3
    n = x.size
    eps = np.empty(m)
    for a in range(m):
        s = 0.0
        for j in range(n):
            s += H[a, j] * x[j]
        e = z[a] - s
        eps[a] = wrap(e) if angles else e
    HP = np.empty((m, n))
    for a in range(m):
        for j in range(n):
            s = 0.0
            for i in range(n):
                s += H[a, i] * P[i, j]
            HP[a, j] = s
    for a in range(m):
        for b in range(a, m):
            s = 0.0
            for j in range(n):
                s += HP[a, j] * H[b, j]
            v = alpha * 0.5 * (Ra[a, b] + Ra[b, a]) + (1.0 - alpha) * (eps[a] * eps[b] + s)
            Ra[a, b] = v
            Ra[b, a] = v
