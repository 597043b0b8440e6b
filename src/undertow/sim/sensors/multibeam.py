"""Multibeam echosounder model: a fan of beams across track, ray-cast onto the floor.

Per ping at t_n (``MultibeamModel.rate_hz``), with the sensor pose from the mounting
(R_ws = R_wb R_bs, origin o = p + R_wb t_s):

    theta_j = -swath/2 + j swath / (B - 1),   u_j = (0, sin theta_j, cos theta_j)  (sensor frame)
    r_j     = ray cast from o along R_ws u_j onto the floor (tank.py, the scenario's heightfield)
    cos g_j = (R_ws u_j)_z                    (the beam's angle g_j from the world vertical)
    sigma_j = sqrt(a^2 + (b r_j cos g_j)^2) / cos g_j                                  (1)
    r~_j    = r_j + sigma_j n_j,   n_j ~ N(0, 1);   detection p_j = r~_j u_j

(1) is the IHO S-44 (6th ed., 2020) total vertical uncertainty sigma_d = sqrt(a^2 + (b d)^2) at
the depth d = r cos g below the head, projected on the beam (a vertical error dd is a range
error dd / cos g): the noise grows with range and with the angle off nadir. A level head
has g_j = theta_j. cos g is floored at 0.05 (a beam near horizontal). A beam whose ray
misses (NaN) or whose noisy range falls outside [min_range, max_range] has no detection (NaN
point), as drivers drop it. The ranges are in the water's own sound speed: a multibeam head
forms and steers its beams with the sound speed measured at its face (a sound velocity probe
at the transducer, as hydrographic surveys run them: IHO C-13, Manual on Hydrography, ch. 3),
unlike the DVL and the Ping, which convert travel times with the speed they are set to.
"""

from __future__ import annotations

import numpy as np

from ...log import Multibeam
from ...robot import SensorMount
from ..motion import kinematics
from ..scenario.sensors import MultibeamModel
from ..tank import Tank
from .imu import sample_times

MIN_COS = 0.05


def multibeam_units(config: MultibeamModel) -> np.ndarray:
    """u_j = (0, sin theta_j, cos theta_j) (B, 3) in the sensor frame, port to starboard."""
    theta = config.across_angles()
    return np.stack([np.zeros_like(theta), np.sin(theta), np.cos(theta)], axis=1)


def range_sigma(config: MultibeamModel, r: np.ndarray, cos_g: np.ndarray) -> np.ndarray:
    """sigma_r = sqrt(a^2 + (b r cos g)^2) / cos g, equation (1), cos g floored at 0.05."""
    c = np.maximum(cos_g, MIN_COS)
    return np.hypot(config.range_sigma_a_m, config.range_sigma_b * r * c) / c


def simulate_multibeam(
    motion, tank: Tank, config: MultibeamModel, mount: SensorMount, duration: float, rng
) -> Multibeam:
    """Pings of ``config`` over ``tank``'s floor along ``motion`` (see the module docstring)."""
    t = sample_times(duration, config.rate_hz)
    n, units = t.size, multibeam_units(config)
    b = units.shape[0]
    kin = kinematics(motion, t, mount.translation)
    R_ws = kin.R @ mount.rotation_matrix()
    dirs = np.einsum("nij,kj->nki", R_ws, units)
    origins = np.repeat(kin.position, b, axis=0)
    true_range = tank.cast_rays(origins, dirs.reshape(-1, 3), config.max_range).reshape(n, b)
    sigma = range_sigma(config, np.nan_to_num(true_range), dirs[..., 2])
    measured = true_range + sigma * rng.standard_normal((n, b))
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(measured) & (measured >= config.min_range)
        ok &= measured <= config.max_range
    r = np.where(ok, measured, np.nan)
    return Multibeam(
        t=t,
        points=r[..., None] * units[None, :, :],
        min_range=config.min_range,
        max_range=config.max_range,
    )
