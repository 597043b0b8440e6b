"""Commands on logs and the simulator: info, simulate (parse, call :mod:`undertow.jobs.data`,
print)."""

from __future__ import annotations

import functools
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
    from ..jobs.data import info_file
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
    from ..jobs.data import RUN_FILES, builtin_scenarios, simulate_to_folder

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


@app.command()
@user_errors
def check(
    path: Annotated[
        Path, typer.Argument(help="ROS 1 bag, ROS 2 bag directory, A50 JSON, .tlog or .BIN log.")
    ],
    write_config: Annotated[
        Path | None,
        typer.Option("--write-config", help="Write the proposed settings file here."),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")] = False,
    topics: TopicsOption = None,
    config: ConfigOption = None,
    time: TimeOption = None,
) -> None:
    """Is this log ready to localize and map, and what should I set? Per stream: topic, type,
    rate, time base, gaps, units evidence, invalid share and its use; what is missing; the
    settings lines that fix each problem. Exit 0 when the log can be localized, else 1.

    Example: `undertow check SO_bag --write-config robot.yaml` then
    `undertow localize SO_bag --config robot.yaml --out run1`
    """
    from ..jobs.check import check_file

    result = check_file(path, config, topics=topics, time=time, write_config=write_config)
    print_warnings(result.warnings)
    if as_json:
        print_json(result.to_dict())
    else:
        _print_check(result)
    if not result.ready:
        err.print(f"[bold red]not ready:[/] {result.reason}", highlight=False, soft_wrap=True)
        raise typer.Exit(1)


def _print_check(result) -> None:
    """One block per stream (topic and type, rate, span, gaps, invalid share; its use and the
    evidence behind its units), then what is missing and each problem with its fix."""
    out = functools.partial(console.print, highlight=False, soft_wrap=True)
    tb = result.time_base
    out(f"[bold]{result.path}[/] ({result.format})")
    if tb:
        what = {"header": "header stamps ", "record": "record (receive) time "}
        out(f"time base: {what.get(tb.get('base'), '')}({tb.get('reason')})")
    for s in result.streams:
        where = f"{s.topic} ({s.msgtype})" if s.topic else ""
        gaps = f"{s.gaps} gaps (longest {s.max_gap_s:.2f} s)" if s.gaps else "no gaps"
        out(f"[bold]{s.stream}[/] {where}: {s.messages} messages, {s.rate_hz:.2f} Hz over "
            f"{s.span_s:.1f} s, {gaps}, {100 * s.invalid_share:.1f} % invalid")  # fmt: skip
        out(f"    use: {s.use}")
        if s.evidence:
            out(f"    {s.evidence}")
    for line in result.missing:
        out(f"[yellow]missing:[/] {line}")
    for p in result.problems:
        out(f"[yellow]problem:[/] {p.what}")
        if p.fix:
            out("    fix:  " + p.fix.replace("\n", "\n          "))
    if result.written:
        out(f"wrote {result.written}")
    if result.ready:
        out(f"[green]{result.reason}[/]")
