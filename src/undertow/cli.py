"""The `undertow` command line: one typer app, each command a thin call of a library function.

Known user errors (UndertowError) become one line on stderr and exit code 1; anything else is
a bug and keeps its traceback.
"""

from __future__ import annotations

import functools
import json
import sys
import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from .errors import UndertowError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    rich_markup_mode="markdown",
    help=(
        "undertow: uncertainty-aware acoustic localization and seafloor mapping for underwater "
        "robots in waves.\n\n"
        "Examples:\n\n"
        "    undertow simulate wave-a0.10-f1.00 --out runs/a10f100 --seed 1\n\n"
        "    undertow info runs/a10f100/log\n\n"
        "    undertow info recording.bag --json\n\n"
    ),
)
evaluate_app = typer.Typer(no_args_is_help=True, help="Evaluate results against ground truth.")
app.add_typer(evaluate_app, name="evaluate")

out = Console()
err = Console(stderr=True)


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    err.print(f"[yellow]warning:[/] {message}", highlight=False, soft_wrap=True)


@app.callback()
def _setup() -> None:
    """Library warnings (bad rows dropped, units fixed) become one line each on stderr."""
    warnings.showwarning = _one_line_warning


def user_errors(fn):
    """Turn UndertowError into one clear line and exit code 1."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except UndertowError as exc:
            err.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
            raise typer.Exit(1) from None

    return wrapper


def _progress(quiet: bool):
    from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    return Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=err,
        disable=quiet,
        transient=True,
    )


def _print_json(data) -> None:
    sys.stdout.write(json.dumps(data, indent=2, default=float) + "\n")


@app.command()
@user_errors
def info(
    path: Annotated[Path, typer.Argument(help="ROS 1 bag, ROS 2 bag directory, or A50 JSON log.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
    topics: Annotated[
        Path | None, typer.Option(help="YAML topic map overriding the BlueROV2 defaults.")
    ] = None,
) -> None:
    """Streams found, message counts, rates, time span and invalid data, in measurement terms.

    Example: `undertow info runs/calm/log --json`
    """
    from .io import read_log
    from .io.info import summarize
    from .io.topics import TopicMap

    topic_map = TopicMap.from_yaml(topics) if topics else None
    summary = summarize(read_log(path, topics=topic_map))
    if as_json:
        _print_json(summary.to_dict())
    else:
        out.print(summary.to_rich_table())


@app.command()
@user_errors
def simulate(
    scenario: Annotated[
        str | None, typer.Argument(help="Built-in scenario name or a scenario YAML file.")
    ] = None,
    out_dir: Annotated[Path | None, typer.Option("--out", help="Output directory.")] = None,
    seed: Annotated[int, typer.Option(help="Random seed (runs are deterministic per seed).")] = 0,
    list_: Annotated[bool, typer.Option("--list", help="List the built-in scenarios.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output directory.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q")] = False,
) -> None:
    """Simulate a wave-tank run: ROS 2 bag, ground truth (TUM, 2000 Hz), floor scan (PLY).

    Example: `undertow simulate wave-a0.10-f0.75 --out runs/a10f075 --seed 3`
    """
    from .sim import list_scenarios, load_scenario, write_simulation
    from .sim import simulate as run_simulation

    if list_:
        for name, description in list_scenarios().items():
            out.print(f"[bold]{name}[/]  {description}", highlight=False)
        return
    if scenario is None or out_dir is None:
        raise UndertowError("simulate needs a SCENARIO and --out DIR (or --list)")
    spec = load_scenario(scenario)
    with _progress(quiet) as progress:
        progress.add_task(f"simulating {spec.name} (seed {seed})", total=None)
        result = run_simulation(spec, seed=seed)
        write_simulation(result, out_dir, overwrite=overwrite)
    if not quiet:
        err.print(f"wrote {out_dir}/log, ground_truth.tum, ground_truth.ply, scenario.yaml")


def main() -> None:  # pragma: no cover - console entry point
    app()
