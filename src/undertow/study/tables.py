"""The paper's tables from the study's results, with the paper's values in adjacent columns.

Input: the per-seed result dicts of :func:`undertow.study.pipeline.run_seed`. Every simulated
cell is the mean over seeds with, for more than one seed, its 95 % Student-t interval of the mean
(:mod:`undertow.study.stats`); every "paper" cell comes from :mod:`undertow.study.paper`.
"""

from __future__ import annotations

from . import paper
from .claims import (
    CHANGING_SEA_CLAIMS,
    CLAIMS,
    FIELD_CLAIMS,
    MAP_SCENARIO_CLAIMS,
    TABLE1_CLAIMS,
    Claim,
    sea_applies,
)
from .maps import SCENARIO_FILTERS, SCENARIO_MAP_RUNS
from .peer_tables import build_peers, peers_section
from .pipeline import ROCK_MARGIN_M
from .stats import aggregate, cell, claim_fraction

AXIS_LABELS = {
    "x_m": "x (m)", "y_m": "y (m)", "z_m": "z (m)", "roll_rad": "roll (rad)",
    "pitch_rad": "pitch (rad)", "yaw_rad": "yaw (rad)", "vx_m_s": "vx (m/s)",
    "vy_m_s": "vy (m/s)", "vz_m_s": "vz (m/s)",
}  # fmt: skip


def build_tables(results: list[dict]) -> dict:
    """Aggregated tables (JSON-serializable): table1..table4, claims, seeds."""
    agg = aggregate(results)
    conditions = list(results[0]["localization"])
    scenarios = list(results[0].get("map_scenarios") or {})
    run = list(results[0]["table1"])
    return {
        "seeds": [r["seed"] for r in results],
        "table1_claims": {c.id: _table1_claim(c, results, run) for c in TABLE1_CLAIMS},
        "conditions": conditions,
        "table1": agg["table1"],
        "localization": agg["localization"],
        "mapping": agg["mapping"],
        "rock_survey": agg.get("rock_survey"),
        "calibration": agg["calibration"],
        "claims": {c.id: _claim(c, results, conditions) for c in CLAIMS},
        "field_claims": {c.id: _claim(c, results, conditions) for c in FIELD_CLAIMS},
        "changing_sea": agg.get("changing_sea"),
        "changing_sea_claims": {c.id: _sea_claim(c, results) for c in CHANGING_SEA_CLAIMS},
        "map_scenario_names": scenarios,
        "map_scenarios": agg.get("map_scenarios") if scenarios else None,
        "map_scenario_claims": {
            c.id: _claim(c, results, scenarios) for c in (MAP_SCENARIO_CLAIMS if scenarios else ())
        },
        "peers": build_peers(results),
        "paper": {
            "table1": paper.TABLE_I,
            "table2_3": paper.TABLE_II_III,
            "table4": paper.TABLE_IV,
        },
    }


def _claim_text(claim: Claim) -> dict:
    return {
        "claim": claim.summary,
        "test": claim.test,
        "statement": claim.statement,
        "by_construction": claim.by_construction,
    }


def _claim(claim: Claim, results: list[dict], conditions: list[str]) -> dict:
    """The claim's text, then per condition the seeds where it holds and why (not)."""
    entry, why = _claim_text(claim), {}
    for c in conditions:
        measured = claim.measure(results, c)
        entry[c] = claim_fraction(measured.verdicts)
        why[c] = claim.explain(measured)
    entry["why"] = why
    return entry


def _table1_claim(claim: Claim, results: list[dict], run: list[str]) -> dict:
    """A Table I claim over the seeds; no verdict (n = 0) when its conditions were not run."""
    entry = _claim_text(claim)
    measured = claim.measure(results) if claim.applies(run) else None
    entry["why"] = claim.explain(measured) if measured else None
    entry["all"] = claim_fraction(measured.verdicts if measured else [])
    return entry


def _sea_claim(claim: Claim, results: list[dict]) -> dict:
    """A changing-sea claim over the seeds; no verdict (n = 0) where it does not apply."""
    entry = _claim_text(claim)
    measured = claim.measure(results) if sea_applies(claim, results[0]) else None
    entry["why"] = claim.explain(measured) if measured else None
    entry["all"] = claim_fraction(measured.verdicts if measured else [])
    return entry


def _mean(stat: dict | None, digits: int = 3) -> str:
    """The mean of an aggregated leaf, without its interval ('-' if absent)."""
    return _num(stat.get("mean") if stat else None, digits)


def _num(value, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _md(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def table1_markdown(t: dict) -> str:
    rows = []
    for c in t["conditions"]:
        sim, ref = t["table1"][c], paper.TABLE_I.get(c, {})
        std, extra = sim["dvl_std_m_s"], sim["dvl_extra_std_m_s"]
        std = [std[a] for a in ("vx", "vy", "vz")]
        extra = [extra[a] for a in ("vx", "vy", "vz")]
        ref_std = ref.get("dvl_std_m_s", (None,) * 3)
        rows.append(
            [
                c,
                _num(ref.get("amplitude_m"), 2), cell(sim["amplitude_m"]),
                _num(ref.get("frequency_hz"), 2), cell(sim["frequency_hz"]),
                *(f"{_num(ref_std[i])} / {cell(std[i])} / {cell(extra[i])}" for i in range(3)),
                cell(sim["depth_std_m"]),
            ]
        )  # fmt: skip
    header = [
        "condition", "a paper (m)", "a sim (m)", "f paper (Hz)", "f sim (Hz)",
        "vx std paper / sim total / sim extra (m/s)", "vy std (same)", "vz std (same)",
        "baro depth std sim (m)",
    ]  # fmt: skip
    return _md(header, rows)


def localization_markdown(t: dict, condition: str, variants: tuple[str, ...]) -> str:
    loc = t["localization"][condition]
    header = ["axis"]
    for v in variants:
        header += [f"{v} paper", f"{v} sim"] if v in paper.TABLE_II_III else [f"{v} sim"]
    rows = []
    for axis, label in AXIS_LABELS.items():
        row = [label]
        for v in variants:
            if v in paper.TABLE_II_III:
                row.append(_num(paper.TABLE_II_III[v].get(axis)))
            row.append(cell(loc[v]["rmse"][axis], 4))
        rows.append(row)
    rows.append(["NEES (pose, 6 dof; 6 = consistent)"] + _nees_cells(loc, variants))
    return _md(header, rows)


def _nees_cells(loc: dict, variants) -> list[str]:
    out = []
    for v in variants:
        if v in paper.TABLE_II_III:
            out.append("-")
        out.append(cell(loc[v]["nees_mean"], 2))
    return out


#: The surface metrics' columns of Table IV: (result key, header, digits).
SURFACE_COLUMNS = (
    ("surface_rmse_m", "surface RMSE (m)", 4),
    ("surface_bias_m", "surface bias (m)", 4),
    ("coverage", "coverage", 3),
    ("fscore_5cm", "F 5 cm", 3),
    ("fscore_10cm", "F 10 cm", 3),
    ("fscore_20cm", "F 20 cm", 3),
    ("within_1sigma", "within 1 sigma", 3),
    ("within_2sigma", "within 2 sigma", 3),
)
#: How the tables name each mapper.
MAPPER_NAMES = {"csm": "CSM", "bki": "BKI", "adaptive": "Adaptive BKI", "tpu": "tpu (default)"}


def table4_markdown(t: dict, condition: str) -> str:
    """Table IV in a wave condition: the paper's metrics next to its values, then the surface
    metrics (:mod:`undertow.evaluation.surface`)."""
    return mapping_markdown(t["mapping"][condition])


def mapping_markdown(runs: dict) -> str:
    """Table IV rows from the aggregated metrics of the maps (``runs[method/variant]``): the
    paper's four, then the default mapper's runs where they ran (no paper value: "-")."""
    rows = []
    for method, variant in SCENARIO_MAP_RUNS:
        key = f"{method}/{variant}"
        if key not in runs:
            continue
        sim, ref = runs[key], paper.TABLE_IV.get(key, {})
        rows.append(
            [
                MAPPER_NAMES[method],
                variant,
                _num(ref.get("c2c_mean_m")), cell(sim["c2c_mean_m"], 4),
                str(ref.get("occupied_cells", "-")), cell(sim["occupied_cells"], 0),
                cell(sim["coverage_mean_m"], 4),
                *(cell(sim.get(k), d) for k, _, d in SURFACE_COLUMNS),
            ]
        )  # fmt: skip
    header = [
        "mapping", "filter", "C2C paper (m)", "C2C sim (m)", "cells paper", "cells sim",
        "coverage sim (m, GT->map)", *(h for _, h, _ in SURFACE_COLUMNS),
    ]  # fmt: skip
    return _md(header, rows)


def map_scenario_markdown(t: dict, name: str) -> str:
    """A mapping scenario: its run and floor, the filters' lateral errors, Table IV."""
    r = t["map_scenarios"][name]
    loc = r["localization"]
    facts = (
        f"Run of {_mean(r['duration_s'], 0)} s in waves of measured amplitude "
        f"{_mean(r['wave']['amplitude_m'], 3)} m and frequency "
        f"{_mean(r['wave']['frequency_hz'], 2)} Hz, over a floor of depth std "
        f"{_mean(r['floor']['depth_std_m'], 3)} m and RMS slope "
        f"{_mean(r['floor']['rms_slope'], 3)} in the surveyed area (means over the seeds). "
        "Filter RMSE: "
        + "; ".join(
            f"{v} x {cell(loc[v]['rmse']['x_m'], 4)} m, y {cell(loc[v]['rmse']['y_m'], 4)} m, "
            f"yaw {cell(loc[v]['rmse']['yaw_rad'], 4)} rad"
            for v in SCENARIO_FILTERS
            if v in loc
        )
        + "."
    )
    return facts + "\n\n" + mapping_markdown(r["mapping"])


def rock_survey_markdown(r: dict) -> str:
    rmse = r["trajectory"]["rmse"]
    lines = [
        "Proposed filter RMSE: "
        + ", ".join(
            f"{AXIS_LABELS[a]} {cell(rmse[a], 4)}" for a in ("x_m", "y_m", "z_m", "yaw_rad")
        )
        + f". Maps evaluated over the rock's footprint plus {ROCK_MARGIN_M:g} m:",
        "",
    ]
    rows = [
        [name, cell(r[key]["c2c_mean_m"], 4), cell(r[key]["occupied_cells"], 0)]
        for name, key in (("Adaptive BKI", "adaptive"), (f"BKI (l = {_rock_bki_l():g} m)", "bki"))
    ]
    return "\n".join(lines) + "\n" + _md(["mapping", "C2C sim (m)", "cells sim"], rows)


def _rock_bki_l() -> float:
    """The rock survey maps with the mapping stage's default length scale."""
    from ..mapping.config import MappingConfig

    return MappingConfig().length_scale


def _titled(entry: dict) -> str:
    return f"{entry['claim']} ({entry['test']})"


def table1_claims_markdown(t: dict, key: str = "table1_claims",
                           title: str = "the paper's reading of Table I") -> str:  # fmt: skip
    rows = []
    for entry in t.get(key, {}).values():
        f = entry["all"]
        if f["n"]:
            rows.append([_titled(entry), f"{f['holds']}/{f['n']}", entry["why"]])
    header = [title, "holds in (seeds)", "measured, and why (not)"]
    return _md(header, rows) if rows else ""


CHANGING_SEA_RUNS = ("baseline", "proposed", "proposed+auto", "adaptive-r")


def changing_sea_markdown(t: dict, scenario: str) -> str:
    """Per run: x, y, yaw, vx RMSE and NEES; then the onboard wave estimate's errors."""
    r = t["changing_sea"][scenario]
    runs = [*CHANGING_SEA_RUNS, *(k for k in r["localization"] if k.startswith("fixed "))]
    axes = ("x_m", "y_m", "yaw_rad", "vx_m_s")
    rows = []
    for run in runs:
        loc = r["localization"][run]
        label = {"proposed": "proposed (true schedule)", "proposed+auto": "proposed --wave auto"}
        rows.append([label.get(run, run), *(cell(loc["rmse"][a], 4) for a in axes),
                     cell(loc["nees_mean"], 2)])  # fmt: skip
    header = ["filter", *(f"{AXIS_LABELS[a]} RMSE" for a in axes), "NEES (6 = consistent)"]
    w = r["wave_estimate"]
    if not w.get("windows"):
        est = "The onboard wave estimate has no stationary window to compare."
    else:
        est = (
            f"Onboard wave estimate in the stationary windows ({cell(w['windows'], 0)}): "
            f"amplitude error median {cell(w['amplitude_error_median_pct'], 1)} %, largest "
            f"{cell(w['amplitude_error_max_pct'], 1)} %; frequency error median "
            f"{cell(w['frequency_error_median_pct'], 1)} %, largest "
            f"{cell(w['frequency_error_max_pct'], 1)} %."
        )
    return _md(header, rows) + "\n\n" + est


def claims_markdown(t: dict, key: str = "claims", conditions: list[str] | None = None) -> str:
    """Claim | holds in k/n seeds per condition | by construction; then, where a claim does not
    hold in every seed of a condition, why (from the measured values). ``conditions``: the
    columns (default: the wave conditions)."""
    conditions = t["conditions"] if conditions is None else conditions
    rows, why_not = [], []
    for entry in t.get(key, {}).values():
        row = [_titled(entry)]
        for c in conditions:
            f = entry[c]
            row.append(f"{f['holds']}/{f['n']}" if f["n"] else "n/a")
            if f["holds"] < f["n"]:
                counts = f"{f['holds']}/{f['n']}"
                why_not.append(f"- {entry['claim']}, {c} ({counts}): {entry['why'][c]}")
        row.append(entry["by_construction"] or "")
        rows.append(row)
    header = ["claim", *(f"holds in (seeds) {c}" for c in conditions), "by construction"]
    table = _md(header, rows)
    if not why_not:
        return table
    return (
        table + "\n\nWhy not, where a claim does not hold in every seed:\n\n" + "\n".join(why_not)
    )


def render_markdown(t: dict) -> str:
    """All tables as one markdown document."""
    n = len(t["seeds"])
    seeds = f"{n} seed{'s' if n > 1 else ''} ({', '.join(map(str, t['seeds']))})"
    parts = [
        "# undertow: the paper's tables, simulated",
        f"Simulated values: mean over {seeds}"
        + (", with the 95 % confidence interval of the mean in brackets." if n > 1 else ".")
        + " Paper values are the paper's own (labelled 'paper'); it does not say which wave "
        "condition its Tables II-IV were measured in, so they are shown next to each.",
        "## Table I: wave characterization",
        "DVL std per axis in the DVL frame about the true motion at cruise speed; 'extra' is "
        "over the calm run (what the filter adds).",
        table1_markdown(t),
        table1_claims_markdown(t),
    ]
    for c in t["conditions"]:
        parts += [
            f"## Table II: RMSE, baseline vs proposed ({c})",
            localization_markdown(t, c, ("baseline", "proposed", "proposed+scale")),
            f"## Table III: ablation ({c})",
            localization_markdown(t, c, ("be", "an", "proposed")),
            f"## Table IV: mapping ({c})",
            table4_markdown(t, c),
            f"## Beyond the paper: no wave probe ({c})",
            "The proposed filter with the probe's condition, with the condition estimated from "
            "the run's own sensors (`--wave auto`), the innovation-adaptive peer baseline "
            "`adaptive-r` (no wave model) and the baseline.",
            localization_markdown(t, c, ("baseline", "proposed", "proposed+auto", "adaptive-r")),
        ]
    if t.get("rock_survey"):
        parts += [
            "## Rock survey (free vehicle in waves; the paper shows it only as a figure)",
            rock_survey_markdown(t["rock_survey"]),
        ]
    for scenario in t.get("changing_sea") or {}:
        parts += [
            f"## Beyond the paper: a changing sea ({scenario})",
            "The sea state changes during the run (the scenario's schedule). The proposed "
            "filter with the true schedule, with `--wave auto`, and with each fixed condition "
            "for the whole run; `adaptive-r` and the baseline.",
            changing_sea_markdown(t, scenario),
        ]
    for name in t.get("map_scenario_names") or []:
        parts += [
            f"## Table IV on a rough floor: {name} (beyond the paper)",
            map_scenario_markdown(t, name),
        ]
    parts += peers_section(t.get("peers"))
    parts += ["## The paper's claims in simulation", claims_markdown(t)]
    if t.get("map_scenario_claims"):
        parts += [
            "## The paper's mapping claims on the mapping scenarios",
            "Each accuracy claim read by the paper's C2C, by the surface RMSE and by the F-score "
            "at 10 cm (the map's implied seafloor against the true floor).",
            claims_markdown(t, "map_scenario_claims", t["map_scenario_names"]),
        ]
    if t.get("field_claims"):
        parts += ["## Beyond the paper: claims for the field", claims_markdown(t, "field_claims"),
                  table1_claims_markdown(t, "changing_sea_claims", "a changing sea")]  # fmt: skip
    return "\n\n".join(parts) + "\n"
