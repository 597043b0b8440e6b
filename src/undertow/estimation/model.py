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
predicted (x, P).

Bias states no sensor informs are held at 0 with a tiny variance and no correlation: all six
for the variants without bias estimation (``ProcessModel.freeze_bias``), the DR bias b^g for a
log without DR, the IMU gyro bias b-bar^g for one without IMU (``hold_dr_bias``,
``hold_gyro_bias``); the held states are one contiguous range (:func:`held_range`).

The variant ``adaptive-r`` (``SensorModel.adapt_r``) replaces the rows' R of the DVL and DR by
a running estimate per kind, updated after each applied update (:func:`_adapt_r`; Akhlaghi,
Zhou and Huang 2017):

    eps_k = z_k - h(x_k^+),   R_k = alpha R_{k-1} + (1 - alpha) (eps_k eps_k^T + H P_k^+ H^T)

starting from the first row's (nominal) R. The other variants take the same path as before
(the branch is off), bit for bit.

The filter's boundary (:func:`_run_filter`) is a few named things: the merged, time-sorted
measurements as one structured array (:data:`MEASUREMENT`: t, kind, z, R), the process model
and the unscented weights as one record (:class:`ProcessModel`), the sensors' mounting and
gates as another (:class:`SensorModel`), the start (t0, x0, P0) and the output times. The loop
predicts to each measurement's time (no prediction when dt <= 0, dt capped at dt_max) and
updates; counters are indexed by the names in :data:`COUNT_NAMES`. The records are built from a
:class:`~undertow.estimation.config.LocalizerConfig` by its ``process_model`` and
``sensor_model``; :mod:`undertow.estimation.localizer` is the Python side.
"""

from __future__ import annotations

from typing import NamedTuple

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
N_SIGMA = 2 * N_STATE + 1
IMU, DVL, DR, BARO = 0, 1, 2, 3
KIND_NAMES = ("imu", "dvl", "dead_reckoning", "pressure")
KIND_DIM = (3, 3, 3, 1)
STATE_ANGLES = np.zeros(N_STATE, dtype=np.bool_)
STATE_ANGLES[3:6] = True
Z_ANGLES = np.ones(3, dtype=np.bool_)  # the DR measurement: three angles, wrapped
Z_LINEAR = np.zeros(3, dtype=np.bool_)  # IMU, DVL and (first entry) barometer

# one merged measurement: time (s), kind (IMU, DVL, DR, BARO), z (the first KIND_DIM[kind]
# entries used) and its noise covariance R (the leading KIND_DIM[kind] square block used)
MEASUREMENT = np.dtype(
    [("t", np.float64), ("kind", np.int64), ("z", np.float64, (3,)), ("R", np.float64, (3, 3))]
)

# counters returned by _run_filter: "used" and "gated" one per kind (index USED + kind,
# GATED + kind), then the others, each indexed by its constant below
COUNT_NAMES = (
    "used_imu", "used_dvl", "used_dead_reckoning", "used_pressure",
    "gated_imu", "gated_dvl", "gated_dead_reckoning", "gated_pressure",
    "nonfinite_rejected", "dt_capped", "no_predict_dt_nonpositive", "cholesky_repairs",
    "numerical_reverts",
)  # fmt: skip
USED = COUNT_NAMES.index("used_imu")
GATED = COUNT_NAMES.index("gated_imu")
NONFINITE_REJECTED = COUNT_NAMES.index("nonfinite_rejected")
DT_CAPPED = COUNT_NAMES.index("dt_capped")
NO_PREDICT = COUNT_NAMES.index("no_predict_dt_nonpositive")
REPAIRS = COUNT_NAMES.index("cholesky_repairs")
REVERTS = COUNT_NAMES.index("numerical_reverts")
# NIS accumulators returned by _run_filter, one row per kind:
# [sum of nu^T S^-1 nu, innovations evaluated, innovations with nis <= CHI2_95[kind]]
NIS_FIELDS = ("nis_sum", "count", "in_95")
CHI2_95 = np.array([7.814727903251179, 7.814727903251179, 7.814727903251179, 3.841458820694124])


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


class SensorModel(NamedTuple):
    """Mounting of the sensors (eq:imu_meas_model .. eq:bar_meas_model) and the gates."""

    imu_Rt: np.ndarray  # (3, 3) R_imu^T, body -> IMU frame
    dvl_Rt: np.ndarray  # (3, 3) R_dvl^T, body -> DVL frame
    dvl_r: np.ndarray  # (3,) DVL lever arm r_dvl, body frame, m
    baro_r: np.ndarray  # (3,) barometer lever arm r_bar, body frame, m
    gate: np.ndarray  # (4,) per kind: largest NIS applied (inf: no gate)
    # innovation-based adaptive R of the DVL and DR (variant adaptive-r, :func:`_adapt_r`):
    # on/off and the forgetting factor alpha
    adapt_r: bool = False
    adapt_alpha: float = 1.0


class FilterState(NamedTuple):
    """Everything the filter loop carries from one measurement to the next, advanced in place:
    the estimate (x, P), the Cholesky factor L of P (valid when ``clock[2]``), ``clock`` =
    (t_cur: the time (x, P) are predicted to, t_last: the last row's time, factored, emit_due:
    the state at t_last is not yet recorded), adaptive-r's running R per kind (``Ra``) and
    whether it started (``adapted``), the counters (COUNT_NAMES) and NIS sums (NIS_FIELDS)."""

    x: np.ndarray
    P: np.ndarray
    L: np.ndarray
    clock: np.ndarray
    Ra: np.ndarray
    adapted: np.ndarray
    counts: np.ndarray
    nis: np.ndarray

    def copy(self) -> FilterState:
        return FilterState(*(a.copy() for a in self))


@njit(cache=True)
def start_state(t0, x0, P0, process, Ra):
    """The :class:`FilterState` at t0: (x0, P0), the held bias states frozen, no output yet;
    ``Ra`` (4, 3, 3) receives adaptive-r's running R."""
    x = x0.copy()
    P = P0.copy()
    first, last = held_range(process.freeze_bias, process.hold_dr_bias, process.hold_gyro_bias)
    if last > first:
        _freeze_bias(x, P, first, last)
    clock = np.array([t0, np.nan, 0.0, 0.0])
    return FilterState(x, P, np.zeros((N_STATE, N_STATE)), clock, Ra,
                       np.zeros(4, dtype=np.bool_), np.zeros(len(COUNT_NAMES), dtype=np.int64),
                       np.zeros((4, len(NIS_FIELDS))))  # fmt: skip


def resume_filter(meas, state: FilterState, process, sensors, flush: bool):
    """Filter the rows ``meas`` (:data:`MEASUREMENT`, time-sorted, none before the state's last
    row) from ``state``, advanced in place. Returns (out_t, out_x, out_P): the states recorded,
    one per distinct time; the last row's state is recorded only with ``flush`` (else when the
    next call's first row has a later time), so rows fed in any pieces give the outputs and
    final state of one :func:`_run_filter` over them all, bit for bit."""
    t, kind, z, R = _columns(meas)
    n_out = _distinct_times(t) + 1 if t.size else 1
    return _filter_from(
        t, kind, z, R, state, process, sensors, None, n_out, flush, np.empty((0, 3))
    )


def pack_measurements(t, kind, z, R) -> np.ndarray:
    """The structured :data:`MEASUREMENT` array of (t (N,), kind (N,), z (N, 3), R (N, 3, 3))."""
    meas = np.empty(len(t), MEASUREMENT)
    meas["t"], meas["kind"], meas["z"], meas["R"] = t, kind, z, R
    return meas


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
def _h(kind, x, sensors, out, R):
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
            out[i] = _wrap(x[3 + i] + x[12 + i])
    else:
        r_bar = sensors.baro_r
        _rotation(x[3], x[4], x[5], R)
        out[0] = x[2] + R[2, 0] * r_bar[0] + R[2, 1] * r_bar[1] + R[2, 2] * r_bar[2]


@njit(cache=True)
def _all_finite(a):
    """No NaN or infinity in a (a sum propagates either; a finite overflow to inf also counts
    as not finite, which is what the callers want)."""
    return np.isfinite(a.sum())


@njit(cache=True)
def _jacobians(sensors):
    """H (3, 18) of the linear models IMU, DVL, DR, column j = h(e_j): (3, 3, 18), indexed by
    kind (the barometer's row is unused: it is not linear)."""
    H = np.zeros((3, 3, N_STATE))
    e = np.zeros(N_STATE)
    col = np.empty(3)
    R = np.empty((3, 3))
    for kd in (IMU, DVL, DR):
        for j in range(N_STATE):
            e[j] = 1.0
            _h(kd, e, sensors, col, R)
            e[j] = 0.0
            for a in range(3):
                H[kd, a, j] = col[a]
    return H


@njit(cache=True)
def _freeze_bias(x, P, first=12, last=18):
    """Baseline / AN variants: bias states held at 0 with a tiny variance and no correlation
    (states first..last-1: all six, or one group a log without its sensor cannot inform)."""
    for i in range(first, last):
        x[i] = 0.0
        for j in range(18):
            P[i, j] = 0.0
            P[j, i] = 0.0
        P[i, i] = 1e-12


@njit(cache=True)
def _predict_workspace():
    """Scratch arrays of :func:`_predict`: chi, f(chi), residuals, L, Q, R, T, a state."""
    n, npts = N_STATE, N_SIGMA
    return (
        np.empty((npts, n)), np.empty((npts, n)), np.empty((n, npts)), np.zeros((n, n)),
        np.empty((n, n)), np.empty((3, 3)), np.empty((3, 3)), np.empty(n),
    )  # fmt: skip


@njit(cache=True)
def _predict(x, P, dt, wm, wc, lam, q_acc, q_bias, mu_bias, ws, factored=False):
    """Unscented prediction of (x, P) over dt through eq:dynamics_model, in place:
    x = mean_i f(chi_i, dt), P = sum_i W^c_i (f(chi_i) - x)(f(chi_i) - x)^T + Q(x, dt), with
    the fields of :class:`ProcessModel` as arguments.

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
def _run_filter(meas, t0, x0, P0, process, sensors, out_times, r_adapted=None, innovations=None):
    """Walk the merged measurements ``meas`` (:data:`MEASUREMENT`, time-sorted) from (t0, x0,
    P0) with the model ``process`` (:class:`ProcessModel`) and ``sensors``
    (:class:`SensorModel`): predict to each measurement time (none if dt <= 0, dt capped at
    dt_max), redraw sigma points, update.

    Records (x, P) after the last update at each distinct time (``out_times`` None) or at
    ``out_times`` (predicted on a copy to each; the filter itself is not changed). A recorded P
    that is not positive definite (rounding after extreme updates) is repaired first, as the
    next sigma-point draw would do, so every emitted covariance is SPD.

    Returns (out_t, out_x, out_P, counts, nis): counts as in COUNT_NAMES; nis (4, 3) per kind
    as in NIS_FIELDS, over every innovation evaluated (applied or gated; not when S cannot be
    factorized), NIS = nu^T S^-1 nu. For a consistent filter E[NIS] = dim z (KIND_DIM) and
    NIS <= CHI2_95[kind] with probability 0.95.

    ``r_adapted`` (4, 3, 3), optional: receives the final adapted R per kind when
    ``sensors.adapt_r`` (the nominal R of the first row of a kind never adapted; zeros for a
    kind without rows).

    ``innovations`` (N, 3), optional, filled with NaN by the caller: row k receives the whitened
    innovation w_k = L_S^-1 (z_k - h(x_k^-)) of measurement k (S = L_S L_S^T; its first
    KIND_DIM entries, NIS_k = w_k^T w_k), for every innovation evaluated (applied or gated);
    NaN where none was (a non-finite row, S not factorizable). For a consistent filter the
    w_k are N(0, I) and white (:mod:`undertow.estimation.consistency`).

    The loop's whole state is a :class:`FilterState` (:func:`start_state`), advanced in place,
    so a caller may also feed the rows in pieces (:func:`resume_filter`, the online filter)
    with the same arithmetic in the same order.

    The records are unpacked (:func:`_filter_from`) into explicit arguments of :func:`_filter`:
    numba keeps arguments in registers through the loop, while it reloads arrays taken out of
    a tuple in the loop (about 10 % more time per step in benchmarks/bench_ukf.py).
    """
    t, kind, z, R = _columns(meas)
    if out_times is None:
        n_out = _distinct_times(t)
    else:
        n_out = out_times.size
    if r_adapted is None:
        Ra = np.zeros((4, 3, 3))
    else:
        Ra = r_adapted
    state = start_state(t0, x0, P0, process, Ra)
    if innovations is None:
        record = np.empty((0, 3))
    else:
        record = innovations
    out = _filter_from(t, kind, z, R, state, process, sensors, out_times, n_out, True, record)
    return out[0], out[1], out[2], state.counts, state.nis


@njit(cache=True, nogil=True)  # the link threads run while the filter loops
def _filter_from(t, kind, z, R, state, process, sensors, out_times, n_out, flush, record):
    """:func:`_filter` from ``state`` (:class:`FilterState`, advanced in place); ``record``:
    the whitened innovations per row (:func:`_run_filter`), or (0, 3) for none."""
    wm, wc, lam, q_acc, q_bias, mu_bias, dt_max, freeze_bias, hold_dr, hold_gyro = process
    first, last = held_range(freeze_bias, hold_dr, hold_gyro)
    x, P, L, clock, Ra, adapted, counts, nis = state
    return _filter(t, kind, z, R, x, P, L, clock, wm, wc, lam, q_acc, q_bias, mu_bias, dt_max,
                   last > first, first, last, _jacobians(sensors), sensors.gate, sensors,
                   out_times, n_out, sensors.adapt_r, sensors.adapt_alpha, Ra, adapted, counts,
                   nis, flush, record)  # fmt: skip


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
def _columns(meas):
    """The fields of the :data:`MEASUREMENT` array as contiguous arrays (t, kind, z, R)."""
    N = meas.size
    t, kind = np.empty(N), np.empty(N, np.int64)
    z, R = np.empty((N, 3)), np.empty((N, 3, 3))
    for k in range(N):
        t[k] = meas[k].t
        kind[k] = meas[k].kind
        z[k] = meas[k].z
        R[k] = meas[k].R
    return t, kind, z, R


@njit(cache=True)
def _distinct_times(t):
    """Number of distinct consecutive times in the (sorted) t."""
    n = 1
    for k in range(1, t.size):
        if t[k] != t[k - 1]:
            n += 1
    return n


@njit(cache=True)
def _filter(t, kind, z, R, x, P, L_in, clock, wm, wc, lam, q_acc, q_bias, mu, dt_max, freeze,
            first, last, H, gate, sensors, out_times, n_out, adapt, alpha, Ra, adapted, counts,
            nis, flush, record):  # fmt: skip
    """The loop of :func:`_run_filter` over its unpacked records, from the state (x, P, L_in,
    clock, Ra, adapted, counts, nis) of a :class:`FilterState`, advanced in place;
    H = _jacobians(sensors); states first..last-1 held when ``freeze``; ``adapt``: the DVL and
    DR use the adapted R of :func:`_adapt_r` (in Ra, per kind) instead of their rows' R.
    The state at a time is recorded when the next row's time differs, the last one only when
    ``flush``; ``record`` (N, 3) or (0, 3): row k's whitened innovation (:func:`_run_filter`)."""
    out_t = np.empty(n_out)
    out_x = np.empty((n_out, N_STATE))
    out_P = np.empty((n_out, N_STATE, N_STATE))
    ws = _predict_workspace()
    L = ws[3]
    xb = np.empty(N_STATE)  # (x, P) before a step, restored when it fails
    Pb = np.empty((N_STATE, N_STATE))
    z3, R3, z1, R1 = np.empty(3), np.empty((3, 3)), np.empty(1), np.empty((1, 1))
    w3 = np.empty(3)  # the whitened innovation of the row being updated
    recording = record.shape[0] > 0
    t_cur, t_last = clock[0], clock[1]
    factored = clock[2] != 0.0  # L holds the Cholesky factor of the current P
    emit_due = clock[3] != 0.0  # the state at t_last is not recorded yet
    if factored:
        L[:, :] = L_in
    k_out = 0
    N = t.size
    for k in range(N + 1):
        tk = t[k] if k < N else np.inf
        if out_times is not None:
            k_out = _record_until(tk, out_times, k_out, x, P, t_cur, wm, wc, lam, q_acc, q_bias,
                                  mu, dt_max, ws, xb, Pb, out_t, out_x, out_P, counts)  # fmt: skip
        if k == N:
            break
        if emit_due and tk != t_last:
            k_out = _emit(t_last, x, P, L, out_t, out_x, out_P, k_out, counts)
            factored = True
            emit_due = False
        kd = kind[k]
        zk, Rk = (z1, R1) if kd == BARO else (z3, R3)
        for a in range(zk.size):
            zk[a] = z[k, a]
            for b in range(zk.size):
                Rk[a, b] = R[k, a, b]
        use_ra = adapt and (kd == DVL or kd == DR) and _all_finite(Rk)
        if use_ra:
            if not adapted[kd]:  # start from the nominal R
                Ra[kd] = Rk
                adapted[kd] = True
            Rk[:, :] = Ra[kd]
        if not (_all_finite(zk) and _all_finite(Rk)):
            counts[NONFINITE_REJECTED] += 1
        else:
            dt = tk - t_cur
            if dt > 0:
                if dt > dt_max:
                    dt = dt_max
                    counts[DT_CAPPED] += 1
                _predict_step(x, P, dt, wm, wc, lam, q_acc, q_bias, mu, freeze, first, last, ws,
                              factored, xb, Pb, counts)  # fmt: skip
                t_cur = tk
            else:
                counts[NO_PREDICT] += 1
            factored = False
            w3[:] = np.nan
            used = _update_step(kd, zk, Rk, x, P, wm, wc, lam, freeze, first, last, H, gate,
                                sensors, ws, xb, Pb, counts, nis, w3)  # fmt: skip
            if recording:
                record[k, 0], record[k, 1], record[k, 2] = w3[0], w3[1], w3[2]
            if use_ra and used:
                _adapt_r(Ra[kd], alpha, zk, x, P, H[kd], kd == DR)
        if out_times is None:
            emit_due = True
            t_last = tk
    if flush and emit_due:
        k_out = _emit(t_last, x, P, L, out_t, out_x, out_P, k_out, counts)
        factored = True
        emit_due = False
    clock[0], clock[1] = t_cur, t_last
    clock[2] = 1.0 if factored else 0.0
    clock[3] = 1.0 if emit_due else 0.0
    if factored:
        L_in[:, :] = L
    return out_t[:k_out], out_x[:k_out], out_P[:k_out]


@njit(cache=True)
def _emit(t_last, x, P, L, out_t, out_x, out_P, k_out, counts):
    """Record (x, P) at t_last after the repair the next sigma-point draw would make, done now:
    every emitted covariance is symmetric positive definite (the next draw then needs none;
    L holds its factor). Returns the next output index."""
    counts[REPAIRS] += max(_cholesky_repair(P, L), 0)
    out_t[k_out] = t_last
    out_x[k_out] = x
    out_P[k_out] = P
    return k_out + 1


@njit(cache=True)
def _record_until(tk, out_times, k_out, x, P, t_cur, wm, wc, lam, q_acc, q_bias, mu, dt_max, ws,
                  xb, Pb, out_t, out_x, out_P, counts):  # fmt: skip
    """Record every output time before tk: (x, P) predicted on a copy from t_cur (dt capped at
    dt_max), its covariance repaired to SPD. Returns the next output index."""
    while k_out < out_times.size and out_times[k_out] < tk:
        xb[:] = x
        Pb[:, :] = P
        dt = min(out_times[k_out] - t_cur, dt_max)
        if dt > 0:
            counts[REPAIRS] += max(_predict(xb, Pb, dt, wm, wc, lam, q_acc, q_bias, mu, ws), 0)
        counts[REPAIRS] += max(_cholesky_repair(Pb, ws[3]), 0)  # emit only a PD covariance
        out_t[k_out] = out_times[k_out]
        out_x[k_out] = xb
        out_P[k_out] = Pb
        k_out += 1
    return k_out


@njit(cache=True)
def _predict_step(x, P, dt, wm, wc, lam, q_acc, q_bias, mu, freeze, first, last, ws, factored, xb,
                  Pb, counts):  # fmt: skip
    """Predict (x, P) over dt; a prediction that leaves them non-finite is undone (counted)."""
    xb[:] = x
    Pb[:, :] = P
    counts[REPAIRS] += max(_predict(x, P, dt, wm, wc, lam, q_acc, q_bias, mu, ws, factored), 0)
    if not (_all_finite(x) and _all_finite(P)):
        x[:] = xb
        P[:, :] = Pb
        counts[REVERTS] += 1
    if freeze:
        _freeze_bias(x, P, first, last)


@njit(cache=True)
def _update_step(kd, zk, Rk, x, P, wm, wc, lam, freeze, first, last, H, gate, sensors, ws, xb, Pb,
                 counts, nis, w_row):  # fmt: skip
    """Update (x, P) with z of kind kd: in closed form for the linear IMU, DVL and DR models,
    through sigma points for the barometer. A gated, failed or non-finite update is undone
    (counted); every innovation evaluated adds to the NIS accumulators and leaves its whitened
    innovation in ``w_row``. Returns whether the update was applied."""
    xb[:] = x
    Pb[:, :] = P
    if kd == BARO:
        chi, L, Rw = ws[0], ws[3], ws[5]
        counts[REPAIRS] += max(_sigma_points(x, P, lam, STATE_ANGLES, L, chi), 0)
        Zs, zi = np.empty((N_SIGMA, 1)), np.empty(3)
        for i in range(N_SIGMA):
            _h(kd, chi[i], sensors, zi, Rw)
            Zs[i, 0] = zi[0]
        status, v = _update(
            x, P, chi, Zs, zk, Rk, wm, wc, STATE_ANGLES, Z_LINEAR[:1], gate[kd], w_row
        )
    else:
        z_angles = Z_ANGLES if kd == DR else Z_LINEAR
        status, v = _update_linear(x, P, H[kd], zk, Rk, STATE_ANGLES, z_angles, gate[kd], w_row)
    if status < 2 and np.isfinite(v):
        nis[kd, 0] += v
        nis[kd, 1] += 1.0
        if v <= CHI2_95[kd]:
            nis[kd, 2] += 1.0
    used = status == 0 and _all_finite(x) and _all_finite(P)
    if used:
        counts[USED + kd] += 1
    else:
        counts[GATED + kd if status == 1 else REVERTS] += 1
        x[:] = xb
        P[:, :] = Pb
    if freeze:
        _freeze_bias(x, P, first, last)
    return used


@njit(cache=True)
def _adapt_r(Ra, alpha, z, x, P, H, angles):
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
        eps[a] = _wrap(e) if angles else e
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
