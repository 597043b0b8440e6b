"""The peers table (beyond the paper): the paper's UKF beside the field's strongest estimators on
the same simulated runs, sensors and noise (:mod:`undertow.peers`).

Per scenario of :attr:`PeerSettings.scenarios` (the three carriage wave conditions,
``rock-survey``, ``field-survey``, ``changing-sea-survey``) and per estimator:

- ``baseline``, ``proposed``: the paper's UKF (:func:`undertow.estimation.localizer.localize`);
- ``proposed+smoother``: the proposed UKF followed by the URTS smoother (``--smooth``);
- ``factor-graph`` (batch Levenberg-Marquardt), ``isam2`` (online), ``inekf``: the peers, each
  with the proposed variant's noise (:func:`undertow.peers.run_estimator`).

Every estimator of a scenario reads the same log with the same options (the wave condition the
study measured for it, the study's noise profile and calibration). Each estimator outputs at its
own times (the UKF after every measurement, the factor graph at its keyframes, the InEKF after
each update), so every trajectory is evaluated at the same instants: the DVL's valid reports
(each estimator's last row at that time, after its DVL update; :func:`at_times`). Metrics,
against the ground truth: RMSE per axis and the pose NEES
(:func:`undertow.evaluation.trajectory.trajectory_rmse`),
the horizontal RMSE sqrt(RMSE_x^2 + RMSE_y^2), the final horizontal drift as a percentage of
the distance travelled (:func:`undertow.evaluation.drift.trajectory_drift`, the ground truth as
the reference, no alignment: the estimators start at the true pose), and the CPU time,
``time.process_time()`` around the estimator's call, per hour of log:
cpu_s_per_hour = cpu_s / (duration_s / 3600).

An estimator can be left out (``skip``) or run under a wall-time cap (``time_cap_s``): it then
runs in a child interpreter (:mod:`undertow.study.peer_worker`) that is killed at the cap, and
the table says so. An estimator whose optional dependency is missing (gtsam for the factor
graph) or that raises is recorded with its one-line reason instead of failing the study.
"""

from __future__ import annotations

import importlib.util
import math
import pickle
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util.dask import describe_exception
from ..estimation.characterize import estimate_waves
from ..estimation.localizer import localize
from ..evaluation.drift import ReferenceTrack, trajectory_drift
from ..evaluation.trajectory import trajectory_rmse
from ..sim import load_scenario, simulate
from ..wavetrack import WaveTrack

PEER_SCENARIOS = ("wave-a0.10-f1.00", "wave-a0.10-f0.75", "wave-a0.05-f0.75", "rock-survey",
                  "field-survey", "changing-sea-survey")  # fmt: skip
#: The estimators of the table, in its order; the UKF's three first.
ESTIMATORS = ("baseline", "proposed", "proposed+smoother", "factor-graph", "isam2", "inekf")
UKF_RUNS = ("baseline", "proposed", "proposed+smoother")
#: The peers that need gtsam (the optional extra ``undertow[peers]``).
GTSAM_PEERS = ("factor-graph", "isam2")
#: The batch factor graph's default wall-time cap (s): its Levenberg-Marquardt grows faster than
#: linearly with the log (docs/peers.md, Cost), so a long run is cut rather than hanging the study.
FACTOR_GRAPH_CAP_S = 900.0
#: Seconds of log the in-process estimators are warmed up on (numba compiles on first use).
WARMUP_S = 3.0
#: The child interpreter's start (imports) is not the estimator's: added to the cap.
CHILD_START_S = 60.0


@dataclass(frozen=True)
class PeerSettings:
    """What the peers table runs: its scenarios and estimators, the estimators left out, and the
    wall-time cap (s) of those run in a child interpreter (killed at the cap)."""

    scenarios: tuple[str, ...] = PEER_SCENARIOS
    estimators: tuple[str, ...] = ESTIMATORS
    skip: tuple[str, ...] = ()
    time_cap_s: Mapping[str, float] = field(
        default_factory=lambda: {"factor-graph": FACTOR_GRAPH_CAP_S}
    )


@dataclass(frozen=True)
class PeerRun:
    """One scenario as every estimator reads it: the log, the options of the call (wave,
    profile, calibration, ...) and the duration of the log (s)."""

    name: str
    log: object
    options: dict
    duration_s: float


def gtsam_available() -> bool:
    """Whether gtsam can be imported (without importing it)."""
    return importlib.util.find_spec("gtsam") is not None


def scenario_run(name: str, seed: int, study, art) -> PeerRun:
    """The scenario ``name`` as the rest of the study runs it: a carriage wave condition with
    the condition its Table I measured and the DVL scale left uncorrected (the paper's
    variants); the rock survey as the study's rock survey (its probe's wave); the field and
    changing-sea surveys with the wave from their probe or, for the changing sea, the true
    schedule, extrapolating the noise profile. ``study``: the seed's ``waves`` (condition ->
    (a, f)), ``calibration`` and ``profile``; the simulation is reused from ``art`` if the
    study ran it."""
    sim = art.simulations.get(name)
    if sim is None:
        sim = simulate(load_scenario(name), seed=seed)
        art.simulations[name] = sim
    log = sim.log
    options = {"profile": study["profile"], "calibration": study["calibration"]}
    if name in study["waves"]:
        options.update(wave=study["waves"][name], dvl_scale_factor=1.0)
    elif name.startswith("changing-sea"):
        wave = WaveTrack.from_dict(log.metadata["wave"], source="scenario")
        options.update(wave=wave, extrapolate=True, dvl_scale_factor=1.0)
    else:
        measured = estimate_waves(log.wave_probe)
        wave = "calm" if measured.calm else (measured.amplitude_m, measured.frequency_hz)
        options.update(wave=wave)
        if name != "rock-survey":
            options.update(extrapolate=True, dvl_scale_factor=1.0)
    gt = log.ground_truth
    return PeerRun(name, log, options, float(gt.t[-1] - gt.t[0]))


def run_peers(seed: int, settings: PeerSettings, study: dict, art) -> dict:
    """The peers table's numbers for one seed: per scenario its duration and distance, and per
    estimator its metrics (module doc) or ``{"status": why not}``."""
    out = {}
    warmed = False
    for name in settings.scenarios:
        run = scenario_run(name, seed, study, art)
        if not warmed:
            warm_up(run, settings)
            warmed = True
        entry = {"duration_s": run.duration_s, "estimators": {}}
        for estimator in settings.estimators:
            traj, record = run_one(estimator, run, settings)
            if traj is not None:
                art.peers[(name, estimator)] = thinned(traj)
            entry["estimators"][estimator] = record
        out[name] = entry
    return out


def run_one(estimator: str, run: PeerRun, settings: PeerSettings):
    """(trajectory or None, metrics or ``{"status": ...}``) of one estimator on one run."""
    if estimator in settings.skip:
        return None, {"status": "skipped (settings)"}
    if estimator in GTSAM_PEERS and not gtsam_available():
        return None, {"status": "not run: gtsam is not installed (pip install undertow[peers])"}
    cap = settings.time_cap_s.get(estimator)
    try:
        if cap is not None:
            traj, cpu_s = run_capped(estimator, run, cap)
        else:
            start = time.process_time()
            traj = call_estimator(estimator, run.log, run.options)
            cpu_s = time.process_time() - start
    except CapExceeded as exc:
        return None, {"status": str(exc)}
    except Exception as exc:  # a peer that fails must not lose the table
        return None, {"status": f"failed: {describe_exception(exc)}"}
    times = dvl_times(run.log)
    return traj, estimator_metrics(at_times(traj, times), run.log.ground_truth, cpu_s,
                                   run.duration_s)  # fmt: skip


def dvl_times(log) -> np.ndarray:
    """The times of the log's valid DVL reports (the common evaluation instants)."""
    return np.asarray(log.dvl.t, float)[np.asarray(log.dvl.valid, bool)]


#: A row is at a time when it is within this (s).
TIME_TOLERANCE_S = 1e-6


def at_times(traj, times: np.ndarray):
    """The rows of ``traj`` at ``times``: at each time its last row within
    :data:`TIME_TOLERANCE_S` (a time without a row is left out)."""
    idx = np.searchsorted(traj.t, times + TIME_TOLERANCE_S, side="right") - 1
    ok = (idx >= 0) & (np.abs(traj.t[np.maximum(idx, 0)] - times) <= TIME_TOLERANCE_S)
    idx = np.unique(idx[ok])
    return traj.replace(t=traj.t[idx], x=traj.x[idx], P=traj.P[idx])


def call_estimator(estimator: str, log, options: dict):
    """The trajectory of ``estimator`` (a name of :data:`ESTIMATORS`) on ``log``."""
    if estimator in ("baseline", "proposed"):
        return localize(log, estimator, **options)
    if estimator == "proposed+smoother":
        return localize(log, "proposed", smooth=True, **options)
    from ..peers import run_estimator

    return run_estimator(estimator, log, variant="proposed", **options)


def estimator_metrics(traj, ground_truth, cpu_s: float, duration_s: float) -> dict:
    """RMSE per axis, horizontal RMSE, pose NEES, final drift (% of distance) and CPU per hour
    of log of one trajectory (module doc), plain numbers."""
    errors = trajectory_rmse(traj, ground_truth)
    reference = ReferenceTrack("ground truth", ground_truth.t, ground_truth.position,
                               source="ground truth")  # fmt: skip
    drift = trajectory_drift(traj, reference, align="none")
    out = {
        "rmse": {k: float(v) for k, v in errors.rmse.items()},
        "horizontal_rmse_m": float(math.hypot(errors.rmse["x_m"], errors.rmse["y_m"])),
        "nees_mean": float(errors.nees_mean),
        "final_drift_m": float(drift.final_drift_m),
        "distance_m": float(drift.distance_m),
        "cpu_s": float(cpu_s),
        "cpu_s_per_hour": float(cpu_s / (duration_s / 3600.0)),
        "samples": len(traj),
    }
    if drift.final_drift_percent is not None:
        out["final_drift_pct"] = float(drift.final_drift_percent)
    return out


#: The figures' copy of a trajectory keeps at most this many rows.
FIGURE_ROWS = 1500


def thinned(traj):
    """``traj`` with at most :data:`FIGURE_ROWS` rows, evenly spaced (the last kept), for the
    report's figures (a full-rate UKF trajectory of an 11 min survey is ~200 MB)."""
    n = len(traj)
    if n <= FIGURE_ROWS:
        return traj
    idx = np.unique(np.r_[np.linspace(0, n - 1, FIGURE_ROWS).astype(int), n - 1])
    return traj.replace(t=traj.t[idx], x=traj.x[idx], P=traj.P[idx])


def log_head(log, seconds: float):
    """The first ``seconds`` of ``log`` (every stream cut at t0 + seconds)."""
    t0 = log.time_span[0]
    return log.replace(**{name: stream.select(stream.t <= t0 + seconds)
                          for name, stream in log.streams().items()})  # fmt: skip


def warm_up(run: PeerRun, settings: PeerSettings) -> None:
    """Run every in-process estimator once on the first seconds of ``run`` so that numba's
    compilation is not counted as an estimator's CPU time (failures are left to the real run)."""
    head = log_head(run.log, WARMUP_S)
    for estimator in settings.estimators:
        if estimator in settings.skip or estimator in settings.time_cap_s:
            continue
        if estimator in GTSAM_PEERS and not gtsam_available():
            continue
        try:
            call_estimator(estimator, head, run.options)
        except Exception:  # noqa: S112 - the timed run reports it
            continue


class CapExceeded(RuntimeError):
    """An estimator run in a child interpreter passed its wall-time cap (it was killed)."""


def child_log(log):
    """What a peer reads of ``log``, for the child interpreter: the heavy streams the peers do
    not read (sonar, multibeam, wave probe) dropped and the ground truth cut to its first
    second (the peers take only their start from it)."""
    gt = log.ground_truth
    if gt is not None and len(gt):
        gt = gt.select(gt.t <= gt.t[0] + 1.0)
    return log.replace(sonar=None, multibeam=None, wave_probe=None, ground_truth=gt)


def run_capped(estimator: str, run: PeerRun, cap_s: float):
    """(trajectory, CPU s) of ``estimator`` run in a child interpreter
    (``python -m undertow.study.peer_worker``), killed after ``cap_s`` wall seconds of
    estimation (plus :data:`CHILD_START_S` for its imports): :class:`CapExceeded`. The CPU time
    is the child's own ``process_time`` around the call."""
    if cap_s <= 0:
        raise CapExceeded("skipped (time cap 0 s)")
    with tempfile.TemporaryDirectory(prefix="undertow-peer-") as tmp:
        job, result = Path(tmp) / "job.pkl", Path(tmp) / "result.pkl"
        with open(job, "wb") as f:
            pickle.dump((estimator, child_log(run.log), run.options), f)
        cmd = [sys.executable, "-m", "undertow.study.peer_worker", str(job), str(result)]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True,
                                  timeout=cap_s + CHILD_START_S)  # fmt: skip
        except subprocess.TimeoutExpired:
            raise CapExceeded(f"stopped at the time cap ({cap_s:g} s wall)") from None
        if proc.returncode != 0 or not result.exists():
            last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            raise RuntimeError(f"the child interpreter failed: {last}")
        with open(result, "rb") as f:
            ok, payload, cpu_s = pickle.load(f)
    if not ok:
        raise RuntimeError(payload)
    return payload, cpu_s


def peer_waves(table1: dict, conditions) -> dict:
    """(amplitude, frequency) per carriage wave condition as its Table I measured them."""
    return {c: (table1[c]["amplitude_m"], table1[c]["frequency_hz"]) for c in conditions}


def finite(value) -> bool:
    return value is not None and bool(np.isfinite(value))
