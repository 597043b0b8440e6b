"""The coherent fit of one regular linear wave to every channel of a window at once, through
the transfer functions of :mod:`undertow.sim.waves` (Dean & Dalrymple, "Water Wave Mechanics for
Engineers and Scientists", 1991, ch. 3-4; the encounter-frequency and pressure/velocity "PUV"
ideas of wave gauging from moving and fixed instruments, e.g. Lewis, "Principles of Naval
Architecture" vol. III, SNAME 1989, and Tucker & Pitt, "Waves in Ocean Engineering", Elsevier
2001, ch. 6).

Phase model along the dead-reckoned track (x(t), y(t)) of the window (the world velocity
smoothed over one encounter period and integrated, :func:`~undertow.seastate.prepare.attach_track`):

    theta(t) = k (x(t) cos beta + y(t) sin beta) - omega t + phi,   omega^2 = g k tanh(k h)

Channels (high-passed, x - MA(MA(x)) over one encounter period, to remove the vehicle's own slow
motion; the final fit applies the same filter to the model), with c = a e^{i phi} and
omega_e(t) = omega - k V(t) . e_beta the encounter frequency, d the body depth:

    rigid:  head(t)  = a K_p(d) cos theta                  (barometer, pressure head in m)
    free:   head(t)  = a (K_p(d) - K_s(d)) cos theta
            u(t)     = a K_h(d) omega_e(t) cos theta e_beta     (DVL velocity over the floor)
            w_dn(t)  = -a K_s(d) omega_e(t) sin theta

Each model is linear in (Re c, Im c) for a given (omega, beta), so the maximum-likelihood fit
(Gaussian noise of unknown variance per channel) is a weighted least squares for c inside a
search over (omega, beta): candidates from the encounter-frequency periodogram peaks
(zero-padded, parabolic interpolation; each peak with each distinct velocity of the window, on
the ridge omega - k V . e_beta = omega_e), directions from a 30 deg grid (rigid) or the
principal axis of the horizontal orbital velocity (free, the PUV direction, both senses), then a
zoom on halving 3 x 3 grids (compiled); the channel weights 1/sigma_c^2 are re-estimated from
the residuals. A rigid mount on a straight track sees beta only through c = cos(beta - course),
searched in [-1.3, 1.3] (:func:`search_mode`). The fit's profile log-likelihood is
-1/2 sum_c n_c log(RSS_c / n_c). A window is calm (:func:`judge`) when the wave's chi-square
improvement sum_c (TSS_c - RSS_c) / sigma_c^2 does not exceed 2 ln(M / alpha), the level a
maximum over the M independent frequency and direction cells reaches in noise alone
(alpha = 1e-3), or the wave explains less than 15 % of the weighted variance.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit

from ..sim.waves import depth_factors_scalar, intrinsic_from_encounter, wavenumber, wavenumber_array
from .prepare import Channel
from .signal import F_LOW_HZ, FASTMATH, highpass_inplace

#: the direction grid of the searches (rad)
BETAS = np.deg2rad(np.arange(0.0, 360.0, 15.0))
#: the grid of c = cos(beta - course) on a straight track
COS_GRID = np.linspace(-1.2, 1.2, 9)
MIN_EXPLAINED = 0.15  # a regular wave explaining less of the high-passed variance is not one
_ALPHA = 1e-3
_KINDS = {"p": 0, "vx": 1, "vy": 2, "vz": 3}


@dataclass(frozen=True)
class Direction:
    """A propagation direction as the fit takes it: beta (rad) and the gain on the direction
    vector e_beta (1, or on a straight track the fitted c = cos(beta - course), beta the
    course)."""

    beta_rad: float
    gain: float


@dataclass(frozen=True, eq=False)
class WaveFit:
    """One platform model's fit in a window: ``model`` ("rigid" | "free"), the search ``mode``
    (:func:`search_mode`), the intrinsic angular frequency omega (rad/s), the direction beta (rad)
    with its gain, the complex amplitude c = a e^{i phi} as (Re c, Im c) (m), each channel's
    residual sum of squares and weight 1/sigma_c^2, the profile log-likelihood and the number of
    direction cells searched; once judged (:func:`judge`), the fraction of the weighted variance
    the wave explains and whether the window is calm; on a window's best fit, the encounter
    peaks searched (rad/s)."""

    model: str
    mode: str
    omega_rad_s: float
    beta_rad: float
    gain: float
    c_m: np.ndarray
    rss: np.ndarray
    weights: np.ndarray
    loglik: float
    cells: int
    peaks_rad_s: np.ndarray | None = None
    explained: float = 0.0
    calm: bool | None = None

    @property
    def amplitude_m(self) -> float:
        return float(np.hypot(*self.c_m))

    @property
    def direction(self) -> Direction:
        """(beta, gain) of the fit, for a neighbour's fixed direction."""
        return Direction(self.beta_rad, self.gain)


@dataclass(frozen=True, eq=False)
class FitWindow:
    """One window's channels as the fit reads them (times from the window start, data
    high-passed, track from its value at the start), with the high-pass lengths (samples), each
    channel's total sum of squares and sample count, the duration (s), whether there is a
    track, the mean slow velocity (2,) (m/s), the distinct slow velocities of the window, the
    course (rad, of the mean velocity; 0 at rest), whether the track keeps within 0.1 m of a
    line, the water depth (m) and gravity (m/s^2)."""

    channels: list[Channel]
    highpass_samples: list[int]
    tss: np.ndarray
    samples: np.ndarray
    duration_s: float
    has_track: bool
    mean_velocity_m_s: np.ndarray
    velocities_m_s: list
    course_rad: float
    straight: bool
    water_depth_m: float
    gravity_m_s2: float

    @cached_property
    def packed(self) -> tuple:
        """Concatenated channel arrays for the compiled kernels."""
        cat = np.concatenate

        def track(name):
            return cat([getattr(c, name) if c.x_m is not None else np.zeros(c.t.size)
                        for c in self.channels])  # fmt: skip

        return (
            cat([c.t for c in self.channels]),
            track("x_m"),
            track("y_m"),
            track("vx_m_s"),
            track("vy_m_s"),
            cat([c.value for c in self.channels]),
            np.cumsum([0] + [c.t.size for c in self.channels]).astype(np.int64),
            np.array([_KINDS[c.kind] for c in self.channels], dtype=np.int64),
            np.array(self.highpass_samples, dtype=np.int64),
            np.array([c.depth_m for c in self.channels], dtype=float),
            np.array(
                [i > 0 and c.t is self.channels[i - 1].t for i, c in enumerate(self.channels)],
                dtype=np.bool_,
            ),  # fmt: skip
        )


# ---------------------------------------------------------------------------- compiled kernels


@njit(cache=True, fastmath=FASTMATH)
def _fit_kernel(omega, ex, ey, g0, h, free, hp, T, X, Y, VX, VY, D, starts, kinds, nhp, depth,
                share, weights, tss, track):  # fmt: skip
    """For each candidate (omega_g, direction vector (ex_g, ey_g) = gain (cos beta, sin beta)),
    k_g from the dispersion relation: the regressors
    A, B of every channel the model predicts (module doc: y = Re(c) A + Im(c) B), high-passed
    like the data if ``hp`` (the search skips it: a sinusoid near the encounter frequency
    passes the filter almost unchanged), then the weighted least squares c and each channel's
    residual sum of squares."""
    G, C = omega.size, kinds.size
    k = wavenumber_array(omega, h, g0)
    chi2, cc, rss = np.empty(G), np.zeros((G, 2)), np.empty((G, C))
    nmax = int(np.max(starts[1:] - starts[:-1]))
    A, B = np.empty(nmax), np.empty(nmax)
    CO, SI, WE = np.empty(nmax), np.empty(nmax), np.empty(nmax)
    cs, tmp = np.empty(nmax + 1), np.empty(nmax)
    part = np.zeros((C, 5))
    for g in range(G):
        w, kk = omega[g], k[g]
        cb, sb = ex[g], ey[g]
        M00 = M01 = M11 = r0 = r1 = 0.0
        done = False
        for c in range(C):
            part[c, :] = 0.0
            kind = kinds[c]
            if not free and kind != 0:
                done = False
                continue
            kh, ks, kp = depth_factors_scalar(kk, h, depth[c])
            s0, n = starts[c], starts[c + 1] - starts[c]
            if not (share[c] and done):  # channels of one stream share the phase
                for i in range(n):
                    j = s0 + i
                    ph = -w * T[j]
                    WE[i] = w
                    if track:
                        ph += kk * (X[j] * cb + Y[j] * sb)
                        WE[i] -= kk * (VX[j] * cb + VY[j] * sb)
                    CO[i], SI[i] = np.cos(ph), np.sin(ph)
            done = True
            for i in range(n):
                co, si, we = CO[i], SI[i], WE[i]
                if kind == 0:
                    gain = kp if not free else kp - ks
                    A[i], B[i] = gain * co, -gain * si
                elif kind == 3:
                    A[i], B[i] = -ks * we * si, -ks * we * co
                else:
                    gg = kh * we * (cb if kind == 1 else sb)
                    A[i], B[i] = gg * co, -gg * si
            if hp:
                highpass_inplace(A, n, nhp[c], cs, tmp)
                highpass_inplace(B, n, nhp[c], cs, tmp)
            a00 = a01 = a11 = ay = by = 0.0
            for i in range(n):
                yv = D[s0 + i]
                a00 += A[i] * A[i]
                a01 += A[i] * B[i]
                a11 += B[i] * B[i]
                ay += A[i] * yv
                by += B[i] * yv
            part[c, 0], part[c, 1], part[c, 2], part[c, 3], part[c, 4] = a00, a01, a11, ay, by
            wc = weights[c]
            M00 += wc * a00
            M01 += wc * a01
            M11 += wc * a11
            r0 += wc * ay
            r1 += wc * by
        det = M00 * M11 - M01 * M01
        c0 = c1 = 0.0
        if abs(det) > 1e-300:
            c0, c1 = (M11 * r0 - M01 * r1) / det, (M00 * r1 - M01 * r0) / det
        cc[g, 0], cc[g, 1] = c0, c1
        total = 0.0
        for c in range(C):
            p = part[c]
            r = tss[c] - 2 * (c0 * p[3] + c1 * p[4]) + c0 * c0 * p[0] + 2 * c0 * c1 * p[1]
            r += c1 * c1 * p[2]
            r = max(r, 1e-12 * tss[c] + 1e-300)
            rss[g, c] = r
            total += weights[c] * r
        chi2[g] = total
    return chi2, cc, rss


@njit(cache=True)
def _zoom_kernel(w, b, dw, db, levels, two_d, mode, beta0, gain0, g0, h, free, packed, weights,
                 tss, track):  # fmt: skip
    """The zoom of :func:`_zoom` in one compiled loop (no Python per level)."""
    T, X, Y, VX, VY, D, starts, kinds, nhp, depth, share = packed
    m = 9 if two_d else 3
    om, ex, ey = np.empty(m), np.empty(m), np.empty(m)
    cbs = np.empty(m)
    for _ in range(levels):
        for i in range(m):
            iw, ib = (i // 3 - 1, i % 3 - 1) if two_d else (i - 1, 0)
            om[i] = max(w + iw * dw, 1e-3)
            cbs[i] = b + ib * db
            if mode == 1:  # c = cos(beta - course), clipped
                c = min(max(cbs[i], -1.3), 1.3)
                ex[i], ey[i] = c * np.cos(beta0), c * np.sin(beta0)
            elif mode == 2:  # fixed direction
                ex[i], ey[i] = gain0 * np.cos(beta0), gain0 * np.sin(beta0)
            else:
                ex[i], ey[i] = np.cos(cbs[i]), np.sin(cbs[i])
        chi2 = _fit_kernel(om, ex, ey, g0, h, free, False, T, X, Y, VX, VY, D, starts, kinds,
                           nhp, depth, share, weights, tss, track)[0]  # fmt: skip
        j = 0
        for i in range(m):
            if chi2[i] < chi2[j]:
                j = i
        w, b = om[j], cbs[j]
        dw, db = dw / 2, db / 2
    return w, b


# ------------------------------------------------------------------------------ the search


def _used(win: FitWindow, model: str) -> list[int]:
    return [i for i, c in enumerate(win.channels) if model == "free" or c.kind == "p"]


def evaluate(win: FitWindow, model: str, omega, beta, weights, hp: bool = False, gain=1.0):
    """For G candidates: chi2 = sum_c w_c RSS_c (G,), c (G, 2), RSS (G, C); channels the model
    does not predict keep RSS = TSS. ``gain`` scales the direction vector (a fitted
    cos(beta - course) beyond +-1 on a straight track, see :func:`fit_model`)."""
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    beta = np.broadcast_to(np.asarray(beta, dtype=float), omega.shape)
    gain = np.broadcast_to(np.asarray(gain, dtype=float), omega.shape)
    ex, ey = gain * np.cos(beta), gain * np.sin(beta)
    chi2, c, rss = _fit_kernel(omega, ex, ey, win.gravity_m_s2, float(win.water_depth_m),
                               model == "free", hp, *win.packed, weights, win.tss,
                               win.has_track)  # fmt: skip
    return np.where(np.isfinite(chi2), chi2, np.inf), c, rss


def ridge(win: FitWindow, omega_e: float, beta, gain=1.0) -> np.ndarray:
    """Intrinsic omega on the ridge omega - k V_mean . e_beta = omega_e, for each beta."""
    v = win.mean_velocity_m_s
    u = gain * (v[0] * np.cos(beta) + v[1] * np.sin(beta))
    return intrinsic_from_encounter(np.full(np.shape(beta), omega_e), u, win.water_depth_m,
                                    win.gravity_m_s2)  # fmt: skip


def _puv_axis(win: FitWindow, omega_e: float) -> list[float]:
    """Both propagation directions along the principal axis of the horizontal velocity's
    complex amplitude at omega_e (alpha = 1/2 atan2(2 S_xy, S_xx - S_yy), S the 2x2 spectral
    matrix): the PUV method's direction, 180 deg ambiguous."""
    z = {}
    for c in win.channels:
        if c.kind in ("vx", "vy"):
            z[c.kind] = (c.value * np.exp(1j * omega_e * c.t)).sum()
    if len(z) < 2:
        return [0.0, np.pi]
    sxx, syy = abs(z["vx"]) ** 2, abs(z["vy"]) ** 2
    sxy = (z["vx"] * np.conj(z["vy"])).real
    alpha = 0.5 * math.atan2(2 * sxy, sxx - syy)
    return [alpha, alpha + np.pi]


def search_mode(win: FitWindow, model: str, beta_fixed: Direction | None) -> str:
    """ "fixed" (a given direction), "none" (no track), "cos" (rigid on a straight track: the
    model depends on beta only through c = cos(beta - course), searched in [-1.3, 1.3] so the
    estimate of c = -1 (head seas) or +1 is not pushed inward by noise, as it would be with
    |c| <= 1, which biased omega), or "beta"."""
    if beta_fixed is not None:
        return "fixed"
    if not win.has_track:
        return "none"
    return "cos" if model == "rigid" and win.straight else "beta"


def _dirs(win: FitWindow, mode: str, b, beta_fixed: Direction | None):
    """(beta, gain) arrays of the search coordinate b."""
    b = np.atleast_1d(np.asarray(b, dtype=float))
    if mode == "cos":
        return np.full(b.shape, win.course_rad), np.clip(b, -1.3, 1.3)
    if mode == "fixed":
        return np.full(b.shape, beta_fixed.beta_rad), np.full(b.shape, beta_fixed.gain)
    return b, np.ones(b.shape)


def _initial(win: FitWindow, model: str, peaks, mode: str, beta_fixed: Direction | None):
    """Candidates: the three highest encounter peaks x the distinct velocities of the window
    (each peak may come from one leg of the track) x directions, on the ridge
    omega - k V . e_beta = omega_e (the zoom's first level spans half a resolution cell)."""
    coords = {"fixed": np.zeros(1), "none": np.zeros(1), "cos": COS_GRID}.get(mode, BETAS[::2])
    wes, us, be = [], [], []
    for i, we in enumerate(peaks[: 2 if mode in ("beta", "cos") and model == "rigid" else 3]):
        if model == "free" and mode == "beta":
            axis = np.array(_puv_axis(win, float(we)))
            coords = np.r_[axis, axis - np.pi / 6, axis + np.pi / 6] if i == 0 else axis
        beta, gain = _dirs(win, mode, coords, beta_fixed)
        for v in win.velocities_m_s:
            us.append(gain * (v[0] * np.cos(beta) + v[1] * np.sin(beta)))
            wes.append(np.full(coords.shape, we))
            be.append(coords)
    be = np.concatenate(be)
    om = intrinsic_from_encounter(np.concatenate(wes), np.concatenate(us), win.water_depth_m,
                                  win.gravity_m_s2)  # fmt: skip
    good = np.isfinite(om) & (om > np.pi * F_LOW_HZ)
    return om[good], be[good]


def _zoom(win: FitWindow, model, weights, w, b, steps, levels, mode, beta_fixed):
    """Refine (omega, b) on 3 x 3 (or 3 x 1) grids around the best point, halved each level."""
    if mode == "fixed":
        beta0, gain0 = beta_fixed.beta_rad, beta_fixed.gain
    else:
        beta0, gain0 = win.course_rad, 1.0
    code = {"beta": 0, "cos": 1}.get(mode, 2 if mode == "fixed" else 0)
    if mode == "none":
        beta0, gain0, code = float(b), 1.0, 2
    w, b = _zoom_kernel(float(w), float(b), float(steps[0]), float(steps[1]), int(levels),
                        mode in ("beta", "cos"), code, float(beta0), float(gain0),
                        win.gravity_m_s2, float(win.water_depth_m), model == "free", win.packed,
                        weights, win.tss, win.has_track)  # fmt: skip
    return float(w), float(b)


def fit_model(win: FitWindow, model: str, peaks, beta_fixed: Direction | None = None):
    """Search, reweight by the residual variances, refine; the :class:`WaveFit` (not yet
    judged), or None without a candidate. ``beta_fixed``: a given direction, else searched."""
    weights = np.where(win.tss > 0, win.samples / np.maximum(win.tss, 1e-300), 0.0)
    used = _used(win, model)
    weights[[i for i in range(weights.size) if i not in used]] = 0.0
    mode = search_mode(win, model, beta_fixed)
    om, be = _initial(win, model, peaks, mode, beta_fixed)
    if om.size == 0:
        return None
    beta, gain = _dirs(win, mode, be, beta_fixed)
    j = int(np.argmin(evaluate(win, model, om, beta, weights, gain=gain)[0]))
    w, b = float(om[j]), float(be[j])
    steps = (np.pi / win.duration_s, 0.15 if mode == "cos" else np.deg2rad(10.0))
    for levels in (5, 0):  # weights 1 / sigma_c^2 from the residuals, then the zoom
        beta, gain = _dirs(win, mode, b, beta_fixed)
        rss = evaluate(win, model, w, beta, weights, hp=True, gain=gain)[2][0]
        weights = np.zeros_like(weights)
        weights[used] = win.samples[used] / np.maximum(rss[used], 1e-300)
        w, b = _zoom(win, model, weights, w, b, steps, levels, mode, beta_fixed)
    beta, gain = _dirs(win, mode, b, beta_fixed)
    chi2, c, rss = evaluate(win, model, w, beta, weights, hp=True, gain=gain)
    loglik = -0.5 * float(np.sum(win.samples * np.log(rss[0] / win.samples)))
    cells = {"beta": BETAS.size, "cos": COS_GRID.size}.get(mode, 1)
    return WaveFit(model, mode, w, float(beta[0]), float(gain[0]), c[0], rss[0], weights, loglik,
                   cells)  # fmt: skip


def encounter(win: FitWindow, fit: WaveFit) -> float:
    """omega_e = omega - k gain V_mean . e_beta of a fit."""
    k = float(wavenumber(fit.omega_rad_s, win.water_depth_m, win.gravity_m_s2))
    e = fit.gain * np.array([np.cos(fit.beta_rad), np.sin(fit.beta_rad)])
    return float(fit.omega_rad_s - k * (win.mean_velocity_m_s @ e))


def judge(win: FitWindow, fit: WaveFit, **changes) -> WaveFit:
    """The fit with its explained fraction sum_c w_c (TSS_c - RSS_c) / sum_c w_c TSS_c and the
    calm test (module doc), and any other ``changes`` of its fields."""
    used = _used(win, fit.model)
    w = fit.weights
    gain = float(((win.tss - fit.rss) * w)[used].sum())
    explained = gain / max(float((win.tss * w)[used].sum()), 1e-300)
    calm = gain <= _calm_level(win, fit.cells) or explained < MIN_EXPLAINED
    return dataclasses.replace(fit, explained=explained, calm=calm, **changes)


def _calm_level(win: FitWindow, searched_betas: int) -> float:
    """2 ln(M / alpha): M = frequency cells (band x duration) x direction cells."""
    nyq = 0.5 * min(c.rate_hz for c in win.channels)
    cells = max((0.9 * nyq - F_LOW_HZ) * win.duration_s, 1.0) * searched_betas
    return 2.0 * math.log(cells / _ALPHA)


__all__ = [
    "BETAS",
    "COS_GRID",
    "MIN_EXPLAINED",
    "Direction",
    "FitWindow",
    "WaveFit",
    "encounter",
    "evaluate",
    "fit_model",
    "judge",
    "ridge",
    "search_mode",
]
