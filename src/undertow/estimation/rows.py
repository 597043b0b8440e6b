"""What the filter takes from a log: its measurement rows and its initial state.

Each sensor's rows (:func:`imu_rows`, :func:`dvl_rows`, :func:`dr_rows`, :func:`pressure_rows`)
are (t, kind, z, R, ok): the measurement z in the units and frame of the model's measurement
equations (:mod:`undertow.estimation.model`), its noise covariance R (the config's standard
deviations, floored, plus the wave noise for the variants that add it: gamma^2 for the DVL and
the DR; for the barometer the swell's pressure head as white noise, for the estimators without
a swell state, the peers) and which rows pass the physical envelopes
(:mod:`undertow.estimation.health`); rejected rows are counted by name. The UKF carries the
swell as states instead: its barometer rows (:func:`filter_pressure_rows`) have R of the sensor
alone and the swell (omega_0, sigma^2) at each row (:func:`swell_columns`).
:func:`merged_rows` merges them into one time-sorted
:data:`~undertow.estimation.filter_loop.MEASUREMENT` array (at equal times IMU, DVL, DR,
barometer), the filter loop's input; :func:`measurements` does both for a whole log.
:func:`initial_state` is the filter's (x0, P0) from the config and the log's first readings.

The offline :class:`~undertow.estimation.localizer.Localizer` and the online filter
(:mod:`undertow.estimation.online`, which builds rows chunk by chunk) use the same builders, so
both filter the same rows.
"""

from __future__ import annotations

import functools

import numpy as np

from ..io.units import depth_reference as log_depth_reference
from ..log import Log
from ..rotations import matrix_to_rpy, quaternion_to_rpy, rpy_to_matrix
from . import filter_loop, model
from .config import LocalizerConfig
from .health import dvl_inside, imu_inside, pressure_inside
from .noise import TrackNoise, WaveNoise
from .noise_physics import pressure_head_variance

#: the streams the filter reads, one row builder each
FILTER_STREAMS = ("imu", "dvl", "dead_reckoning", "pressure")


def measurements(log: Log, cfg: LocalizerConfig, noise: WaveNoise | TrackNoise):
    """The merged, time-sorted :data:`~undertow.estimation.filter_loop.MEASUREMENT` array (at equal
    times IMU, DVL, DR, baro) and the rows rejected up front, by stream."""
    parts, rejected = [], {}
    for stream in (imu_rows, dvl_rows, dr_rows):
        part = stream(log, cfg, noise, rejected)
        if part is not None:
            t, kind, z, R, ok = part
            parts.append((t[ok], kind, z[ok], R[ok]))
    part = filter_pressure_rows(log, cfg, noise, rejected)
    if part is not None:
        t, kind, z, R, ok, swell = part
        parts.append((t[ok], kind, z[ok], R[ok], swell[ok]))
    rows, _ = merged_rows(parts, cfg.std_floor**2)
    return rows, rejected


def merged_rows(parts, floor2: float) -> tuple[np.ndarray, np.ndarray]:
    """One :data:`~undertow.estimation.filter_loop.MEASUREMENT` array of the streams' rows ``parts``
    [(t (n,), kind, z (n, d), R (n, d, d)[, swell (n, 2)])]: z and R zero-padded to three
    dimensions, the diagonal of R floored at ``floor2``, the swell NaN where a part has none,
    merged by time, then kind. Also the merge order (the index into the parts' rows
    concatenated), to carry values kept beside the rows."""
    n = sum(part[0].size for part in parts)
    rows = np.zeros(n, filter_loop.MEASUREMENT)
    rt, rk, rz, rR, rs = rows["t"], rows["kind"], rows["z"], rows["R"], rows["swell"]
    rs[:] = np.nan
    a = 0
    for t, kind, z, R, *swell in parts:
        b, d = a + t.size, z.shape[1]
        rt[a:b], rk[a:b] = t, kind
        rz[a:b, :d] = z
        rR[a:b, :d, :d] = R
        if swell and swell[0] is not None:
            rs[a:b] = swell[0]
        a = b
    diagonal = rR.reshape(n, 9)[:, ::4]  # (a view: each row's 3 x 3 are contiguous)
    np.maximum(diagonal, floor2, out=diagonal)
    order = np.lexsort((rk, rt))
    return rows[order], order


def imu_rows(
    log: Log, cfg: LocalizerConfig, noise: WaveNoise | TrackNoise, rejected: dict, warn: bool = True
):
    """IMU angular velocity z (rad/s, IMU frame), R = diag(imu_gyro_std_rad_s^2). None
    without an IMU."""
    imu = log.imu
    if imu is None or not len(imu):
        return None
    w = imu.angular_velocity
    ok = _finite_rows(w)
    rejected["rejected_imu"] = _count_false(ok)
    ok = imu_inside(imu.t, w, ok, cfg.gyro_max_rate_rad_s, rejected, warn)
    return imu.t, model.IMU, w, _diag(cfg.imu_gyro_std_rad_s, len(imu), cfg), ok


def dvl_rows(
    log: Log, cfg: LocalizerConfig, noise: WaveNoise | TrackNoise, rejected: dict, warn: bool = True
):
    """DVL velocity z = v_measured / scale (m/s, DVL frame) with the log's covariance (scaled
    by 1 / scale^2, symmetrized) or diag(dvl_velocity_std_m_s^2), its diagonal floored at
    dvl_std_floor_m_s^2, plus gamma_DVL^2 (at the row's time, for a track) for the variants with
    wave noise."""
    dvl = log.dvl
    v = dvl.velocity / cfg.dvl_scale_factor
    cov = np.array(dvl.covariance, float) / cfg.dvl_scale_factor**2
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    has_cov = np.isfinite(cov).all(axis=(1, 2))
    R = np.where(has_cov[:, None, None], cov, _diag(cfg.dvl_velocity_std_m_s, len(dvl), cfg))
    diagonal = R.reshape(-1, 9)[:, ::4]  # (a view: R is a new contiguous array)
    np.maximum(diagonal, cfg.dvl_std_floor_m_s**2, out=diagonal)
    if cfg.adds_wave_noise:
        diagonal += noise.std_at("dvl", dvl.t) ** 2
    finite = _finite_rows(v)
    rejected["rejected_dvl_invalid"] = _count_false(dvl.valid)
    rejected["rejected_dvl_nonfinite"] = int(np.count_nonzero(dvl.valid & ~finite))
    ok = dvl_inside(dvl.t, dvl.velocity, finite & dvl.valid, cfg.dvl_max_speed_m_s, rejected, warn)
    return dvl.t, model.DVL, v, R, ok


def dr_rows(
    log: Log, cfg: LocalizerConfig, noise: WaveNoise | TrackNoise, rejected: dict, warn: bool = True
):
    """DR orientation z (rad; reported for the DVL frame, R_dr = R_body R_mount, it is moved to
    the body: R_body = R_dr R_mount^T), R = diag(dr_orientation_std_rad^2) plus gamma_DR^2 for
    the variants with wave noise. None when the log has no DR."""
    dr = log.dead_reckoning
    if dr is None or not len(dr):
        return None
    rpy = np.array(dr.orientation, float)
    ok = _finite_rows(rpy)
    if cfg.dr_orientation_frame == "dvl":
        rpy[ok] = matrix_to_rpy(rpy_to_matrix(rpy[ok]) @ log.mounting.dvl.rotation_matrix().T)
    R = _diag(cfg.dr_orientation_std_rad, len(dr), cfg)
    if cfg.adds_wave_noise:
        i = np.arange(3)
        R[:, i, i] += noise.std_at("dr", dr.t) ** 2
    rejected["rejected_dead_reckoning"] = _count_false(ok)
    return dr.t, model.DR, rpy, R, ok


def pressure_rows(
    log: Log,
    cfg: LocalizerConfig,
    noise: WaveNoise | TrackNoise,
    rejected: dict,
    warn: bool = True,
    jumps: bool = True,
    white_swell: bool = True,
):
    """Depth z = (p - p_surface) / (rho g) (m), R = depth_std_m^2, plus (``white_swell``, for an
    estimator without swell states) the swell's pressure head a^2 K_p(z)^2 / 2 at the row's time
    and depth as white noise for the variants with wave noise (``pressure_wave_noise``;
    :func:`~undertow.estimation.noise_physics.pressure_head_variance`: the barometer reads the
    wave's dynamic pressure as depth, an error the size of the swell at the sensor that its
    noise would otherwise leave out). None without pressure.
    ``jumps`` False: the depth-rate check (:func:`~undertow.estimation.health.depth_jumps`) is
    left to the caller (the online filter, which sees the depths in pieces)."""
    p = log.pressure
    if p is None or not len(p):
        return None
    d = p.depth(*depth_reference(log, cfg))[:, None]
    ok = _finite_rows(d)
    rejected["rejected_pressure"] = _count_false(ok)
    ok = pressure_inside(p.t, d[:, 0], ok, cfg, rejected, warn, jumps)
    R = _diag([cfg.depth_std_m] * 3, len(p), cfg)[:, :1, :1]
    if cfg.adds_pressure_wave_noise and white_swell:
        R = R + pressure_head_variance(*noise.wave_at(p.t), d[:, 0])[:, None, None]
    return p.t, model.BARO, d, R, ok


def filter_pressure_rows(log: Log, cfg: LocalizerConfig, noise, rejected: dict, warn: bool = True,
                         jumps: bool = True):  # fmt: skip
    """The UKF's barometer rows: :func:`pressure_rows` with R of the sensor alone, and the
    swell at each row (:func:`swell_columns`; None for a variant without it) as a sixth
    entry. None without pressure."""
    part = pressure_rows(log, cfg, noise, rejected, warn, jumps, white_swell=False)
    if part is None:
        return None
    t, kind, z, R, ok = part
    return t, kind, z, R, ok, swell_columns(t, z[:, 0], cfg, noise)


def swell_columns(t: np.ndarray, depth: np.ndarray, cfg: LocalizerConfig, noise) -> np.ndarray:
    """(omega_0 = 2 pi f rad/s, sigma^2 = a^2 K_p(d)^2 / 2 m^2, cos beta, sin beta) per barometer
    row at its time and depth (:func:`~undertow.estimation.noise_physics.pressure_head_variance`),
    beta the waves' direction ``wave_heading_deg`` (NaN: unknown), the swell model of the UKF's
    swell states (:mod:`~undertow.estimation.model`); sigma^2 = 0 where calm or for a variant
    without it (``pressure_wave_noise`` off or no wave noise)."""
    out = np.full((np.size(t), 4), np.nan)
    out[:, 1] = 0.0
    if cfg.adds_pressure_wave_noise:
        a, f = noise.wave_at(t)
        out[:, 1] = pressure_head_variance(a, f, depth)
        out[:, 0] = np.where(out[:, 1] > 0, 2.0 * np.pi * f, np.nan)
        if cfg.wave_heading_deg is not None:
            beta = np.deg2rad(cfg.wave_heading_deg)
            out[:, 2], out[:, 3] = np.cos(beta), np.sin(beta)
    return out


def depth_reference(log: Log, cfg: LocalizerConfig) -> tuple[float, float]:
    """(water density rho kg/m^3, surface pressure p_surface Pa) of d = (p - p_surface) / (rho g):
    the config's when set, else the log's (``metadata`` ``water_density_kg_m3`` and
    ``surface_pressure_pa``, as its reader resolved them), else fresh water and one standard
    atmosphere (:func:`undertow.io.units.depth_reference`)."""
    return log_depth_reference(log.metadata, cfg.water_density_kg_m3, cfg.surface_pressure_pa)


def _diag(std, n: int, cfg: LocalizerConfig) -> np.ndarray:
    """n copies of diag(max(std, std_floor)^2)."""
    std = tuple(std) if isinstance(std, (list, tuple)) else float(std)
    return np.repeat(_diag_one(std, cfg.std_floor), n, axis=0)  # (np.tile, without its set-up)


@functools.lru_cache(maxsize=64)
def _diag_one(std, floor: float) -> np.ndarray:
    """diag(max(std, floor)^2) as a (1, 3, 3) array (read-only: shared by every call)."""
    D = np.diag(np.maximum(np.asarray(std, float), floor) ** 2)[None]
    D.flags.writeable = False
    return D


def _finite_rows(a: np.ndarray) -> np.ndarray:
    return np.isfinite(a).all(axis=1)


def _count_false(ok: np.ndarray) -> int:
    return ok.size - int(np.count_nonzero(ok))


def initial_state(log: Log, cfg: LocalizerConfig):
    """x0 from the config, else zeros with the first DR orientation (without DR:
    :func:`start_attitude`) and the first depth, and the configured start position (DVL and IMU
    observe no absolute x, y: the user gives the start); P0 = diag(max(initial_std, 1e-9)^2)."""
    P0 = np.diag(np.maximum(np.asarray(cfg.initial_std, float), 1e-9) ** 2)
    if cfg.initial_state is not None:
        return np.array(cfg.initial_state, float), P0
    x0 = np.zeros(model.N_POSE)
    dr = log.dead_reckoning
    if dr is not None and len(dr):
        ok = np.flatnonzero(_finite_rows(np.asarray(dr.orientation)))
        if ok.size:
            rpy = np.array(dr.orientation[ok[0]], float)
            if cfg.dr_orientation_frame == "dvl":
                rpy = matrix_to_rpy(rpy_to_matrix(rpy) @ log.mounting.dvl.rotation_matrix().T)
            x0[3:6] = rpy
    else:
        rpy, _ = start_attitude(log)
        if rpy is not None:
            x0[3:6] = rpy
    if log.pressure is not None and len(log.pressure):
        d = log.pressure.depth(*depth_reference(log, cfg))
        lo, hi = cfg.min_depth_m, cfg.max_depth_m  # the first depth within the envelope
        with np.errstate(invalid="ignore"):
            inside = np.isfinite(d) & (d >= (-np.inf if lo is None else lo))
            ok = np.flatnonzero(inside & (d <= (np.inf if hi is None else hi)))
        if ok.size:
            lever = rpy_to_matrix(x0[3:6]) @ np.asarray(log.mounting.barometer.translation, float)
            x0[2] = d[ok[0]] - lever[2]
    if cfg.initial_position is not None:
        x0[0:3] = cfg.initial_position
    x0[12:15] = cfg.dr_bias_rad  # held at 0 by the variants without bias states
    x0[15:18] = cfg.gyro_bias_rad_s
    return x0, P0


def start_attitude(log: Log) -> tuple[np.ndarray | None, str]:
    """(rpy or None, where from) of the initial attitude of a log without DR: the first
    ground-truth pose, else the IMU's first orientation report, else None (zeros)."""
    gt = log.ground_truth
    if gt is not None and len(gt):
        ok = np.flatnonzero(_finite_rows(np.asarray(gt.orientation, float)))
        if ok.size:
            return np.array(gt.orientation[ok[0]], float), "initial attitude from the ground truth"
    imu = log.imu
    if imu is not None and imu.orientation is not None and len(imu):
        q = np.asarray(imu.orientation, float)
        ok = np.flatnonzero(_finite_rows(q) & (np.linalg.norm(q, axis=1) > 0.5))
        if ok.size:
            rpy = quaternion_to_rpy(q[ok[0]] / np.linalg.norm(q[ok[0]]))
            return np.asarray(rpy, float), "initial attitude from the IMU's orientation report"
    return None, "initial attitude zeros (no ground truth or IMU orientation report)"
