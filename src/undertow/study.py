"""The whole study (`undertow demo` / `undertow reproduce`): every seed, tables, figures, report.

1. The first seed runs in this process and keeps its in-memory results for the figures; its
   simulated runs, trajectories and maps are written under ``OUT/runs/`` so every step can be
   redone with the CLI (and the files opened in evo, CloudCompare, Foxglove).
2. The other seeds are independent Dask tasks (:func:`undertow.batch.run_batch`): a local
   cluster by default, or an existing scheduler. A failed seed is reported and the rest kept.
3. ``tables.md`` / ``tables.json`` aggregate all seeds (mean and 95 % interval per cell, the
   fraction of seeds where each claim of the paper holds); ``seeds/seed_N.json`` keep every seed's
   numbers; figures (PNG) and ``report.html`` come from the first seed.
"""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ._atomic import atomic_path
from ._plain import to_plain
from .errors import UndertowError
from .experiments import Artifacts, StudySettings, run_seed, run_seed_with_artifacts


@dataclass
class StudyResult:
    out_dir: Path
    tables: dict
    markdown: str
    failures: dict[int, str] = field(default_factory=dict)
    figures: list[tuple[str, Path]] = field(default_factory=list)
    report: Path | None = None
    wall_s: float = 0.0


def run_study(
    out_dir: str | Path,
    seeds: list[int] | None = None,
    scheduler: str | None = None,
    settings: StudySettings | None = None,
    progress: Callable[[str], None] | None = None,
    report: bool = True,
) -> StudyResult:
    """Run the paper's study for ``seeds`` (default [0]); write everything under ``out_dir``."""
    from .report.tables import build_tables, render_markdown

    start = time.perf_counter()
    settings = settings or StudySettings()
    seeds = list(seeds or [0])
    if len(set(seeds)) != len(seeds):
        raise UndertowError(f"seeds must be distinct, got {seeds}")
    note = progress or (lambda _msg: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    note(f"seed {seeds[0]}: simulate, characterize, localize, map")
    first, artifacts = run_seed_with_artifacts(seeds[0], settings)
    results = {seeds[0]: first}
    failures: dict[int, str] = {}
    if len(seeds) > 1:
        from .batch import run_batch

        note(f"seeds {seeds[1:]}: {len(seeds) - 1} Dask tasks")
        batch = run_batch(
            run_seed,
            seeds[1:],
            scheduler=scheduler,
            args=(settings,),
            progress=lambda done, total: note(f"Monte Carlo: {done}/{total} seeds done"),
        )
        results.update(batch.results)
        failures.update(batch.failures)
    ordered = [results[s] for s in sorted(results)]
    tables = build_tables(ordered)
    tables["failures"] = {str(k): v for k, v in failures.items()}
    markdown = render_markdown(tables)
    if failures:
        markdown += "\n## Failed seeds\n\n" + "\n".join(
            f"- seed {s}: {msg}" for s, msg in sorted(failures.items())
        )
    _write_text(out / "tables.md", markdown)
    _write_text(out / "tables.json", json.dumps(to_plain(tables), indent=1, allow_nan=False))
    for seed, result in results.items():
        _write_text(out / "seeds" / f"seed_{seed}.json", json.dumps(result, indent=1))
    note("writing runs, figures and report")
    _write_runs(out / "runs", artifacts)
    study = StudyResult(out, tables, markdown, failures)
    if report:
        from .report.build import build_report

        study.figures, study.report = build_report(out, tables, markdown, artifacts, _versions())
    study.wall_s = time.perf_counter() - start
    return study


def _write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _write_runs(root: Path, art: Artifacts) -> None:
    """First seed's runs: simulation outputs, trajectories per variant, maps per method."""
    from .estimation.run import save_trajectory
    from .mapping.mappers import write_map_ply
    from .sim import write_simulation

    for name, sim in art.simulations.items():
        write_simulation(sim, root / name / "sim", overwrite=True)
    for (name, variant), trajectory in art.trajectories.items():
        save_trajectory(trajectory, root / name / "localization" / variant, overwrite=True)
    for (name, key), occupancy in art.maps.items():
        folder = root / name / "maps" / key.replace("/", "_")
        folder.mkdir(parents=True, exist_ok=True)
        occupancy.save(folder / "map.npz")
        write_map_ply(folder / "map.ply", occupancy)


def _versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version(), "platform": platform.platform()}
    for pkg in ("undertow", "numpy", "scipy", "numba", "rosbags", "matplotlib", "dask"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "not installed"
    return out
