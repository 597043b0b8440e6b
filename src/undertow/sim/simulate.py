"""Run a scenario: motion, waves, tank and sensors -> a Log, a ground-truth floor cloud.

Randomness: one numpy Generator per sensor, children of SeedSequence(seed) in the fixed order
of ``RNG_STREAMS`` (SeedSequence.spawn). A child depends only on (seed, its index), so a new
sensor appended to ``RNG_STREAMS`` (the multibeam was) leaves every other stream's noise
unchanged. The multibeam is simulated only when the scenario has a ``multibeam`` section.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .._util.atomic import output_folder
from ..errors import ConfigError
from ..log import GroundTruth, Log
from ..rotations import wrap_angle
from .motion import CarriageMotion, SurveyMotion, WaypointMotion, kinematics
from .scenario.checks import floor_cloud_count
from .scenario.model import Scenario
from .seabed import scenario_heightfield
from .seastate import build_wave, wave_track
from .sensors.dvl import simulate_dead_reckoning, simulate_dvl
from .sensors.env import simulate_barometer, simulate_sonar, simulate_wave_probe
from .sensors.imu import sample_times, simulate_imu
from .sensors.multibeam import simulate_multibeam
from .tank import Tank
from .wavefield import WaveField
from .waves import LinearWave

RNG_STREAMS = ("imu", "dvl", "dead_reckoning", "pressure", "sonar", "wave_probe", "multibeam")


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """A simulated log (with ground truth), the floor cloud (M, 3) and the scenario used;
    ``gyro_bias`` (N, 3) is the IMU's true gyro bias at the IMU's sample times (rad/s), a hidden
    state no sensor reports, kept for checking estimators."""

    log: Log
    floor_cloud: np.ndarray
    scenario: Scenario
    gyro_bias: np.ndarray | None = None


def build_tank(s: Scenario) -> Tank:
    """The scenario's tank: the original flat one in closed form, else its heightfield floor
    (sim/seabed.py), walls as set."""
    r = s.tank.rock
    return Tank(
        s.tank.length_m, s.tank.width_m, s.water.depth_m, r.center_x_m, r.center_y_m,
        r.length_m, r.width_m, r.height_m, r.edge_radius_m,
        walls=s.tank.walls, heightfield=scenario_heightfield(s),
    )  # fmt: skip


def build_motion(s: Scenario, wave: LinearWave | WaveField):
    if s.motion.kind == "carriage":
        return CarriageMotion(s.motion.carriage, wave)
    if s.motion.kind == "waypoints":
        return WaypointMotion(s.motion.waypoints, wave)
    return SurveyMotion(s.motion.survey, wave)


def simulate(scenario: Scenario, seed: int | None = None) -> SimulationResult:
    """Simulate ``scenario`` with ``seed`` (default: the scenario's own seed); a seed must be a
    non-negative integer (numpy's SeedSequence), else ConfigError."""
    if seed is not None:
        if isinstance(seed, bool) or int(seed) != seed or seed < 0:
            raise ConfigError(f"seed {seed}: must be a non-negative integer")
        scenario = scenario.model_copy(update={"seed": int(seed)})
    s = scenario
    rngs = dict(
        zip(
            RNG_STREAMS,
            (
                np.random.default_rng(c)
                for c in np.random.SeedSequence(s.seed).spawn(len(RNG_STREAMS))
            ),
            strict=True,
        )
    )
    wave, tank = build_wave(s), build_tank(s)
    motion = build_motion(s, wave)
    mounting = s.mounting.to_mounting()
    T = motion.duration
    g = s.water.gravity_m_s2

    imu, gyro_bias = simulate_imu(motion, s.imu, mounting.imu, g, T, rngs["imu"])
    dvl = simulate_dvl(
        motion, wave, tank, s.dvl, mounting.dvl, s.water.sound_speed_m_s, T, rngs["dvl"]
    )
    dr = simulate_dead_reckoning(
        motion, dvl, s.dead_reckoning, mounting.dvl, T, rngs["dead_reckoning"]
    )
    pressure = simulate_barometer(
        motion,
        wave,
        s.barometer,
        mounting.barometer,
        s.water.surface_pressure_pa,
        T,
        rngs["pressure"],
    )
    sonar = simulate_sonar(
        motion, tank, s.sonar, mounting.sonar, s.water.sound_speed_m_s, T, rngs["sonar"], wave
    )
    probe = simulate_wave_probe(wave, s.wave_probe, T, rngs["wave_probe"])
    multibeam = None
    if s.multibeam is not None:
        multibeam = simulate_multibeam(
            motion, tank, s.multibeam, mounting.multibeam, T, rngs["multibeam"]
        )

    t_gt = sample_times(T, s.ground_truth.rate_hz)
    kin = kinematics(motion, t_gt)
    rpy = kin.rpy.copy()
    rpy[:, 2] = wrap_angle(rpy[:, 2])
    gt = GroundTruth(t=t_gt, position=kin.position, orientation=rpy, velocity=kin.velocity)

    log = Log(
        imu=imu, dvl=dvl, dead_reckoning=dr, pressure=pressure, sonar=sonar, wave_probe=probe,
        ground_truth=gt, multibeam=multibeam, mounting=mounting, source=f"simulator:{s.name}",
        metadata={"scenario": s.name, "seed": s.seed, **wave_metadata(s, wave, T),
                  "dvl_geometry": s.dvl.geometry().to_dict()},
    )  # fmt: skip
    cloud = floor_cloud(s, tank, kin.position)
    return SimulationResult(log=log, floor_cloud=cloud, scenario=s, gyro_bias=gyro_bias)


def wave_metadata(s: Scenario, wave: LinearWave | WaveField, duration: float) -> dict:
    """The log's record of the sea: ``wave`` = {amplitude_m, frequency_hz} and
    ``wavenumber_rad_m`` for a constant sea, the schedule's WaveTrack.to_dict() (nodes up to
    ``duration``) for a changing one; the heading beta and the still-water depth h always."""
    if s.wave.schedule is None:
        wave_meta = {
            "wave": {"amplitude_m": s.wave.amplitude_m, "frequency_hz": s.wave.frequency_hz},
            "wavenumber_rad_m": wave.k,
        }
    else:
        wave_meta = {"wave": _track_dict(wave_track(s, duration), s.wave.frequency_hz)}
    return {
        **wave_meta,
        "wave_heading_deg": s.wave.heading_deg,
        "water_depth_m": s.water.depth_m,
        "water_density_kg_m3": s.water.density_kg_m3,
        "surface_pressure_pa": s.water.surface_pressure_pa,
        # what the simulated DVL converts with (a standard DVL message's sound_speed)
        "dvl_sound_speed_m_s": s.dvl.sound_speed_setting,
    }


def _track_dict(track, calm_f: float) -> dict:
    """``track.to_dict()`` with each calm node's frequency the one the phase runs at there (f
    linear between the nodes that have one): no None in the lists, which a bag sidecar would
    drop (always calm: ``calm_f``), and the same track again from ``WaveTrack.from_dict`` (NaN
    where a = 0)."""
    out = track.to_dict()
    has_f = np.isfinite(track.frequency_hz)
    f = np.full(track.t.shape, calm_f)  # always calm: the wave.frequency_hz the phase runs at
    if has_f.any():
        f = np.interp(track.t, track.t[has_f], track.frequency_hz[has_f])
    out["frequency_hz"] = [float(x) for x in f]
    return out


def floor_cloud(s: Scenario, tank: Tank, positions: np.ndarray) -> np.ndarray:
    """Dense floor points over the robot's x-y extent plus the configured margin."""
    c = s.floor_cloud
    lo, hi = positions[:, :2].min(axis=0), positions[:, :2].max(axis=0)
    count = floor_cloud_count(s, lo[0], hi[0], lo[1], hi[1])
    if count > c.max_points:  # the scenario's validator checks this first, from the path's box
        raise ConfigError(
            f"field floor_cloud.spacing_m: {c.spacing_m} m gives ~{count} points, more than"
            f" floor_cloud.max_points = {c.max_points}"
        )
    lo, hi = lo - c.margin_m, hi + c.margin_m
    return tank.floor_cloud(lo[0], hi[0], lo[1], hi[1], c.spacing_m)


def write_simulation(result: SimulationResult, out_dir, overwrite: bool = False) -> Path:
    """Write DIR/log/ (ROS 2 mcap bag), ground_truth.tum (2000 Hz), ground_truth.ply (floor
    cloud) and scenario.yaml. Everything goes to a temporary sibling folder first and is renamed
    into place, so nothing is left half-written."""
    from ..io import write_log
    from ..io.ply import write_ply
    from ..io.tum import write_tum

    out = Path(out_dir)
    with output_folder(out, overwrite) as tmp:
        gt = result.log.ground_truth
        write_log(result.log, tmp / "log", flavor="driver", overwrite=False)
        write_tum(tmp / "ground_truth.tum", gt.t, gt.position, gt.orientation)
        write_ply(tmp / "ground_truth.ply", result.floor_cloud)
        with open(tmp / "scenario.yaml", "w") as f:
            yaml.safe_dump(result.scenario.to_yaml_dict(), f, sort_keys=False)
    return out


__all__ = ["SimulationResult", "simulate", "write_simulation"]
