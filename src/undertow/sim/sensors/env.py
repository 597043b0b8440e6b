"""Barometer, Ping sonar and wave probe models.

Barometer at depth d (world z of the sensor point, lever arm included):

    p = p_atm + rho g d + rho g a cosh(k(h - d)) / cosh(k h) cos(theta) + n_p,  n_p ~ N(0, s_p^2)

Ping sonar: the first return inside the cone of full angle alpha is the minimum slant range over
the cone, found by casting a fan (the axis plus ``rings`` rings of ``azimuths`` rays at half
angles j alpha / (2 rings)) and taking the minimum r*; measured
r = (c_set / c_true) (r* + N(0, s_0^2 + (f r*)^2 + (kappa_r zeta_rms(d))^2)): the Ping converts
the echo's two-way travel time t to c_set t / 2 with the sound speed it is set to
(ping-protocol ``set_speed_of_sound``, 1500 m/s by default), c_true the water's; the wave term
is the DVL's (dvl.py: the acoustic path's disturbance, kappa_r times the vertical orbital
displacement RMS at the sonar's depth d), which a Ping on the same vehicle meets alike.
Confidence = share of the fan's rays whose range is within ``confidence_window`` of r* (a wide
flat echo is a confident one; a ray fan split by the rock edge is not). No return in
[min_range, max_range]: range NaN, confidence 0.

Wave probe at fixed (x_p, y_p): eta = a cos(k (x_p cos beta + y_p sin beta) - omega t + phi_0) +
N(0, s_eta^2), positive UP. In a changing sea (sim/wavefield.py) a, omega, k and theta are
those at each sample time.
"""

from __future__ import annotations

import numpy as np

from ...log import Pressure, SonarRange, WaveProbe
from ...robot import SensorMount
from ..motion import kinematics
from ..scenario.sensors import BarometerModel, SonarModel, WaveProbeModel
from ..tank import Tank
from ..wavefield import WaveField
from ..waves import LinearWave
from .imu import sample_times


def simulate_barometer(
    motion, wave: LinearWave | WaveField, config: BarometerModel, mount: SensorMount,
    p_atm: float, duration: float, rng,
) -> Pressure:  # fmt: skip
    t = sample_times(duration, config.rate_hz)
    pos = kinematics(motion, t, mount.translation).position
    d = pos[:, 2]
    p = p_atm + wave.rho * wave.g * d + wave.dynamic_pressure(pos[:, 0], pos[:, 1], d, t)
    return Pressure(t=t, pressure=p + rng.normal(0.0, config.noise_sigma_pa, t.size))


def sonar_fan(beam_angle_deg: float, rings: int, azimuths: int) -> np.ndarray:
    """Unit ray directions (M, 3) in the sonar frame (+z the acoustic axis) covering the cone."""
    half = np.deg2rad(beam_angle_deg) / 2
    rays = [np.array([0.0, 0.0, 1.0])]
    az = 2 * np.pi * np.arange(azimuths) / azimuths
    for j in range(1, rings + 1):
        c = half * j / rings
        rays.extend(
            np.stack(
                [np.sin(c) * np.cos(az), np.sin(c) * np.sin(az), np.full(azimuths, np.cos(c))], 1
            )
        )
    return np.asarray(rays)


def simulate_sonar(
    motion,
    tank: Tank,
    config: SonarModel,
    mount: SensorMount,
    sound_speed_true: float,
    duration: float,
    rng,
    wave: LinearWave | WaveField | None = None,
) -> SonarRange:
    t = sample_times(duration, config.rate_hz)
    n = t.size
    kin = kinematics(motion, t, mount.translation)
    R_ws = kin.R @ mount.rotation_matrix()
    fan = sonar_fan(config.beam_angle_deg, config.fan_rings, config.fan_azimuths)
    m = fan.shape[0]
    dirs = np.einsum("nij,kj->nki", R_ws, fan).reshape(-1, 3)
    ranges = tank.cast_rays(np.repeat(kin.position, m, axis=0), dirs, config.max_range)
    ranges = ranges.reshape(n, m)
    hit = np.isfinite(ranges).any(axis=1)
    first = np.where(hit, np.nanmin(np.where(np.isfinite(ranges), ranges, np.inf), axis=1), np.nan)
    within = np.abs(ranges - first[:, None]) <= config.confidence_window
    confidence = np.where(hit, within.sum(axis=1) / m, 0.0)
    sigma = np.hypot(config.range_sigma, config.range_sigma_fraction * np.nan_to_num(first))
    if wave is not None and config.wave_range_noise_coefficient > 0:
        _, W = wave.velocity_amplitude_at(kin.position[:, 2], t)  # as the DVL's (dvl.py)
        zeta_rms = (W / wave.omega_at(t)) / np.sqrt(2.0)
        sigma = np.hypot(sigma, config.wave_range_noise_coefficient * zeta_rms)
    scale = config.sound_speed_setting / sound_speed_true
    measured = scale * (first + sigma * rng.standard_normal(n))
    ok = hit & (measured >= config.min_range) & (measured <= config.max_range)
    return SonarRange(
        t=t,
        range=np.where(ok, measured, np.nan),
        confidence=np.where(ok, confidence, 0.0),
        field_of_view=float(np.deg2rad(config.beam_angle_deg)),
        min_range=config.min_range,
        max_range=config.max_range,
    )


def simulate_wave_probe(
    wave: LinearWave | WaveField, config: WaveProbeModel, duration: float, rng
) -> WaveProbe:
    t = sample_times(duration, config.rate_hz)
    eta = wave.elevation(config.x_m, config.y_m, t) + rng.normal(0.0, config.noise_sigma, t.size)
    return WaveProbe(t=t, elevation=eta, x=config.x_m)
