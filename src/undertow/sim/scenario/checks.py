"""Cross-field checks of a :class:`~undertow.sim.scenario.Scenario`: reject what cannot happen.

Each field is valid alone but some combinations are physically impossible and would simulate
all-NaN sensors; the scenario's model validator runs :func:`check_scenario`, which raises a
pydantic ``ValidationError`` located at the offending field (so the one-line error reads
``file.yaml: field motion.carriage.depth_m: ...``) and naming the limit:

- sensor limits: ``min_range < max_range`` (DVL, sonar);
- breaking: wave steepness H / lambda = 2 a / lambda <= 1/7 (Michell's limit; Dean & Dalrymple,
  "Water Wave Mechanics for Engineers and Scientists"), lambda = 2 pi / k
  with k from the dispersion relation omega^2 = g k tanh(k h); for a schedule at every held
  condition and along every ramp;
- a schedule (``wave.schedule``, sim/seastate.py): segments in time order, each ramp ending
  before its segment does, ``until_s`` on all but the last, ``wave.amplitude_m`` 0, and slowly
  varying (sim/wavefield.py): a ramp that changes the sea lasts >= 2 periods of the slower wave,
  and the local-frequency error |dk/dt| D / omega <= 10 % while a > 0, D the largest
  along-wave distance from the wave probe (where the phase is exact) to the robot's path;
- way points: no zero-length leg, no reversal, each leg long enough for its rounded corners;
- the rock platform inside the tank and under water; the wave probe inside the tank;
- the robot's path (carriage run, survey lawnmower or way points, widened by the sensors'
  horizontal lever arms and, for the free vehicle, by the largest orbital excursion) inside the
  tank walls;
- the robot in the water: its highest point (body origin or a sensor above it) below the wave
  trough (depth > a), its lowest sensor above the floor (the rock's top where the path crosses
  the rock), the free vehicle's heave included;
- the floor scan's point budget (``floor_cloud.max_points``) for the area the path covers;
- a heightfield floor (sim/seabed.py): its file readable, its rocks inside the tank with their
  tops under water, and the robot's lowest sensor above the floor's shallowest point under the
  path (widened by the lever arms and a node).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import ValidationError
from pydantic_core import InitErrorDetails, PydanticCustomError

from ...errors import ConfigError
from ..paths import corner_geometry
from ..seabed import scenario_heightfield, uses_heightfield
from ..seastate import build_wave, schedule_track, segments
from ..waves import LinearWave, solve_wavenumbers

BREAKING_STEEPNESS = 1.0 / 7.0  # H / lambda above which a wave breaks (Michell's limit)
RAMP_PERIODS = 2.0  # a ramp that changes the sea lasts at least this many wave periods
MAX_FLOOR_NODES = 2.0e7  # heightfield nodes (8 bytes each): ~160 MB
LOCAL_FREQUENCY_ERROR = 0.1  # |dk/dt| D / omega allowed during a ramp (slowly varying)


def _fail(loc: tuple, value, message: str) -> ValidationError:
    error = PydanticCustomError("physically_impossible", "{message}", {"message": message})
    return ValidationError.from_exception_data(
        "Scenario", [InitErrorDetails(type=error, loc=loc, input=value)]
    )


@dataclass(frozen=True)
class PathExtent:
    """Plan-view box the body origin covers (m) and how far it heaves (m, the free vehicle)."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float
    depth: float
    heave: float
    prefix: tuple
    x_field: str = "start_x_m"
    y_field: str = "y_m"


def wave_conditions(s) -> tuple[np.ndarray, np.ndarray]:
    """(a, f) the sea goes through: the constant wave, or a schedule's samples with a > 0 (its
    nodes and 64 points on each ramp); ([0], [1]) if always calm."""
    if s.wave.schedule is None:
        return np.array([s.wave.amplitude_m]), np.array([s.wave.frequency_hz])
    _, a, f = _schedule_samples(s)
    waves = a > 0
    if not waves.any():
        return np.zeros(1), np.ones(1)
    return a[waves], f[waves]


def _schedule_samples(s):
    """(t, a, f) on the schedule's nodes and 64 points on each interval between them."""
    track = schedule_track(s.wave)
    pieces = [np.linspace(t0, t1, 65) for t0, t1 in zip(track.t[:-1], track.t[1:], strict=True)]
    t = np.unique(np.concatenate([track.t, *pieces]))
    a, f = track.at(t)
    return t, a, f


def orbital_excursion(s, depth: float) -> tuple[float, float]:
    """Largest orbital displacement amplitudes (U / omega, W / omega) at ``depth`` (m)."""
    U, W = 0.0, 0.0
    for a, f in zip(*wave_conditions(s), strict=True):
        if a > 0 and depth > 0:
            wave = LinearWave(a, f, s.water.depth_m, g=s.water.gravity_m_s2)
            u, w = (float(x) / wave.omega for x in wave.velocity_amplitude(depth))
            U, W = max(U, u), max(W, w)
    return U, W


def path_extent(s) -> PathExtent:
    """The box of the carriage run, the survey's lawnmower (turns included) or the way points,
    widened for a free vehicle by its orbital excursion (horizontal U / omega, vertical W / omega
    at its depth, the largest over a schedule)."""
    if s.motion.kind == "carriage":
        c = s.motion.carriage
        x1 = c.start_x_m + c.run_length_m
        return PathExtent(c.start_x_m, x1, c.y_m, c.y_m, c.depth_m, 0.0, ("motion", "carriage"))
    if s.motion.kind == "waypoints":
        v = s.motion.waypoints
        pts = np.asarray(v.points, float)
        U, W = orbital_excursion(s, v.depth_m)
        lo, hi = pts.min(axis=0) - U, pts.max(axis=0) + U
        return PathExtent(lo[0], hi[0], lo[1], hi[1], v.depth_m, W, ("motion", "waypoints"),
                          "points", "points")  # fmt: skip
    v = s.motion.survey
    r = 0.5 * v.pass_spacing_m
    y_last = v.first_pass_y_m + (v.passes - 1) * v.pass_spacing_m
    U, W = orbital_excursion(s, v.depth_m)
    return PathExtent(
        v.start_x_m - r - U,
        v.start_x_m + v.pass_length_m + r + U,
        v.first_pass_y_m - U,
        y_last + U,
        v.depth_m,
        W,
        ("motion", "survey"),
        "start_x_m",
        "first_pass_y_m",
    )


def check_scenario(s) -> None:
    """Raise ValidationError (at the offending field) if ``s`` cannot happen; see the module."""
    _check_ranges(s)
    if s.wave.schedule is None:
        _check_wave(s)
    else:
        _check_schedule(s)
    _check_tank_objects(s)
    heightfield = _check_floor(s)
    if s.motion.kind == "waypoints":
        _check_waypoints(s.motion.waypoints)
    path = path_extent(s)
    _check_path_in_tank(s, path)
    if s.wave.schedule is not None:
        _check_slowly_varying(s, path)
    _check_in_water(s, path, heightfield)
    _check_floor_cloud(s, path)


def _check_floor(s):
    """The scenario's heightfield (None for the original flat tank), its rocks in place."""
    L, W = s.tank.length_m, s.tank.width_m
    for i, rock in enumerate(s.floor.rocks):
        for field, c, lo, hi in (("center_x_m", rock.center_x_m, 0.0, L),
                                 ("center_y_m", rock.center_y_m, -W / 2, W / 2)):  # fmt: skip
            if not lo <= c <= hi:
                raise _fail(
                    ("floor", "rocks", i, field),
                    c,
                    f"{c} m: the rock's centre must lie in the tank ({lo:g} to {hi:g} m)",
                )
    res = s.floor.resolution_m
    nodes = (L / res + 1) * (W / res + 1)
    if uses_heightfield(s) and nodes > MAX_FLOOR_NODES:
        raise _fail(("floor", "resolution_m"), res,
                    f"{res} m over the {L:g} m x {W:g} m tank gives {nodes:.3g} heightfield nodes,"
                    f" more than {MAX_FLOOR_NODES:.0e} (~{MAX_FLOOR_NODES * 8e-6:.0f} MB);"
                    " coarsen it or shrink the tank")  # fmt: skip
    try:
        hf = scenario_heightfield(s)
    except ConfigError as exc:
        raise _fail(("floor", "file"), s.floor.file, str(exc)) from None
    if hf is None:
        return None
    for i, rock in enumerate(s.floor.rocks):
        top = float(hf.sample(rock.center_x_m, rock.center_y_m))
        if top <= 0.0:
            raise _fail(("floor", "rocks", i, "height_m"), rock.height_m,
                        f"{rock.height_m} m: the rock's top at {top:.3f} m depth must stay"
                        " under water")  # fmt: skip
    return hf


def _check_ranges(s) -> None:
    for name, sensor in (("dvl", s.dvl), ("sonar", s.sonar)):
        if sensor.min_range >= sensor.max_range:
            raise _fail(
                (name, "min_range"),
                sensor.min_range,
                f"{sensor.min_range} m is not below {name}.max_range = {sensor.max_range} m",
            )


def _check_wave(s) -> None:
    a, f, h = s.wave.amplitude_m, s.wave.frequency_hz, s.water.depth_m
    if a == 0:
        return
    wave = LinearWave(a, f, h, g=s.water.gravity_m_s2)
    steepness = 2 * a / wave.wavelength
    if steepness > BREAKING_STEEPNESS:
        raise _fail(
            ("wave", "amplitude_m"),
            a,
            f"{a} m at {f} Hz is a breaking wave: steepness H/lambda = 2a/lambda ="
            f" {steepness:.3f} exceeds the limit 1/7 = {BREAKING_STEEPNESS:.3f} (lambda ="
            f" {wave.wavelength:.2f} m from omega^2 = g k tanh(k h) in {h} m of water;"
            f" a must be at most {wave.wavelength * BREAKING_STEEPNESS / 2:.3f} m)",
        )


def _steepness(a: np.ndarray, f: np.ndarray, s) -> tuple[np.ndarray, np.ndarray]:
    """(2 a / lambda, lambda) with k from the dispersion relation."""
    k = solve_wavenumbers(2 * np.pi * np.asarray(f, float), s.water.depth_m, s.water.gravity_m_s2)
    return 2 * a * k / (2 * np.pi), 2 * np.pi / k


def _segment_at(segs, t: float) -> int:
    """Index of the segment whose ramp or hold contains time t."""
    return max([g.index for g in segs if g.start_s <= t] or [0])


def _check_schedule(s) -> None:
    w = s.wave
    if w.amplitude_m != 0:
        raise _fail(
            ("wave", "amplitude_m"),
            w.amplitude_m,
            f"{w.amplitude_m} m: with a wave.schedule the amplitude comes from its"
            " segments; set wave.amplitude_m to 0",
        )
    segs = segments(w)
    prev_a, prev_f = 0.0, segs[0].frequency_hz
    for g in segs:
        loc = ("wave", "schedule", g.index)
        last = g.index == len(segs) - 1
        if g.until_s is None and not last:
            raise _fail(
                (*loc, "until_s"), None, "required on every segment but the last (when it ends)"
            )
        if g.until_s is not None and g.until_s <= g.start_s + g.ramp_s:
            raise _fail(
                (*loc, "until_s"),
                g.until_s,
                f"{g.until_s} s must come after this segment's ramp ends at"
                f" {g.start_s + g.ramp_s:g} s (segments in time order)",
            )
        changed = prev_a != g.amplitude_m or (
            prev_f != g.frequency_hz and max(prev_a, g.amplitude_m) > 0
        )
        if g.index == 0 and g.ramp_s == 0:
            changed = False  # the first condition from t = 0, like a constant sea
        sides = [f for a, f in ((prev_a, prev_f), (g.amplitude_m, g.frequency_hz)) if a > 0]
        f_slow = min(sides) if sides else g.frequency_hz
        if changed and g.ramp_s < RAMP_PERIODS / f_slow:
            raise _fail(
                (*loc, "ramp_s"),
                g.ramp_s,
                f"{g.ramp_s} s is too short for a slowly varying sea: a ramp that changes"
                f" the wave must last at least {RAMP_PERIODS:g} wave periods"
                f" ({RAMP_PERIODS / f_slow:.2f} s at {f_slow:g} Hz)",
            )
        prev_a, prev_f = g.amplitude_m, g.frequency_hz
    t, a, f = _schedule_samples(s)
    waves = a > 0
    steep, lam = np.zeros_like(a), np.full_like(a, np.inf)
    steep[waves], lam[waves] = _steepness(a[waves], f[waves], s)
    bad = np.flatnonzero(steep > BREAKING_STEEPNESS)
    if bad.size:
        i = bad[np.argmax(steep[bad])]
        g = segs[_segment_at(segs, t[i])]
        raise _fail(
            ("wave", "schedule", g.index, "amplitude_m"),
            g.amplitude_m,
            f"the sea at t = {t[i]:.1f} s (a = {a[i]:.3f} m, f = {f[i]:.3f} Hz) is a"
            f" breaking wave: steepness 2a/lambda = {steep[i]:.3f} exceeds the limit"
            f" 1/7 = {BREAKING_STEEPNESS:.3f} (lambda = {lam[i]:.2f} m in"
            f" {s.water.depth_m} m of water)",
        )


def _check_slowly_varying(s, path: PathExtent) -> None:
    """|dk/dt| D / omega <= LOCAL_FREQUENCY_ERROR wherever a > 0 (the module docstring)."""
    wave = build_wave(s)
    reach = float(np.max(np.hypot(*_lever_arms(s)[:, :2].T)))
    xs = np.array([path.x_min - reach, path.x_max + reach])
    ys = np.array([path.y_min - reach, path.y_max + reach])
    along = (xs[:, None] * np.cos(wave.beta) + ys[None, :] * np.sin(wave.beta)).ravel()
    D = float(np.max(np.abs(along - wave.s_ref)))
    track = wave.track
    t = np.arange(0.0, track.t[-1] + 0.1, 0.05)
    error = np.abs(np.gradient(wave.k_at(t), t)) * D / wave.omega_at(t)
    error[wave.amplitude_at(t) <= 0] = 0.0
    i = int(np.argmax(error))
    if error[i] > LOCAL_FREQUENCY_ERROR:
        segs = segments(s.wave)
        g = segs[_segment_at(segs, t[i])]
        raise _fail(
            ("wave", "schedule", g.index, "ramp_s"),
            g.ramp_s,
            f"{g.ramp_s} s is too short for a slowly varying sea over this path: at"
            f" t = {t[i]:.1f} s the local frequency is off by {100 * error[i]:.0f} %"
            f" (|dk/dt| D / omega, D = {D:.1f} m from the wave probe where the phase is"
            f" exact), more than {100 * LOCAL_FREQUENCY_ERROR:g} %; lengthen the ramp or"
            " move the wave probe nearer the path",
        )


def _check_waypoints(v) -> None:
    """No zero-length leg, no reversal, each leg long enough for its two rounded corners."""
    loc = ("motion", "waypoints")
    pts = np.asarray(v.points, float)
    pts = np.concatenate([pts] + [pts[1:]] * (v.laps - 1))
    n = len(v.points)
    legs = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    if np.any(legs == 0):
        i = int(np.argmax(legs == 0)) % (n - 1)
        raise _fail(
            (*loc, "points"),
            v.points[i],
            f"points {i} and {i + 1} are the same: a leg of zero length",
        )
    _, length, phi, tang = corner_geometry(pts, v.turn_radius_m)
    if np.any(np.abs(phi) > np.deg2rad(175.0)):
        i = (int(np.argmax(np.abs(phi) > np.deg2rad(175.0))) + 1) % (n - 1)
        raise _fail(
            (*loc, "points"),
            v.points[i],
            f"point {i}: the path turns back on itself (more than 175 deg); add a way"
            " point to turn around",
        )
    need = np.concatenate([[0.0], tang]) + np.concatenate([tang, [0.0]])
    if np.any(need > length):
        i = int(np.argmax(need - length)) % (n - 1)
        raise _fail(
            (*loc, "turn_radius_m"),
            v.turn_radius_m,
            f"{v.turn_radius_m} m: the rounded corners do not fit on the leg from point"
            f" {i} to {i + 1} ({length[i]:.2f} m long, the corners need"
            f" {need[i]:.2f} m)",
        )


def _check_tank_objects(s) -> None:
    L, W, h = s.tank.length_m, s.tank.width_m, s.water.depth_m
    rock = s.tank.rock
    if rock.height_m >= h:
        raise _fail(
            ("tank", "rock", "height_m"),
            rock.height_m,
            f"{rock.height_m} m: the rock must stay under water (water.depth_m = {h} m)",
        )
    if 2 * rock.edge_radius_m > min(rock.length_m, rock.width_m, 2 * rock.height_m):
        raise _fail(
            ("tank", "rock", "edge_radius_m"),
            rock.edge_radius_m,
            f"{rock.edge_radius_m} m: the edge fillet must fit the rock (at most half its"
            f" length, width and its height: {min(rock.length_m, rock.width_m) / 2} m,"
            f" {rock.height_m} m)",
        )
    for field, centre, half, lo, hi in (
        ("center_x_m", rock.center_x_m, rock.length_m / 2, 0.0, L),
        ("center_y_m", rock.center_y_m, rock.width_m / 2, -W / 2, W / 2),
    ):
        if centre - half < lo or centre + half > hi:
            raise _fail(
                ("tank", "rock", field),
                centre,
                f"{centre} m: the rock ({centre - half:g} to {centre + half:g} m) must lie inside"
                f" the tank ({lo:g} to {hi:g} m)",
            )
    p = s.wave_probe
    if not (0.0 <= p.x_m <= L and abs(p.y_m) <= W / 2):
        raise _fail(
            ("wave_probe", "x_m" if not 0.0 <= p.x_m <= L else "y_m"),
            p.x_m,
            f"probe at ({p.x_m}, {p.y_m}) m is outside the tank (x 0 to {L:g} m,"
            f" y {-W / 2:g} to {W / 2:g} m)",
        )


def _lever_arms(s) -> np.ndarray:
    m = s.mounting
    return np.array(
        [x.translation for x in (m.imu, m.dvl, m.sonar, m.barometer)] + [(0.0, 0.0, 0.0)]
    )


def _check_path_in_tank(s, path: PathExtent) -> None:
    L, W = s.tank.length_m, s.tank.width_m
    reach = float(np.max(np.hypot(*_lever_arms(s)[:, :2].T)))
    x0, x1 = path.x_min - reach, path.x_max + reach
    y0, y1 = path.y_min - reach, path.y_max + reach
    kind = path.prefix[1]
    widened = "sensor lever arms" + (" and orbital excursion" if kind != "carriage" else "")
    if x0 < 0.0 or x1 > L:
        raise _fail(
            (*path.prefix, path.x_field),
            x0,
            f"the {kind} path covers x = {x0:.2f} to {x1:.2f} m ({widened} included), outside"
            f" the tank (x from 0 to {L:g} m, tank.length_m)",
        )
    if y0 < -W / 2 or y1 > W / 2:
        raise _fail(
            (*path.prefix, path.y_field),
            y0,
            f"the {kind} path covers y = {y0:.2f} to {y1:.2f} m ({widened} included), outside"
            f" the tank (y from {-W / 2:g} to {W / 2:g} m, tank.width_m)",
        )


def _rock_under(s, path: PathExtent, reach: float) -> bool:
    rock = s.tank.rock
    return (
        path.x_min - reach <= rock.center_x_m + rock.length_m / 2
        and path.x_max + reach >= rock.center_x_m - rock.length_m / 2
        and path.y_min - reach <= rock.center_y_m + rock.width_m / 2
        and path.y_max + reach >= rock.center_y_m - rock.width_m / 2
    )


def _floor_under(hf, path: PathExtent, reach: float) -> float:
    """Shallowest heightfield depth over the path's box widened by ``reach`` and a node."""
    xs, ys = hf.nodes()
    pad_x, pad_y = reach + hf.dx, reach + hf.dy
    i = (xs >= path.x_min - pad_x) & (xs <= path.x_max + pad_x)
    j = (ys >= path.y_min - pad_y) & (ys <= path.y_max + pad_y)
    if not i.any() or not j.any():
        return float(hf.sample(0.5 * (path.x_min + path.x_max), 0.5 * (path.y_min + path.y_max)))
    return float(hf.z[np.ix_(i, j)].min())


def _check_in_water(s, path: PathExtent, hf=None) -> None:
    arms = _lever_arms(s)
    a, h = float(wave_conditions(s)[0].max()), s.water.depth_m
    top = path.depth + float(arms[:, 2].min()) - path.heave
    bottom = path.depth + float(arms[:, 2].max()) + path.heave
    loc = (*path.prefix, "depth_m")
    if top <= a:
        surface = f"the wave trough at {a} m depth" if a > 0 else "the still surface (0 m)"
        raise _fail(
            loc,
            path.depth,
            f"{path.depth} m puts the robot out of the water: its highest point at {top:.3f} m"
            f" depth must be below {surface}",
        )
    reach = float(np.max(np.hypot(*arms[:, :2].T)))
    if hf is None:
        floor = h - (s.tank.rock.height_m if _rock_under(s, path, reach) else 0.0)
        where = " (the rock's top, under the path)" if floor < h else ""
    else:
        floor = _floor_under(hf, path, reach)
        where = " (the floor's shallowest point under the path)"
    if bottom >= floor:
        raise _fail(
            loc,
            path.depth,
            f"{path.depth} m puts the robot into the floor: its lowest sensor at {bottom:.3f} m"
            f" depth must be above the floor at {floor:g} m{where}; water.depth_m = {h} m",
        )


def floor_cloud_count(s, x_min, x_max, y_min, y_max) -> int:
    """Points of the floor scan over the plan box plus the margin, clipped to the tank."""
    c = s.floor_cloud
    x0, x1 = max(x_min - c.margin_m, 0.0), min(x_max + c.margin_m, s.tank.length_m)
    y0 = max(y_min - c.margin_m, -s.tank.width_m / 2)
    y1 = min(y_max + c.margin_m, s.tank.width_m / 2)
    nx = np.floor(max(x1 - x0, 0.0) / c.spacing_m) + 1
    ny = np.floor(max(y1 - y0, 0.0) / c.spacing_m) + 1
    return int(nx * ny)


def _check_floor_cloud(s, path: PathExtent) -> None:
    c = s.floor_cloud
    count = floor_cloud_count(s, path.x_min, path.x_max, path.y_min, path.y_max)
    if count > c.max_points:
        raise _fail(
            ("floor_cloud", "spacing_m"),
            c.spacing_m,
            f"{c.spacing_m} m gives ~{count} points over the area the robot covers, more than"
            f" floor_cloud.max_points = {c.max_points}",
        )
