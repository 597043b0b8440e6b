"""`undertow waves`: the wave condition over time from a log's own sensors."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ._app import (
    ConfigOption,
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
def waves(
    log_path: Annotated[
        Path, typer.Argument(metavar="LOG", help="Bag, A50 JSON log or MAVLink .tlog.")
    ],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
    plot: Annotated[
        Path | None, typer.Option(help="Draw the estimate over time (and the truth) to this PNG.")
    ] = None,
    platform: Annotated[
        str,
        typer.Option(
            help="auto | rigid (sensor held firm: carriage, station keeping) | free (vehicle "
            "riding the orbital motion)."
        ),
    ] = "auto",
    window_periods: Annotated[
        float, typer.Option(help="Window length in wave periods (stepped by half a window).")
    ] = 20.0,
    water_depth: Annotated[
        float | None,
        typer.Option(help="Water depth h, m (default: barometer depth + DVL altitude)."),
    ] = None,
    config: ConfigOption = None,
    topics: TopicsOption = None,
) -> None:
    """Estimate the sea state (amplitude, frequency, direction) per window from the barometer,
    the DVL and the orientation, with no wave probe; compared with the truth when the log has
    one (a simulated run, a wave probe).

    Example: `undertow waves runs/a10/log --plot waves.png`
    """
    from ..commands.waves import waves_file

    result = waves_file(
        log_path, config, topics=topics, platform=platform, window_periods=window_periods,
        water_depth_m=water_depth, plot=plot,
    )  # fmt: skip
    print_warnings(result.warnings)
    if as_json:
        print_json(result.to_dict())
    else:
        console.print(window_table(result))
        for note in result.estimate.notes:
            err.print(f"note: {note}", highlight=False, soft_wrap=True)
    if plot is not None:
        err.print(f"wrote {plot}")


def _num(value, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def window_table(result):
    """A rich Table, one row per estimation window (and the truth at its centre, if known)."""
    from rich import box
    from rich.table import Table

    est = result.estimate
    table = Table(
        title=f"sea state: {len(est.windows)} window(s) of {est.window_s:.0f} s",
        caption="t window centre, a amplitude, f wave and fe encounter frequency, dir "
        "propagation direction (world, deg), rel relative to the heading, fit variance "
        "explained; --json for the window spans"
        + (f"; true: {result.truth.source}" if result.truth is not None else ""),
        box=box.SIMPLE_HEAD,
        pad_edge=False,
        padding=(0, 1),
    )
    columns = ["t s", "a m", "f Hz", "fe Hz", "dir", "rel", "platform", "fit"]
    if result.truth is not None:
        columns += ["true a", "true f"]
    for col in columns:
        table.add_column(col, justify="left" if col == "platform" else "right", no_wrap=True)
    for w in est.windows:
        row = [
            f"{0.5 * (w.t_start + w.t_end):.1f}", f"{w.amplitude_m:.3f}",
            _num(w.frequency_hz, ".3f"), _num(w.encounter_frequency_hz, ".3f"),
            _num(w.direction_deg, ".0f"), _num(w.relative_direction_deg, ".0f"), w.platform,
            f"{w.explained:.2f}",
        ]  # fmt: skip
        if result.truth is not None:
            a, f = result.truth.at(0.5 * (w.t_start + w.t_end))
            row += [f"{float(a):.3f}", "-" if not float(f) == float(f) else f"{float(f):.3f}"]
        table.add_row(*row)
    return table
