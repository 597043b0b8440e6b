"""Mapping commands: map, evaluate map."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from ..errors import UndertowError
from ._app import (
    ConfigOption,
    OverwriteOption,
    TimeOption,
    TopicsOption,
    app,
    console,
    err,
    evaluate_app,
    print_json,
    progress_bar,
    settings_with_time,
    user_errors,
)

TrajectoryOption = Annotated[
    Path,
    typer.Option(
        help="Localization folder or trajectory.npz (with covariances), or a TUM file (t tx ty "
        "tz qx qy qz qw, optionally + sx sy sz sroll spitch syaw std columns; see "
        "docs/mapping.md)."
    ),
]
PoseStdOption = Annotated[
    str | None,
    typer.Option(
        metavar="SX,SY,SZ[,SROLL,SPITCH,SYAW]",
        help="TUM trajectory only: constant pose standard deviations (m, rad; the file's axes), "
        "for a file without std columns or to replace them (settings: trajectory: "
        "{position_std_m, orientation_std_rad}).",
    ),
]
TrajectoryFrameOption = Annotated[
    str | None,
    typer.Option(
        metavar="ned|enu",
        help="TUM trajectory only: ned (z down; undertow's) or enu (z up, body forward-left-up); "
        "default: detected from the log's depth (NED when it cannot be).",
    ),
]


@app.command("map")
@user_errors
def map_command(
    log_path: Annotated[
        Path, typer.Argument(metavar="LOG", help="Bag, A50 JSON log or MAVLink .tlog.")
    ],
    trajectory: TrajectoryOption,
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
    tiles: Annotated[
        float | None,
        typer.Option(
            metavar="SIZE_M",
            help="Map in square x-y tiles of SIZE_M metres, each an independent Dask task "
            "(halo of the kernel support; the merged map equals the untiled one); the tiles "
            "are also written to OUT/tiles.",
        ),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="With --tiles: local (a cluster of worker processes, default) | threads | sync "
            "| tcp://host:8786 (a running Dask scheduler)."
        ),
    ] = None,
    pose_std: PoseStdOption = None,
    trajectory_frame: TrajectoryFrameOption = None,
    config: ConfigOption = None,
    topics: TopicsOption = None,
    time: TimeOption = None,
    overwrite: OverwriteOption = False,
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="No progress or summary on stderr.")
    ] = False,
) -> None:
    """Occupancy map of the seafloor from DVL beams and sonar ranges; writes map.npz, map.ply
    (occupied cell centres with mean and variance) and config.yaml.

    Example: `undertow map runs/a10/log --trajectory runs/a10/proposed --method adaptive
    --out runs/a10/map`; from a TUM file: `--trajectory est.tum --pose-std 0.05,0.05,0.02`
    """
    from ..commands.mapping import map_file

    options = {"method": method, "resolution": resolution, "length_scale": length_scale,
               "variance_bounds": _variance_bounds(variance_bounds)}  # fmt: skip
    given = {k: v for k, v in options.items() if v is not None}  # options win over the file
    frame = _trajectory_frame(trajectory_frame)
    with progress_bar(quiet) as progress:
        progress.add_task(f"mapping ({method})" if method else "mapping", total=None)
        result = map_file(log_path, trajectory, settings_with_time(config, time), topics=topics,
                          prior=prior,
                          out_dir=out_dir, overwrite=overwrite, tiles=tiles,
                          scheduler=scheduler, pose_std=_pose_std(pose_std),
                          trajectory_frame=frame, **given)  # fmt: skip
    print_warnings(result.warnings)
    if not quiet:
        _print_trajectory(result.metadata.get("trajectory", {}))
        normalization = result.metadata["mapper"].get("normalization")
        how = f", {normalization} normalization" if normalization else ""
        tiled = result.metadata.get("tiling")
        where = f", tiles/ ({tiled['tiles']} tiles on {tiled['scheduler']})" if tiled else ""
        err.print(
            f"wrote {out_dir}/map.npz, map.ply ({result.metadata['occupied_cells']} occupied "
            f"cells{how}), config.yaml{where}"
        )


def _print_trajectory(used: dict) -> None:
    """The one line stating how a TUM trajectory was read (a trajectory.npz: nothing)."""
    if str(used.get("format", "")).startswith("TUM"):
        err.print(
            f"trajectory: {used['file']} ({used['format']}); frame {used['frame']} "
            f"({used['frame_source']}); covariance: {used['covariance']}",
            highlight=False,
            soft_wrap=True,
        )


def print_warnings(lines: list[str]) -> None:
    for line in lines:
        err.print(f"[yellow]warning:[/] {line}", highlight=False, soft_wrap=True)


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


def _pose_std(text: str | None):
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) not in (3, 6):
        raise UndertowError(
            "--pose-std: expected 3 or 6 comma-separated numbers SX,SY,SZ[,SROLL,SPITCH,SYAW] "
            f"(m, rad), got {text!r}"
        )
    if not all(math.isfinite(v) and v >= 0 for v in values):
        raise UndertowError(
            f"--pose-std: standard deviations must be finite and >= 0, got {text!r}"
        )
    return tuple(values)


def _trajectory_frame(text: str | None) -> str | None:
    if text is not None and text not in ("ned", "enu", "auto"):
        raise UndertowError(f"--trajectory-frame: expected ned or enu (or auto), got {text!r}")
    return text


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
    from ..commands.mapping import evaluate_map_file

    result = evaluate_map_file(map_path, ground_truth, threshold)
    print_warnings(result.warnings)
    values = result.to_dict()
    if as_json:
        print_json(values)
        return
    for key, value in values.items():
        shown = f"{value:.4f}" if isinstance(value, float) and key != "threshold" else value
        console.print(f"{key:>28}: {shown}", highlight=False)
