"""Linear (Airy) waves in water of finite depth: the one home of the wave physics the simulator
and the estimators share, the dispersion relation and the transfer functions from the surface
elevation to what a robot's sensors see (Dean & Dalrymple, "Water Wave Mechanics for Engineers
and Scientists", World Scientific 1991, ch. 3-4).

Airy theory is written with z UP and z = 0 at the still surface (the water is -h < z_up < 0):

    eta(x, t)  = a cos(theta),  theta = k (x cos(beta) + y sin(beta)) - omega t + phi_0
    omega^2    = g k tanh(k h)                         (dispersion relation)
    u_h        = a omega cosh(k (z_up + h)) / sinh(k h) cos(theta)   (along the wave heading beta)
    w_up       = a omega sinh(k (z_up + h)) / sinh(k h) sin(theta)
    xi_h       = -a cosh(k (z_up + h)) / sinh(k h) sin(theta)        (particle displacement)
    zeta_up    =  a sinh(k (z_up + h)) / sinh(k h) cos(theta)
    p_d        = rho g a cosh(k (z_up + h)) / cosh(k h) cos(theta)   (dynamic pressure, K_p)

The log's world frame has z DOWN (depth d = -z_up), so every function here takes the depth ``d``
and returns vertical components positive DOWN: w_down = -w_up, zeta_down = -zeta_up.
Deep water (k h > pi) everything decays as a e^{-k d}. The depth factors at depth d
(0 <= d <= h) and the encounter frequency of a sensor moving at speed V over ground on course psi:

    K_h(d)  = cosh(k (h - d)) / sinh(k h)      (horizontal particle displacement / a)
    K_s(d)  = sinh(k (h - d)) / sinh(k h)      (vertical particle displacement / a)
    K_p(d)  = cosh(k (h - d)) / cosh(k h)      (dynamic pressure head / a)
    omega_e = omega - k V cos(beta - psi)

A rigidly held sensor reads the dynamic pressure head a K_p cos(theta). A free body riding the
orbit is displaced by xi_h = -a K_h sin(theta) along beta and zeta_up = a K_s cos(theta), so its
barometer reads a (K_p - K_s) cos(theta) and its velocity over the floor is
u_h = a K_h omega_e cos(theta), w_up = a K_s omega_e sin(theta) (theta's rate is -omega_e along
the path).

Two solvers of the dispersion relation serve two uses, and each output keeps its own numbers:
the simulator's Newton iteration to a tolerance (:func:`solve_wavenumber`,
:func:`solve_wavenumbers`), and the estimator's compiled Fenton & McKee start with four Newton
steps (:func:`wavenumber`, which also takes deep water h = inf, and :func:`wavenumber_array`,
callable from compiled kernels). They agree within 5e-16 relative (two units in the last place).
Likewise the depth factors: :func:`depth_factors` (any depth, h = inf included; the estimators)
and :func:`depth_factors_finite` (finite depth; the simulator's waves), the same K_h, K_s, K_p
within 1e-13 relative, computed through different exponents.

A sea state that changes during a run is :class:`~undertow.sim.wavefield.WaveField`; it and
:class:`LinearWave` answer the same questions at given times (``velocity_amplitude_at(d, t)``,
``omega_at(t)``, ``orbital_slope``, ``is_calm``), so every sensor model takes either.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit

from ..log import FRESH_WATER_DENSITY

# ------------------------------------------------------------------------ dispersion relation


def solve_wavenumbers(omega, depth: float, g: float, tol: float = 1e-12) -> np.ndarray:
    """Wavenumbers k (rad/m) with omega^2 = g k tanh(k h), elementwise, by Newton's method, for
    omega > 0 in finite depth h.

    Newton on F(k) = g k tanh(k h) - omega^2, F'(k) = g tanh(k h) + g k h sech^2(k h),
    started from the larger of the deep (omega^2/g) and shallow (omega/sqrt(g h)) limits, from
    which the iteration is monotone (F is convex in k); every element is stepped until all have
    converged (|step| < tol k).
    """
    omega = np.asarray(omega, float)
    k = np.maximum(omega * omega / g, omega / np.sqrt(g * depth))
    for _ in range(100):
        th = np.tanh(k * depth)
        # sech^2 = 1 - tanh^2, no overflow
        step = (g * k * th - omega * omega) / (g * th + g * k * depth * (1.0 - th * th))
        k = k - step
        if np.all(np.abs(step) < tol * k):
            break
    return k


def solve_wavenumber(omega: float, depth: float, g: float, tol: float = 1e-12) -> float:
    """Wavenumber k (rad/m) of one omega (:func:`solve_wavenumbers` on its own, so it converges
    on its own tolerance). Returns 0 for omega <= 0."""
    if omega <= 0.0:
        return 0.0
    return float(solve_wavenumbers(np.array([omega]), depth, g, tol)[0])


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
def wavenumber_array(w, h, g):
    """:func:`wavenumber` of a 1-D float array ``w``, compiled: callable from other kernels."""
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
    return wavenumber_array(np.ascontiguousarray(w).reshape(-1), float(h), float(g)).reshape(
        w.shape
    )


# ------------------------------------------------------------------------ transfer functions


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


@njit(cache=True)
def depth_factors_scalar(k, h, d):
    """(K_h, K_s, K_p) of :func:`depth_factors` for scalars, compiled: callable from kernels."""
    if not np.isfinite(h):
        e = np.exp(-k * max(d, 0.0))
        return e, e, e
    d = min(max(d, 0.0), h)
    e1, e2, m = np.exp(-k * d), np.exp(-k * (2.0 * h - d)), np.exp(-2.0 * k * h)
    return (e1 + e2) / (1.0 - m), (e1 - e2) / (1.0 - m), (e1 + e2) / (1.0 + m)


def depth_factors_finite(k, h: float, d):
    """(K_h, K_s, K_p) at depth d (clipped to [0, h]) in finite depth h, as the simulator's waves
    compute them: ratios of exponentials of s - k h and -s - k h, s = k (h - d)."""
    kh = k * h
    s = k * (h - np.clip(np.asarray(d, dtype=float), 0.0, h))
    e, e2 = np.exp(s - kh), np.exp(-s - kh)  # e^{k(z+h) - kh}, e^{-k(z+h) - kh}
    one_m, one_p = 1.0 - np.exp(-2.0 * kh), 1.0 + np.exp(-2.0 * kh)
    return (e + e2) / one_m, (e - e2) / one_m, (e + e2) / one_p


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


# ------------------------------------------------------------------------ one regular wave


@dataclass(frozen=True)
class LinearWave:
    """A single monochromatic Airy wave: amplitude ``a`` (m), frequency ``f`` (Hz), heading
    ``beta`` (rad, direction of propagation in the world x-y plane), phase ``phi_0`` (rad), in
    water of depth ``h`` (m) and density ``rho``; ``g`` gravity. ``a = 0`` gives calm water."""

    a: float
    f: float
    h: float
    beta: float = np.pi
    phi_0: float = 0.0
    rho: float = FRESH_WATER_DENSITY
    g: float = 9.80665

    @property
    def omega(self) -> float:
        return 2.0 * np.pi * self.f

    @cached_property
    def k(self) -> float:
        return solve_wavenumber(self.omega, self.h, self.g)

    @property
    def wavelength(self) -> float:
        return 2.0 * np.pi / self.k if self.k > 0 else float("inf")

    def phase(self, x, y, t) -> np.ndarray:
        """theta = k (x cos beta + y sin beta) - omega t + phi_0."""
        along = np.asarray(x) * np.cos(self.beta) + np.asarray(y) * np.sin(self.beta)
        return self.k * along - self.omega * np.asarray(t) + self.phi_0

    def elevation(self, x, y, t) -> np.ndarray:
        """Surface elevation eta (m, positive UP, as a wave probe reads it)."""
        return self.a * np.cos(self.phase(x, y, t))

    def velocity_amplitude(self, d) -> tuple[np.ndarray, np.ndarray]:
        """Orbital speed amplitudes (horizontal U, vertical W) in m/s at depth d (m)."""
        if self.a == 0.0 or self.k == 0.0:
            z = np.zeros_like(np.asarray(d, dtype=float))
            return z, z
        ch, sh, _ = depth_factors_finite(self.k, self.h, d)
        return self.a * self.omega * ch, self.a * self.omega * sh

    def orbital_velocity(self, x, y, d, t) -> np.ndarray:
        """Water velocity (..., 3) in the z-down world frame at (x, y, depth d, t)."""
        theta = self.phase(x, y, t)
        U, W = self.velocity_amplitude(d)
        u_h = U * np.cos(theta)
        w_down = -W * np.sin(theta)
        return np.stack([u_h * np.cos(self.beta), u_h * np.sin(self.beta), w_down], axis=-1)

    def orbital_acceleration(self, x, y, d, t) -> np.ndarray:
        """Local water acceleration du/dt (..., 3), z-down world frame, at a fixed point."""
        theta = self.phase(x, y, t)
        U, W = self.velocity_amplitude(d)
        du_h = U * self.omega * np.sin(theta)
        dw_down = W * self.omega * np.cos(theta)
        return np.stack([du_h * np.cos(self.beta), du_h * np.sin(self.beta), dw_down], axis=-1)

    def particle_displacement(self, x, y, d, t) -> np.ndarray:
        """Orbital displacement (..., 3) about the mean point (x, y, d), z-down world frame."""
        theta = self.phase(x, y, t)
        U, W = self.velocity_amplitude(d)
        xi_h = -U / self.omega * np.sin(theta) if self.omega > 0 else 0.0 * theta
        zeta_down = -W / self.omega * np.cos(theta) if self.omega > 0 else 0.0 * theta
        return np.stack([xi_h * np.cos(self.beta), xi_h * np.sin(self.beta), zeta_down], axis=-1)

    def dynamic_pressure(self, x, y, d, t) -> np.ndarray:
        """p_d = rho g a K_p(d) cos(theta) (Pa), K_p = cosh(k(h - d)) / cosh(k h)."""
        if self.a == 0.0 or self.k == 0.0:
            return np.zeros(np.broadcast(np.asarray(x), np.asarray(t)).shape)
        _, _, kp = depth_factors_finite(self.k, self.h, d)
        return self.rho * self.g * self.a * kp * np.cos(self.phase(x, y, t))

    @property
    def is_calm(self) -> bool:
        """True when there is no wave at any time (a = 0)."""
        return self.a == 0.0

    def omega_at(self, t) -> float:
        """omega at the times ``t`` (constant here)."""
        return self.omega

    def velocity_amplitude_at(self, d, t) -> tuple[np.ndarray, np.ndarray]:
        """(U, W) at depth d and times t (constant in time here: ``velocity_amplitude(d)``)."""
        return self.velocity_amplitude(d)

    def orbital_slope(self, x, y, d, t) -> np.ndarray:
        """Along-wave slope of the orbital path surface through depth d,
        d zeta_up / d s = -k (W / omega) sin(theta), s the along-wave coordinate."""
        _, W = self.velocity_amplitude(d)
        return -self.k * (W / self.omega) * np.sin(self.phase(x, y, t))


__all__ = [
    "LinearWave",
    "depth_factors",
    "depth_factors_finite",
    "depth_factors_scalar",
    "encounter_frequency",
    "intrinsic_from_encounter",
    "solve_wavenumber",
    "solve_wavenumbers",
    "wavenumber",
    "wavenumber_array",
]
