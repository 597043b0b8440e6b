"""The whole study (`undertow demo` / `undertow reproduce`): every seed, tables, figures, report.

0. Inputs are checked before any work: distinct seeds >= 0, an output folder that is not a file,
   and the scheduler (a known name or a reachable address; Dask installed).
1. The first seed runs in this process and keeps its in-memory results for the figures; its
   simulated runs, trajectories and maps are written under ``OUT/runs/`` so every step can be
   redone with the CLI (and the files opened in evo, CloudCompare, Foxglove). It stays out of
   Dask on purpose: those in-memory results are about 330 MB per seed (the logs with their
   2 kHz ground truth, 16 trajectories with full 18-state covariances, 12 maps) and would have
   to be pickled and shipped back from a worker (over the network from a remote cluster). It
   runs under the same guard as a Dask task: if it raises, the failure is recorded by seed and
   the next seed takes its place (in this process) for the figures and runs.
2. The other seeds are independent Dask tasks (:func:`undertow.study.batch.run_batch`): a local
   cluster by default, or an existing scheduler. A failed seed is reported and the rest kept.
3. ``tables.md`` / ``tables.json`` aggregate all seeds (mean and 95 % interval per cell, the
   fraction of seeds where each claim of the paper holds); ``seeds/seed_N.json`` keep every seed's
   numbers; figures (PNG) and ``report.html`` come from the first successful seed.
"""

from __future__ import annotations

import json
import platform
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from numbers import Integral
from pathlib import Path

from .._util.atomic import atomic_path, check_output_folder
from .._util.plain import to_plain
from ..errors import ConfigError, UndertowError
from .pipeline import Artifacts, StudySettings, run_seed, run_seed_with_artifacts


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
    from .tables import build_tables, render_markdown

    start = time.perf_counter()
    settings = settings or StudySettings()
    seeds = check_study_inputs(out_dir, seeds, scheduler)
    note = progress or (lambda _msg: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    results, failures, artifacts, rest = _first_seed(seeds, settings, note)
    if rest:
        from .batch import run_batch

        note(f"seeds {rest}: {len(rest)} Dask tasks")
        batch = run_batch(
            run_seed,
            rest,
            scheduler=scheduler,
            args=(settings,),
            progress=lambda done, total: note(f"Monte Carlo: {done}/{total} seeds done"),
        )
        results.update(batch.results)
        failures.update(batch.failures)
    if not results:
        first = min(failures)
        raise UndertowError(f"every seed failed; seed {first}: {failures[first]}")
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
        from .report import build_report

        study.figures, study.report = build_report(
            out, tables, markdown, artifacts, _versions(), settings
        )
    study.wall_s = time.perf_counter() - start
    return study


def check_study_inputs(out_dir, seeds, scheduler) -> list[int]:
    """The seeds to run (default [0]), after checking every input before any work: distinct
    integer seeds >= 0, ``out_dir`` not an existing file, the scheduler valid (and reachable if
    an address) when more than one seed runs; with one seed a scheduler is unused (warning)."""
    from .._util.dask import check_scheduler

    seeds = list(seeds if seeds is not None else [0])
    if not seeds:
        raise ConfigError("no seeds to run")
    if any(not isinstance(s, Integral) or isinstance(s, bool) or s < 0 for s in seeds):
        raise ConfigError(f"seeds must be integers >= 0, got {seeds}")
    seeds = [int(s) for s in seeds]
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"seeds must be distinct, got {seeds}")
    check_output_folder(out_dir, overwrite=True)
    if len(seeds) > 1:
        check_scheduler(scheduler, reach=True)
    elif scheduler is not None:
        check_scheduler(scheduler)
        warnings.warn(
            f"scheduler {scheduler!r} not used: with one seed, the seed runs in this process "
            "(it makes the figures); the scheduler runs the seeds after the first",
            stacklevel=2,
        )
    return seeds


def _first_seed(seeds: list[int], settings: StudySettings, note):
    """Run seeds in this process, in order, until one succeeds (its artifacts make the figures
    and runs); a seed that raises is recorded as a failure, as a Dask task's would be.
    Returns (results, failures, artifacts, the seeds left for Dask)."""
    from .._util.dask import describe_exception

    results: dict[int, dict] = {}
    failures: dict[int, str] = {}
    for i, seed in enumerate(seeds):
        note(f"seed {seed}: simulate, characterize, localize, map")
        try:
            result, artifacts = run_seed_with_artifacts(seed, settings)
        except Exception as exc:  # a failing seed must not lose the others
            failures[seed] = describe_exception(exc)
            note(f"seed {seed} failed: {failures[seed]}")
            continue
        results[seed] = result
        return results, failures, artifacts, seeds[i + 1 :]
    return results, failures, None, []


def _write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _write_runs(root: Path, art: Artifacts) -> None:
    """First seed's runs: simulation outputs, trajectories per variant, maps per method."""
    from ..io.ply import write_map_ply
    from ..io.results import save_trajectory
    from ..sim import write_simulation

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
