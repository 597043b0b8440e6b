"""`undertow info` and `undertow simulate` as library functions: what those commands do.

:func:`info_file` reads a log (ROS 1/2 bag or A50 JSON) and summarizes its streams;
:func:`simulate_to_folder` runs a scenario and writes the run folder. Both return a result
object instead of printing, so a Python user gets what the command prints::

    from undertow.commands.data import info_file, simulate_to_folder

    run = simulate_to_folder("calm", "runs/calm", seed=0)
    print(info_file(run.out_dir / "log").to_dict())
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .._util.atomic import check_output_folder
from ..io.info import LogSummary, summarize
from ..settings import Settings
from ..sim import SimulationResult, list_scenarios, load_scenario, simulate, write_simulation
from .common import load_log

#: what :func:`simulate_to_folder` writes in its folder
RUN_FILES = ("log", "ground_truth.tum", "ground_truth.ply", "scenario.yaml")


@dataclass(frozen=True)
class InfoResult:
    """The summary of one log: per stream messages, median rate, span, invalid rows and missing
    values (see :mod:`undertow.io.info`); ``warnings`` are the reader's notes (rows dropped,
    units fixed, topics of the topic map the log lacks)."""

    path: Path
    summary: LogSummary

    @property
    def warnings(self) -> list[str]:
        return self.summary.warnings

    def to_dict(self) -> dict:
        """What ``undertow info --json`` prints (NaN as null)."""
        return self.summary.to_dict()


def info_file(
    path: str | Path, topics: str | Path | None = None, settings: Settings | None = None
) -> InfoResult:
    """Summarize the log at ``path``. Topic names: the ``topics`` YAML when given, else the
    settings' ``topics`` section, else the BlueROV2 defaults (see :func:`.common.load_log`)."""
    return InfoResult(path=Path(path), summary=summarize(load_log(path, topics, settings)))


@dataclass(frozen=True, eq=False)
class SimulateResult:
    """A simulated run written to ``out_dir`` (:data:`RUN_FILES`): the seed used and the
    simulation itself (log with ground truth, floor cloud, scenario with that seed)."""

    out_dir: Path
    seed: int
    simulation: SimulationResult

    @property
    def scenario(self):
        return self.simulation.scenario


def simulate_to_folder(
    name_or_path: str | Path,
    out_dir: str | Path,
    seed: int | None = None,
    overwrite: bool = False,
    *,
    on_start: Callable[[str], None] | None = None,
) -> SimulateResult:
    """Simulate a built-in scenario (by name) or a scenario YAML file and write the run folder:
    ``log/`` (ROS 2 mcap bag), ``ground_truth.tum``, ``ground_truth.ply``, ``scenario.yaml``.

    ``seed``: the given one wins, else the scenario file's own (default 0), so a written
    ``scenario.yaml`` reproduces its run. The folder is checked before the (long) simulation: a
    non-empty one is replaced only with ``overwrite``, and never when it holds the scenario file.
    ``on_start`` is called with a one-line description once the scenario is read (e.g. to label
    a progress bar).
    """
    spec = load_scenario(name_or_path)
    inputs = [name_or_path] if Path(name_or_path).exists() else []
    check_output_folder(out_dir, overwrite, inputs=inputs)
    seed = spec.seed if seed is None else seed
    if on_start is not None:
        on_start(f"simulating {spec.name} (seed {seed})")
    result = simulate(spec, seed=seed)
    write_simulation(result, out_dir, overwrite=overwrite)
    return SimulateResult(out_dir=Path(out_dir), seed=result.scenario.seed, simulation=result)


def builtin_scenarios() -> list[tuple[str, str]]:
    """(name, description) of every built-in scenario, as ``undertow simulate --list`` shows."""
    return [(name, load_scenario(name).description) for name in list_scenarios()]
