"""The paper's experiments end to end for one seed (over seeds: :mod:`undertow.study.runner`).

For a seed s, with every simulator parameter from the built-in scenarios (never tuned here):

1. simulate the calm carriage run and the three wave conditions (and the rock survey);
2. characterize the waves and the DVL noise (Table I) -> a noise profile of the EXTRA noise;
3. calibrate on the calm run (with its ground truth): mu_b (DR drift) and the DVL scale factor;
4. localize each wave run with the paper's four variants (baseline, be, an, proposed), the
   measured wave condition and the characterized profile (the rock survey too: its wave from its
   own probe, the profile of step 2); the calibration's mu_b is used by the
   bias-estimating variants (the paper's "standard sensor calibration"), the DVL scale factor is
   NOT (the paper does not correct it); ``proposed+scale`` adds it (beyond the paper);
   Beyond the paper, for the field: ``proposed+auto`` is the proposed filter with the wave
   condition estimated from the run's own sensors (``--wave auto``, no probe), and
   ``adaptive-r`` the peer baseline that adapts R from the innovations instead;
5. map with CSM on the baseline trajectory and CSM, BKI (l = 0.15 m) and adaptive BKI on the
   proposed one (Table IV); evaluate against the ground truth with the paper's metrics (C2C,
   cells) and the surface metrics (:mod:`undertow.study.maps`);
5b. (beyond the paper) the same four maps on the mapping scenarios (``map_scenarios``: the
   basin with walls, beach and a rough floor, and a field survey over a rough seabed), whose
   floors let a lateral pose error show in the map; read with the water's sound speed given,
   with the default mapper beside, also on the log as recorded (:mod:`undertow.study.maps`).

6. (beyond the paper) the changing-sea scenarios: the sea state changes during the run; the
   proposed filter with the true schedule, with ``--wave auto``, with each fixed condition,
   ``adaptive-r`` and the baseline, and the onboard wave estimate against the schedule.
7. (beyond the paper, ``settings.peers``) the peers table: the UKF beside the factor graph
   (batch and iSAM2) and the InEKF on the same runs (:mod:`undertow.study.peers`).

Returns plain, JSON-serializable numbers; :func:`run_seed_with_artifacts` also returns the
in-memory objects the figures need.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._util.plain import to_plain
from ..estimation.calibration import calibrate
from ..estimation.characterize import characterize, estimate_waves
from ..estimation.localizer import localize
from ..evaluation.cloud import evaluate_map
from ..evaluation.trajectory import trajectory_rmse
from ..mapping.config import MappingConfig
from ..mapping.run import map_log
from ..sim import list_scenarios, load_scenario, simulate
from ..wavetrack import WaveTrack
from . import paper
from .claims import evaluate_seed
from .maps import MAP_RUNS, evaluate_runs, filter_options, map_scenario
from .peers import PeerSettings, peer_waves, run_peers

WAVE_CONDITIONS = ("wave-a0.10-f1.00", "wave-a0.10-f0.75", "wave-a0.05-f0.75")
VARIANTS = ("baseline", "be", "an", "proposed")
#: Beyond the paper, for the field: the proposed filter with the wave condition estimated from
#: the log (no probe) and the innovation-adaptive peer baseline.
FIELD_VARIANTS = ("proposed+auto", "adaptive-r")
#: The states whose filter standard deviation is averaged along the trajectory (index in x).
MEAN_STD_STATES = {"x_m": 0, "y_m": 1, "z_m": 2, "yaw_rad": 5, "vx_m_s": 6}
#: The rock survey's maps are evaluated over the rock's footprint plus this margin.
ROCK_MARGIN_M = 0.5
#: The mapping scenarios the study evaluates Table IV on (those that exist; beyond the paper).
MAP_SCENARIOS = ("mhl-basin", "field-survey")


def default_map_scenarios() -> tuple[str, ...]:
    """:data:`MAP_SCENARIOS` that the installed scenarios hold."""
    known = set(list_scenarios())
    return tuple(name for name in MAP_SCENARIOS if name in known)


@dataclass(frozen=True)
class StudySettings:
    """What the study runs (defaults: the paper's experiments)."""

    conditions: tuple[str, ...] = WAVE_CONDITIONS
    calm: str = "calm"
    rock_survey: str | None = "rock-survey"
    changing_sea: tuple[str, ...] = ("changing-sea-carriage", "changing-sea-survey")
    bki_length_scale: float = paper.BKI_LENGTH_SCALE_M
    map_scenarios: tuple[str, ...] = field(default_factory=default_map_scenarios)
    #: the peers table (:mod:`undertow.study.peers`); None: not run
    peers: PeerSettings | None = None


@dataclass
class Artifacts:
    """In-memory results of one seed for figures and the report (not serialized)."""

    simulations: dict = field(default_factory=dict)
    trajectories: dict = field(default_factory=dict)  # (condition, variant) -> Trajectory
    maps: dict = field(default_factory=dict)  # (condition, "method/variant") -> OccupancyMap
    wave_estimates: dict = field(default_factory=dict)  # scenario -> (estimate dict, truth)
    peers: dict = field(default_factory=dict)  # (scenario, estimator) -> thinned Trajectory


def run_seed(seed: int, settings: StudySettings | None = None) -> dict:
    """The whole study for one seed; plain numbers only (a Dask task)."""
    return run_seed_with_artifacts(seed, settings)[0]


def run_seed_with_artifacts(seed: int, settings: StudySettings | None = None):
    """(results, artifacts) of the whole study for one seed."""
    settings = settings or StudySettings()
    art = Artifacts()
    names = [settings.calm, *settings.conditions]
    for name in names:
        art.simulations[name] = simulate(load_scenario(name), seed=seed)
    logs = {name: art.simulations[name].log for name in names}
    char = characterize([logs[n] for n in names], name=f"simulated (seed {seed})")
    table1 = {name: row for name, row in zip(names, char.table(), strict=True)}
    calibration = calibrate(logs[settings.calm])
    results = {
        "seed": seed,
        "table1": {n: _table1_row(table1[n]) for n in names},
        "calibration": to_plain(calibration.to_dict()),
        "localization": {},
        "mapping": {},
    }
    for name in settings.conditions:
        log = logs[name]
        row = table1[name]
        wave = (row["amplitude_m"], row["frequency_hz"])
        loc = {}
        for variant in (*VARIANTS, "proposed+scale", *FIELD_VARIANTS):
            base, params = filter_options(variant)
            run_wave = "auto" if variant.endswith("+auto") else wave
            traj = localize(
                log, base, profile=char.profile, wave=run_wave, calibration=calibration, **params
            )
            art.trajectories[(name, variant)] = traj
            loc[variant] = _trajectory_metrics(traj, log.ground_truth)
        results["localization"][name] = loc
        results["mapping"][name] = _mapping(name, log, art, settings)
    if settings.rock_survey:
        results["rock_survey"] = _rock_survey(
            settings.rock_survey, seed, calibration, char.profile, art
        )
    fixed = {"calm": "calm"}
    fixed.update(
        {n: (table1[n]["amplitude_m"], table1[n]["frequency_hz"]) for n in settings.conditions}
    )
    results["changing_sea"] = {
        name: _changing_sea(name, seed, calibration, char.profile, fixed, art)
        for name in settings.changing_sea
    }
    results["map_scenarios"] = {
        name: map_scenario(
            name,
            seed,
            calibration,
            char.profile,
            settings.bki_length_scale,
            art,
            _trajectory_metrics,
        )  # fmt: skip
        for name in settings.map_scenarios
    }
    if settings.peers is not None:
        study = {"waves": peer_waves(table1, settings.conditions), "profile": char.profile,
                 "calibration": calibration}  # fmt: skip
        results["peers"] = run_peers(seed, settings.peers, study, art)
    results["claims"], results["claims_table1"] = evaluate_seed(results)
    return results, art


def _trajectory_metrics(traj, ground_truth) -> dict:
    errors = trajectory_rmse(traj, ground_truth)
    std = np.sqrt(np.einsum("nii->ni", traj.P[:, :9, :9]))
    return {
        "rmse": errors.rmse,
        "nees_mean": errors.nees_mean,
        "nees_fraction_in_95": errors.nees_fraction_in_95,
        "mean_std": {key: float(std[:, i].mean()) for key, i in MEAN_STD_STATES.items()},
    }


def _mapping(name: str, log, art: Artifacts, settings: StudySettings) -> dict:
    trajectories = {v: art.trajectories[(name, v)] for v in {v for _, v in MAP_RUNS}}
    return evaluate_runs(name, art.simulations[name], trajectories, settings.bki_length_scale, art)


def _rock_survey(name: str, seed: int, calibration, profile, art: Artifacts) -> dict:
    """The free-vehicle survey over the rock: localize (proposed) as a user would, with the
    wave measured by the survey's own wave probe and the noise profile characterized in this
    study (its Table I; not the scenario's true wave nor the paper's profile), map (adaptive and
    BKI), and evaluate the map over the rock's footprint (plus a margin)."""
    sim = simulate(load_scenario(name), seed=seed)
    art.simulations[name] = sim
    measured = estimate_waves(sim.log.wave_probe)
    wave = "calm" if measured.calm else (measured.amplitude_m, measured.frequency_hz)
    traj = localize(sim.log, "proposed", profile=profile, wave=wave, calibration=calibration)
    art.trajectories[(name, "proposed")] = traj
    rock = sim.scenario.tank.rock
    margin = ROCK_MARGIN_M
    lo = np.array([rock.center_x_m - rock.length_m / 2, rock.center_y_m - rock.width_m / 2])
    hi = np.array([rock.center_x_m + rock.length_m / 2, rock.center_y_m + rock.width_m / 2])
    near = np.all(
        (sim.floor_cloud[:, :2] > lo - margin) & (sim.floor_cloud[:, :2] < hi + margin), 1
    )
    out = {
        "wave": {"amplitude_m": measured.amplitude_m, "frequency_hz": measured.frequency_hz},
        "trajectory": _trajectory_metrics(traj, sim.log.ground_truth),
    }
    for method in ("adaptive", "bki"):
        result = map_log(sim.log, traj, MappingConfig(method=method))
        art.maps[(name, f"{method}/proposed")] = result.map
        pts = result.map.points(0.5)
        inside = np.all((pts[:, :2] > lo - margin) & (pts[:, :2] < hi + margin), axis=1)
        evaluation = evaluate_map(pts[inside], sim.floor_cloud[near], resolution=0.1)
        out[method] = to_plain(evaluation.to_dict())
    return out


def _changing_sea(name: str, seed: int, calibration, profile, fixed: dict, art) -> dict:
    """A run whose sea state changes: the proposed filter with the true schedule (the
    scenario's), with the condition estimated from the log (``auto``), with each ``fixed``
    condition for the whole run; ``adaptive-r`` and the baseline; and the onboard wave
    estimate's error against the schedule in its stationary windows."""
    sim = simulate(load_scenario(name), seed=seed)
    art.simulations[name] = sim
    log = sim.log
    truth = WaveTrack.from_dict(log.metadata["wave"], source="scenario")
    runs = {
        "baseline": ("baseline", None), "proposed": ("proposed", truth),
        "proposed+auto": ("proposed", "auto"), "adaptive-r": ("adaptive-r", None),
        **{f"fixed {label}": ("proposed", wave) for label, wave in fixed.items()},
    }  # fmt: skip
    out = {"localization": {}}
    for key, (variant, wave) in runs.items():
        traj = localize(log, variant, profile=profile, wave=wave, calibration=calibration,
                        extrapolate=True, dvl_scale_factor=1.0)  # fmt: skip
        art.trajectories[(name, key)] = traj
        metrics = _trajectory_metrics(traj, log.ground_truth)
        metrics["nees_deviation"] = abs(metrics["nees_mean"] / 6.0 - 1.0)
        out["localization"][key] = metrics
        if key == "proposed+auto":
            art.wave_estimates[name] = (traj.metadata.get("wave_estimate"), truth)
    out["wave_estimate"] = wave_estimate_errors(art.wave_estimates[name][0], truth)
    return out


def wave_estimate_errors(estimate: dict | None, truth: WaveTrack) -> dict:
    """Largest and median relative errors (%) of the onboard estimate's amplitude and frequency
    over its stationary windows (the truth the same at the window's start, centre and end and
    not calm), and the count of such windows."""
    errors_a, errors_f = [], []
    for w in (estimate or {}).get("windows", []):
        span = np.array([w["t_start"], 0.5 * (w["t_start"] + w["t_end"]), w["t_end"]])
        a, f = truth.at(span)
        if not (np.all(a > 0) and np.ptp(a) == 0 and np.ptp(f) == 0):
            continue
        errors_a.append(100 * abs(w["amplitude_m"] / a[1] - 1))
        est_f = w["frequency_hz"] if w["frequency_hz"] is not None else np.nan
        errors_f.append(100 * abs(est_f / f[1] - 1))
    if not errors_a:
        return {"windows": 0}
    return {
        "windows": len(errors_a),
        "amplitude_error_max_pct": float(np.max(errors_a)),
        "amplitude_error_median_pct": float(np.median(errors_a)),
        "frequency_error_max_pct": float(np.max(errors_f)),
        "frequency_error_median_pct": float(np.median(errors_f)),
    }


def _table1_row(row: dict) -> dict:
    """Scalars, with per-axis values as {vx, vy, vz} (aggregation works on named leaves)."""
    out = {k: row[k] for k in ("amplitude_m", "frequency_hz", "depth_std_m")}
    for key in ("dvl_std_m_s", "dvl_extra_std_m_s"):
        out[key] = dict(zip(("vx", "vy", "vz"), row[key], strict=True))
    return to_plain(out)
