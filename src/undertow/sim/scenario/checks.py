"""Cross-field checks of a :class:`~undertow.sim.scenario.Scenario`: reject what cannot happen.

Each field is valid alone but some combinations are physically impossible and would simulate
all-NaN sensors; the scenario's model validator runs :func:`check_scenario`, which raises a
pydantic ``ValidationError`` located at the offending field (so the one-line error reads
``file.yaml: field motion.carriage.depth_m: ...``) and naming the limit:

- sensor limits: ``min_range < max_range`` (DVL, sonar);
- breaking: wave steepness H / lambda = 2 a / lambda <= 1/7 (Michell's limit; Dean & Dalrymple,
  "Water Wave Mechanics for Engineers and Scientists"), lambda = 2 pi / k
  with k from the dispersion relation omega^2 = g k tanh(k h);
- the rock platform inside the tank and under water; the wave probe inside the tank;
- the robot's path (carriage run or survey lawnmower, widened by the sensors' horizontal lever
  arms and, for the free vehicle, by the orbital excursion) inside the tank walls;
- the robot in the water: its highest point (body origin or a sensor above it) below the wave
  trough (depth > a), its lowest sensor above the floor (the rock's top where the path crosses
  the rock), the free vehicle's heave included;
- the floor scan's point budget (``floor_cloud.max_points``) for the area the path covers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import ValidationError
from pydantic_core import InitErrorDetails, PydanticCustomError

from ..waves import LinearWave

BREAKING_STEEPNESS = 1.0 / 7.0  # H / lambda above which a wave breaks (Michell's limit)


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


def path_extent(s) -> PathExtent:
    """The box of the carriage run or of the survey's lawnmower (turns included), widened by the
    free vehicle's orbital excursion (horizontal U / omega, vertical W / omega at its depth)."""
    if s.motion.kind == "carriage":
        c = s.motion.carriage
        x1 = c.start_x_m + c.run_length_m
        return PathExtent(c.start_x_m, x1, c.y_m, c.y_m, c.depth_m, 0.0, ("motion", "carriage"))
    v = s.motion.survey
    r = 0.5 * v.pass_spacing_m
    y_last = v.first_pass_y_m + (v.passes - 1) * v.pass_spacing_m
    U, W = 0.0, 0.0
    if s.wave.amplitude_m > 0 and v.depth_m > 0:
        wave = LinearWave(
            s.wave.amplitude_m, s.wave.frequency_hz, s.water.depth_m, g=s.water.gravity_m_s2
        )
        U, W = (float(x) / wave.omega for x in wave.velocity_amplitude(v.depth_m))
    return PathExtent(
        v.start_x_m - r - U,
        v.start_x_m + v.pass_length_m + r + U,
        v.first_pass_y_m - U,
        y_last + U,
        v.depth_m,
        W,
        ("motion", "survey"),
    )


def check_scenario(s) -> None:
    """Raise ValidationError (at the offending field) if ``s`` cannot happen; see the module."""
    _check_ranges(s)
    _check_wave(s)
    _check_tank_objects(s)
    path = path_extent(s)
    _check_path_in_tank(s, path)
    _check_in_water(s, path)
    _check_floor_cloud(s, path)


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
    widened = "sensor lever arms" + (" and orbital excursion" if kind == "survey" else "")
    if x0 < 0.0 or x1 > L:
        raise _fail(
            (*path.prefix, "start_x_m"),
            x0,
            f"the {kind} path covers x = {x0:.2f} to {x1:.2f} m ({widened} included), outside"
            f" the tank (x from 0 to {L:g} m, tank.length_m)",
        )
    if y0 < -W / 2 or y1 > W / 2:
        field = "y_m" if kind == "carriage" else "first_pass_y_m"
        raise _fail(
            (*path.prefix, field),
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


def _check_in_water(s, path: PathExtent) -> None:
    arms = _lever_arms(s)
    a, h = s.wave.amplitude_m, s.water.depth_m
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
    floor = h - (s.tank.rock.height_m if _rock_under(s, path, reach) else 0.0)
    if bottom >= floor:
        where = " (the rock's top, under the path)" if floor < h else ""
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
