"""Figures and the HTML report of a study, from the first seed's in-memory results.

The drawing and the page are generic (:mod:`undertow.report`); this module picks what the study
shows: which runs go in which paper figure, the captions, and the notes on the paper's claims.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .pipeline import Artifacts, StudySettings

Figures = list[tuple[str, Path]]


def build_report(
    out: Path,
    tables: dict,
    markdown: str,
    art: Artifacts,
    versions: dict,
    settings: StudySettings | None = None,
) -> tuple[Figures, Path]:
    """Write ``figures/*.png`` and ``report.html`` under ``out``; return (figures, report)."""
    from ..report.html import write_report

    settings = settings or StudySettings()
    cond = tables["conditions"][0]
    figures = condition_figures(out / "figures", cond, art, settings)
    figures += rock_survey_figures(out / "figures", tables, art)
    figures += map_scenario_figures(out / "figures", tables, art, settings)
    figures += wave_estimate_figures(out / "figures", art)
    figures += peer_figures(out / "figures", art)
    sim = art.simulations[cond]
    report = write_report(
        out / "report.html",
        title="undertow: the paper's experiments in the simulated wave basin",
        tables_markdown=markdown,
        tables=tables,
        figures=figures,
        map_points=art.maps[(cond, "adaptive/proposed")].points(0.5),
        ground_truth_points=sim.floor_cloud,
        config={"scenario": sim.scenario.to_yaml_dict(), "seeds": tables["seeds"]},
        versions=versions,
        notes=report_notes(tables),
    )
    return figures, report


def condition_figures(figdir: Path, cond: str, art: Artifacts, settings: StudySettings) -> Figures:
    """The paper's figures 2b, 3, 4, 6, 7 and 8 for one wave condition (captions, paths)."""
    from ..report import figures as fig
    from ..report import figures_map, figures_traj

    sim = art.simulations[cond]
    log, cloud = sim.log, sim.floor_cloud
    trajs = {v: art.trajectories[(cond, v)] for v in ("baseline", "proposed")}
    adaptive = art.maps[(cond, "adaptive/proposed")]
    bki_label = f"BKI (l = {settings.bki_length_scale:g} m)"
    slice_maps = {"adaptive BKI": adaptive, bki_label: art.maps[(cond, "bki/proposed")]}
    lateral = float(np.median(log.ground_truth.position[:, 1]))
    half = 0.5 * adaptive.resolution
    gt = log.ground_truth
    return [
        (f"Trajectory ({cond}): proposed (blue) vs baseline (red) vs ground truth (green) "
         "(paper Fig. 3a).",
         figures_traj.plot_trajectories(figdir / "trajectories.png", gt, trajs)),
        (f"Error along the trajectory ({cond}); baseline dashed, proposed solid with its own "
         "2-sigma band (paper Fig. 3b).",
         figures_traj.plot_trajectory_errors(figdir / "trajectory_errors.png", gt, trajs)),
        (f"Adaptive BKI map ({cond}, proposed filter) coloured by distance to the ground-truth "
         "floor scan (paper Fig. 4).",
         figures_map.plot_map_distance(figdir / "map_distance.png", adaptive.points(0.5), cloud)),
        (f"Map slice near the floor, adaptive vs BKI ({cond}; paper Fig. 6).",
         figures_map.plot_map_slice(figdir / "map_slice.png", slice_maps, cloud,
                                    (lateral - half, lateral + half))),
        (f"x velocity ({cond}): DVL (red) vs estimate (blue) vs ground truth (green) "
         "(paper Fig. 8).",
         fig.plot_velocity(figdir / "velocity.png", log, trajs["proposed"])),
        (f"Wave elevation, DVL altitude and DVL x velocity ({cond}; paper Fig. 2b).",
         fig.plot_disturbance(figdir / "disturbance.png", log)),
        ("The adaptive kernel for small and large pose uncertainty (l_min vs l_max; paper "
         "Fig. 7).",
         fig.plot_kernel_shapes(figdir / "kernel_shapes.png", *adaptive_lengths())),
    ]  # fmt: skip


def rock_survey_figures(figdir: Path, tables: dict, art: Artifacts) -> Figures:
    """Paper Fig. 5 (the adaptive BKI map over the rock), when the rock survey ran."""
    from ..report import figures_map

    other = {*tables["conditions"], *(tables.get("map_scenario_names") or [])}
    survey = next((name for name, _ in art.maps if name not in other), None)
    if survey is None:
        return []
    sim = art.simulations[survey]
    rock = sim.scenario.tank.rock
    outline = (rock.center_x_m, rock.center_y_m, rock.length_m, rock.width_m, rock.height_m)
    path = figures_map.plot_rock_map(
        figdir / "rock_map.png",
        art.maps[(survey, "adaptive/proposed")],
        outline,
        sim.scenario.water.depth_m,
    )
    caption = (
        "Rock survey (free vehicle in waves): adaptive BKI map over the rock's true outline "
        "(paper Fig. 5)."
    )
    return [(caption, path)]


def map_scenario_figures(figdir: Path, tables: dict, art: Artifacts,
                         settings: StudySettings) -> Figures:  # fmt: skip
    """Per mapping scenario: the four Table IV maps' implied seafloor coloured by depth error
    (top view), and a slice like the paper's Fig. 6 (adaptive BKI, BKI, CSM on the baseline)
    across the floor along one pass."""
    from ..mapping.surface import map_surface
    from ..report import figures_map
    from .maps import CONSISTENT, RECORDED, SCENARIO_MAP_RUNS, THRESHOLD, floor_truth

    out = []
    for name in tables.get("map_scenario_names") or []:
        sim = art.simulations[name]
        maps = {f"{m}/{v}": art.maps[(name, f"{m}/{v}")]
                for m, v in SCENARIO_MAP_RUNS if v not in (RECORDED, CONSISTENT)}  # fmt: skip
        surfaces = {key: map_surface(occ, THRESHOLD) for key, occ in maps.items()}
        top = figures_map.plot_surface_error(
            figdir / f"surface_error_{name}.png", surfaces, floor_truth(sim),
            title=f"{name}: map surfaces coloured by depth error (top view)",
        )  # fmt: skip
        out.append((f"{name}: each Table IV map's implied seafloor (the paper's maps: the "
                    "expected first occupied depth per column; tpu: its evidence), coloured "
                    "by its error against the true floor; red too "
                    "deep, blue too shallow.", top))  # fmt: skip
        lateral, x_range = _busiest_row(maps["csm/proposed"], SLICE_LENGTH_M)
        half = 0.5 * maps["adaptive/proposed"].resolution
        bki_label = f"BKI (l = {settings.bki_length_scale:g} m)"
        slice_maps = {"tpu (default)": maps["tpu/proposed"],
                      "adaptive BKI": maps["adaptive/proposed"], bki_label: maps["bki/proposed"],
                      "CSM, baseline filter": maps["csm/baseline"]}  # fmt: skip
        path = figures_map.plot_map_slice(figdir / f"map_slice_{name}.png", slice_maps,
                                          sim.floor_cloud, (lateral - half, lateral + half),
                                          x_range)  # fmt: skip
        out.append(
            (
                f"{name}: map slice across the rough floor at y = {lateral:.2f} m, adaptive "
                "BKI vs BKI vs CSM on the baseline filter (as the paper's Fig. 6).",
                path,
            )
        )
    return out  # fmt: skip


#: The length (m) of the mapping scenarios' slice figure along x.
SLICE_LENGTH_M = 12.0


def _busiest_row(occupancy, length: float) -> tuple[float, tuple[float, float]]:
    """The y (cell centre) of the map row with the most occupied cells (a survey line), and an
    x range of ``length`` centred on that row's occupied cells."""
    occ = occupancy.occupied()
    if not len(occ):
        return 0.0, (0.0, length)
    rows, counts = np.unique(occ.cells[:, 1], return_counts=True)
    row = rows[np.argmax(counts)]
    x = occ.centres[occ.cells[:, 1] == row, 0]
    mid = float(np.median(x))
    return float((row + 0.5) * occupancy.resolution), (mid - length / 2, mid + length / 2)


def wave_estimate_figures(figdir: Path, art: Artifacts) -> Figures:
    """The onboard wave estimate over time against the scenario's schedule, per changing-sea
    scenario that ran."""
    from ..report.figures_waves import plot_wave_estimate

    out = []
    for name, (estimate, truth) in art.wave_estimates.items():
        if estimate is None:
            continue
        path = plot_wave_estimate(estimate, figdir / f"waves_{name}.png", truth, title=name)
        caption = (
            f"Wave condition over time ({name}): the estimate from the robot's own sensors per "
            "window (blue, no wave probe) against the scenario's schedule (green)."
        )
        out.append((caption, path))
    return out


def peer_figures(figdir: Path, art: Artifacts) -> Figures:
    """Per scenario of the peers table: every estimator's trajectory and errors together."""
    from ..report.figures_traj import plot_estimators

    out = []
    for name in dict.fromkeys(scenario for scenario, _ in art.peers):
        trajs = {est: traj for (scenario, est), traj in art.peers.items() if scenario == name}
        gt = art.simulations[name].log.ground_truth
        path = plot_estimators(figdir / f"peers_{name}.png", gt, trajs,
                               title=f"{name}: the UKF and its peers, top view")  # fmt: skip
        caption = (
            f"Peers ({name}): the paper's UKF (baseline, proposed, proposed + URTS smoother; "
            "solid) beside the factor graph (batch, iSAM2) and the InEKF (dashed): top view "
            "against the ground truth (green), horizontal position error and yaw error."
        )
        out.append((caption, path))
    return out


def adaptive_lengths():
    """(l_min, l_max) of the adaptive kernel the study maps with (the mapping defaults)."""
    from ..mapping.config import MappingConfig

    cfg = MappingConfig()
    return cfg.l_min, cfg.l_max


def _verdict(holds: int, n: int) -> str:
    return "holds" if holds == n else "does not hold" if holds == 0 else "holds partly"


def report_notes(tables: dict) -> list[str]:
    """What holds and what does not, read from the claim fractions and the measured values."""
    notes = []
    for entry in tables.get("table1_claims", {}).values():
        f = entry["all"]
        if f["n"]:
            notes.append(
                f"Table I: {entry['claim']} ({entry['test']}): {_verdict(f['holds'], f['n'])} "
                f"({f['holds']}/{f['n']} seeds). The paper: {entry['statement']} "
                f"Measured: {entry['why']}."
            )
    for entry in tables.get("changing_sea_claims", {}).values():
        f = entry["all"]
        if f["n"]:
            notes.append(
                f"Changing sea: {entry['claim']} ({entry['test']}): "
                f"{_verdict(f['holds'], f['n'])} ({f['holds']}/{f['n']} seeds). Measured: "
                f"{entry['why']}."
            )
    notes += peer_notes(tables.get("peers"))
    scenarios = tables.get("map_scenario_names") or []
    entries = [(e, tables["conditions"]) for e in tables["claims"].values()]
    entries += [(e, tables["conditions"]) for e in tables.get("field_claims", {}).values()]
    entries += [(e, scenarios) for e in (tables.get("map_scenario_claims") or {}).values()]
    for entry, columns in entries:
        counts = {c: entry[c] for c in columns if entry[c]["n"]}
        holds = sum(f["holds"] for f in counts.values())
        total = sum(f["n"] for f in counts.values())
        where = "seed-scenarios" if columns is scenarios else "seed-conditions"
        note = (
            f"{entry['claim']} ({entry['test']}): {_verdict(holds, total)} ({holds}/{total} "
            f"{where}). The paper: {entry['statement']}"
        )
        if entry["by_construction"]:
            note += f" By construction of the simulator: {entry['by_construction']}."
        for c, f in counts.items():
            if f["holds"] < f["n"]:
                note += f" {c}: {entry['why'][c]}."
        notes.append(note)
    return notes


def peer_notes(peers: dict | None) -> list[str]:
    """One note per scenario and comparison of the peers table: the verdict's why."""
    if not peers:
        return []
    return [
        f"Peers, {name}, {pair}: {why}."
        for name in peers["scenarios"]
        for pair, why in peers["tables"][name]["why"].items()
        if why
    ]
