"""The peers table's verdicts: undertow's UKF against each peer, per scenario and metric, from
the measured values (:mod:`undertow.study.claim_model`'s quantities and claims).

Three comparisons, each of like with like (docs/peers.md):

- ``proposed`` (online UKF) against ``isam2`` (online factor graph);
- ``proposed+smoother`` (UKF + URTS) against ``factor-graph`` (batch Levenberg-Marquardt);
- ``proposed`` against ``inekf`` (the invariant EKF, online).

Per metric (horizontal RMSE, yaw RMSE, vx RMSE, NEES deviation abs(NEES / 6 - 1), final drift in %
of distance, CPU per hour of log; lower is better for all) the claim "undertow < peer" is read
per seed, and the per-seed difference d = peer - undertow is summarized by its mean and 95 %
Student-t interval (:func:`undertow.study.stats.summarize`, paired over the seeds where both
ran). Verdict: *undertow ahead* when the interval lies above 0, *peer ahead* when below,
*tie* when it contains 0 (with one seed there is no interval: the sign, labelled so).
The explanation names the metric whose difference is largest relative to the better value and
the modelling difference that acts on it (:data:`CAUSES`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .claim_model import CONDITION, LESS, Claim, Measured, Quantity
from .stats import summarize

#: (undertow's run, the peer, what they both are)
COMPARISONS = (
    ("proposed", "isam2", "online estimates"),
    ("proposed+smoother", "factor-graph", "smoothers (the whole log)"),
    ("proposed", "inekf", "online filters"),
)
#: metric key -> (label, path below the estimator, unit)
METRICS = {
    "horizontal_rmse_m": ("horizontal RMSE", ("horizontal_rmse_m",), "m"),
    "yaw_rad": ("yaw RMSE", ("rmse", "yaw_rad"), "rad"),
    "vx_m_s": ("vx RMSE", ("rmse", "vx_m_s"), "m/s"),
    "nees_deviation": ("NEES deviation from 6 (abs(NEES/6 - 1))", ("nees_deviation",), ""),
    "final_drift_pct": ("final drift", ("final_drift_pct",), "% of distance"),
    "cpu_s_per_hour": ("CPU", ("cpu_s_per_hour",), "s per hour of log"),
}
#: The accuracy metrics the explanation chooses from (CPU is explained on its own).
ACCURACY = ("horizontal_rmse_m", "yaw_rad", "vx_m_s", "nees_deviation", "final_drift_pct")
#: The modelling difference that acts on a metric, per peer (docs/peers.md).
CAUSES = {
    ("isam2", "horizontal_rmse_m"): "position is the integral of the velocity: between DVL "
    "reports the graph propagates it with the accelerometer (IMU preintegration), the UKF with "
    "its constant-velocity model; both share the DVL's uncorrected scale factor (no estimator "
    "has a scale state), which sets most of the along-track error",
    ("isam2", "yaw_rad"): "heading: both estimate the DR heading bias as a random walk; the "
    "graph relinearizes its past keyframes at each update where the UKF linearizes once",
    ("isam2", "vx_m_s"): "velocity: the graph's is constrained by the accelerometer between "
    "DVL reports (the waves' orbital accelerations are measured), the UKF's by its "
    "constant-velocity process noise",
    ("isam2", "nees_deviation"): "covariance: iSAM2's marginals come from a linearization with "
    "IMU preintegration noise; the UKF's from sigma points with its process noise; neither "
    "models the DVL scale error, which dominates the position NEES",
    ("isam2", "final_drift_pct"): "drift: the along-track scale error is shared; the "
    "difference is the heading (DR bias) and the velocity propagation between DVL reports",
    ("inekf", "horizontal_rmse_m"): "position: the InEKF integrates the accelerometer, the UKF "
    "a constant-velocity model; both read the same DVL with the same uncorrected scale",
    ("inekf", "yaw_rad"): "heading: the UKF estimates the DR heading bias as a random walk, the "
    "InEKF holds it at its calibrated value",
    ("inekf", "vx_m_s"): "velocity: the InEKF's is the accelerometer's integral between DVL "
    "updates, the UKF's a constant-velocity prediction",
    ("inekf", "nees_deviation"): "covariance: the InEKF's right-invariant error makes its "
    "covariance independent of the estimate, but the held DR bias (variance not grown) makes "
    "its heading variance optimistic; the UKF grows the DR bias's",
    ("inekf", "final_drift_pct"): "drift: the heading (the InEKF holds the DR bias, the UKF "
    "estimates it) and the velocity between DVL updates (accelerometer vs constant velocity)",
}
CPU_CAUSES = {
    "isam2": "iSAM2 relinearizes and re-solves part of its Bayes tree at every keyframe, in "
    "GTSAM through Python calls per factor; the UKF is one compiled (numba) sigma-point update "
    "per measurement",
    "factor-graph": "the batch graph re-solves the whole log at every Levenberg-Marquardt "
    "iteration and computes every keyframe's marginal; the URTS smoother is one backward pass "
    "over the UKF's states",
    "inekf": "both are compiled (numba) Kalman filters of similar state size; the InEKF "
    "propagates every IMU sample with the accelerometer",
}


def quantity(scenario_key: str, estimator: str, metric: str) -> Quantity:
    """``metric`` of ``estimator`` in the peers table of the claim's scenario."""
    label, path, unit = METRICS[metric]
    return Quantity(f"{label} of {estimator}", ("peers", scenario_key, "estimators", estimator,
                                                 *path), unit)  # fmt: skip


def with_derived(results: list[dict]) -> list[dict]:
    """The seeds' results with each peers entry's ``nees_deviation`` = abs(NEES / 6 - 1)
    added."""
    for result in results:
        for entry in (result.get("peers") or {}).values():
            for metrics in entry["estimators"].values():
                if "nees_mean" in metrics and "nees_deviation" not in metrics:
                    metrics["nees_deviation"] = abs(metrics["nees_mean"] / 6.0 - 1.0)
    return results


def peer_claim(ukf: str, peer: str, metric: str) -> Claim:
    """The claim "``ukf``'s ``metric`` < ``peer``'s" (undertow ahead), in any scenario."""
    label = METRICS[metric][0]
    return Claim(
        f"peers:{ukf}<{peer}:{metric}",
        f"{ukf} has a lower {label} than {peer}",
        "beyond the paper: the field's estimators on the same runs",
        (quantity(CONDITION, ukf, metric),),
        LESS,
        (quantity(CONDITION, peer, metric),),
        lambda m: m.compared(),
    )


@dataclass(frozen=True)
class Verdict:
    """One comparison on one metric in one scenario (module doc)."""

    ukf: str
    peer: str
    metric: str
    ukf_mean: float
    peer_mean: float
    difference: dict  # summarize(peer - ukf)
    holds: int  # seeds where undertow is lower
    n: int
    verdict: str

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def _both_ran(results: list[dict], scenario: str, ukf: str, peer: str, metric: str) -> list:
    path = METRICS[metric][1]

    def has(r, est):
        node = ((r.get("peers") or {}).get(scenario) or {}).get("estimators", {}).get(est, {})
        for key in path:
            node = node.get(key) if isinstance(node, dict) else None
        return node is not None and math.isfinite(node)

    return [r for r in results if has(r, ukf) and has(r, peer)]


def verdict(results: list[dict], scenario: str, ukf: str, peer: str, metric: str):
    """The :class:`Verdict` of ``ukf`` against ``peer`` on ``metric`` in ``scenario``, over the
    seeds where both ran (None if none)."""
    both = _both_ran(results, scenario, ukf, peer, metric)
    if not both:
        return None
    claim = peer_claim(ukf, peer, metric)
    measured: Measured = claim.measure(both, scenario)
    u, p = claim.left[0], claim.right[0]
    diffs = [p.read(r, scenario, claim.id) - u.read(r, scenario, claim.id) for r in both]
    d = summarize(diffs)
    if d["n"] == 1:
        word = ("undertow ahead" if d["mean"] > 0 else "peer ahead" if d["mean"] < 0
                else "tie") + " (1 seed, no interval)"  # fmt: skip
    elif d["ci95_low"] is not None and d["ci95_low"] > 0:
        word = "undertow ahead"
    elif d["ci95_high"] is not None and d["ci95_high"] < 0:
        word = "peer ahead"
    else:
        word = "tie (within the interval)"
    return Verdict(ukf, peer, metric, measured[u], measured[p], d, measured.holds, measured.n,
                   word)  # fmt: skip


def scenario_verdicts(results: list[dict], scenario: str) -> list[dict]:
    """Every comparison's verdict on every metric in ``scenario`` (plain dicts)."""
    out = []
    for ukf, peer, _ in COMPARISONS:
        for metric in METRICS:
            v = verdict(results, scenario, ukf, peer, metric)
            if v is not None:
                out.append(v.to_dict())
    return out


def explain(verdicts: list[dict], ukf: str, peer: str) -> str | None:
    """Why, for one comparison in one scenario: where each side is ahead (the metrics), the one
    with the largest relative difference, and the modelling difference acting on it."""
    rows = [v for v in verdicts if v["ukf"] == ukf and v["peer"] == peer]
    if not rows:
        return None
    ahead = [v for v in rows if v["metric"] in ACCURACY and not v["verdict"].startswith("tie")]
    parts = []
    for side in ("undertow ahead", "peer ahead"):
        names = [METRICS[v["metric"]][0] for v in ahead if v["verdict"].startswith(side)]
        if names:
            parts.append(f"{side.replace('peer', peer).replace('undertow', ukf)} on "
                         f"{', '.join(names)}")  # fmt: skip
    if not parts:
        parts.append(f"{ukf} and {peer} tie on every accuracy metric within the interval")
    if ahead:
        top = max(ahead, key=_relative_gap)
        key = "isam2" if peer == "factor-graph" else peer
        gap = 100 * _relative_gap(top)
        parts.append(f"largest gap: {METRICS[top['metric']][0]} ({gap:.0f} % of the better "
                     f"value); {CAUSES.get((key, top['metric']), '')}")  # fmt: skip
    cpu = next((v for v in rows if v["metric"] == "cpu_s_per_hour"), None)
    if cpu is not None and cpu["ukf_mean"] > 0:
        parts.append(f"CPU: {peer} uses {cpu['peer_mean'] / cpu['ukf_mean']:.1f} times {ukf}'s "
                     f"({CPU_CAUSES.get(peer, '')})")  # fmt: skip
    return "; ".join(parts)


def _relative_gap(v: dict) -> float:
    better = min(abs(v["ukf_mean"]), abs(v["peer_mean"]))
    return abs(v["peer_mean"] - v["ukf_mean"]) / max(better, 1e-12)
