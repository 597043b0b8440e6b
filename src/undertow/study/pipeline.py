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
5. map with CSM on the baseline trajectory and CSM, BKI (l = 0.15 m) and adaptive BKI on the
   proposed one (Table IV); evaluate against the ground truth.

Returns plain, JSON-serializable numbers; :func:`run_seed_with_artifacts` also returns the
in-memory objects the figures need.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._util.plain import to_plain
from ..estimation.calibration import calibrate
from ..estimation.characterize import characterize, estimate_waves
from ..estimation.run import localize
from ..evaluation.cloud import evaluate_map
from ..evaluation.trajectory import trajectory_rmse
from ..mapping.config import MappingConfig
from ..mapping.run import map_log
from ..sim import load_scenario, simulate

WAVE_CONDITIONS = ("wave-a0.10-f1.00", "wave-a0.10-f0.75", "wave-a0.05-f0.75")
VARIANTS = ("baseline", "be", "an", "proposed")
MAP_RUNS = (("csm", "baseline"), ("csm", "proposed"), ("bki", "proposed"), ("adaptive", "proposed"))


@dataclass(frozen=True)
class StudySettings:
    """What the study runs (defaults: the paper's experiments)."""

    conditions: tuple[str, ...] = WAVE_CONDITIONS
    calm: str = "calm"
    rock_survey: str | None = "rock-survey"
    bki_length_scale: float = 0.15


@dataclass
class Artifacts:
    """In-memory results of one seed for figures and the report (not serialized)."""

    simulations: dict = field(default_factory=dict)
    trajectories: dict = field(default_factory=dict)  # (condition, variant) -> Trajectory
    maps: dict = field(default_factory=dict)  # (condition, "method/variant") -> OccupancyMap


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
        for variant in (*VARIANTS, "proposed+scale"):
            base = variant.split("+")[0]
            params = {} if variant.endswith("+scale") else {"dvl_scale_factor": 1.0}
            traj = localize(
                log, base, profile=char.profile, wave=wave, calibration=calibration, **params
            )
            art.trajectories[(name, variant)] = traj
            loc[variant] = _trajectory_metrics(traj, log.ground_truth)
        results["localization"][name] = loc
        results["mapping"][name] = _mapping(name, log, art, settings)
    if settings.rock_survey:
        results["rock_survey"] = _rock_survey(
            settings.rock_survey, seed, calibration, char.profile, art
        )
    results["claims"] = evaluate_claims(results)
    results["claims_table1"] = evaluate_table1_claims(results["table1"])
    return results, art


def _trajectory_metrics(traj, ground_truth) -> dict:
    errors = trajectory_rmse(traj, ground_truth)
    std = np.sqrt(np.einsum("nii->ni", traj.P[:, :9, :9]))
    return {
        "rmse": errors.rmse,
        "nees_mean": errors.nees_mean,
        "nees_fraction_in_95": errors.nees_fraction_in_95,
        "mean_std": {
            "x_m": float(std[:, 0].mean()),
            "y_m": float(std[:, 1].mean()),
            "yaw_rad": float(std[:, 5].mean()),
            "vx_m_s": float(std[:, 6].mean()),
        },
    }


def _mapping(name: str, log, art: Artifacts, settings: StudySettings) -> dict:
    out = {}
    cloud = art.simulations[name].floor_cloud
    for method, variant in MAP_RUNS:
        cfg = MappingConfig(method=method, length_scale=settings.bki_length_scale)
        result = map_log(log, art.trajectories[(name, variant)], cfg)
        key = f"{method}/{variant}"
        art.maps[(name, key)] = result.map
        evaluation = evaluate_map(result.map.points(0.5), cloud, resolution=result.map.resolution)
        out[key] = to_plain(evaluation.to_dict())
    return out


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
    margin = 0.5
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


def _table1_row(row: dict) -> dict:
    """Scalars, with per-axis values as {vx, vy, vz} (aggregation works on named leaves)."""
    out = {k: row[k] for k in ("amplitude_m", "frequency_hz", "depth_std_m")}
    for key in ("dvl_std_m_s", "dvl_extra_std_m_s"):
        out[key] = dict(zip(("vx", "vy", "vz"), row[key], strict=True))
    return to_plain(out)


#: The paper's qualitative claims, as predicates over one condition's results.
CLAIMS = {
    "bias_estimation_reduces_yaw_error": (
        "bias estimation removes the heading drift (yaw RMSE: be < baseline)",
        lambda c: (
            c["localization"]["be"]["rmse"]["yaw_rad"]
            < c["localization"]["baseline"]["rmse"]["yaw_rad"]
        ),
    ),
    "bias_estimation_reduces_y_error": (
        "bias estimation removes the y error (y RMSE: be < baseline)",
        lambda c: (
            c["localization"]["be"]["rmse"]["y_m"] < c["localization"]["baseline"]["rmse"]["y_m"]
        ),
    ),
    "added_noise_reduces_velocity_error": (
        "added noise improves the velocity error (vx RMSE: an < baseline)",
        lambda c: (
            c["localization"]["an"]["rmse"]["vx_m_s"]
            < c["localization"]["baseline"]["rmse"]["vx_m_s"]
        ),
    ),
    "added_noise_widens_covariance": (
        "added noise widens the covariance in waves (mean vx std: an > baseline)",
        lambda c: (
            c["localization"]["an"]["mean_std"]["vx_m_s"]
            > c["localization"]["baseline"]["mean_std"]["vx_m_s"]
        ),
    ),
    "x_error_not_removed_by_filter": (
        "the x error (DVL along-track offset) stays: proposed within 10 % of baseline",
        lambda c: (
            abs(
                c["localization"]["proposed"]["rmse"]["x_m"]
                - c["localization"]["baseline"]["rmse"]["x_m"]
            )
            < 0.1 * c["localization"]["baseline"]["rmse"]["x_m"]
        ),
    ),
    "proposed_filter_improves_csm_map": (
        "the proposed filter improves the CSM map (C2C: csm/proposed < csm/baseline)",
        lambda c: (
            c["mapping"]["csm/proposed"]["c2c_mean_m"] < c["mapping"]["csm/baseline"]["c2c_mean_m"]
        ),
    ),
    "adaptive_bki_most_accurate": (
        "adaptive BKI is the most accurate map (lowest C2C of csm, bki, adaptive)",
        lambda c: (
            c["mapping"]["adaptive/proposed"]["c2c_mean_m"]
            < min(
                c["mapping"]["bki/proposed"]["c2c_mean_m"],
                c["mapping"]["csm/proposed"]["c2c_mean_m"],
            )
        ),
    ),
    "bki_denser_than_csm": (
        "both BKI maps are denser than CSM (occupied cells)",
        lambda c: (
            min(
                c["mapping"]["bki/proposed"]["occupied_cells"],
                c["mapping"]["adaptive/proposed"]["occupied_cells"],
            )
            > c["mapping"]["csm/proposed"]["occupied_cells"]
        ),
    ),
    "adaptive_fewer_cells_than_bki": (
        "adaptive BKI has fewer occupied cells than BKI",
        lambda c: (
            c["mapping"]["adaptive/proposed"]["occupied_cells"]
            < c["mapping"]["bki/proposed"]["occupied_cells"]
        ),
    ),
    "adaptive_proposed_more_accurate_than_csm_baseline": (
        "Table IV headline: adaptive BKI with the proposed filter is more accurate than CSM with "
        "the baseline filter (C2C: adaptive/proposed < csm/baseline)",
        lambda c: (
            c["mapping"]["adaptive/proposed"]["c2c_mean_m"]
            < c["mapping"]["csm/baseline"]["c2c_mean_m"]
        ),
    ),
    "adaptive_proposed_denser_than_csm_baseline": (
        "Table IV headline: adaptive BKI with the proposed filter is denser than CSM with the "
        "baseline filter (occupied cells)",
        lambda c: (
            c["mapping"]["adaptive/proposed"]["occupied_cells"]
            > c["mapping"]["csm/baseline"]["occupied_cells"]
        ),
    ),
    "scale_calibration_removes_x_error": (
        "beyond the paper: calibrating the DVL scale factor removes most of the x error",
        lambda c: (
            c["localization"]["proposed+scale"]["rmse"]["x_m"]
            < 0.5 * c["localization"]["proposed"]["rmse"]["x_m"]
        ),
    ),
}


#: What explains a claim failing in the simulated basin (shown only where it does not hold in
#: every seed): mechanisms of the simulator and the metric, not numbers.
WHY_NOT = {
    "bias_estimation_reduces_yaw_error": "the DR drift mu_b comes from the calm run's "
    "calibration; a drift that differs from it is absorbed only slowly by the bias random walk",
    "bias_estimation_reduces_y_error": "see the yaw claim: y error follows the heading error",
    "added_noise_reduces_velocity_error": "where the wave noise at the DVL's depth is small, the "
    "added variance is small and its effect is within the seed-to-seed spread",
    "proposed_filter_improves_csm_map": "the simulated floor is flat: a lateral pose error moves "
    "map points along the floor, not away from it, and the barometer keeps the depth error at "
    "millimetres, so C2C cannot see the baseline's y and yaw drift (the paper's basin scan has "
    "walls and slopes that can)",
    "adaptive_proposed_more_accurate_than_csm_baseline": "neither half of the paper's gain "
    "can show here: the simulated floor is flat, so the baseline's lateral (y, yaw) error moves "
    "CSM points along the floor, not away from it (see the CSM claim), and C2C is quantized by "
    "the 0.1 m grid (the floor lies on a cell boundary, every occupied cell centre is 0.05 m "
    "from it), so both maps sit at about 0.05 m and differ by fractions of a millimetre",
    "adaptive_bki_most_accurate": "C2C is quantized by the 0.1 m grid (the floor lies on a cell "
    "boundary, cell centres are 0.05 m from it), so CSM and adaptive BKI differ by fractions of "
    "a millimetre and sampling noise decides",
}


#: The paper's reading of its Table I (section IV-B), as predicates over the simulated Table I;
#: a claim whose conditions were not run is not evaluable (KeyError).
TABLE1_CLAIMS = {
    "shorter_waves_more_dvl_noise": (
        "shorter waves give larger DVL noise (vx std: f = 1.00 Hz > f = 0.75 Hz at a = 0.10 m)",
        lambda t: (
            t["wave-a0.10-f1.00"]["dvl_std_m_s"]["vx"] > t["wave-a0.10-f0.75"]["dvl_std_m_s"]["vx"]
        ),
        "the simulator's wave noise scales with the orbital velocity at the DVL's depth (an "
        "assumption, coefficient 1), which for the same amplitude is larger for the longer "
        "0.75 Hz waves because they decay less with depth (linear theory); the paper explains "
        "its opposite finding by shorter waves being faster, but by the dispersion relation "
        "the 1.00 Hz waves travel at 1.56 m/s and the 0.75 Hz waves at 2.08 m/s",
    ),
    "smaller_amplitude_less_dvl_noise": (
        "smaller waves give smaller DVL noise (vx std: a = 0.05 m < a = 0.10 m at 0.75 Hz)",
        lambda t: (
            t["wave-a0.05-f0.75"]["dvl_std_m_s"]["vx"] < t["wave-a0.10-f0.75"]["dvl_std_m_s"]["vx"]
        ),
        None,
    ),
}


def evaluate_table1_claims(table1: dict) -> dict:
    """{claim: bool} for one seed (claims whose conditions were not run are left out)."""
    out = {}
    for key, (_, pred, _) in TABLE1_CLAIMS.items():
        try:
            out[key] = bool(pred(table1))
        except KeyError:
            continue
    return out


def condition_view(results: dict, condition: str) -> dict:
    """One condition's localization and mapping results (what claim predicates read)."""
    return {
        "localization": results["localization"][condition],
        "mapping": results["mapping"][condition],
    }


def evaluate_claims(results: dict) -> dict:
    """{claim: {condition: bool}} for one seed."""
    return {
        key: {c: bool(pred(condition_view(results, c))) for c in results["localization"]}
        for key, (_, pred) in CLAIMS.items()
    }
