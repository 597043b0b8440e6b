"""Linear (Airy) wave transfer functions from the surface elevation to what a robot's sensors see.

Symbols (z down in the log; Dean & Dalrymple, "Water Wave Mechanics for Engineers and
Scientists", World Scientific 1991, ch. 3-4): surface eta = a cos(theta), water depth h, sensor
depth d (0 <= d <= h), wavenumber k, intrinsic angular frequency omega, propagation direction
beta (world x-y), gravity g.

    omega^2 = g k tanh(k h)                                   (dispersion relation)
    K_p(d)  = cosh(k (h - d)) / cosh(k h)                     (dynamic pressure head / a)
    K_h(d)  = cosh(k (h - d)) / sinh(k h)                     (horizontal particle displacement / a)
    K_s(d)  = sinh(k (h - d)) / sinh(k h)                     (vertical particle displacement / a)
    omega_e = omega - k V cos(beta - psi)                     (encounter frequency, speed V over
                                                               ground on course psi)

A rigidly held sensor reads the dynamic pressure head a K_p cos(theta). A free body riding the
orbit is displaced by xi_h = -a K_h sin(theta) along beta and zeta_up = a K_s cos(theta), so its
barometer reads a (K_p - K_s) cos(theta) and its velocity over the floor is
u_h = a K_h omega_e cos(theta), w_up = a K_s omega_e sin(theta) (theta's rate is -omega_e along
the path).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _wavenumber_one(w, h, g):
    """Scalar k(omega): Fenton & McKee start, four Newton steps (see :func:`wavenumber`)."""
    if not w > 0:
        return 0.0
    k0 = w * w / g
    if not np.isfinite(h):
        return k0
    k = k0 / np.tanh((w * np.sqrt(h / g)) ** 1.5) ** (2.0 / 3.0)
    for _ in range(4):
        th = np.tanh(k * h)
        k -= (g * k * th - w * w) / (g * th + g * k * h * (1.0 - th * th))
    return k


@njit(cache=True)
def _wavenumber_flat(w, h, g):
    out = np.zeros(w.size)
    for i in range(w.size):
        out[i] = _wavenumber_one(w[i], h, g)
    return out


def wavenumber(omega, h: float, g: float = 9.80665) -> np.ndarray:
    """k (rad/m) with omega^2 = g k tanh(k h), elementwise: the explicit approximation of
    Fenton & McKee (Coastal Engineering 14, 1990), k h = k_0 h coth((omega sqrt(h/g))^1.5)^(2/3)
    with k_0 = omega^2 / g (within 1.7 %), polished by four Newton steps on
    F(k) = g k tanh(k h) - omega^2 (quadratic convergence: ~1e-15 relative). Deep water
    (h = inf) gives k_0; omega <= 0 (or NaN) gives 0."""
    w = np.asarray(omega, dtype=float)
    return _wavenumber_flat(np.ascontiguousarray(w).reshape(-1), float(h), float(g)).reshape(
        w.shape
    )


def depth_factors(k, h: float, d) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K_h, K_s, K_p) at depth d (m, clipped to [0, h]) for wavenumber k in depth h, as ratios of
    exponentials (no overflow in deep water; h = inf gives e^{-k d} for all three)."""
    k = np.asarray(k, dtype=float)
    if not np.isfinite(h):
        e = np.exp(-k * np.maximum(np.asarray(d, float), 0.0))
        return e, e, e
    d = np.clip(np.asarray(d, dtype=float), 0.0, h)
    kh = k * h
    e1 = np.exp(-k * d)  # e^{k(h-d) - kh}
    e2 = np.exp(-k * (2.0 * h - d))  # e^{-k(h-d) - kh}
    m = np.exp(-2.0 * kh)
    with np.errstate(divide="ignore", invalid="ignore"):
        k_h = (e1 + e2) / (1.0 - m)
        k_s = (e1 - e2) / (1.0 - m)
    return k_h, k_s, (e1 + e2) / (1.0 + m)


def encounter_frequency(omega, k, speed, course_rad, beta_rad) -> np.ndarray:
    """omega_e = omega - k V cos(beta - psi)."""
    return np.asarray(omega) - np.asarray(k) * np.asarray(speed) * np.cos(
        np.asarray(beta_rad) - np.asarray(course_rad)
    )


@njit(cache=True)
def _intrinsic_flat(we, u, h, g):
    out = np.full(we.size, np.nan)
    for i in range(we.size):
        if not we[i] > 0:
            continue
        w = we[i]
        for _ in range(30):
            k = _wavenumber_one(w, h, g)
            kh = 2.0 * min(k * h, 300.0)
            cg = 0.5 * (w / k) * (1.0 + (kh / np.sinh(kh) if np.isfinite(h) else 0.0))
            slope = 1.0 - u[i] / cg
            if not slope > 1e-6:
                w = np.nan
                break
            step = (w - k * u[i] - we[i]) / slope
            w -= step
            if abs(step) <= 1e-14 * w:
                break
        if np.isfinite(w) and w > 0:
            k = _wavenumber_one(w, h, g)
            if abs(w - k * u[i] - we[i]) <= 1e-6 * we[i]:
                out[i] = w
    return out


def intrinsic_from_encounter(omega_e, along_speed, h: float, g: float = 9.80665) -> np.ndarray:
    """omega with omega - k(omega) U = omega_e, U = V cos(beta - psi) the speed along beta.

    F(omega) = omega - k(omega) U - omega_e, F' = 1 - U / c_g (d omega / d k = c_g, the group
    speed). For U <= 0 (head seas) F is convex and increasing: one root, Newton from omega_e
    (where F >= 0) decreases to it monotonically. For U > 0 (following seas) omega_e rises to a
    maximum where c_g = U and falls again; the vehicle is assumed slower than the waves, so the
    root on the rising branch is taken, reached monotonically from omega_e (F <= 0, F concave);
    NaN where there is none (omega_e above the maximum) or omega_e <= 0."""
    we, u = np.broadcast_arrays(np.asarray(omega_e, float), np.asarray(along_speed, float))
    out = _intrinsic_flat(np.ascontiguousarray(we).reshape(-1), np.ascontiguousarray(u).reshape(-1),
                          float(h), float(g))  # fmt: skip
    return out.reshape(we.shape)


__all__ = ["depth_factors", "encounter_frequency", "intrinsic_from_encounter", "wavenumber"]
