"""The readiness check: check (parse, call :func:`undertow.commands.check.check_file`, print
one block per stream, then what is missing and each problem with its fix)."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated

import typer

from ._app import (
    ConfigOption,
    TimeOption,
    TopicsOption,
    app,
    console,
    err,
    print_json,
    print_warnings,
    user_errors,
)


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
    from ..commands.check import check_file

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
