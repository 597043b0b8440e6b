"""Table IV's maps and every map metric, on the wave conditions and on the mapping scenarios.

Per map: the paper's C2C and occupied cells (:mod:`undertow.evaluation.cloud`), and the
grid-independent surface metrics (:mod:`undertow.evaluation.surface`): the bathymetric surface
error (RMSE, bias, coverage) and accuracy, completeness and F-score at tau = 0.05, 0.10, 0.20 m.

The surveyed area is where the log's beams hit the floor with the TRUE pose and the true ranges
(the ground truth put through the mapping stage's own ray geometry, the ranges in the water's
sound speed: :func:`true_ranges`), so it does not depend on the filter or the mapper. The
true floor is the simulator's heightfield where it exposes one, else its ground-truth cloud.

A mapping scenario (beyond the paper's carriage runs: ``mhl-basin``, ``field-survey``) is
localized as a user would (wave from its own probe, the study's noise profile and calibration,
the water's sound speed given) with the baseline and proposed filters, then mapped with the four
Table IV runs and the default mapper, which also maps the proposed filter on the log as
recorded (:data:`RECORDED`).
"""

from __future__ import annotations

import math

import numpy as np

from .._util.plain import to_plain
from ..estimation.characterize import estimate_waves
from ..estimation.localizer import localize
from ..evaluation.cloud import evaluate_map
from ..evaluation.surface import cloud_spacing, evaluate_surface
from ..io.read_options import LogOptions
from ..io.sound_speed import correct_sound_speed
from ..mapping.config import MappingConfig
from ..mapping.run import map_log
from ..mapping.samples import build_samples
from ..mapping.surface import map_surface, surface_from_points
from ..sim import load_scenario, simulate
from ..trajectory import STATE_NAMES, Trajectory

MAP_RUNS = (("csm", "baseline"), ("csm", "proposed"), ("bki", "proposed"), ("adaptive", "proposed"))
#: A mapping scenario is read as a user who gave the water's sound speed reads it
#: (:func:`true_ranges`); this variant is the proposed filter and its map on the log as
#: recorded instead (no sound speed given: the DVL's and the Ping's 1500 m/s in fresh water).
RECORDED = "proposed+recorded"
#: The proposed filter's trajectory with its position covariance scaled per axis to its own
#: error against the ground truth (:func:`consistent_covariance`: an oracle only a simulation
#: has), so that the map's depth std is judged with a pose covariance that means what it says.
CONSISTENT = "proposed+consistent"
#: The mapping scenarios add the default mapper (tpu) beside the paper's four maps, the same
#: mapper on :data:`RECORDED` (what the sound speed left uncorrected costs the map) and from
#: :data:`CONSISTENT` (the map's std apart from the filter's covariance).
SCENARIO_MAP_RUNS = (*MAP_RUNS, ("tpu", "proposed"), ("tpu", RECORDED), ("tpu", CONSISTENT))
#: The filters of a mapping scenario (the paper's two, then :data:`RECORDED`).
SCENARIO_FILTERS = ("baseline", "proposed", RECORDED)
#: The map threshold the paper evaluates at.
THRESHOLD = 0.5
#: The ground truth's pose is decimated to this rate to find where the beams hit (Hz).
AREA_POSE_RATE_HZ = 50.0
#: Attributes of a simulation result that may hold the true floor as a heightfield z(x, y).
HEIGHTFIELD_ATTRIBUTES = ("heightfield", "floor_depth", "seabed")


def filter_options(variant: str) -> tuple[str, dict]:
    """The localize filter of a study ``variant`` (its name before any "+") and its DVL
    scale option: a ``+scale`` variant divides out the calibration's factor, the others keep
    1 (the paper's filters do not correct it)."""
    scale = {} if variant.endswith("+scale") else {"dvl_scale_factor": 1.0}
    return variant.split("+")[0], scale


def floor_truth(sim):
    """The true floor of a simulation as a heightfield z(x, y): an attribute of the result
    named in :data:`HEIGHTFIELD_ATTRIBUTES` (a callable, or an object with ``sample``), else
    the floor the simulator's tank casts its rays on (:func:`undertow.sim.simulate.build_tank`
    of the scenario: ``Tank.floor_depth``, walls excluded), else the ground-truth cloud."""
    for name in HEIGHTFIELD_ATTRIBUTES:
        value = getattr(sim, name, None)
        if callable(value):
            return value
        if value is not None and callable(getattr(value, "sample", None)):
            return value.sample
    scenario = getattr(sim, "scenario", None)
    if scenario is not None:
        from ..sim.simulate import build_tank

        tank = build_tank(scenario)
        if callable(getattr(tank, "floor_depth", None)):
            return tank.floor_depth
    return sim.floor_cloud


def true_pose_trajectory(ground_truth, rate_hz: float = AREA_POSE_RATE_HZ) -> Trajectory:
    """The ground truth's pose as a zero-covariance :class:`Trajectory` at about ``rate_hz``."""
    t = ground_truth.t
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    step = max(1, int(round(1.0 / (rate_hz * dt))))
    idx = np.unique(np.r_[np.arange(0, len(t), step), len(t) - 1])
    x = np.zeros((len(idx), len(STATE_NAMES)))
    x[:, :3] = ground_truth.position[idx]
    x[:, 3:6] = np.unwrap(ground_truth.orientation[idx], axis=0)
    P = np.zeros((len(idx), len(STATE_NAMES), len(STATE_NAMES)))
    return Trajectory(t[idx], x, P, variant="ground truth")


def consistent_covariance(trajectory: Trajectory, ground_truth) -> Trajectory:
    """``trajectory`` with its covariance P scaled to S P S, S = diag(k_x, k_y, k_z, 1, ...),
    k_j^2 = mean(e_j^2) / mean(P_jj) over its poses inside the ground truth's span (e_j the
    position error against the ground truth interpolated at the pose's time): each position
    axis's mean variance is then its mean squared error, and P stays positive semidefinite (a
    congruence). An axis without error or variance keeps its scale 1."""
    gt = ground_truth
    inside = (trajectory.t >= gt.t[0]) & (trajectory.t <= gt.t[-1])
    scale = np.ones(trajectory.P.shape[1])
    for j in range(3):
        error = trajectory.position[inside, j] - np.interp(trajectory.t[inside], gt.t,
                                                             gt.position[:, j])  # fmt: skip
        variance = float(np.mean(trajectory.P[inside, j, j])) if inside.any() else 0.0
        if variance > 0 and np.isfinite(variance):
            scale[j] = np.sqrt(float(np.mean(error**2)) / variance) or 1.0
    return trajectory.replace(P=trajectory.P * scale[None, :, None] * scale[None, None, :])


def true_ranges(sim):
    """``sim``'s log with its DVL and sonar ranges (and DVL velocities) in the water's sound
    speed: the simulator's own c and the sensors' settings (the DVL and the Ping convert with
    the speed they are set to: :mod:`undertow.io.sound_speed`), so the beams end on the floor."""
    s = sim.scenario
    options = LogOptions(sound_speed_m_s=s.water.sound_speed_m_s,
                         dvl_sound_speed_m_s=s.dvl.sound_speed_setting,
                         sonar_sound_speed_m_s=s.sonar.sound_speed_setting)  # fmt: skip
    return correct_sound_speed(sim.log, options, state=False)


def surveyed_area(log) -> np.ndarray:
    """(K, 2) x-y of every beam hit (DVL and sonar ranges) placed with the true pose (give it
    :func:`true_ranges` of a simulation, so the ranges are true too)."""
    trajectory = true_pose_trajectory(log.ground_truth)
    samples = build_samples(log, trajectory, free_resolution=10.0)
    return samples.points[samples.label == 1, :2]


def map_metrics(occupancy, truth, cloud, area) -> dict:
    """C2C, cells and coverage (the paper's, against ``cloud``) and the surface metrics (against
    ``truth``, over ``area``) of one map, plain numbers; ``withheld_columns``: the columns its
    surface left out as failing the IHO order (a tpu map's; 0 for the others)."""
    out = evaluate_map(occupancy.points(THRESHOLD), cloud, resolution=occupancy.resolution)
    held = map_surface(occupancy, THRESHOLD)
    surface = evaluate_surface(held, truth, area=area)
    return to_plain({**out.to_dict(), **surface.to_dict(), "withheld_columns": held.withheld})


def floor_relief(truth, area: np.ndarray, resolution: float) -> dict:
    """How much the true floor varies over the surveyed area: the standard deviation of its
    depth and its RMS slope |grad z| (central differences over one grid cell), at the surveyed
    points."""
    fn = truth if callable(truth) else surface_from_points(truth, cloud_spacing(truth)).at
    x, y = area[:, 0], area[:, 1]
    h = resolution / 2
    z = np.asarray(fn(x, y), float)
    gx = (np.asarray(fn(x + h, y), float) - np.asarray(fn(x - h, y), float)) / (2 * h)
    gy = (np.asarray(fn(x, y + h), float) - np.asarray(fn(x, y - h), float)) / (2 * h)
    slope = np.hypot(gx, gy)
    return to_plain({
        "depth_std_m": float(np.nanstd(z)) if np.isfinite(z).any() else None,
        "rms_slope": float(np.sqrt(np.nanmean(slope**2))) if np.isfinite(slope).any() else None,
    })  # fmt: skip


def evaluate_runs(name: str, sim, trajectories: dict, bki_length_scale: float, art,
                  area: np.ndarray | None = None, runs=MAP_RUNS, logs=None) -> dict:  # fmt: skip
    """Map ``sim``'s log (or ``logs[variant]``, the log a variant was localized on) with the
    Table IV ``runs`` (method, filter variant; trajectories by variant) and evaluate each map
    over ``area`` (default: :func:`surveyed_area`); the maps go to
    ``art.maps[(name, "method/variant")]``."""
    logs = logs or {}
    truth, cloud = floor_truth(sim), sim.floor_cloud
    area = surveyed_area(true_ranges(sim)) if area is None else area
    out = {}
    for method, variant in runs:
        # the consistent covariance's z variance holds the swell the map would add to it
        cfg = MappingConfig(method=method, length_scale=bki_length_scale,
                            wave_depth_noise=variant != CONSISTENT)  # fmt: skip
        result = map_log(logs.get(variant, sim.log), trajectories[variant], cfg)
        key = f"{method}/{variant}"
        art.maps[(name, key)] = result.map
        out[key] = map_metrics(result.map, truth, cloud, area)
    return out


def map_scenario(name: str, seed: int, calibration, profile, bki_length_scale: float, art,
                 trajectory_metrics) -> dict:  # fmt: skip
    """One mapping scenario: simulate, localize (:data:`SCENARIO_FILTERS`) with the wave from
    its own probe, scale the proposed filter's covariance to its error (:data:`CONSISTENT`),
    map with :data:`SCENARIO_MAP_RUNS` and evaluate; also how rough its floor is. Read as a
    user who gave the water's sound speed (:func:`true_ranges`), but for :data:`RECORDED`;
    the filters leave the DVL scale factor at 1 (the paper's filters do not correct it, and
    the sound speed leaves none to correct)."""
    sim = simulate(load_scenario(name), seed=seed)
    art.simulations[name] = sim
    measured = estimate_waves(sim.log.wave_probe)
    wave = "calm" if measured.calm else (measured.amplitude_m, measured.frequency_hz)
    water = true_ranges(sim)
    logs = {v: sim.log if v == RECORDED else water for v in SCENARIO_FILTERS}
    trajectories, localization = {}, {}
    for variant in SCENARIO_FILTERS:
        base, scale = filter_options(variant)
        traj = localize(logs[variant], base, profile=profile, wave=wave,
                        calibration=calibration, extrapolate=True, **scale)  # fmt: skip
        art.trajectories[(name, variant)] = trajectories[variant] = traj
        localization[variant] = trajectory_metrics(traj, sim.log.ground_truth)
    trajectories[CONSISTENT] = consistent_covariance(trajectories["proposed"],
                                                     sim.log.ground_truth)  # fmt: skip
    localization[CONSISTENT] = trajectory_metrics(trajectories[CONSISTENT], sim.log.ground_truth)
    logs[CONSISTENT] = water
    area = surveyed_area(water)
    mapping = evaluate_runs(name, sim, trajectories, bki_length_scale, art, area,
                            SCENARIO_MAP_RUNS, logs)  # fmt: skip
    return {
        "duration_s": float(sim.log.ground_truth.t[-1] - sim.log.ground_truth.t[0]),
        "wave": {"amplitude_m": measured.amplitude_m, "frequency_hz": measured.frequency_hz},
        "floor": floor_relief(floor_truth(sim), area, paper_resolution()),
        "localization": localization,
        "mapping": mapping,
        # what a depth std that means what it says covers: erf(k / sqrt 2) of a normal error
        "normal": {f"within_{k}sigma": math.erf(k / math.sqrt(2)) for k in (1, 2)},
    }


def paper_resolution() -> float:
    from . import paper

    return paper.GRID_RESOLUTION_M
