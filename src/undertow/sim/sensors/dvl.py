"""DVL model (bottom track): four beams, ray-cast ranges, least squares velocity.

Beams b_i (DVL frame) from the scenario's geometry (``DvlModel.geometry()``: a preset of
``robot.DVL_PRESETS``, the Water Linked A50 by default, or tilt and azimuths given), world
directions R_wd b_i with
R_wd = R_wb R_bd (Mounting.dvl). Per report at t_n, with v_d = R_wd^T v the DVL-point velocity
over the fixed floor in the DVL frame:

    r_i   = (c_set / c_true) (ray cast from the DVL origin along R_wd b_i onto the floor
            (tank.py) + n_r)                                                (range)
    m_i   = (c_set / c_true) b_i . v_d + n_b,   n_b ~ N(0, sigma_b^2)      (radial velocity)
    v_hat = (B^T B)^{-1} B^T m   over the valid beams (>= 3), B rows b_i,
            Cov = sigma_b^2 (B^T B)^{-1}  ->  sigma_x = sigma_b / (sqrt2 sin tilt),
                                              sigma_z = sigma_b / (2 cos tilt)  with 4 beams
                                              at azimuths 90 deg apart
    v_meas = v_hat + R_wd^T (g_a e_beta + g_c e_perp + g_v e_z),  g_j ~ N(0, (kappa_j U(d)/sqrt2)^2)
    altitude = mean over valid beams of r_i b_i,z

A beam is valid when it hits the floor at 0.05 <= r <= 50 m. The wave term is the acoustic-path
disturbance (bubbles, pressure fluctuation near the surface): its standard deviation scales with
the orbital speed amplitude U(d) = a omega cosh(k(h-d))/sinh(kh) at the DVL depth d, kappa per
axis from the scenario (or given directly); in a changing sea a, omega, k are those at t_n.
The paper's Table I values are measured data; the simulator does NOT copy them. The wave range
noise scales likewise with the vertical orbital displacement RMS. c_set / c_true is the
sound-speed scale error: each beam's radial velocity is c f_D / (2 f_0) (the Doppler relation,
f_0 the carrier and f_D the Doppler shift), so a DVL with fixed beam angles scales every
velocity by the sound speed it is set to; each range is c t / 2 of the echo's two-way travel
time t, so it scales every range (and the altitude) by the same ratio.

Dead reckoning (A50 ``position_local``): orientation = true body roll, pitch, yaw plus a
constant-rate drift (uncalibrated gyro bias) and white noise; position integrated (forward
Euler, reset frame = world, starting at the true position) from its own velocity reports
rotated by that drifting orientation: p[n+1] = p[n] + R(rpy_dr[n]) R_bd v_meas[n] dt.
"""

from __future__ import annotations

import numpy as np

from ...log import DeadReckoning, Dvl
from ...robot import SensorMount
from ...rotations import rpy_to_matrix, wrap_angle
from ..motion import kinematics
from ..scenario.sensors import DeadReckoningModel, DvlModel
from ..tank import Tank
from ..wavefield import WaveField
from ..waves import LinearWave
from .imu import sample_times


def least_squares_velocity(B: np.ndarray, m: np.ndarray, valid: np.ndarray):
    """Velocity (N, 3) and (B_v^T B_v)^{-1} (N, 3, 3) from radial velocities m (N, 4) over the
    valid beams of each row; NaN where fewer than 3 beams are valid."""
    n = m.shape[0]
    v = np.full((n, 3), np.nan)
    info_inv = np.full((n, 3, 3), np.nan)
    codes = valid.astype(int) @ (1 << np.arange(valid.shape[1]))
    for code in np.unique(codes):
        mask = (code >> np.arange(valid.shape[1])) & 1 == 1
        if mask.sum() < 3:
            continue
        rows = codes == code
        Bm = B[mask]
        cov = np.linalg.inv(Bm.T @ Bm)
        v[rows] = m[rows][:, mask] @ (cov @ Bm.T).T
        info_inv[rows] = cov
    return v, info_inv


def simulate_dvl(
    motion,
    wave: LinearWave | WaveField,
    tank: Tank,
    config: DvlModel,
    mount: SensorMount,
    sound_speed_true: float,
    duration: float,
    rng,
) -> Dvl:
    t = sample_times(duration, config.rate_hz)
    n = t.size
    kin = kinematics(motion, t, mount.translation)
    R_wd = kin.R @ mount.rotation_matrix()
    B = config.geometry().units()
    dirs = np.einsum("nij,kj->nki", R_wd, B)
    origins = np.repeat(kin.position, 4, axis=0)
    true_range = tank.cast_rays(origins, dirs.reshape(-1, 3), config.max_range).reshape(n, 4)

    depth = kin.position[:, 2]
    U, W = wave.velocity_amplitude_at(depth, t)  # U(d, t): the sea state at each report
    zeta_rms = (W / wave.omega_at(t)) / np.sqrt(2.0)
    range_sigma = np.hypot(config.range_sigma, config.wave_range_noise_coefficient * zeta_rms)
    scale = config.sound_speed_setting / sound_speed_true
    beam_range = scale * (true_range + range_sigma[:, None] * rng.standard_normal((n, 4)))
    beam_valid = np.isfinite(beam_range)
    beam_valid &= (beam_range >= config.min_range) & (beam_range <= config.max_range)
    beam_range = np.where(beam_valid, beam_range, np.nan)

    v_d = np.einsum("nji,nj->ni", R_wd, kin.velocity)
    radial = scale * v_d @ B.T + rng.normal(0.0, config.beam_velocity_sigma, (n, 4))
    velocity, info_inv = least_squares_velocity(B, radial, beam_valid)

    if config.wave_noise_sigma is not None:
        wave_sigma = np.tile(np.asarray(config.wave_noise_sigma, float), (n, 1))
    else:
        wave_sigma = (
            np.asarray(config.wave_noise_coefficient)[None, :] * (U / np.sqrt(2.0))[:, None]
        )
    g_wave = wave_sigma * rng.standard_normal((n, 3))
    e_beta = np.array([np.cos(wave.beta), np.sin(wave.beta), 0.0])
    e_perp = np.array([-np.sin(wave.beta), np.cos(wave.beta), 0.0])
    world = g_wave[:, :1] * e_beta + g_wave[:, 1:2] * e_perp + g_wave[:, 2:3] * [0.0, 0.0, 1.0]
    velocity = velocity + np.einsum("nji,nj->ni", R_wd, world)

    valid = np.all(np.isfinite(velocity), axis=1)
    covariance = config.beam_velocity_sigma**2 * info_inv
    fom = np.sqrt(np.max(np.diagonal(covariance, axis1=1, axis2=2), axis=1))
    n_valid = beam_valid.sum(axis=1)
    altitude = np.where(
        n_valid > 0, np.nansum(beam_range * B[:, 2], axis=1) / np.maximum(n_valid, 1), np.nan
    )
    return Dvl(
        t=t,
        velocity=velocity,
        valid=valid,
        fom=fom,
        covariance=covariance,
        altitude=altitude,
        beam_id=np.tile(np.arange(4), (n, 1)),
        beam_unit=np.tile(B, (n, 1, 1)),
        beam_range=beam_range,
        beam_valid=beam_valid,
        beam_velocity=np.where(beam_valid, radial, np.nan),
    )


def simulate_dead_reckoning(
    motion, dvl: Dvl, config: DeadReckoningModel, mount: SensorMount, duration: float, rng
) -> DeadReckoning:
    drift = np.array([*config.roll_pitch_drift_rate, config.yaw_drift_rate])
    # orientation at the DVL reports drives the integration
    rpy_at_dvl = kinematics(motion, dvl.t).rpy + drift * dvl.t[:, None]
    v = np.array(dvl.velocity)
    good = np.all(np.isfinite(v), axis=1)
    if not good.any():
        v[:] = 0.0
    else:  # hold the last valid velocity (the first valid one before any)
        idx = np.maximum.accumulate(np.where(good, np.arange(v.shape[0]), -1))
        idx = np.where(idx < 0, np.argmax(good), idx)
        v = v[idx]
    v_world = np.einsum("nij,nj->ni", rpy_to_matrix(rpy_at_dvl) @ mount.rotation_matrix(), v)
    dt = np.diff(dvl.t, append=dvl.t[-1])
    p0 = motion.pose(dvl.t[:1])[0][0]
    p_dvl = p0 + np.concatenate([[np.zeros(3)], np.cumsum(v_world * dt[:, None], axis=0)[:-1]])

    t = sample_times(duration, config.rate_hz)
    position = np.stack([np.interp(t, dvl.t, p_dvl[:, i]) for i in range(3)], axis=1)
    rpy = kinematics(motion, t).rpy + drift * t[:, None]
    rpy = rpy + rng.normal(0.0, config.orientation_sigma, rpy.shape)
    rpy[:, 2] = wrap_angle(rpy[:, 2])
    return DeadReckoning(t=t, position=position, orientation=rpy, std=None)
