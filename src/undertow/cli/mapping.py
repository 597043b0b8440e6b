"""Mapping commands: map, evaluate map."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._util.atomic import check_output_folder
from ..errors import UndertowError
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
        float | None, typer.Option(help="bki only: isotropic length scale, m (0.15).")
    ] = None,
    prior: Annotated[Path | None, typer.Option(help="Seed from a saved map.npz.")] = None,
    variance_bounds: Annotated[
        str | None,
        typer.Option(
            help="adaptive only: fixed pose-variance bounds for the length scales, six numbers "
            "min_x,min_y,min_z,max_x,max_y,max_z (m^2), so maps of several logs (or online "
            "updates) share one normalization; default: min and max over this log's samples."
        ),
    ] = None,
    config: ConfigOption = None,
    topics: TopicsOption = None,
    overwrite: OverwriteOption = False,
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="No progress or summary on stderr.")
    ] = False,
) -> None:
    """Occupancy map of the seafloor from DVL beams and sonar ranges; writes map.npz, map.ply
    (occupied cell centres with mean and variance) and config.yaml.

    Example: `undertow map runs/a10/log --trajectory runs/a10/proposed --method adaptive
    --out runs/a10/map`
    """
    from ..mapping.config import MappingConfig
    from ..mapping.run import map_log, save_map
    from ..settings import Settings
    from ..trajectory import Trajectory

    check_output_folder(out_dir, overwrite, inputs=[log_path, trajectory, prior, config, topics])
    trajectory_file = trajectory / "trajectory.npz" if trajectory.is_dir() else trajectory
    _check_npz(trajectory_file, "a trajectory.npz written by `undertow localize` (or its folder)")
    if prior is not None:
        prior = prior / "map.npz" if prior.is_dir() else prior
        _check_npz(prior, "a map.npz written by `undertow map` (or its folder)", "--prior ")
    settings = Settings.from_yaml(config)
    options = {
        "method": method,
        "resolution": resolution,
        "length_scale": length_scale,
        "variance_bounds": _variance_bounds(variance_bounds),
    }
    given = {k: v for k, v in options.items() if v is not None}  # options win over the file
    cfg = MappingConfig.from_dict({**settings.mapping.model_dump(), **given})
    for option, value, applies in (
        ("--length-scale", length_scale, "bki"),
        ("--variance-bounds", variance_bounds, "adaptive"),
    ):
        if value is not None and cfg.method != applies:
            raise UndertowError(f"{option} applies to the {applies} method, not {cfg.method}")
    with _progress(quiet) as progress:
        progress.add_task(f"mapping ({cfg.method})", total=None)
        log = _load_log(log_path, topics, settings)
        result = map_log(log, Trajectory.load_npz(trajectory_file), cfg, prior=prior)
        save_map(result, out_dir, overwrite)
    if not quiet:
        normalization = result.metadata["mapper"].get("normalization")
        how = f", {normalization} normalization" if normalization else ""
        err.print(
            f"wrote {out_dir}/map.npz, map.ply ({result.metadata['occupied_cells']} occupied "
            f"cells{how}), config.yaml"
        )


def _check_npz(path: Path, expected: str, prefix: str = "") -> None:
    """A wrong kind of file (a .tum, .ply, .yaml) named as an .npz input: one clear line."""
    from ..errors import ReaderError
    from ..mapping.grid import not_an_npz

    problem = not_an_npz(path, expected)
    if problem:
        raise ReaderError(prefix + problem)


def _variance_bounds(text: str | None):
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 6:
        raise UndertowError(
            "--variance-bounds: expected six comma-separated numbers "
            f"min_x,min_y,min_z,max_x,max_y,max_z (m^2), got {text!r}"
        )
    return (tuple(values[:3]), tuple(values[3:]))


@evaluate_app.command("map")
@user_errors
def evaluate_map_command(
    map_path: Annotated[Path, typer.Argument(metavar="MAP", help="map.npz, map.ply or folder.")],
    ground_truth: Annotated[Path, typer.Argument(help="Ground-truth point cloud (PLY).")],
    threshold: Annotated[
        float | None,
        typer.Option(
            help="Occupied if mean > threshold, in (0, 1); default: the threshold the map was "
            "made with (mapping.occupied_threshold; 0.5 for maps that do not record it). A "
            "map.npz only: a map.ply holds the cells already thresholded when it was written."
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Average cloud-to-cloud distance map -> ground truth (CloudCompare's C2C), occupied cells
    (the paper's Table IV) and the reverse distance (coverage).

    Example: `undertow evaluate map runs/a10/map runs/a10/ground_truth.ply --json`
    """
    from ..errors import DataError
    from ..evaluation.cloud import evaluate_map, map_threshold
    from ..io.ply import read_ply
    from ..mapping.grid import OccupancyMap

    if threshold is not None and not 0.0 < threshold < 1.0:
        raise UndertowError(f"--threshold must be in (0, 1), got {threshold}")
    if map_path.is_dir():
        map_path = map_path / "map.npz"
    resolution, threshold_from = None, "the map.ply (thresholded when it was written)"
    if map_path.suffix.lower() == ".ply":
        if threshold is not None:
            raise UndertowError(
                f"--threshold applies to a map.npz; {map_path} holds the cells already "
                "thresholded when it was written (give the map.npz, or leave --threshold out)"
            )
        points = read_ply(map_path)[0]
        if len(points) == 0:
            err.print(
                f"[yellow]warning:[/] {map_path}: the map has no points",
                highlight=False,
                soft_wrap=True,
            )
    else:
        occupancy = OccupancyMap.load(map_path)
        threshold, threshold_from = map_threshold(occupancy, threshold)
        points = occupancy.points(threshold)
        resolution = occupancy.resolution
    gt_points = read_ply(ground_truth)[0]
    if len(gt_points) == 0:
        raise DataError(f"{ground_truth}: the ground-truth cloud has no points")
    result = evaluate_map(points, gt_points, resolution=resolution)
    values = {**result.to_dict(), "threshold": threshold, "threshold_from": threshold_from}
    if as_json:
        _print_json(values)
        return
    for key, value in values.items():
        shown = f"{value:.4f}" if isinstance(value, float) and key != "threshold" else value
        console.print(f"{key:>28}: {shown}", highlight=False)
