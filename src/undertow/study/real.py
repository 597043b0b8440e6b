"""The peers on a real recording, which has no ground truth: every estimator of the peers table
(:mod:`undertow.study.peers`) on the log as ``undertow localize --config`` reads it, judged by

- its agreement with the DVL's own dead reckoning (:func:`undertow.evaluation.drift.
  trajectory_drift` with ``--reference dvl-dr``: the reference translated to agree at the first
  common time; final drift in m and in % of the distance travelled, and its growth). The A50's
  dead reckoning integrates the same DVL velocities with the A50's own attitude: agreement, not
  accuracy;
- the innovations' consistency where the estimator has innovations: the UKF's NIS mean per
  sensor against its dimension (:mod:`undertow.estimation.consistency`, with its verdict), the
  InEKF's mean NIS per update kind (DVL 3, depth 1, attitude 3); the factor graphs have none
  (their residuals are not innovations): the batch graph's final error is reported instead.

Every in-process estimator is first run on the log's first seconds (numba's compilation is not
an estimator's CPU time).

The peers need the accelerometer (IMU preintegration, the InEKF's propagation): a log without
``imu.linear_acceleration`` records them as not run, with that reason.

    >>> from undertow.study.real import real_peers, real_markdown        # doctest: +SKIP
    >>> print(real_markdown(real_peers("SO_bag", "robot.yaml")))          # doctest: +SKIP
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from .._util.dask import describe_exception
from ..evaluation.drift import reference_track, trajectory_drift
from ..io import read_log
from ..settings import Settings
from .peer_tables import ESTIMATOR_LABELS
from .peers import (
    ESTIMATORS,
    GTSAM_PEERS,
    PeerRun,
    PeerSettings,
    call_estimator,
    gtsam_available,
    warm_up,
)

#: The degrees of freedom of the InEKF's update kinds (its mean NIS's expected value).
INEKF_DOF = {"dvl": 3, "depth": 1, "attitude": 3}


def load_real_log(path: str | Path, settings: str | Path | Settings | None = None):
    """The log at ``path`` read as ``undertow localize --config settings`` reads it, and the
    settings' localizer fields."""
    if not isinstance(settings, Settings):
        settings = Settings.from_yaml(settings)
    log = read_log(path, topics=settings.topics, options=settings.log)
    return settings.apply_mounting(log), settings.localizer_params()


def has_accelerometer(log) -> bool:
    acc = getattr(log.imu, "linear_acceleration", None) if log.imu is not None else None
    return acc is not None and len(acc) > 0 and bool(np.isfinite(acc).any())


def real_peers(path: str | Path, settings: str | Path | Settings | None = None,
               estimators: tuple[str, ...] = ESTIMATORS) -> dict:  # fmt: skip
    """Every estimator on the recording at ``path`` (module doc): per estimator its drift
    against the DVL's dead reckoning, its innovations' consistency and CPU, or its reason for
    not running."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log, params = load_real_log(path, settings)
    t0, t1 = log.time_span
    out = {
        "source": str(path),
        "duration_s": float(t1 - t0),
        "accelerometer": has_accelerometer(log),
        "reading_warnings": sorted({str(w.message).splitlines()[0] for w in caught}),
        "estimators": {},
    }
    reference = reference_track(log, "dvl-dr")
    run = PeerRun(str(path), log, dict(params), out["duration_s"])
    runnable = tuple(e for e in estimators if e in ESTIMATORS[:3] or out["accelerometer"])
    with warnings.catch_warnings():  # numba compiles on first use: not an estimator's CPU
        warnings.simplefilter("ignore")
        warm_up(run, PeerSettings(estimators=runnable, time_cap_s={}))
    for estimator in estimators:
        out["estimators"][estimator] = _one(estimator, log, params, reference, out)
    return out


def _one(estimator: str, log, params: dict, reference, out: dict) -> dict:
    if estimator not in ("baseline", "proposed", "proposed+smoother"):
        if not out["accelerometer"]:
            return {"status": "not run: the log has no accelerometer (imu.linear_acceleration)"}
        if estimator in GTSAM_PEERS and not gtsam_available():
            return {"status": "not run: gtsam is not installed (pip install undertow[peers])"}
    start = time.process_time()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            traj = call_estimator(estimator, log, dict(params))
    except Exception as exc:  # reported in its row
        return {"status": f"failed: {describe_exception(exc)}"}
    cpu_s = time.process_time() - start
    drift = trajectory_drift(traj, reference)
    return {
        "samples": len(traj),
        "cpu_s": cpu_s,
        "cpu_s_per_hour": cpu_s / (out["duration_s"] / 3600.0),
        "distance_m": drift.distance_m,
        "final_drift_m": drift.final_drift_m,
        "final_drift_pct": drift.final_drift_percent,
        "growth_pct": drift.growth_percent,
        "consistency": consistency(traj.metadata),
    }


def consistency(meta: dict) -> dict:
    """sensor -> {"nis_mean", "dof", "verdict"} from a trajectory's metadata (the UKF's
    consistency report, the InEKF's NIS means); ``{"final_graph_error": e}`` for a factor
    graph; {} when there is neither."""
    if "consistency" in meta:
        sensors = meta["consistency"].get("sensors", {})
        return {name: {"nis_mean": s.get("nis_mean"), "dof": s.get("dof"),
                       "verdict": s.get("verdict")} for name, s in sensors.items()}  # fmt: skip
    if "inekf" in meta:
        inekf = meta["inekf"]
        return {name: {"nis_mean": inekf.get(f"{name}_mean_nis"), "dof": dof, "verdict": None}
                for name, dof in INEKF_DOF.items()}  # fmt: skip
    if "keyframes" in meta:
        return {"final_graph_error": meta.get("final_error")}
    return {}


def _num(value, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def real_markdown(result: dict) -> str:
    """The real recording's table: per estimator its drift against the DVL's dead reckoning,
    CPU and innovation consistency, then the estimators that did not run and why."""
    header = ["estimator", "final drift vs DVL DR (m)", "final drift (% of distance)",
              "growth (% of distance)", "CPU s per hour of log",
              "innovation consistency: NIS mean / dimension"]  # fmt: skip
    rows, notes = [], []
    for estimator, r in result["estimators"].items():
        label = ESTIMATOR_LABELS.get(estimator, estimator)
        if "status" in r:
            notes.append(f"- {label}: {r['status']}")
            continue
        rows.append([label, _num(r["final_drift_m"], 2), _num(r["final_drift_pct"], 2),
                     _num(r["growth_pct"], 2), _num(r["cpu_s_per_hour"], 1),
                     _consistency_text(r["consistency"])])  # fmt: skip
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    text = "\n".join(lines)
    return text + ("\n\n" + "\n".join(notes) if notes else "")


def _consistency_text(c: dict) -> str:
    if "final_graph_error" in c:
        error = c["final_graph_error"]
        if error is None:
            return "none (a factor graph has no innovations)"
        return f"none (a factor graph has no innovations; final graph error {error:.1f})"
    parts = []
    for name, s in c.items():
        if s.get("nis_mean") is None:
            continue
        verdict = f" ({s['verdict']})" if s.get("verdict") else ""
        parts.append(f"{name} {s['nis_mean']:.2f}/{s['dof']}{verdict}")
    return ", ".join(parts) or "-"
