"""Figures and the HTML report of a study, from the first seed's in-memory results."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .pipeline import Artifacts


def build_report(
    out: Path, tables: dict, markdown: str, art: Artifacts, versions: dict
) -> tuple[list[tuple[str, Path]], Path]:
    """Write ``figures/*.png`` and ``report.html`` under ``out``; return (figures, report)."""
    from ..report import figures as fig
    from ..report.html import write_report

    figdir = out / "figures"
    cond = tables["conditions"][0]
    sim = art.simulations[cond]
    log, cloud = sim.log, sim.floor_cloud
    trajs = {v: art.trajectories[(cond, v)] for v in ("baseline", "proposed")}
    adaptive = art.maps[(cond, "adaptive/proposed")]
    bki = art.maps[(cond, "bki/proposed")]
    lateral = float(np.median(log.ground_truth.position[:, 1]))
    mapping_cfg = adaptive_lengths()
    figures = [
        (
            f"Trajectory ({cond}): proposed (blue) vs baseline (red) vs ground truth (green) "
            "(paper Fig. 3a).",
            fig.plot_trajectories(figdir / "trajectories.png", log.ground_truth, trajs),
        ),
        (
            f"Error along the trajectory ({cond}); baseline dashed, proposed solid with its own "
            "2-sigma band (paper Fig. 3b).",
            fig.plot_trajectory_errors(figdir / "trajectory_errors.png", log.ground_truth, trajs),
        ),
        (
            f"Adaptive BKI map ({cond}, proposed filter) coloured by distance to the ground-truth "
            "floor scan (paper Fig. 4).",
            fig.plot_map_distance(figdir / "map_distance.png", adaptive.points(0.5), cloud),
        ),
        (
            f"Map slice near the floor, adaptive vs BKI ({cond}; paper Fig. 6).",
            fig.plot_map_slice(
                figdir / "map_slice.png",
                {"adaptive BKI": adaptive, "BKI (l = 0.15 m)": bki},
                cloud,
                (lateral - 0.05, lateral + 0.05),
            ),
        ),
        (
            f"x velocity ({cond}): DVL (red) vs estimate (blue) vs ground truth (green) "
            "(paper Fig. 8).",
            fig.plot_velocity(figdir / "velocity.png", log, trajs["proposed"]),
        ),
        (
            f"Wave elevation, DVL altitude and DVL x velocity ({cond}; paper Fig. 2b).",
            fig.plot_disturbance(figdir / "disturbance.png", log),
        ),
        (
            "The adaptive kernel for small and large pose uncertainty (l_min vs l_max; paper "
            "Fig. 7).",
            fig.plot_kernel_shapes(figdir / "kernel_shapes.png", *mapping_cfg),
        ),
    ]
    survey = next((name for name, _ in art.maps if name not in tables["conditions"]), None)
    if survey is not None:
        rock_sim = art.simulations[survey]
        rock = rock_sim.scenario.tank.rock
        figures.append(
            (
                "Rock survey (free vehicle in waves): adaptive BKI map over the rock's true "
                "outline (paper Fig. 5).",
                fig.plot_rock_map(
                    figdir / "rock_map.png",
                    art.maps[(survey, "adaptive/proposed")],
                    (rock.center_x_m, rock.center_y_m, rock.length_m, rock.width_m, rock.height_m),
                    rock_sim.scenario.water.depth_m,
                ),
            )
        )
    report = write_report(
        out / "report.html",
        title="undertow: the paper's experiments in the simulated wave basin",
        tables_markdown=markdown,
        tables=tables,
        figures=figures,
        map_points=adaptive.points(0.5),
        ground_truth_points=cloud,
        config={"scenario": sim.scenario.to_yaml_dict(), "seeds": tables["seeds"]},
        versions=versions,
        notes=report_notes(tables),
    )
    return figures, report


def adaptive_lengths():
    from ..mapping.config import MappingConfig

    cfg = MappingConfig()
    return cfg.l_min, cfg.l_max


def report_notes(tables: dict) -> list[str]:
    """What holds and what does not, read from the claim fractions (never typed in)."""
    notes = []
    for entry in tables.get("table1_claims", {}).values():
        f = entry["all"]
        if f["n"]:
            verdict = "holds" if f["holds"] == f["n"] else "does not hold"
            note = f"Table I: {entry['claim']}: {verdict} ({f['holds']}/{f['n']} seeds)."
            if f["holds"] < f["n"]:
                note += f" Why: {entry['why_not'] or 'not explained yet'}."
            notes.append(note)
    for entry in tables["claims"].values():
        counts = [entry[c] for c in tables["conditions"] if entry[c]["n"]]
        holds = sum(c["holds"] for c in counts)
        total = sum(c["n"] for c in counts)
        verdict = "holds" if holds == total else "does not hold" if holds == 0 else "holds partly"
        note = f"{entry['claim']}: {verdict} ({holds}/{total} seed-conditions)."
        if holds < total:
            note += f" Why: {entry.get('why_not') or 'not explained yet'}."
        notes.append(note)
    return notes
