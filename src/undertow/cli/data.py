"""Commands on logs and the simulator: info, simulate (parse, call
:mod:`undertow.commands.data`, print)."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Annotated

import typer

from ..errors import UndertowError
from ._app import (
    ConfigOption,
    TimeOption,
    TopicsOption,
    app,
    console,
    err,
    print_json,
    print_warnings,
    progress_bar,
    settings_with_time,
    user_errors,
)


@app.command()
@user_errors
def info(
    path: Annotated[
        Path, typer.Argument(help="ROS 1 bag, ROS 2 bag directory, A50 JSON log, or MAVLink .tlog.")
    ],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
    topics: TopicsOption = None,
    config: ConfigOption = None,
    time: TimeOption = None,
) -> None:
    """Streams found, message counts, rates, time span and invalid data, in measurement terms.

    Example: `undertow info runs/calm/log --json`
    """
    from ..commands.data import info_file
    from ..settings import Settings

    settings = settings_with_time(config, time)
    if settings is not None and not isinstance(settings, Settings):
        settings = Settings.from_yaml(settings)
    # every warning once, each time (not left to the process's warning registry, which hides a
    # warning already shown from the same line: a second `info` in one process would miss it)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = info_file(path, topics=topics, settings=settings)
    lines = list(result.warnings)
    lines += [str(w.message) for w in caught if str(w.message) not in lines]
    print_warnings(dict.fromkeys(lines))
    if as_json:
        print_json(result.to_dict())
    else:
        console.print(summary_table(result.summary))


def summary_table(summary):
    """A rich Table of a :class:`~undertow.io.info.LogSummary`, one row per stream."""
    from rich.table import Table

    table = Table(title=f"{summary.source or 'log'}: {summary.duration_s:.1f} s")
    table.add_column("stream", no_wrap=True)
    for col in ("messages", "rate Hz", "span s", "invalid", "missing values"):
        table.add_column(col, justify="right")
    for s in summary.streams:
        detail = ", ".join(f"{k} {v}" for k, v in s.missing_detail.items() if v)
        table.add_row(
            s.name,
            str(s.messages),
            f"{s.rate_hz:.2f}",
            f"{s.start_s:.3f} - {s.end_s:.3f}",
            str(s.invalid),
            f"{s.missing_values}" + (f" ({detail})" if detail else ""),
        )
    return table


@app.command()
@user_errors
def simulate(
    scenario: Annotated[
        str | None, typer.Argument(help="Built-in scenario name or a scenario YAML file.")
    ] = None,
    out_dir: Annotated[Path | None, typer.Option("--out", help="Output directory.")] = None,
    seed: Annotated[
        int | None,
        typer.Option(
            help="Random seed, >= 0 (runs are deterministic per seed). Default: the scenario"
            " file's own seed (a written scenario.yaml reproduces its run), else 0."
        ),
    ] = None,
    list_: Annotated[bool, typer.Option("--list", help="List the built-in scenarios.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output directory.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q")] = False,
) -> None:
    """Simulate a wave-tank run: ROS 2 bag, ground truth (TUM, 2000 Hz), floor scan (PLY).

    Example: `undertow simulate wave-a0.10-f0.75 --out runs/a10f075 --seed 3`

    Re-run it exactly: `undertow simulate runs/a10f075/scenario.yaml --out runs/again`
    """
    from ..commands.data import RUN_FILES, builtin_scenarios, simulate_to_folder

    if list_:
        for name, description in builtin_scenarios():
            console.print(f"[bold]{name}[/]  {description}", highlight=False)
        return
    if scenario is None or out_dir is None:
        raise UndertowError("simulate needs a SCENARIO and --out DIR (or --list)")
    if seed is not None and seed < 0:
        raise UndertowError(f"--seed {seed}: must be a non-negative integer")
    with progress_bar(quiet) as progress:
        simulate_to_folder(
            scenario,
            out_dir,
            seed,
            overwrite,
            on_start=lambda label: progress.add_task(label, total=None),
        )
    if not quiet:
        err.print(f"wrote {out_dir}/{', '.join(RUN_FILES)}", soft_wrap=True, highlight=False)
