"""Commands on logs and the simulator: info, simulate."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._util.atomic import check_output_folder
from ..errors import UndertowError
from ._app import (
    _print_json,
    _progress,
    app,
    console,
    err,
    user_errors,
)


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
    from ..io import read_log
    from ..io.info import summarize
    from ..io.topics import TopicMap

    topic_map = TopicMap.from_yaml(topics) if topics else None
    summary = summarize(read_log(path, topics=topic_map))
    if as_json:
        _print_json(summary.to_dict())
    else:
        console.print(summary.to_rich_table())


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
    from ..sim import list_scenarios, load_scenario, write_simulation
    from ..sim import simulate as run_simulation

    if list_:
        for name in list_scenarios():
            console.print(f"[bold]{name}[/]  {load_scenario(name).description}", highlight=False)
        return
    if scenario is None or out_dir is None:
        raise UndertowError("simulate needs a SCENARIO and --out DIR (or --list)")
    if seed is not None and seed < 0:
        raise UndertowError(f"--seed {seed}: must be a non-negative integer")
    spec = load_scenario(scenario)
    check_output_folder(out_dir, overwrite, inputs=[scenario] if Path(scenario).exists() else [])
    seed = spec.seed if seed is None else seed  # given wins; else the scenario's own (default 0)
    with _progress(quiet) as progress:
        progress.add_task(f"simulating {spec.name} (seed {seed})", total=None)
        result = run_simulation(spec, seed=seed)
        write_simulation(result, out_dir, overwrite=overwrite)
    if not quiet:
        err.print(f"wrote {out_dir}/log, ground_truth.tum, ground_truth.ply, scenario.yaml")
