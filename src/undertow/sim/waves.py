"""Linear (Airy) waves in water of finite depth (Dean & Dalrymple, "Water Wave Mechanics for
Engineers and Scientists", chapters 3-4).

Airy theory is written with z UP and z = 0 at the still surface (the water is -h < z_up < 0):

    eta(x, t)  = a cos(theta),  theta = k (x cos(beta) + y sin(beta)) - omega t + phi_0
    omega^2    = g k tanh(k h)                         (dispersion relation, solved by Newton)
    u_h        = a omega cosh(k (z_up + h)) / sinh(k h) cos(theta)   (along the wave heading beta)
    w_up       = a omega sinh(k (z_up + h)) / sinh(k h) sin(theta)
    xi_h       = -a cosh(k (z_up + h)) / sinh(k h) sin(theta)        (particle displacement)
    zeta_up    =  a sinh(k (z_up + h)) / sinh(k h) cos(theta)
    p_d        = rho g a cosh(k (z_up + h)) / cosh(k h) cos(theta)   (dynamic pressure, K_p)

The log's world frame has z DOWN (depth d = -z_up), so every method here takes the depth ``d``
and returns vertical components positive DOWN: w_down = -w_up, zeta_down = -zeta_up.
Deep water (k h > pi) everything decays as a e^{-k d}.

A sea state that changes during a run is :class:`~undertow.sim.wavefield.WaveField`; both classes
answer the same questions at given times (``velocity_amplitude_at(d, t)``, ``omega_at(t)``,
``orbital_slope``, ``is_calm``), so every sensor model takes either.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..log import FRESH_WATER_DENSITY


def solve_wavenumber(omega: float, depth: float, g: float, tol: float = 1e-12) -> float:
    """Wavenumber k (rad/m) with omega^2 = g k tanh(k h), by Newton's method.

    Newton on F(k) = g k tanh(k h) - omega^2, F'(k) = g tanh(k h) + g k h sech^2(k h),
    started from the larger of the deep (omega^2/g) and shallow (omega/sqrt(g h)) limits, from
    which the iteration is monotone (F is convex in k). Returns 0 for omega = 0.
    """
    if omega <= 0.0:
        return 0.0
    k = max(omega * omega / g, omega / np.sqrt(g * depth))
    for _ in range(100):
        th = np.tanh(k * depth)
        f = g * k * th - omega * omega
        df = g * th + g * k * depth * (1.0 - th * th)  # sech^2 = 1 - tanh^2, no overflow
        step = f / df
        k -= step
        if abs(step) < tol * k:
            break
    return float(k)


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

    def _depth_factors(self, d):
        """cosh(k(h - d))/sinh(kh), sinh(k(h - d))/sinh(kh), cosh(k(h - d))/cosh(kh), computed
        as ratios of exponentials so deep water does not overflow."""
        kh = self.k * self.h
        s = self.k * (self.h - np.clip(np.asarray(d, dtype=float), 0.0, self.h))
        e = np.exp(s - kh)  # e^{k(z+h) - kh}
        e2 = np.exp(-s - kh)
        one_m = 1.0 - np.exp(-2.0 * kh)
        one_p = 1.0 + np.exp(-2.0 * kh)
        return (e + e2) / one_m, (e - e2) / one_m, (e + e2) / one_p

    def velocity_amplitude(self, d) -> tuple[np.ndarray, np.ndarray]:
        """Orbital speed amplitudes (horizontal U, vertical W) in m/s at depth d (m)."""
        if self.a == 0.0 or self.k == 0.0:
            z = np.zeros_like(np.asarray(d, dtype=float))
            return z, z
        ch, sh, _ = self._depth_factors(d)
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
        _, _, kp = self._depth_factors(d)
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
