"""The paper's tables from the study's results, with the paper's values in adjacent columns.

Input: the per-seed result dicts of :func:`undertow.study.pipeline.run_seed`. Every simulated
cell is the mean over seeds with, for more than one seed, its 95 % Student-t interval of the mean
(:mod:`undertow.study.stats`); every "paper" cell comes from :mod:`undertow.study.paper`.
"""

from __future__ import annotations

from . import paper
from .pipeline import CLAIMS, MAP_RUNS, TABLE1_CLAIMS, WHY_NOT
from .stats import aggregate, claim_fraction

AXIS_LABELS = {
    "x_m": "x (m)", "y_m": "y (m)", "z_m": "z (m)", "roll_rad": "roll (rad)",
    "pitch_rad": "pitch (rad)", "yaw_rad": "yaw (rad)", "vx_m_s": "vx (m/s)",
    "vy_m_s": "vy (m/s)", "vz_m_s": "vz (m/s)",
}  # fmt: skip


def build_tables(results: list[dict]) -> dict:
    """Aggregated tables (JSON-serializable): table1..table4, claims, seeds."""
    agg = aggregate(results)
    conditions = list(results[0]["localization"])
    claims = {}
    for key, (text, pred) in CLAIMS.items():
        claims[key] = {"claim": text, "why_not": WHY_NOT.get(key)}
        for c in conditions:
            claims[key][c] = claim_fraction(results, lambda r, c=c, pred=pred: pred(_view(r, c)))
    table1_claims = {}
    for key, (text, _, why_not) in TABLE1_CLAIMS.items():
        fraction = claim_fraction(results, lambda r, key=key: r["claims_table1"][key])
        table1_claims[key] = {"claim": text, "why_not": why_not, "all": fraction}
    return {
        "seeds": [r["seed"] for r in results],
        "table1_claims": table1_claims,
        "conditions": conditions,
        "table1": agg["table1"],
        "localization": agg["localization"],
        "mapping": agg["mapping"],
        "rock_survey": agg.get("rock_survey"),
        "calibration": agg["calibration"],
        "claims": claims,
        "paper": {
            "table1": paper.TABLE_I,
            "table2_3": paper.TABLE_II_III,
            "table4": paper.TABLE_IV,
        },
    }


def _view(result: dict, condition: str) -> dict:
    return {
        "localization": result["localization"][condition],
        "mapping": result["mapping"][condition],
    }


def cell(stat: dict | None, digits: int = 3) -> str:
    """'mean' for one seed, 'mean [lo, hi]' (95 % CI of the mean) for several; '-' if absent."""
    if not stat or stat.get("mean") is None:
        return "-"
    mean = f"{stat['mean']:.{digits}f}"
    if stat.get("n", 1) > 1 and stat.get("ci95_low") is not None:
        return f"{mean} [{stat['ci95_low']:.{digits}f}, {stat['ci95_high']:.{digits}f}]"
    return mean


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


def table4_markdown(t: dict, condition: str) -> str:
    rows = []
    for method, variant in MAP_RUNS:
        key = f"{method}/{variant}"
        sim, ref = t["mapping"][condition][key], paper.TABLE_IV[key]
        rows.append(
            [
                method.upper() if method != "adaptive" else "Adaptive BKI",
                variant,
                _num(ref["c2c_mean_m"]), cell(sim["c2c_mean_m"], 4),
                str(ref["occupied_cells"]), cell(sim["occupied_cells"], 0),
                cell(sim["coverage_mean_m"], 4),
            ]
        )  # fmt: skip
    header = [
        "mapping", "filter", "C2C paper (m)", "C2C sim (m)", "cells paper", "cells sim",
        "coverage sim (m, GT->map)",
    ]  # fmt: skip
    return _md(header, rows)


def rock_survey_markdown(r: dict) -> str:
    rmse = r["trajectory"]["rmse"]
    lines = [
        "Proposed filter RMSE: "
        + ", ".join(
            f"{AXIS_LABELS[a]} {cell(rmse[a], 4)}" for a in ("x_m", "y_m", "z_m", "yaw_rad")
        )
        + ". Maps evaluated over the rock's footprint plus 0.5 m:",
        "",
    ]
    rows = [
        [name, cell(r[key]["c2c_mean_m"], 4), cell(r[key]["occupied_cells"], 0)]
        for name, key in (("Adaptive BKI", "adaptive"), ("BKI (l = 0.15 m)", "bki"))
    ]
    return "\n".join(lines) + "\n" + _md(["mapping", "C2C sim (m)", "cells sim"], rows)


def table1_claims_markdown(t: dict) -> str:
    rows = []
    for entry in t.get("table1_claims", {}).values():
        f = entry["all"]
        if not f["n"]:
            continue
        why = "" if f["holds"] == f["n"] else entry["why_not"] or "not explained yet"
        rows.append([entry["claim"], f"{f['holds']}/{f['n']}", why])
    return (
        _md(["the paper's reading of Table I", "holds in (seeds)", "why not"], rows) if rows else ""
    )


def claims_markdown(t: dict) -> str:
    """Claim | holds in k/n seeds per condition | why, where it does not hold in every seed."""
    rows = []
    for entry in t["claims"].values():
        row = [entry["claim"]]
        always = True
        for c in t["conditions"]:
            f = entry[c]
            row.append(f"{f['holds']}/{f['n']}" if f["n"] else "n/a")
            always = always and f["n"] > 0 and f["holds"] == f["n"]
        row.append("" if always else entry.get("why_not") or "not explained yet")
        rows.append(row)
    header = ["claim", *(f"holds in (seeds) {c}" for c in t["conditions"]), "why not, where not"]
    return _md(header, rows)


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
        ]
    if t.get("rock_survey"):
        parts += [
            "## Rock survey (free vehicle in waves; the paper shows it only as a figure)",
            rock_survey_markdown(t["rock_survey"]),
        ]
    parts += ["## The paper's claims in simulation", claims_markdown(t)]
    return "\n\n".join(parts) + "\n"
