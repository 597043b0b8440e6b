"""A sea state that changes during a run: one Airy wave whose amplitude and frequency follow a
:class:`~undertow.wavetrack.WaveTrack` (nodes (t_i, a_i, f_i), linear in between), in the
quasi-stationary (slowly varying) approximation of linear theory (Mei, Stiassnie & Yue, "Theory
and Applications of Ocean Surface Waves", ch. 3, the WKB wave train; Dean & Dalrymple, "Water
Wave Mechanics for Engineers and Scientists", ch. 3-4 for the Airy fields):

    a(t), f(t)   from the track (f held over calm nodes, so a ramp from calm keeps the new f)
    omega(t)     = 2 pi f(t),  omega(t)^2 = g k(t) tanh(k(t) h)   (dispersion at each t)
    Phi(t)       = int_0^t omega(tau) dtau                         (closed form, omega piecewise
                                                                    linear: a quadratic per ramp)
    theta(x,y,t) = k(t) (s - s_r) + k(0) s_r - Phi(t) + phi_0,   s = x cos(beta) + y sin(beta)

with s_r the along-wave coordinate of the reference point (the wave probe), where the phase is
exact: there eta = a(t) cos(k(0) s_r - Phi(t) + phi_0) has the instantaneous frequency omega(t)
and no phase jump anywhere (Phi is continuous). With a constant condition theta reduces to
LinearWave's k s - omega t + phi_0. The fields are LinearWave's with a, omega, k taken at t:

    eta = a cos(theta),  U = a omega cosh(k (h - d)) / sinh(k h),  W = a omega sinh(..)/sinh(k h),
    u = (U cos theta) e_beta + (-W sin theta) e_z,   du/dt = U omega sin theta e_beta
    + W omega cos theta e_z,  xi = -(U / omega) sin theta e_beta - (W / omega) cos theta e_z,
    p_d = rho g a cosh(k (h - d)) / cosh(k h) cos theta     (z down, d the depth).

Slowly varying means the terms this drops, da/dt / (a omega) and the local-frequency error
-d theta/dt - omega = -k'(t) (s - s_r), stay small: the scenario checks ramps of at least two
wave periods and |k'| |s - s_r| <= 10 % of omega over the robot's path (``scenario/checks.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..log import FRESH_WATER_DENSITY
from ..wavetrack import WaveTrack
from .waves import depth_factors_finite, solve_wavenumber, solve_wavenumbers


def phase_integral(t, t_nodes: np.ndarray, omega_nodes: np.ndarray) -> np.ndarray:
    """Phi(t) = int_0^t omega, omega linear between the nodes and held outside them."""
    t = np.asarray(t, float)
    dt = np.diff(t_nodes)
    d_omega = np.diff(omega_nodes)
    slope = np.zeros(t_nodes.size)
    slope[:-1] = np.divide(d_omega, dt, out=np.zeros_like(dt), where=dt > 0)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (omega_nodes[:-1] + omega_nodes[1:]) * dt)])

    def from_first(tt):
        j = np.clip(np.searchsorted(t_nodes, tt, side="right") - 1, 0, t_nodes.size - 1)
        tau = tt - t_nodes[j]
        ramp = np.where(tau > 0, slope[j], 0.0)
        return cum[j] + omega_nodes[j] * tau + 0.5 * ramp * tau * tau

    return from_first(t) - from_first(np.zeros(1))[0]


@dataclass(frozen=True, eq=False)
class WaveField:
    """The time-varying wave of a ``track`` (heading ``beta`` rad, phase ``phi_0`` rad at the
    world origin at t = 0, reference point ``reference_xy`` where the phase is exact) in water of
    depth ``h`` (m), density ``rho``, gravity ``g``."""

    track: WaveTrack
    h: float
    beta: float = np.pi
    phi_0: float = 0.0
    rho: float = FRESH_WATER_DENSITY
    g: float = 9.80665
    reference_xy: tuple[float, float] = (0.0, 0.0)

    @cached_property
    def _nodes(self):
        """(t, omega, k) at the track's nodes that have a frequency (one node at 1 Hz if none)."""
        tr = self.track
        has_f = np.isfinite(tr.frequency_hz)
        t_f = tr.t[has_f] if has_f.any() else np.zeros(1)
        omega = 2 * np.pi * (tr.frequency_hz[has_f] if has_f.any() else np.ones(1))
        k = np.array([solve_wavenumber(float(w), self.h, self.g) for w in omega])
        return t_f, omega, k

    @property
    def is_calm(self) -> bool:
        return bool(np.all(self.track.amplitude_m == 0.0))

    @property
    def s_ref(self) -> float:
        x, y = self.reference_xy
        return float(x * np.cos(self.beta) + y * np.sin(self.beta))

    def amplitude_at(self, t) -> np.ndarray:
        return np.interp(np.asarray(t, float), self.track.t, self.track.amplitude_m)

    def omega_at(self, t) -> np.ndarray:
        t_f, omega, _ = self._nodes
        return np.interp(np.asarray(t, float), t_f, omega)

    def k_at(self, t) -> np.ndarray:
        """k(t) from the dispersion relation: exact node values while held, Newton in ramps."""
        t = np.asarray(t, float)
        t_f, omega, k_n = self._nodes
        k = np.interp(t, t_f, k_n)
        if t_f.size > 1:
            j = np.clip(np.searchsorted(t_f, t, side="right") - 1, 0, t_f.size - 2)
            ramp = (omega[j] != omega[j + 1]) & (t > t_f[j]) & (t < t_f[j + 1])
            if np.any(ramp):
                k[ramp] = solve_wavenumbers(self.omega_at(t[ramp]), self.h, self.g)
        return k

    def phase(self, x, y, t) -> np.ndarray:
        """theta = k(t) (s - s_r) + k(0) s_r - Phi(t) + phi_0."""
        t = np.asarray(t, float)
        t_f, omega, _ = self._nodes
        along = np.asarray(x) * np.cos(self.beta) + np.asarray(y) * np.sin(self.beta)
        s_r = self.s_ref
        k0 = float(self.k_at(np.zeros(1))[0])
        return self.k_at(t) * (along - s_r) + k0 * s_r - phase_integral(t, t_f, omega) + self.phi_0

    def elevation(self, x, y, t) -> np.ndarray:
        """eta = a(t) cos(theta) (m, positive UP)."""
        return self.amplitude_at(t) * np.cos(self.phase(x, y, t))

    def _factors(self, d, t):
        """(a, omega, k, cosh(k(h-d))/sinh(kh), sinh(k(h-d))/sinh(kh), cosh(k(h-d))/cosh(kh))."""
        a, omega, k = self.amplitude_at(t), self.omega_at(t), self.k_at(t)
        return a, omega, k, *depth_factors_finite(k, self.h, d)

    def velocity_amplitude_at(self, d, t) -> tuple[np.ndarray, np.ndarray]:
        """(U, W) = a omega (cosh, sinh)(k (h - d)) / sinh(k h) at depth d and times t."""
        a, omega, _, ch, sh, _ = self._factors(d, t)
        return a * omega * ch, a * omega * sh

    def orbital_velocity(self, x, y, d, t) -> np.ndarray:
        theta = self.phase(x, y, t)
        U, W = self.velocity_amplitude_at(d, t)
        u_h = U * np.cos(theta)
        return np.stack(
            [u_h * np.cos(self.beta), u_h * np.sin(self.beta), -W * np.sin(theta)], axis=-1
        )

    def orbital_acceleration(self, x, y, d, t) -> np.ndarray:
        """Quasi-stationary du/dt = U omega sin(theta) e_beta + W omega cos(theta) e_z."""
        theta = self.phase(x, y, t)
        U, W = self.velocity_amplitude_at(d, t)
        omega = self.omega_at(t)
        du_h = U * omega * np.sin(theta)
        return np.stack(
            [du_h * np.cos(self.beta), du_h * np.sin(self.beta), W * omega * np.cos(theta)],
            axis=-1,
        )

    def particle_displacement(self, x, y, d, t) -> np.ndarray:
        theta = self.phase(x, y, t)
        U, W = self.velocity_amplitude_at(d, t)
        omega = self.omega_at(t)
        xi_h = -U / omega * np.sin(theta)
        zeta_down = -W / omega * np.cos(theta)
        return np.stack([xi_h * np.cos(self.beta), xi_h * np.sin(self.beta), zeta_down], axis=-1)

    def dynamic_pressure(self, x, y, d, t) -> np.ndarray:
        """p_d = rho g a(t) K_p(d, t) cos(theta), K_p = cosh(k(h - d)) / cosh(k h)."""
        a, _, _, _, _, kp = self._factors(d, t)
        return self.rho * self.g * a * kp * np.cos(self.phase(x, y, t))

    def orbital_slope(self, x, y, d, t) -> np.ndarray:
        """d zeta_up / d s = -k(t) (W / omega) sin(theta)."""
        a, _, k, _, sh, _ = self._factors(d, t)
        return -k * (a * sh) * np.sin(self.phase(x, y, t))
