"""The sea-state estimate's input: the log's sensors as channels in the world frame.

Channels: the barometer's pressure head (p - p_atm) / (rho g); the DVL velocity rotated to the
body (mount rotation), less the lever-arm velocity omega_b x r_dvl (gyro), then to the world
frame by the orientation (dead reckoning's attitude, else the IMU's orientation, else the gyro's
yaw rate integrated, else none: body frame). Water depth h = median(barometer depth + lever +
DVL altitude), else the caller's or the log's "water_depth_m", else deep water. The track along
which the phase is modelled is the world velocity smoothed over one encounter period and
integrated (:func:`attach_track`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError, DataError
from ..log import FRESH_WATER_DENSITY, G0, P_ATM, Log
from ..rotations import quaternion_to_rpy, rpy_to_matrix
from .signal import moving_average

PLATFORMS = ("auto", "rigid", "free")


@dataclass(frozen=True, eq=False)
class Channel:
    """One measured channel: ``name`` (its sensor), ``kind`` ("p": pressure head in m; "vx",
    "vy", "vz": velocity in m/s), times ``t`` (s) and values ``value``, the sensor's depth (m)
    and sample rate (Hz); with a track, the dead-reckoned position (m) and slow velocity over
    ground (m/s) at ``t`` (None without a track)."""

    name: str
    kind: str
    t: np.ndarray
    value: np.ndarray
    depth_m: float
    rate_hz: float
    x_m: np.ndarray | None = None
    y_m: np.ndarray | None = None
    vx_m_s: np.ndarray | None = None
    vy_m_s: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class SensorData:
    """The channels of a log, the sensors they come from, the water depth (m, inf for deep
    water), the frame of the velocities ("world", "relative": heading integrated from the gyro,
    "body", or None without a DVL), the heading (t, yaw rad) and world velocity (t, (N, 3) m/s)
    of the DVL's samples (None without), notes, and gravity (m/s^2)."""

    channels: list[Channel]
    sensors: tuple[str, ...]
    water_depth_m: float
    frame: str | None
    heading: tuple[np.ndarray, np.ndarray] | None
    velocity: tuple[np.ndarray, np.ndarray] | None
    notes: list[str]
    gravity_m_s2: float = G0


def check_options(platform, window_periods, step_fraction, water_depth_m, rho, t_start, t_end):
    """One-line :class:`ConfigError` for an option out of range."""
    if platform not in PLATFORMS:
        raise ConfigError(f"platform {platform!r}: expected one of {', '.join(PLATFORMS)}")
    for name, value, positive in (
        ("window_periods", window_periods, True), ("step_fraction", step_fraction, True),
        ("water_depth_m", water_depth_m, True), ("water_density_kg_m3", rho, True),
        ("t_start", t_start, False), ("t_end", t_end, False),
    ):  # fmt: skip
        if value is None and name not in ("window_periods", "step_fraction"):
            continue
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{name} {value!r:.40}: not a number") from None
        if not math.isfinite(v) or (positive and v <= 0):
            raise ConfigError(f"{name} {value!r:.40}: must be a finite number" + (
                " > 0" if positive else ""))  # fmt: skip
    if float(step_fraction) > 1.0 or float(window_periods) < 3.0:
        raise ConfigError(
            "step_fraction must be in (0, 1] and window_periods at least 3 "
            f"(got {step_fraction}, {window_periods})"
        )


def crop(log: Log, t_start, t_end) -> Log:
    """The log's samples inside [t_start, t_end] (None: unbounded)."""
    if t_start is None and t_end is None:
        return log
    lo = -np.inf if t_start is None else float(t_start)
    hi = np.inf if t_end is None else float(t_end)
    changes = {n: s.select((s.t >= lo) & (s.t <= hi)) for n, s in log.streams().items()}
    return log.replace(**changes)


def water_density(log: Log, given: float | None) -> float:
    """rho (kg/m^3): as given, else the log's metadata, else fresh water."""
    rho = given or log.metadata.get("water_density_kg_m3") or FRESH_WATER_DENSITY
    if not _positive(rho):
        rho = FRESH_WATER_DENSITY
    return float(rho)


def _orientation(log: Log, t: np.ndarray, notes: list[str]):
    """(R world-from-body (N, 3, 3), yaw (N,), frame) at ``t`` from the dead reckoning's
    attitude, else the IMU's orientation, else the gyro's yaw rate integrated (relative to the
    first heading), else the body frame (identity)."""
    dr, imu = log.dead_reckoning, log.imu
    if dr is not None and len(dr) >= 2 and np.isfinite(dr.orientation).all():
        rpy = np.unwrap(dr.orientation, axis=0)
        rpy = np.stack([np.interp(t, dr.t, rpy[:, i]) for i in range(3)], axis=1)
        return rpy_to_matrix(rpy), rpy[:, 2], "world"
    if imu is not None and len(imu) >= 2:
        if imu.orientation is not None and np.isfinite(imu.orientation).all():
            rpy = np.unwrap(quaternion_to_rpy(imu.orientation), axis=0)
            rpy = np.stack([np.interp(t, imu.t, rpy[:, i]) for i in range(3)], axis=1)
            return rpy_to_matrix(rpy), rpy[:, 2], "world"
        r = np.nan_to_num(imu.angular_velocity[:, 2])
        yaw = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(imu.t))])
        notes.append("orientation: yaw integrated from the gyro (small roll and pitch assumed); "
                     "directions relative to the first heading")  # fmt: skip
        yaw = np.interp(t, imu.t, yaw)
        rpy = np.stack([np.zeros_like(t), np.zeros_like(t), yaw], axis=1)
        return rpy_to_matrix(rpy), yaw, "relative"
    notes.append("no orientation: DVL velocities in the body frame, directions relative to "
                 "the vehicle only")  # fmt: skip
    return np.broadcast_to(np.eye(3), (t.size, 3, 3)), np.zeros_like(t), "body"


def _depths(log: Log, rho: float, water_depth_m, notes: list[str]):
    """(barometer depth d_p, body depth d_b, water depth h); NaN where unknown, h = inf for
    deep water. h = median(d_p + lever + altitude) with both sensors; the body depth (where a
    free vehicle is displaced by the orbit as a whole) is d_p minus the barometer's lever arm."""
    p, dvl = log.pressure, log.dvl
    surface = float(log.metadata.get("surface_pressure_pa", P_ATM) or P_ATM)
    d_p = float(np.nanmedian(p.depth(rho, surface))) if p is not None and len(p) else np.nan
    z_baro, z_dvl = log.mounting.barometer.translation[2], log.mounting.dvl.translation[2]
    alt = np.nan
    if dvl is not None and np.isfinite(dvl.altitude).any():
        alt = float(np.nanmedian(dvl.altitude))
    h = np.nan
    if water_depth_m is not None:
        h = float(water_depth_m)
    elif np.isfinite(d_p) and np.isfinite(alt):
        h = d_p - z_baro + z_dvl + alt
    elif _positive(log.metadata.get("water_depth_m")):
        h = float(log.metadata["water_depth_m"])
    if not np.isfinite(h):
        h = np.inf
        notes.append("water depth unknown: deep water assumed")
    d_b = d_p - z_baro if np.isfinite(d_p) else h - alt - z_dvl
    if not np.isfinite(d_b) and dvl is not None:
        d_b = 0.0
        notes.append("vehicle depth unknown (no barometer, no water depth): taken at the "
                     "surface, so the amplitude is a lower bound")  # fmt: skip
    return d_p, d_b, h


def _positive(v) -> bool:
    try:
        return math.isfinite(float(v)) and float(v) > 0
    except (TypeError, ValueError):
        return False


def _lever_velocity(log: Log, t: np.ndarray) -> np.ndarray:
    """omega_b x r_dvl (N, 3): the DVL point's velocity from the body's rotation (gyro rates
    interpolated at ``t``), subtracted so the velocity is the body origin's; zero without an
    IMU."""
    imu = log.imu
    if imu is None or len(imu) < 2:
        return np.zeros((t.size, 3))
    w_i = np.nan_to_num(imu.angular_velocity) @ log.mounting.imu.rotation_matrix().T
    w = np.stack([np.interp(t, imu.t, w_i[:, i]) for i in range(3)], axis=1)
    return np.cross(w, np.asarray(log.mounting.dvl.translation, float))


def prepare(log: Log, rho: float, water_depth_m) -> SensorData:
    """The channels of ``log`` (module doc); :class:`DataError` without a barometer or a DVL."""
    notes: list[str] = []
    d_p, d_b, h = _depths(log, rho, water_depth_m, notes)
    chans, sensors, frame, heading, vel = [], [], None, None, None
    p = log.pressure
    if p is not None and len(p) > 8:
        ok = np.isfinite(p.pressure)
        pr = p.select(ok)
        head = (pr.pressure - float(log.metadata.get("surface_pressure_pa", P_ATM) or P_ATM)) / (
            rho * G0
        )
        chans.append(Channel("pressure", "p", pr.t, head, d_p, pr.rate_hz))
        sensors.append("pressure")
    dvl = log.dvl
    if dvl is not None and len(dvl) > 8:
        ok = dvl.valid & np.all(np.isfinite(dvl.velocity), axis=1)
        d = dvl.select(ok)
        if len(d) > 8:
            R, yaw, frame = _orientation(log, d.t, notes)
            v_b = d.velocity @ log.mounting.dvl.rotation_matrix().T - _lever_velocity(log, d.t)
            v = np.einsum("nij,nj->ni", R, v_b)
            vel, heading = (d.t, v), (d.t, yaw)
            for i, kind in enumerate(("vx", "vy", "vz")):
                chans.append(Channel("dvl", kind, d.t, v[:, i], d_b, d.rate_hz))
            sensors.append("dvl")
            if frame == "world":
                sensors.append("dead_reckoning" if log.dead_reckoning is not None else "imu")
            elif frame == "relative":
                sensors.append("imu")
    if not chans:
        raise DataError(
            "sea-state estimate needs stream pressure (barometer) or dvl (with valid "
            f"velocities); the log has: {', '.join(log.streams()) or 'none'}"
        )
    return SensorData(chans, tuple(sensors), h, frame, heading, vel, notes)


def attach_track(data: SensorData, smooth_s: float) -> SensorData:
    """``data`` with the track (x, y) and slow velocity at every channel's times: the world
    velocity smoothed over ``smooth_s`` (one encounter period: the orbital part averages out)
    and integrated. Unchanged without a velocity."""
    if data.velocity is None:
        return data
    t, v = data.velocity
    n = max(int(round(smooth_s * len(t) / max(t[-1] - t[0], 1e-9))), 1)
    vs = moving_average(moving_average(v[:, :2].T, n), n)
    xy = np.concatenate([np.zeros((2, 1)), np.cumsum(0.5 * (vs[:, 1:] + vs[:, :-1]) * np.diff(t),
                                                      axis=1)], axis=1)  # fmt: skip
    channels = [
        dataclasses.replace(
            c,
            x_m=np.interp(c.t, t, xy[0]),
            y_m=np.interp(c.t, t, xy[1]),
            vx_m_s=np.interp(c.t, t, vs[0]),
            vy_m_s=np.interp(c.t, t, vs[1]),
        )  # fmt: skip
        for c in data.channels
    ]
    return dataclasses.replace(data, channels=channels)


def platform_models(data: SensorData, platform: str, notes: list[str]) -> list[str]:
    """The platform models to fit: the one forced, else rigid and free as the sensors allow
    (a note when the barometer alone decides)."""
    has_p = any(c.kind == "p" for c in data.channels)
    has_v = any(c.kind != "p" for c in data.channels)
    if platform == "rigid" and not has_p:
        raise DataError("platform rigid: needs the barometer (pressure stream), the log has none")
    if platform != "auto":
        return [platform]
    if not has_v:
        notes.append("barometer only: rigid mount assumed (a free vehicle's barometer sees "
                     "only a (K_p - K_s)), no direction")  # fmt: skip
        return ["rigid"]
    return ["rigid", "free"] if has_p else ["free"]


__all__ = [
    "PLATFORMS",
    "Channel",
    "SensorData",
    "attach_track",
    "check_options",
    "crop",
    "platform_models",
    "prepare",
    "water_density",
]
