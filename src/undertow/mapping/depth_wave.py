"""The swell's pressure in a trajectory's depth, as its filter passed it on, for the ``tpu``
mapper.

A barometer at depth d under a linear wave of amplitude a and angular frequency omega reads
the wave's dynamic pressure too: p = rho g d + rho g a K_p(d) cos(theta), K_p = cosh(k (h -
d)) / cosh(k h) (Dean and Dalrymple, "Water Wave Mechanics for Engineers and Scientists",
1991, ch. 4; k from omega^2 = g k tanh(k h), h the water depth), a depth error of RMS
a K_p / sqrt(2) that the paper's barometer model (``eq:bar_meas_model``) does not carry, so
the filter's depth covariance leaves it out (undertow's filters with wave noise carry it as
swell states, ``pressure_wave_noise``: their covariance holds what of it they could not separate
from the depth, and nothing is added here).

The filter's depth follows it as its depth update weighs the barometer: in steady state a
scalar Kalman filter's estimate is the first-order recursion x_n = (1 - K) x_{n-1}' + K z_n
with gain K = P^+ / R (P^+ the posterior variance, R the measurement's; Gelb, "Applied
Optimal Estimation", 1974, ch. 4), whose response to a sinusoid of angular frequency omega in
the measurements sampled every Delta is

    |H|^2 = K^2 / (1 - 2 (1 - K) cos(omega Delta) + (1 - K)^2).

So a hit placed from a pose of depth variance s_z^2 carries the swell's share

    s_p^2 = |H|^2 a^2 K_p(d)^2 / 2,   K = min(s_z^2 / R, 1),

R = (the filter's depth noise)^2 and Delta the barometer's sample interval; the mapper adds
s_p^2 to the pose's depth variance (:mod:`undertow.mapping.tpu`). The first-order model leaves
out the velocity the filter also corrects from the barometer and, being taken at the pose's
covariance (between updates as well as after them), slightly overstates the gain. The settings'
``depth_noise`` (std m, interval s) gives R and Delta; else they are the trajectory's: its
filter's ``depth_std_m`` and its pressure updates over its time span
(:func:`trajectory_depth_noise`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


def trajectory_depth_noise(trajectory) -> tuple[float, float] | None:
    """(std m, interval s) of the depth measurements the trajectory's filter fused: its
    config's ``depth_std_m`` and its time span over the pressure updates it used (metadata
    ``sensors.pressure.used``); None when the trajectory does not say (another estimator's,
    or no barometer) or when its filter already carried the swell (a variant
    with wave noise and ``pressure_wave_noise``: metadata ``wave_noise`` set and the config's
    ``pressure_wave_noise`` true), so its depth covariance holds it."""
    meta = getattr(trajectory, "metadata", None) or {}
    config = meta.get("config") if isinstance(meta.get("config"), dict) else {}
    if meta.get("wave_noise") is not None and config.get("pressure_wave_noise") is True:
        return None
    sensors = meta.get("sensors") if isinstance(meta.get("sensors"), dict) else {}
    pressure = sensors.get("pressure") if isinstance(sensors.get("pressure"), dict) else {}
    std, used = config.get("depth_std_m"), pressure.get("used")
    t = getattr(trajectory, "t", None)
    if not isinstance(std, (int, float)) or not isinstance(used, int) or used < 2 or t is None:
        return None
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    if not (std > 0 and span > 0 and math.isfinite(std)):
        return None
    return float(std), span / (used - 1)


def depth_wave_terms(depth_wave) -> tuple[float, float, float]:
    """(a, cos(omega Delta), R) of ``depth_wave`` (a m, f Hz, std m, Delta s); (0, 1, 1),
    which adds nothing, for None."""
    if depth_wave is None:
        return 0.0, 1.0, 1.0
    amplitude, frequency, std, interval = (float(v) for v in depth_wave)
    return amplitude, math.cos(2.0 * math.pi * frequency * interval), std * std


@njit(cache=True, inline="always")
def swell_variance(var_z, k_p, amplitude, cos_wd, r):
    """s_p^2 = |H|^2 a^2 K_p^2 / 2 (module doc) of a pose of depth variance ``var_z``."""
    if amplitude <= 0.0 or not var_z >= 0.0:
        return 0.0
    gain = min(var_z / r, 1.0)
    rest = 1.0 - gain
    h2 = gain * gain / (1.0 - 2.0 * rest * cos_wd + rest * rest)
    return h2 * (amplitude * k_p) ** 2 / 2.0


@njit(cache=True)
def swell_variances(var_z, k_p, amplitude, cos_wd, r):
    """:func:`swell_variance` of arrays (the same floating-point steps as one by one)."""
    out = np.empty(var_z.size)
    for i in range(var_z.size):
        out[i] = swell_variance(var_z[i], k_p[i], amplitude, cos_wd, r)
    return out
