"""The study: characterize, reproduce, demo."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ._app import (
    ConfigOption,
    QuietOption,
    TopicsOption,
    app,
    console,
    err,
    fmt_number,
    print_json,
    progress_bar,
    user_errors,
)


@app.command("characterize")
@user_errors
def characterize_command(
    logs: Annotated[list[Path], typer.Argument(metavar="LOG...", help="Runs with a wave probe.")],
    out: Annotated[
        Path | None, typer.Option("--out", help="Noise profile YAML for `undertow localize`.")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    config: ConfigOption = None,
    topics: TopicsOption = None,
    quiet: QuietOption = False,
) -> None:
    """Wave amplitude and frequency (wave probe) and the DVL noise per axis during the waves,
    about the true motion (the paper's Table I), plus the barometer's wave-induced depth noise.
    A calm run among the logs is the reference whose noise is subtracted.

    Example: `undertow characterize runs/calm/log runs/a10/log runs/a05/log --out profile.yaml`
    """
    from ..commands.study import characterize_files

    with progress_bar(quiet) as progress:
        progress.add_task("characterizing", total=None)
        result = characterize_files(logs, config, topics=topics, out=out)
    for warning in result.warnings:
        err.print(f"[yellow]warning:[/] {warning}", highlight=False, soft_wrap=True)
    if as_json:
        print_json(result.to_dict())
        return
    console.print(_characterize_table(result.rows()))
    if out is not None and not quiet:
        err.print(f"wrote {out}")


def _characterize_table(rows: list[dict]):
    from rich.table import Table

    table = Table(title="Wave characterization (DVL std in the DVL frame, m/s)")
    columns = ("run", "a (m)", "f (Hz)", "onboard a", "onboard f", "vx", "vy", "vz", "extra vx",
               "depth std (m)")  # fmt: skip
    for col in columns:
        table.add_column(col, justify="right")
    for row in rows:
        table.add_row(
            row["source"],
            fmt_number(row["amplitude_m"]),
            fmt_number(row["frequency_hz"]),
            fmt_number(row.get("onboard_amplitude_m")),
            fmt_number(row.get("onboard_frequency_hz")),
            *(fmt_number(v) for v in row["dvl_std_m_s"]),
            fmt_number(row["dvl_extra_std_m_s"][0]),
            fmt_number(row["depth_std_m"]),
        )
    return table


@app.command()
@user_errors
def reproduce(
    out_dir: Annotated[Path, typer.Option("--out", help="Results folder.")] = Path("results"),
    seeds: Annotated[int, typer.Option(help="Number of independent seeds (Monte Carlo).")] = 1,
    first_seed: Annotated[
        int, typer.Option(help="Seeds are first_seed, first_seed+1, ... (>= 0).")
    ] = 0,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Dask scheduler for the seeds after the first (the first runs in this process "
            "and makes the figures; unused with --seeds 1): local (default: a local cluster), "
            "threads, sync, or the address of a running scheduler (tcp://host:8786). Checked "
            "before any work."
        ),
    ] = None,
    rock_survey: Annotated[bool, typer.Option(help="Also run the rock survey.")] = True,
    map_scenarios: Annotated[
        bool,
        typer.Option(help="Also Table IV on the mapping scenarios (mhl-basin, field-survey)."),
    ] = True,
    peers: Annotated[
        bool,
        typer.Option(
            help="Also the peers table: the UKF beside the factor graph (batch, "
            "iSAM2) and the InEKF on six scenarios (needs undertow[peers] for gtsam)."
        ),
    ] = True,
    peer_time_cap: Annotated[
        float | None,
        typer.Option(
            help="Wall-time cap (s) of each batch factor-graph run (default 900; 0 "
            "leaves it out); a capped run is reported as such in the table."
        ),
    ] = None,
    peer_scenarios: Annotated[
        str | None,
        typer.Option(
            help="The peers table's scenarios, comma-separated (default: the three wave "
            "conditions, rock-survey, field-survey, changing-sea-survey)."
        ),
    ] = None,
    quiet: QuietOption = False,
) -> None:
    """The paper's experiments end to end: simulate, characterize, localize (4 variants), map
    (CSM, BKI, adaptive BKI), evaluate; tables with the paper's values, figures, report.html.

    Example: `undertow reproduce --seeds 10 --out results_mc`
    """
    from ..commands import study

    _run_study(study.reproduce, out_dir, quiet, seeds=seeds, first_seed=first_seed,
               scheduler=scheduler, rock_survey=rock_survey,
               map_scenarios=map_scenarios, peers=peers,
               peer_time_cap_s=peer_time_cap,
               peer_scenarios=_names(peer_scenarios))  # fmt: skip


def _names(text: str | None) -> list[str] | None:
    """A comma-separated list of names (None if not given)."""
    return None if text is None else [n.strip() for n in text.split(",") if n.strip()]


@app.command()
@user_errors
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Results folder.")] = Path("results"),
) -> None:
    """The main job with its defaults: `undertow reproduce --seeds 1 --out results`."""
    from ..commands import study

    _run_study(study.demo, out_dir, quiet=False)


def _run_study(job, out_dir: Path, quiet: bool, **options) -> None:
    """Run a study job under a progress line, then print its tables and where it wrote."""
    from rich.markdown import Markdown

    with progress_bar(quiet) as progress:
        task = progress.add_task("starting", total=None)
        result = job(out_dir, progress=lambda msg: progress.update(task, description=msg),
                     **options)  # fmt: skip
    if quiet:
        return
    console.print(Markdown(result.markdown))
    for seed, message in result.failures.items():
        err.print(f"[red]seed {seed} failed:[/] {message}", highlight=False)
    err.print(
        f"results in {out_dir}/ (tables.md, tables.json, figures/, runs/); report: "
        f"{result.report} ({result.wall_s:.0f} s)"
    )
