"""The peers table per scenario and its verdicts, from the seeds' results
(:mod:`undertow.study.peers`, :mod:`undertow.study.peer_claims`): each cell the mean over the
seeds with its 95 % interval (:mod:`undertow.study.stats`), each estimator that did not run in
every seed named with why.
"""

from __future__ import annotations

from collections import Counter

from .peer_claims import COMPARISONS, METRICS, explain, scenario_verdicts, with_derived
from .peers import ESTIMATORS, GTSAM_PEERS
from .stats import aggregate, cell

AXES = ("x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "yaw_rad", "vx_m_s", "vy_m_s", "vz_m_s")
AXIS_HEADERS = ("x (m)", "y (m)", "z (m)", "roll (rad)", "pitch (rad)", "yaw (rad)", "vx (m/s)",
                "vy (m/s)", "vz (m/s)")  # fmt: skip
ESTIMATOR_LABELS = {
    "proposed+smoother": "proposed + smoother (URTS)",
    "factor-graph": "factor graph (batch, LM)",
    "isam2": "factor graph (iSAM2, online)",
    "inekf": "InEKF",
}


def build_peers(results: list[dict]) -> dict | None:
    """The peers tables' data (JSON-safe): per scenario the aggregated metrics, per estimator
    the seeds it ran in and why not elsewhere, and the verdicts; None if the peers did not run."""
    runs = [r for r in results if r.get("peers")]
    if not runs:
        return None
    runs = with_derived(runs)
    scenarios = list(runs[0]["peers"])
    agg = aggregate([r["peers"] for r in runs])
    out = {"scenarios": scenarios, "seeds": len(runs), "tables": {}}
    for name in scenarios:
        status = {}
        for estimator in _estimators(runs, name):
            entries = [r["peers"][name]["estimators"].get(estimator, {}) for r in runs]
            reasons = Counter(e["status"] for e in entries if "status" in e)
            status[estimator] = {"ran": len(entries) - sum(reasons.values()),
                                 "n": len(entries), "reasons": dict(reasons)}  # fmt: skip
        verdicts = scenario_verdicts(runs, name)
        out["tables"][name] = {
            "duration_s": agg[name]["duration_s"],
            "metrics": agg[name].get("estimators", {}),
            "status": status,
            "verdicts": verdicts,
            "why": {f"{u} vs {p}": explain(verdicts, u, p) for u, p, _ in COMPARISONS},
        }
    return out


def _estimators(runs: list[dict], name: str) -> list[str]:
    seen = {e for r in runs for e in r["peers"][name]["estimators"]}
    return [e for e in ESTIMATORS if e in seen] + sorted(seen - set(ESTIMATORS))


def peers_markdown(t: dict, name: str) -> str:
    """One scenario's peers table, the estimators that did not run, and its verdicts."""
    table = t["tables"][name]
    header = ["estimator", *(f"{h} RMSE" for h in AXIS_HEADERS), "NEES (6 = consistent)",
              "final drift (% of distance)", "CPU s per hour of log"]  # fmt: skip
    rows, notes = [], []
    for estimator, st in table["status"].items():
        label = ESTIMATOR_LABELS.get(estimator, estimator)
        for reason, count in st["reasons"].items():
            notes.append(f"- {label}: {reason} ({count}/{st['n']} seeds)")
        if not st["ran"]:
            continue
        if st["ran"] < st["n"]:
            label += f" ({st['ran']}/{st['n']} seeds)"
        m = table["metrics"][estimator]
        rows.append([label, *(cell(m["rmse"][a], 4) for a in AXES), cell(m["nees_mean"], 2),
                     cell(m.get("final_drift_pct"), 2), cell(m["cpu_s_per_hour"], 1)])  # fmt: skip
    parts = [_md(header, rows)]
    notes = _gtsam_line(notes, table["status"])
    if notes:
        parts.append("\n".join(notes))
    if table["verdicts"]:
        parts += ["Verdicts (difference = peer - undertow; lower is better for every metric):",
                  verdicts_markdown(table)]  # fmt: skip
    return "\n\n".join(parts)


def _gtsam_line(notes: list[str], status: dict) -> list[str]:
    """The gtsam peers' 'not installed' notes folded into one line."""
    missing = [
        e
        for e in GTSAM_PEERS
        if any("gtsam is not installed" in r for r in status.get(e, {}).get("reasons", {}))
    ]
    if not missing:
        return notes
    kept = [n for n in notes if "gtsam is not installed" not in n]
    return [f"- {', '.join(missing)}: not run, gtsam is not installed "
            "(`pip install undertow[peers]`)", *kept]  # fmt: skip


def verdicts_markdown(table: dict) -> str:
    rows = []
    for v in table["verdicts"]:
        label, _, unit = METRICS[v["metric"]]
        digits = 1 if v["metric"] == "cpu_s_per_hour" else 4
        d = v["difference"]
        rows.append([f"{v['ukf']} vs {v['peer']}", f"{label} ({unit})" if unit else label,
                     f"{v['ukf_mean']:.{digits}f}", f"{v['peer_mean']:.{digits}f}",
                     cell(d, digits), f"{v['holds']}/{v['n']}", v["verdict"]])  # fmt: skip
    header = ["comparison", "metric", "undertow", "peer", "difference [95 % CI]",
              "undertow lower in (seeds)", "verdict"]  # fmt: skip
    why = [f"- **{k}**: {w}." for k, w in table["why"].items() if w]
    return _md(header, rows) + ("\n\nWhy:\n\n" + "\n".join(why) if why else "")


def _md(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def peers_section(t: dict | None) -> list[str]:
    """The markdown parts of the peers section (empty if the peers did not run)."""
    if not t:
        return []
    parts = [
        "## Beyond the paper: the field's estimators on the same runs (peers)",
        "The paper's UKF (baseline, proposed, proposed + URTS smoother) beside a factor graph "
        "with IMU preintegration and a DVL factor on GTSAM (batch Levenberg-Marquardt and "
        "iSAM2) and an invariant EKF on SE_2(3), all reading the same log with the proposed "
        "variant's noise (docs/peers.md). The peers also integrate the accelerometer, which "
        "the UKF does not read. Drift: final horizontal error against the ground truth in % of "
        "the distance travelled; CPU: process time of the estimator's call per hour of log.",
    ]
    for name in t["scenarios"]:
        dur = t["tables"][name]["duration_s"].get("mean")
        parts += [f"### Peers: {name} ({dur:.0f} s of log)", peers_markdown(t, name)]
    return parts
