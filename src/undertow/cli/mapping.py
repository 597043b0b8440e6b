"""Mapping commands: map, evaluate map."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._atomic import check_output_folder
from ._app import (
    ConfigOption,
    OverwriteOption,
    TopicsOption,
    _load_log,
    _print_json,
    _progress,
    app,
    console,
    err,
    evaluate_app,
    user_errors,
)


@app.command("map")
@user_errors
def map_command(
    log_path: Annotated[Path, typer.Argument(metavar="LOG", help="Bag or A50 JSON log.")],
    trajectory: Annotated[
        Path, typer.Option(help="Localization folder or trajectory.npz (with covariances).")
    ],
    out_dir: Annotated[Path, typer.Option("--out", help="Output directory.")],
    method: Annotated[str | None, typer.Option(help="adaptive (default) | bki | csm")] = None,
    resolution: Annotated[float | None, typer.Option(help="Grid size, m (0.1).")] = None,
    length_scale: Annotated[
        float | None, typer.Option(help="Isotropic length scale of bki, m (0.15).")
    ] = None,
    prior: Annotated[Path | None, typer.Option(help="Seed from a saved map.npz.")] = None,
    config: ConfigOption = None,
    topics: TopicsOption = None,
    overwrite: OverwriteOption = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q")] = False,
) -> None:
    """Occupancy map of the seafloor from DVL beams and sonar ranges; writes map.npz, map.ply
    (occupied cell centres with mean and variance) and config.yaml.

    Example: `undertow map runs/a10/log --trajectory runs/a10/proposed --method adaptive
    --out runs/a10/map`
    """
    from ..config import Settings
    from ..mapping.config import MappingConfig
    from ..mapping.run import map_log, save_map
    from ..trajectory import Trajectory

    check_output_folder(out_dir, overwrite)
    settings = Settings.from_yaml(config)
    options = {"method": method, "resolution": resolution, "length_scale": length_scale}
    given = {k: v for k, v in options.items() if v is not None}  # options win over the file
    cfg = MappingConfig.from_dict({**settings.mapping.model_dump(), **given})
    with _progress(quiet) as progress:
        progress.add_task(f"mapping ({cfg.method})", total=None)
        log = _load_log(log_path, topics, settings)
        result = map_log(log, Trajectory.load_npz(trajectory), cfg, prior=prior)
        save_map(result, out_dir, overwrite)
    if not quiet:
        err.print(
            f"wrote {out_dir}/map.npz, map.ply ({result.metadata['occupied_cells']} occupied "
            "cells), config.yaml"
        )


@evaluate_app.command("map")
@user_errors
def evaluate_map_command(
    map_path: Annotated[Path, typer.Argument(metavar="MAP", help="map.npz, map.ply or folder.")],
    ground_truth: Annotated[Path, typer.Argument(help="Ground-truth point cloud (PLY).")],
    threshold: Annotated[float, typer.Option(help="Occupied if mean > threshold.")] = 0.5,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Average cloud-to-cloud distance map -> ground truth (CloudCompare's C2C), occupied cells
    (the paper's Table IV) and the reverse distance (coverage).

    Example: `undertow evaluate map runs/a10/map runs/a10/ground_truth.ply --json`
    """
    from ..evaluation.cloud import evaluate_map
    from ..io.ply import read_ply
    from ..mapping.grid import OccupancyMap

    if map_path.is_dir():
        map_path = map_path / "map.npz"
    resolution = None
    if map_path.suffix == ".ply":
        points, _ = read_ply(map_path)
    else:
        occupancy = OccupancyMap.load(map_path)
        points, resolution = occupancy.points(threshold), occupancy.resolution
    gt_points, _ = read_ply(ground_truth)
    result = evaluate_map(points, gt_points, resolution=resolution)
    if as_json:
        _print_json(result.to_dict())
        return
    for key, value in result.to_dict().items():
        console.print(
            f"{key:>28}: {value:.4f}" if isinstance(value, float) else f"{key:>28}: {value}"
        )
