"""Unscented Rauch-Tung-Striebel smoother (Saerkkae 2008) for offline use: Trajectory -> Trajectory.

Backward pass over the filtered (x_k, P_k) at the filter's distinct update times t_k, from
k = N-2 down to 0, with the filter's own step dt_k = min(t_{k+1} - t_k, max_dt_s) and its
process model f and noise Q (eq:dynamics_model, :mod:`undertow.estimation.model`):

    chi_i  = sigma points of N(x_k, P_k)                            (ukf.py, angles wrapped)
    m^-    = mean_i f(chi_i, dt_k)                                  (reference-point angle mean)
    P^-    = sum_i W^c_i (f(chi_i) - m^-)(f(chi_i) - m^-)^T + Q(x_k, dt_k)
    C      = sum_i W^c_i (chi_i - x_k)(f(chi_i) - m^-)^T             (wrapped residuals)
    G      = C (P^-)^-1                                             (Cholesky solves)
    x^s_k  = x_k + G wrap(x^s_{k+1} - m^-)
    P^s_k  = P_k + G (P^s_{k+1} - P^-) G^T                          (symmetrized, repaired)

starting from x^s_{N-1} = x_{N-1}, P^s_{N-1} = P_{N-1}. Variants without bias estimation use
the filter's handling: no mean drift mu_b, and the bias states frozen at 0 (variance 1e-12, no
correlation) in (m^-, P^-) and in the result. A step whose result is not finite keeps the
filtered (x_k, P_k) and is counted.

The smoother needs the filter output at every processed measurement time
(``LocalizerConfig.output_rate_hz = None``): a decimated trajectory has lost the updates between
its rows and is refused.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .._util.validate import validate
from ..errors import ConfigError, DataError
from ..trajectory import Trajectory
from ..trajectory_chunks import CHUNK_STATES, TrajectoryStore
from . import model
from .config import LocalizerConfig
from .ukf import (
    all_finite,
    cholesky_repair,
    gain,
    residuals,
    symmetrize,
    weighted_outer,
    wrap,
)

SMOOTHER_COUNT_NAMES = ("cholesky_repairs", "nonfinite_kept_filtered")


@njit(cache=True)
def _rts_workspace(n):
    npts = 2 * n + 1
    return (
        np.empty((n, npts)), np.empty((n, n)), np.zeros((n, n)), np.empty((n, n)), np.empty(n),
        np.empty(n), np.empty((n, n)),
    )  # fmt: skip


@njit(cache=True)
def _rts_step(x, P, chi, DfT, m_pred, P_pred, xs_next, Ps_next, wc, angle_mask, ws):
    """One URTS backward step, in place: (x, P) = (x_k, P_k) -> (x^s_k, P^s_k).

    chi: sigma points (2n+1, n) of N(x_k, P_k); DfT: transposed residuals f(chi_i) - m^-
    (n, 2n+1); (m_pred, P_pred) = (m^-, P^-), P_pred is used as a workspace. Returns the number
    of Cholesky repairs (0-2) or -1 if P^- is not finite.
    """
    DxT, C, L, G, row, d, GA = ws
    n = x.size
    residuals(chi, x, angle_mask, DxT)
    weighted_outer(DxT, DfT, wc, C)  # C = sum W^c (chi_i - x_k)(f(chi_i) - m^-)^T
    status = cholesky_repair(P_pred, L)
    if status < 0:
        return -1
    gain(C, L, G, row)  # G = C (P^-)^-1
    for a in range(n):
        v = xs_next[a] - m_pred[a]
        d[a] = wrap(v) if angle_mask[a] else v
    for i in range(n):
        s = 0.0
        for a in range(n):
            s += G[i, a] * d[a]
        x[i] += s
        if angle_mask[i]:
            x[i] = wrap(x[i])
    for i in range(n):  # GA = G (P^s_{k+1} - P^-)
        for b in range(n):
            s = 0.0
            for a in range(n):
                s += G[i, a] * (Ps_next[a, b] - P_pred[a, b])
            GA[i, b] = s
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for a in range(n):
                s += GA[i, a] * G[j, a]
            v = P[i, j] + s
            P[i, j] = v
            P[j, i] = v
    symmetrize(P)
    repaired = cholesky_repair(P, L)  # floor eigenvalues if round-off made P^s indefinite
    return status + max(repaired, 0)


@njit(cache=True)
def _run_smoother(t, xf, Pf, wm, wc, lam, q_acc, q_bias, mu_bias, dt_max, freeze_bias,
                  hold_dr=False, hold_gyro=False, swell_damping=0.1):  # fmt: skip
    """URTS backward pass of the 18-state model over filtered (t, xf (N, 18), Pf (N, 18, 18))
    with the filter's process model: the fields of its
    :class:`~undertow.estimation.model.ProcessModel` as arguments (``*process``); the bias
    states the filter held are held here too.

    The filter's sigma points span its N_STATE states, the swell pair too, which the trajectory
    leaves out (module doc of :mod:`~undertow.estimation.model`). The states are padded with the
    pair held at 0 (as the filter holds it without a swell): the Cholesky factor's first 18
    columns are then those of the 18 states' own, the pair's columns leave the 18 states at
    their mean and the motion of the 18 does not depend on the pair, so the prediction of the
    18 states is the filter's, with its weights (``swell_damping`` is not used).

    Returns (xs, Ps, counts) with counts as in SMOOTHER_COUNT_NAMES.
    """
    n, m18, s0 = model.N_STATE, model.N_POSE, model.SWELL
    N = t.size
    first, last = model.held_range(freeze_bias, hold_dr, hold_gyro)
    freeze = last > first
    xs = np.empty((N, n))
    Ps = np.empty((N, n, n))
    for k in range(N):
        _padded(xf[k], Pf[k], xs[k], Ps[k])
    counts = np.zeros(len(SMOOTHER_COUNT_NAMES), dtype=np.int64)
    ws = model.predict_workspace()
    ws_rts = _rts_workspace(n)
    m = np.empty(n)
    Pm = np.empty((n, n))
    x = np.empty(n)
    P = np.empty((n, n))
    for k in range(N - 2, -1, -1):
        dt = min(t[k + 1] - t[k], dt_max)
        _padded(xf[k], Pf[k], m, Pm)
        status = model.predict(m, Pm, dt, wm, wc, lam, q_acc, q_bias, mu_bias, ws)
        if freeze:
            model.freeze_states(m, Pm, first, last)
        model.freeze_states(m, Pm, s0, n)
        _padded(xf[k], Pf[k], x, P)
        flag = _rts_step(x, P, ws[0], ws[2], m, Pm, xs[k + 1], Ps[k + 1], wc,
                         model.STATE_ANGLES, ws_rts)  # fmt: skip
        if status < 0 or flag < 0 or not (all_finite(x) and all_finite(P)):
            counts[1] += 1
            continue
        counts[0] += max(status, 0) + flag
        if freeze:
            model.freeze_states(x, P, first, last)
        model.freeze_states(x, P, s0, n)
        xs[k] = x
        Ps[k] = P
    return xs[:, :m18].copy(), Ps[:, :m18, :m18].copy(), counts


@njit(cache=True)
def _padded(x18, P18, x, P):
    """(x, P) of the filter's N_STATE states from a trajectory's (x18, P18): the swell pair held
    at 0 (variance 1e-12, no correlation), as the filter holds it without a swell."""
    m18 = model.N_POSE
    x[:m18] = x18
    P[:, :] = 0.0
    P[:m18, :m18] = P18
    model.freeze_states(x, P, model.SWELL, model.N_STATE)


def smooth(trajectory: Trajectory, config: LocalizerConfig | None = None) -> Trajectory:
    """Unscented RTS smoothing of a filtered trajectory (see the module docstring).

    ``config``: the LocalizerConfig the trajectory was filtered with; None takes it from
    ``trajectory.metadata["config"]`` (set by :meth:`Localizer.run`); the bias groups the filter
    held for want of their sensor (``metadata["held_bias"]``) are held here too. The result has
    ``metadata["smoothed"] = True`` and ``metadata["smoother_counts"]``.
    """
    meta = trajectory.metadata or {}
    process = _process_model(meta, config)
    _check_times(trajectory.t)
    x, P = np.ascontiguousarray(trajectory.x), np.ascontiguousarray(trajectory.P)
    xs, Ps, counts = _run_smoother(trajectory.t, x, P, *process)
    return trajectory.replace(x=xs, P=Ps, metadata=smoothed_metadata(meta, counts))


def smooth_store(store: TrajectoryStore, metadata: dict, config: LocalizerConfig | None = None,
                 chunk: int = CHUNK_STATES) -> dict:  # fmt: skip
    """:func:`smooth` of the filtered states in ``store`` (a
    :class:`~undertow.trajectory_chunks.TrajectoryStore`), rewritten in place backward chunk by
    chunk: the chunk [k0, k1) is smoothed with the state k1 already smoothed (the previous
    chunk's first), which is all step k1 - 1 needs of the states after it, so the states are
    those of :func:`smooth` bit for bit, with at most ``chunk`` + 1 states in memory.
    ``metadata``: the trajectory's (config, held bias); returns it as :func:`smooth` would."""
    meta = metadata or {}
    process = _process_model(meta, config)
    _check_times(store.read_array("t"))
    counts = np.zeros(len(SMOOTHER_COUNT_NAMES), dtype=np.int64)
    for k0, k1 in store.chunks(chunk, reverse=True):
        t, x, P = store.read(k0, k1 + 1)  # and the next chunk's first state, smoothed already
        xs, Ps, c = _run_smoother(t, x, P, *process)
        store.rewrite(k0, xs[: k1 - k0], Ps[: k1 - k0])
        counts += c
    return smoothed_metadata(meta, counts)


def smoothed_metadata(meta: dict, counts: np.ndarray) -> dict:
    """The metadata of a smoothed trajectory: ``smoothed`` and the ``smoother_counts``."""
    return {
        **meta,
        "smoothed": True,
        "smoother_counts": dict(zip(SMOOTHER_COUNT_NAMES, counts.tolist(), strict=True)),
    }


def _process_model(meta: dict, config: LocalizerConfig | None):
    """The filter's process model for smoothing a trajectory of metadata ``meta`` (the config
    given, else the one it records), refusing a smoothed or decimated trajectory."""
    if meta.get("smoothed"):
        raise ConfigError("smooth: the trajectory is already smoothed")
    if config is None:
        if "config" not in meta:
            raise ConfigError("smooth: the trajectory carries no filter config; pass the "
                              "LocalizerConfig it was filtered with")  # fmt: skip
        config = validate(LocalizerConfig, meta["config"], "smooth: the trajectory's config: ")
    rate = meta.get("config", {}).get("output_rate_hz", config.output_rate_hz)
    if rate is not None or config.output_rate_hz is not None:
        raise ConfigError(f"smooth: the trajectory was decimated (output_rate_hz={rate}); run the "
                          "Localizer with output_rate_hz=None to smooth it")  # fmt: skip
    return config.process_model(held=meta.get("held_bias") or ())


def _check_times(t: np.ndarray) -> None:
    if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
        raise DataError("smooth: trajectory times must be finite and strictly increasing")
