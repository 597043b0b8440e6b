"""IMU model: gyro with white noise and a random-walk bias, accelerometer specific force.

    omega_m[n] = R_bs^T omega_b(t_n) + b[n] + sigma_d w[n],     b[n] = b[n-1] + sigma_bd v[n]
    f_m[n]     = R_bs^T R_wb^T (a_s(t_n) - g e_z) + sigma_ad w'[n]    (z down: g e_z is gravity)

with w, v standard normal. The scenario gives continuous densities and the rate f_s; the
per-sample values are (the discretization of Kalibr's "IMU Noise Model": sigma_c = sigma_d /
sqrt(rate), sigma_bc = sigma_bd sqrt(rate), i.e. the inverse conversion)

    sigma_d = sigma_c sqrt(f_s),   sigma_bd = sigma_bc / sqrt(f_s),   sigma_ad = sigma_ac sqrt(f_s).

a_s is the acceleration of the IMU point (lever arm included); at rest f_m = (0, 0, -g) in FRD.
No orientation is reported (``Imu.orientation`` is None).
"""

from __future__ import annotations

import numpy as np

from ...log import Imu
from ...robot import SensorMount
from ..motion import kinematics
from ..scenario.sensors import ImuModel


def sample_times(duration: float, rate_hz: float) -> np.ndarray:
    """t_n = n / rate for 0 <= t_n <= duration."""
    return np.arange(int(np.floor(duration * rate_hz + 1e-9)) + 1) / rate_hz


def simulate_imu(
    motion, config: ImuModel, mount: SensorMount, g: float, duration: float, rng
) -> tuple[Imu, np.ndarray]:
    """The IMU stream and the true gyro bias b (N, 3) at its samples."""
    t = sample_times(duration, config.rate_hz)
    n = t.size
    kin = kinematics(motion, t, mount.translation)
    R_bs = mount.rotation_matrix()
    omega_s = kin.omega_body @ R_bs
    f_world = kin.acceleration - np.array([0.0, 0.0, g])
    f_body = np.einsum("nji,nj->ni", kin.R, f_world)
    f_s = f_body @ R_bs

    sqrt_rate = np.sqrt(config.rate_hz)
    sigma_d = config.gyro_noise_density * sqrt_rate
    sigma_bd = config.gyro_bias_random_walk / sqrt_rate
    sigma_ad = config.accel_noise_density * sqrt_rate
    b0 = rng.normal(0.0, config.gyro_initial_bias_sigma, 3)
    steps = rng.normal(0.0, sigma_bd, (n, 3))
    steps[0] = 0.0
    bias = b0 + np.cumsum(steps, axis=0)
    gyro = omega_s + bias + rng.normal(0.0, sigma_d, (n, 3))
    accel = f_s + rng.normal(0.0, sigma_ad, (n, 3))
    return Imu(t=t, angular_velocity=gyro, linear_acceleration=accel, orientation=None), bias
