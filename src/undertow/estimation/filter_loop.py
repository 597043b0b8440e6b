"""The filter loop of the paper's UKF: the merged measurements walked in time order with the
model of :mod:`undertow.estimation.model` (predict to each measurement, update), as numba
kernels on plain arrays.

The filter's boundary (:func:`run_filter`) is a few named things: the merged, time-sorted
measurements as one structured array (:data:`MEASUREMENT`: t, kind, z, R, swell), the process
model and the unscented weights as one record
(:class:`~undertow.estimation.model.ProcessModel`), the sensors' mounting and gates as another
(:class:`~undertow.estimation.model.SensorModel`), the start (t0, x0, P0) and the output times.
The loop predicts to each measurement's time (no prediction when dt <= 0, dt capped at dt_max)
and updates; counters are indexed by the names in :data:`COUNT_NAMES`. A row's ``swell``
(omega_0 rad/s, sigma^2 m^2, cos beta, sin beta; sigma^2 NaN: none; beta NaN: unknown) sets the
swell states' model from its time on (:mod:`~undertow.estimation.model`'s module doc): sigma^2 >
0 starts them at their stationary covariance when they were held, 0 holds them at 0 again; each
prediction centres the band at the encounter frequency of the mean state
(:func:`~undertow.estimation.model.encounter`). The states recorded are the trajectory's
:data:`~undertow.estimation.model.N_POSE`; the loop's own state has the swell pair too. The
records are built from a :class:`~undertow.estimation.config.LocalizerConfig` by its
``process_model`` and ``sensor_model``; :mod:`undertow.estimation.localizer` is the Python side.

The loop carries its whole state in a :class:`FilterState` (:func:`start_state`), so the online
filter feeds the rows in pieces (:func:`resume_filter`) with the same arithmetic in the same
order; the rows themselves are built by :mod:`undertow.estimation.rows`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .model import (
    BARO,
    DR,
    DVL,
    N_POSE,
    N_SIGMA,
    N_STATE,
    STATE_ANGLES,
    SWELL,
    Z_ANGLES,
    Z_LINEAR,
    adapt_r,
    encounter,
    freeze_states,
    h,
    held_range,
    jacobians,
    predict,
    predict_workspace,
)
from .ukf import all_finite, cholesky_repair, sigma_points, update, update_linear

# one merged measurement: time (s), kind (IMU, DVL, DR, BARO), z (the first KIND_DIM[kind]
# entries used), its noise covariance R (the leading KIND_DIM[kind] square block used) and the
# swell from its time on (omega_0 rad/s, sigma^2 m^2, cos beta, sin beta of the waves'
# direction; sigma^2 NaN: the row sets none; beta NaN: unknown)
MEASUREMENT = np.dtype(
    [("t", np.float64), ("kind", np.int64), ("z", np.float64, (3,)), ("R", np.float64, (3, 3)),
     ("swell", np.float64, (4,))]
)  # fmt: skip
#: the ``out_times`` of a loop that records at each distinct row time
NO_TIMES = np.empty(0)

# counters returned by run_filter: "used" and "gated" one per kind (index USED + kind,
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
# NIS accumulators returned by run_filter, one row per kind:
# [sum of nu^T S^-1 nu, innovations evaluated, innovations with nis <= CHI2_95[kind]]
NIS_FIELDS = ("nis_sum", "count", "in_95")
CHI2_95 = np.array([7.814727903251179, 7.814727903251179, 7.814727903251179, 3.841458820694124])


class FilterState(NamedTuple):
    """Everything the filter loop carries from one measurement to the next, advanced in place:
    the estimate (x, P), the Cholesky factor L of P (valid when ``clock[2]``), ``clock`` =
    (t_cur: the time (x, P) are predicted to, t_last: the last row's time, factored, emit_due:
    the state at t_last is not yet recorded), adaptive-r's running R per kind (``Ra``) and
    whether it started (``adapted``), the counters (COUNT_NAMES), NIS sums (NIS_FIELDS) and the
    swell model in force (``swell`` = (omega_0, sigma^2, cos beta, sin beta); sigma^2 = 0:
    held)."""

    x: np.ndarray
    P: np.ndarray
    L: np.ndarray
    clock: np.ndarray
    Ra: np.ndarray
    adapted: np.ndarray
    counts: np.ndarray
    nis: np.ndarray
    swell: np.ndarray

    def copy(self) -> FilterState:
        return FilterState(*(a.copy() for a in self))


@njit(cache=True)
def start_state(t0, x0, P0, process, Ra):
    """The :class:`FilterState` at t0: (x0, P0) (the trajectory's N_POSE states, or all
    N_STATE), the held bias states frozen, the swell held until a row sets it, no output yet;
    ``Ra`` (4, 3, 3) receives adaptive-r's running R."""
    x = np.zeros(N_STATE)
    P = np.zeros((N_STATE, N_STATE))
    m = x0.size
    x[:m] = x0
    P[:m, :m] = P0
    first, last = held_range(process.freeze_bias, process.hold_dr_bias, process.hold_gyro_bias)
    if last > first:
        freeze_states(x, P, first, last)
    freeze_states(x, P, SWELL, N_STATE)
    clock = np.array([t0, np.nan, 0.0, 0.0])
    return FilterState(x, P, np.zeros((N_STATE, N_STATE)), clock, Ra,
                       np.zeros(4, dtype=np.bool_), np.zeros(len(COUNT_NAMES), dtype=np.int64),
                       np.zeros((4, len(NIS_FIELDS))),
                       np.array([np.nan, 0.0, np.nan, np.nan]))  # fmt: skip


def resume_filter(meas, state: FilterState, process, sensors, flush: bool, innovations=None):
    """Filter the rows ``meas`` (:data:`MEASUREMENT`, time-sorted, none before the state's last
    row) from ``state``, advanced in place. Returns (out_t, out_x, out_P): the states recorded,
    one per distinct time; the last row's state is recorded only with ``flush`` (else when the
    next call's first row has a later time), so rows fed in any pieces give the outputs and
    final state of one :func:`run_filter` over them all, bit for bit. ``innovations``
    (len(meas), 3), optional: the rows' whitened innovations, as in :func:`run_filter`."""
    t, kind, z, R, sw = _columns(meas)
    n_out = _distinct_times(t) + 1 if t.size else 1
    record = np.empty((0, 3)) if innovations is None or t.size == 0 else innovations
    return _filter_from(
        t, kind, z, R, sw, state, process, sensors, NO_TIMES, False, n_out, flush, record
    )


def pack_measurements(t, kind, z, R, swell=None) -> np.ndarray:
    """The structured :data:`MEASUREMENT` array of (t (N,), kind (N,), z (N, 3), R (N, 3, 3),
    swell (N, 4); None: no row sets a swell)."""
    meas = np.empty(len(t), MEASUREMENT)
    meas["t"], meas["kind"], meas["z"], meas["R"] = t, kind, z, R
    meas["swell"] = np.nan if swell is None else swell
    return meas


def run_filter(meas, t0, x0, P0, process, sensors, out_times, r_adapted=None, innovations=None):
    """Walk the merged measurements ``meas`` (:data:`MEASUREMENT`, time-sorted) from (t0, x0,
    P0) with the model ``process`` (:class:`~undertow.estimation.model.ProcessModel`) and
    ``sensors`` (:class:`~undertow.estimation.model.SensorModel`): predict to each measurement
    time (none if dt <= 0, dt capped at dt_max), redraw sigma points, update.

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
    a tuple in the loop (about 10 % more time per step in benchmarks/bench_ukf.py). This entry
    is plain Python, so the loop is compiled once, in :func:`_filter_from`, for it and for
    :func:`resume_filter` (a jitted entry compiles the whole loop again for each combination of
    optional arguments), and runs without the GIL.
    """
    t, kind, z, R, sw = _columns(meas)
    at_times = out_times is not None
    if at_times:
        out_times = np.ascontiguousarray(out_times, dtype=np.float64)
        n_out = out_times.size
    else:
        out_times = NO_TIMES
        n_out = _distinct_times(t)
    if r_adapted is None:
        Ra = np.zeros((4, 3, 3))
    else:
        Ra = r_adapted
    state = start_state(t0, x0, P0, process, Ra)
    if innovations is None:
        record = np.empty((0, 3))
    else:
        record = innovations
    out = _filter_from(
        t, kind, z, R, sw, state, process, sensors, out_times, at_times, n_out, True, record
    )
    return out[0], out[1], out[2], state.counts, state.nis


@njit(cache=True, nogil=True)  # the link threads run while the filter loops
def _filter_from(t, kind, z, R, sw, state, process, sensors, out_times, at_times, n_out, flush,
                 record):  # fmt: skip
    """:func:`_filter` from ``state`` (:class:`FilterState`, advanced in place); the states
    recorded at ``out_times`` when ``at_times``, else at each distinct row time (one compiled
    loop for both: a None would compile it twice); ``record``: the whitened innovations per
    row (:func:`run_filter`), or (0, 3) for none."""
    wm, wc, lam, q_acc, q_bias, mu_bias, dt_max, freeze_bias, hold_dr, hold_gyro, damping = process
    first, last = held_range(freeze_bias, hold_dr, hold_gyro)
    x, P, L, clock, Ra, adapted, counts, nis, swell = state
    return _filter(t, kind, z, R, sw, x, P, L, clock, wm, wc, lam, q_acc, q_bias, mu_bias, dt_max,
                   last > first, first, last, jacobians(sensors), sensors.gate, sensors,
                   out_times, at_times, n_out, sensors.adapt_r, sensors.adapt_alpha, Ra, adapted,
                   counts, nis, flush, record, swell, damping)  # fmt: skip


@njit(cache=True)
def _columns(meas):
    """The fields of the :data:`MEASUREMENT` array as contiguous arrays (t, kind, z, R, swell)."""
    N = meas.size
    t, kind = np.empty(N), np.empty(N, np.int64)
    z, R, sw = np.empty((N, 3)), np.empty((N, 3, 3)), np.empty((N, 4))
    for k in range(N):
        t[k] = meas[k].t
        kind[k] = meas[k].kind
        z[k] = meas[k].z
        R[k] = meas[k].R
        sw[k] = meas[k].swell
    return t, kind, z, R, sw


@njit(cache=True)
def _distinct_times(t):
    """Number of distinct consecutive times in the (sorted) t."""
    n = 1
    for k in range(1, t.size):
        if t[k] != t[k - 1]:
            n += 1
    return n


@njit(cache=True)
def _filter(t, kind, z, R, sw, x, P, L_in, clock, wm, wc, lam, q_acc, q_bias, mu, dt_max,
            freeze, first, last, H, gate, sensors, out_times, at_times, n_out, adapt, alpha, Ra,
            adapted, counts, nis, flush, record, swell, damping):  # fmt: skip
    """The loop of :func:`run_filter` over its unpacked records, from the state (x, P, L_in,
    clock, Ra, adapted, counts, nis, swell) of a :class:`FilterState`, advanced in place; ``sw``
    the rows' swell, ``damping`` the swell model's lambda;
    H = jacobians(sensors); states first..last-1 held when ``freeze``; ``adapt``: the DVL and
    DR use the adapted R of :func:`~undertow.estimation.model.adapt_r` (in Ra, per kind)
    instead of their rows' R.
    The state at a time is recorded when the next row's time differs, the last one only when
    ``flush``; ``record`` (N, 3) or (0, 3): row k's whitened innovation (:func:`run_filter`)."""
    out_t = np.empty(n_out)
    out_x = np.empty((n_out, N_POSE))
    out_P = np.empty((n_out, N_POSE, N_POSE))
    ws = predict_workspace()
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
        if at_times:
            k_out = _record_until(tk, out_times, k_out, x, P, t_cur, wm, wc, lam, q_acc, q_bias,
                                  mu, dt_max, ws, xb, Pb, out_t, out_x, out_P, counts,
                                  swell, damping)  # fmt: skip
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
        use_ra = adapt and (kd == DVL or kd == DR) and all_finite(Rk)
        if use_ra:
            if not adapted[kd]:  # start from the nominal R
                Ra[kd] = Rk
                adapted[kd] = True
            Rk[:, :] = Ra[kd]
        if not (all_finite(zk) and all_finite(Rk)):
            counts[NONFINITE_REJECTED] += 1
        else:
            if np.isfinite(sw[k, 1]) and _set_swell(sw[k], swell, x, P):
                factored = False
            dt = tk - t_cur
            if dt > 0:
                if dt > dt_max:
                    dt = dt_max
                    counts[DT_CAPPED] += 1
                band = _band(x, swell, damping, ws[6])  # (predict's T: a scratch until then)
                _predict_step(x, P, dt, wm, wc, lam, q_acc, q_bias, mu, freeze, first, last, ws,
                              factored, xb, Pb, counts, band)  # fmt: skip
                t_cur = tk
            else:
                counts[NO_PREDICT] += 1
            factored = False
            w3[:] = np.nan
            used = _update_step(kd, zk, Rk, x, P, wm, wc, lam, freeze, first, last, H, gate,
                                sensors, ws, xb, Pb, counts, nis, w3)  # fmt: skip
            if swell[1] <= 0.0:  # no swell: its states stay held at 0
                freeze_states(x, P, SWELL, N_STATE)
            if recording:
                record[k, 0], record[k, 1], record[k, 2] = w3[0], w3[1], w3[2]
            if use_ra and used:
                adapt_r(Ra[kd], alpha, zk, x, P, H[kd], kd == DR)
        if not at_times:
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
    counts[REPAIRS] += max(cholesky_repair(P, L), 0)
    out_t[k_out] = t_last
    out_x[k_out] = x[:N_POSE]
    out_P[k_out] = P[:N_POSE, :N_POSE]
    return k_out + 1


@njit(cache=True)
def _band(x, swell, damping, R):
    """(omega_e, sigma^2, lambda_e) of the swell model in force at the mean x
    (:func:`~undertow.estimation.model.encounter`), (NaN, 0, lambda) without a swell."""
    if not swell[1] > 0.0:
        return np.nan, 0.0, damping
    omega, lam_e = encounter(x, swell[0], swell[2], swell[3], damping, R)
    return omega, swell[1], lam_e


@njit(cache=True)
def _set_swell(row, swell, x, P):
    """A row's swell (omega_0, sigma^2, cos beta, sin beta) into ``swell`` (the model in
    force): held states start at their stationary covariance diag(sigma^2 / omega_0^2, sigma^2)
    (module doc of :mod:`~undertow.estimation.model`); sigma^2 = 0 (or no frequency) holds them
    at 0. Returns whether P changed."""
    omega, var = row[0], row[1]
    on = var > 0.0 and omega > 0.0 and np.isfinite(omega)
    was_on = swell[1] > 0.0
    swell[0] = omega if on else np.nan
    swell[1] = var if on else 0.0
    swell[2], swell[3] = row[2], row[3]
    if on and not was_on:
        freeze_states(x, P, SWELL, N_STATE)
        P[SWELL, SWELL] = var / (omega * omega)
        P[SWELL + 1, SWELL + 1] = var
        return True
    if was_on and not on:
        freeze_states(x, P, SWELL, N_STATE)
        return True
    return False


@njit(cache=True)
def _record_until(tk, out_times, k_out, x, P, t_cur, wm, wc, lam, q_acc, q_bias, mu, dt_max, ws,
                  xb, Pb, out_t, out_x, out_P, counts, swell, damping):  # fmt: skip
    """Record every output time before tk: (x, P) predicted on a copy from t_cur (dt capped at
    dt_max), its covariance repaired to SPD. Returns the next output index."""
    while k_out < out_times.size and out_times[k_out] < tk:
        xb[:] = x
        Pb[:, :] = P
        dt = min(out_times[k_out] - t_cur, dt_max)
        if dt > 0:
            band = _band(xb, swell, damping, ws[6])
            status = predict(xb, Pb, dt, wm, wc, lam, q_acc, q_bias, mu, ws, False, band)
            counts[REPAIRS] += max(status, 0)
        counts[REPAIRS] += max(cholesky_repair(Pb, ws[3]), 0)  # emit only a PD covariance
        out_t[k_out] = out_times[k_out]
        out_x[k_out] = xb[:N_POSE]
        out_P[k_out] = Pb[:N_POSE, :N_POSE]
        k_out += 1
    return k_out


@njit(cache=True)
def _predict_step(x, P, dt, wm, wc, lam, q_acc, q_bias, mu, freeze, first, last, ws, factored, xb,
                  Pb, counts, swell):  # fmt: skip
    """Predict (x, P) over dt with the swell band ``swell`` (omega_e, sigma^2, lambda_e); a
    prediction that leaves them non-finite is undone (counted)."""
    xb[:] = x
    Pb[:, :] = P
    status = predict(x, P, dt, wm, wc, lam, q_acc, q_bias, mu, ws, factored, swell)
    counts[REPAIRS] += max(status, 0)
    if not (all_finite(x) and all_finite(P)):
        x[:] = xb
        P[:, :] = Pb
        counts[REVERTS] += 1
    if freeze:
        freeze_states(x, P, first, last)


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
        counts[REPAIRS] += max(sigma_points(x, P, lam, STATE_ANGLES, L, chi), 0)
        Zs, zi = np.empty((N_SIGMA, 1)), np.empty(3)
        for i in range(N_SIGMA):
            h(kd, chi[i], sensors, zi, Rw)
            Zs[i, 0] = zi[0]
        status, v = update(
            x, P, chi, Zs, zk, Rk, wm, wc, STATE_ANGLES, Z_LINEAR[:1], gate[kd], w_row
        )
    else:
        z_angles = Z_ANGLES if kd == DR else Z_LINEAR
        status, v = update_linear(x, P, H[kd], zk, Rk, STATE_ANGLES, z_angles, gate[kd], w_row)
    if status < 2 and np.isfinite(v):
        nis[kd, 0] += v
        nis[kd, 1] += 1.0
        if v <= CHI2_95[kd]:
            nis[kd, 2] += 1.0
    used = status == 0 and all_finite(x) and all_finite(P)
    if used:
        counts[USED + kd] += 1
    else:
        counts[GATED + kd if status == 1 else REVERTS] += 1
        x[:] = xb
        P[:, :] = Pb
    if freeze:
        freeze_states(x, P, first, last)
    return used
