"""True units and references of a read log: the gyro's unit, the surface pressure, the water.

Nothing here is assumed silently: each choice is one line in ``log.metadata['warnings']`` when
it changes the data or departs from the default, and a dict in ``log.metadata`` (and so in
every output's ``config.yaml``), and the settings' ``log:`` section
(:class:`~undertow.io.read_options.LogOptions`) overrides it.

**Gyro unit.** A gyro logged in deg/s read as rad/s spins the vehicle 57.3 times too fast.
With an orientation in the log (the IMU's own quaternion, else the DVL's dead reckoning), the
rotation between orientations :data:`WINDOW_S` apart, theta = |log(R_a^T R_b)| (a body-frame
rotation vector: any world or sensor axis convention cancels), is compared with the gyro's integral
over the same window, |sum omega_k dt|: the least-squares ratio s = sum |gyro| |theta| / sum
|theta|^2 is 1 for rad/s and 180/pi for deg/s; a ratio within a factor 2 of 180/pi with the
two correlated (r >= 0.5) converts the gyro (x pi/180) with a warning naming the ratio.
Without a usable orientation, the physical envelope speaks: a 99th-percentile rate above
:data:`ENVELOPE_RAD_S` as rad/s (no ROV or small AUV turns that fast) marks the unit
ambiguous; the localizer then refuses the log in one line naming the setting
(``log: {imu_units: deg/s}``).

**Surface pressure.** Depth is d = (p - p_surface) / (rho g), and p_surface is not 101,325 Pa: it
falls about 12 Pa per metre of altitude (86 kPa at 1,400 m) and moves with the weather by +-3 kPa
(+-0.3 m of water). In order: the settings' value; an autopilot's own ground pressure recorded in
the log (e.g. ArduSub's ``BARO<n>_GND_PRESS`` of its depth sensor, put in ``metadata`` by the
dataflash reader); the pressure while the vehicle is at the surface at the start, where the log
shows that (the log's shallowest pressures are in its first :data:`START_S` s, held there for
:data:`SURFACE_HOLD_S` s, and it dives by more than :data:`DIVE_M` afterwards): the median of those
first pressures within :data:`SURFACE_BAND_M` of water of the minimum (a log that starts at rest
just below the surface reads the same: depths are then from there); else the standard atmosphere, or
the log's minimum pressure when that lies below the standard atmosphere's weather range (the surface
cannot be above the shallowest point). A depth more than 0.5 m above the surface is a warning naming
the likely cause.

**Water density.** Fresh (998 kg/m^3) or salt (1025) by the settings' ``water``; stated.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np

from .._util.plain import json_safe
from ..log import FRESH_WATER_DENSITY, G0, P_ATM, Log
from ..rotations import quaternion_to_rpy, rpy_to_matrix
from .read_options import LogOptions
from .sound_speed import correct_sound_speed

DEG = math.pi / 180.0
#: a gyro rate (rad/s) no ROV or small AUV sustains: 300 deg/s (BlueROV2 yaw rates are tens of
#: deg/s); a 99th percentile above it as rad/s is a gyro in deg/s
ENVELOPE_RAD_S = 300 * DEG
#: the orientation window of the unit test, s: long enough for a turn to dominate a MEMS gyro's
#: noise and a receive clock's jitter, short enough that few turns exceed MAX_TURN
WINDOW_S = 3.0
#: windows turning less (noise) or more (|log R| wraps at pi) are left out
MIN_TURN = 2 * math.pi / 180.0
MAX_TURN = 120 * math.pi / 180.0
START_S = 30.0
DIVE_M = 0.3
SURFACE_BAND_M = 0.05
#: the vehicle rests at the surface at least this long before it dives (s)
SURFACE_HOLD_S = 2.0
#: the standard atmosphere's weather range: p_surface = P_ATM +- 3 kPa at sea level
WEATHER_PA = 3_000.0
ABOVE_SURFACE_M = 0.5


def _rotation_angle(R: np.ndarray) -> np.ndarray:
    """|log(R)| of rotation matrices (..., 3, 3): acos((tr R - 1) / 2)."""
    c = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def gyro_orientation_ratio(t, gyro, rpy, window_s: float = WINDOW_S):
    """(s, r, windows): the least-squares ratio of the gyro's integrated rotation to the
    orientation's over windows of ``window_s`` (see the module docstring), their correlation,
    and the number of windows used (NaN, NaN, n when fewer than 5 windows turn between
    :data:`MIN_TURN` and :data:`MAX_TURN`).
    ``rpy`` are orientations at the gyro's times ``t``."""
    t, gyro, rpy = np.asarray(t, float), np.asarray(gyro, float), np.asarray(rpy, float)
    ok = np.isfinite(gyro).all(axis=1) & np.isfinite(rpy).all(axis=1) & np.isfinite(t)
    t, gyro, rpy = t[ok], gyro[ok], rpy[ok]
    if t.size < 10 or t[-1] <= t[0]:
        return math.nan, math.nan, 0
    dt = (t[-1] - t[0]) / (t.size - 1)  # the mean interval: receive-time jitter cancels
    if not (np.isfinite(dt) and dt > 0) or window_s / dt >= t.size:
        return math.nan, math.nan, 0
    per = max(int(round(window_s / dt)), 1)
    starts = np.arange(0, t.size - per, per)
    R = rpy_to_matrix(rpy)
    theta = _rotation_angle(np.einsum("nji,njk->nik", R[starts], R[starts + per]))
    cumulative = np.vstack([np.zeros(3), np.cumsum(gyro * dt, axis=0)])
    integral = np.linalg.norm(cumulative[starts + per] - cumulative[starts], axis=1)
    turning = (theta > MIN_TURN) & (theta < MAX_TURN)
    if turning.sum() < 5:
        return math.nan, math.nan, int(turning.sum())
    a, b = theta[turning], integral[turning]
    s = float(np.dot(a, b) / np.dot(a, a))
    r = float(np.corrcoef(a, b)[0, 1]) if np.std(a) > 0 and np.std(b) > 0 else math.nan
    return s, r, int(turning.sum())


def _orientation_at_gyro(log: Log):
    """(orientation roll-pitch-yaw at the IMU's times, its source) or (None, None)."""
    imu = log.imu
    if imu.orientation is not None and np.isfinite(imu.orientation).all(axis=1).any():
        q = np.asarray(imu.orientation, float)
        if np.any(np.linalg.norm(q, axis=1) > 0.5):
            return quaternion_to_rpy(q), "the IMU's orientation"
    dr = log.dead_reckoning
    ok = np.isfinite(np.asarray(dr.orientation, float)).all(axis=1) if dr is not None else None
    if dr is not None and ok.sum() >= 10:
        t_dr = np.asarray(dr.t)[ok]
        unwrapped = np.unwrap(np.asarray(dr.orientation, float)[ok], axis=0)
        rpy = np.column_stack([np.interp(imu.t, t_dr, unwrapped[:, i]) for i in range(3)])
        inside = (imu.t >= t_dr[0]) & (imu.t <= t_dr[-1])
        rpy[~inside] = np.nan
        return rpy, "the DVL's dead-reckoning attitude"
    return None, None


def gyro_units(log: Log, setting: str = "auto") -> dict:
    """The gyro's unit verdict: ``unit`` (rad/s | deg/s | ambiguous), ``how`` (settings,
    orientation, envelope), ``evidence`` (one sentence) and the figures behind it."""
    imu = log.imu
    if setting != "auto":
        return {"unit": setting, "how": "settings", "evidence": f"imu_units: {setting} (settings)"}
    gyro = np.asarray(imu.angular_velocity, float)
    norms = np.linalg.norm(gyro[np.isfinite(gyro).all(axis=1)], axis=1)
    p99 = float(np.percentile(norms, 99)) if norms.size else math.nan
    verdict = {"p99_rate": p99}
    rpy, source = _orientation_at_gyro(log)
    if rpy is not None:
        s, r, n = gyro_orientation_ratio(imu.t, gyro, rpy)
        verdict.update(ratio_to_orientation=s, correlation=r, windows=n)
        if math.isfinite(s) and math.isfinite(r) and r >= 0.5:
            deg = abs(math.log(s / (1 / DEG))) < math.log(2)
            rad = abs(math.log(s)) < math.log(2)
            if deg or rad:
                unit = "deg/s" if deg else "rad/s"
                return verdict | {"unit": unit, "how": "orientation", "evidence": (
                    f"the gyro turns {s:.3g} times as far as {source} over {n} windows of "
                    f"{WINDOW_S:g} s (correlation {r:.2f}): {unit}")}  # fmt: skip
    if math.isfinite(p99) and p99 > ENVELOPE_RAD_S:
        return verdict | {"unit": "ambiguous", "how": "envelope", "evidence": (
            f"the gyro's 99th-percentile rate is {p99:.3g}, i.e. {p99 / DEG:,.0f} deg/s as "
            f"rad/s, beyond any ROV's turn rate ({ENVELOPE_RAD_S / DEG:.0f} deg/s): likely "
            "deg/s")}  # fmt: skip
    why = "no orientation to compare with" if rpy is None else "the orientation is inconclusive"
    return verdict | {"unit": "rad/s", "how": "envelope", "evidence": (
        f"rates inside the physical envelope (99th percentile {p99:.3g} rad/s; {why})"
    )}  # fmt: skip


def surface_pressure(log: Log, setting="auto", rho: float = 998.0) -> tuple[float, str]:
    """(p_surface Pa, where it came from): see the module docstring."""
    if setting != "auto":
        return float(setting), "settings (log: surface_pressure_pa)"
    meta = log.metadata
    recorded = meta.get("surface_pressure_pa")
    if isinstance(recorded, int | float) and math.isfinite(recorded) and recorded > 0:
        return float(recorded), str(meta.get("surface_pressure_source", "the log's metadata"))
    p = log.pressure
    ok = np.isfinite(p.pressure)
    t, pr = np.asarray(p.t)[ok], np.asarray(p.pressure)[ok]
    if not pr.size:
        return P_ATM, "standard atmosphere (no finite pressure)"
    band, dive = SURFACE_BAND_M * rho * G0, DIVE_M * rho * G0
    lo = float(pr.min())
    start = t <= t[0] + START_S
    near = np.flatnonzero(pr <= lo + band)
    held = near[t[near] <= t[near[0]] + SURFACE_HOLD_S + 1.0] if near.size else near
    held_s = float(t[held[-1]] - t[held[0]]) if held.size else 0.0
    if (pr[start] <= lo + band).any() and pr.max() - lo > dive and held_s >= SURFACE_HOLD_S:
        head = held
        value = float(np.median(pr[head]))
        return value, (
            f"the log's first pressures at the surface ({head.size} readings from "
            f"t = {t[head[0]] - t[0]:.1f} s, before it dives {(pr.max() - lo) / (rho * G0):.1f} m)"
        )
    if lo < P_ATM - WEATHER_PA:
        return lo, (
            "the log's minimum pressure (below the standard atmosphere's weather range; the "
            "log does not show the surface, so depths are at least this deep)"
        )
    return P_ATM, "standard atmosphere (the log does not show the surface at its start)"


def resolve_units(log: Log, options: LogOptions | None = None) -> Log:
    """``log`` with its gyro in rad/s and its depth references resolved and stated (see the
    module docstring): ``metadata`` ``imu_units``, ``surface_pressure_pa``,
    ``surface_pressure_source``, ``water_density_kg_m3``, ``water``; and its acoustic ranges and
    velocities in the water's sound speed when the options give it (``sound_speed``:
    :func:`~undertow.io.sound_speed.correct_sound_speed`)."""
    options = options or LogOptions()
    meta = dict(log.metadata)
    lines = list(meta.get("warnings", []))
    src = f"{log.source}: " if log.source else ""
    changes = {}
    if log.imu is not None and len(log.imu):
        with np.errstate(all="ignore"):  # absurd rates give inf/NaN figures, not warnings
            verdict = gyro_units(log, options.imu_units)
        meta["imu_units"] = verdict
        if verdict["unit"] == "deg/s":
            imu = log.imu
            changes["imu"] = replace(imu, angular_velocity=np.asarray(imu.angular_velocity) * DEG)
            verdict["converted"] = True
            if verdict["how"] != "settings":
                lines.append(f"{src}imu: gyro converted from deg/s to rad/s ({verdict['evidence']}"
                             "); set log: {imu_units: rad/s} to keep it as it is")  # fmt: skip
        elif verdict["unit"] == "ambiguous":
            lines.append(f"{src}imu: {verdict['evidence']}; set log: {{imu_units: deg/s}} (or "
                         "rad/s) to localize")  # fmt: skip
    # the water: salt when the settings say so, else the density the log records (a simulated
    # run's sidecar), else fresh
    if options.water == "salt" or "water_density_kg_m3" not in meta:
        meta["water_density_kg_m3"] = options.water_density_kg_m3
        meta["water"] = options.water
    if log.pressure is not None and len(log.pressure):
        rho = float(meta["water_density_kg_m3"])
        with np.errstate(all="ignore"):
            p0, how = surface_pressure(log, options.surface_pressure_pa, rho)
        meta["surface_pressure_pa"] = p0
        meta["surface_pressure_source"] = how
        if abs(p0 - P_ATM) > 1.0 or options.surface_pressure_pa != "auto":
            lines.append(
                f"{src}pressure: surface pressure {p0:,.0f} Pa from {how}; water {rho:g} kg/m^3;"
                " set log: {surface_pressure_pa: PA} to override"
            )
        depth = (np.asarray(log.pressure.pressure) - p0) / (rho * G0)
        with np.errstate(invalid="ignore"):
            high = float(np.nanmin(depth)) if np.isfinite(depth).any() else math.nan
        if high < -ABOVE_SURFACE_M:
            lines.append(
                f"{src}pressure: depths down to {high:.2f} m, above the water: the surface "
                f"pressure {p0:,.0f} Pa ({how}) is likely too high (a lake at altitude, the "
                "weather, or a pressure in other units); set log: {surface_pressure_pa: PA}"
            )
    for line in lines[len(meta.get("warnings", [])) :]:
        warnings.warn(line, stacklevel=2)
    meta["warnings"] = lines
    return correct_sound_speed(log.replace(metadata=meta, **changes), options)


#: what every output's config.yaml records of how its log was read
READING_KEYS = ("format", "topics", "topics_guessed", "time_base", "imu_units",
                "surface_pressure_pa", "surface_pressure_source", "water", "water_density_kg_m3",
                "depth_z", "gps_origin", "dvl_frame", "mounting_source", "sound_speed",
                "dvl_sound_speed_m_s")  # fmt: skip


def reading_record(metadata: dict) -> dict:
    """The choices made reading a log (time base, units, references, topics), as recorded in
    every output's ``config.yaml``."""
    return json_safe({k: metadata[k] for k in READING_KEYS if k in metadata})


def depth_reference(metadata: dict, water_density=None, surface_pressure=None):
    """(rho kg/m^3, p_surface Pa) of d = (p - p_surface) / (rho g): the values given, else the
    log's ``metadata`` (``water_density_kg_m3``, ``surface_pressure_pa``, as
    :func:`resolve_units` resolved them), else fresh water and one standard atmosphere."""
    meta = metadata if isinstance(metadata, dict) else {}
    rho = water_density or _positive(meta.get("water_density_kg_m3"))
    p0 = surface_pressure or _positive(meta.get("surface_pressure_pa"))
    return rho or FRESH_WATER_DENSITY, p0 or P_ATM


def _positive(value) -> float | None:
    try:
        value = float(value)
    except (TypeError, ValueError, OverflowError):
        return None
    return value if math.isfinite(value) and value > 0 else None
