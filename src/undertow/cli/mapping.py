"""Mapping commands: map, evaluate map."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from ..errors import UndertowError
from ._app import (
    ConfigOption,
    InPiecesOption,
    OverwriteOption,
    PieceSOption,
    QuietOption,
    SoundSpeedOption,
    TimeOption,
    TopicsOption,
    app,
    console,
    err,
    evaluate_app,
    pieces_option,
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
MethodOption = Annotated[
    str | None,
    typer.Option(help="tpu (default: each hit's total propagated uncertainty) | adaptive "
                 "(the paper's) | bki | csm"),
]  # fmt: skip
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
    method: MethodOption = None,
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
    in_pieces: InPiecesOption = None,
    piece_s: PieceSOption = None,
    pose_std: PoseStdOption = None,
    trajectory_frame: TrajectoryFrameOption = None,
    config: ConfigOption = None,
    topics: TopicsOption = None,
    time: TimeOption = None,
    sound_speed: SoundSpeedOption = None,
    overwrite: OverwriteOption = False,
    quiet: QuietOption = False,
) -> None:
    """Occupancy map of the seafloor from DVL beams and sonar ranges; writes map.npz, map.ply
    (occupied cell centres with mean and variance) and config.yaml.

    Example: `undertow map runs/a10/log --trajectory runs/a10/proposed --out runs/a10/map`
    (the default tpu mapper; `--method adaptive` for the paper's); from a TUM file:
    `--trajectory est.tum --pose-std 0.05,0.05,0.02`
    """
    from ..commands.mapping import map_file

    options = {"method": method, "resolution": resolution, "length_scale": length_scale,
               "variance_bounds": _variance_bounds(variance_bounds)}  # fmt: skip
    given = {k: v for k, v in options.items() if v is not None}  # options win over the file
    frame = _trajectory_frame(trajectory_frame)
    with progress_bar(quiet) as progress:
        progress.add_task(f"mapping ({method})" if method else "mapping", total=None)
        settings = settings_with_time(config, time, sound_speed)
        result = map_file(log_path, trajectory, settings, topics=topics, prior=prior,
                          out_dir=out_dir, overwrite=overwrite, tiles=tiles,
                          scheduler=scheduler, pose_std=_pose_std(pose_std),
                          trajectory_frame=frame, **pieces_option(in_pieces, piece_s),
                          **given)  # fmt: skip
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


def _numbers(text: str, option: str, counts: tuple[int, ...], expected: str) -> list[float]:
    """The comma-separated numbers of ``option``, as many as one of ``counts``; else one line."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) not in counts:
        raise UndertowError(f"{option}: expected {expected}, got {text!r}")
    return values


def _variance_bounds(text: str | None):
    if text is None:
        return None
    values = _numbers(text, "--variance-bounds", (6,), "six comma-separated numbers "
                      "min_x,min_y,min_z,max_x,max_y,max_z (m^2)")  # fmt: skip
    return (tuple(values[:3]), tuple(values[3:]))


def _pose_std(text: str | None):
    if text is None:
        return None
    values = _numbers(text, "--pose-std", (3, 6), "3 or 6 comma-separated numbers "
                      "SX,SY,SZ[,SROLL,SPITCH,SYAW] (m, rad)")  # fmt: skip
    if not all(math.isfinite(v) and v >= 0 for v in values):
        raise UndertowError(
            f"--pose-std: standard deviations must be finite and >= 0, got {text!r}"
        )
    return tuple(values)


def _trajectory_frame(text: str | None) -> str | None:
    if text is not None and text not in ("ned", "enu", "auto"):
        raise UndertowError(f"--trajectory-frame: expected ned or enu (or auto), got {text!r}")
    return text


#: `evaluate map --iho-order`
EvaluatedOrder = Annotated[
    str | None,
    typer.Option(
        help="A map.npz whose depth std is a propagated uncertainty (a tpu map): judge the "
        "columns whose depth meets this IHO S-44 order (exclusive | special | 1a | 1b | 2 | "
        "none; default 1a): 1.96 std <= sqrt(a^2 + (b depth)^2).",
    ),
]


@evaluate_app.command("map")
@user_errors
def evaluate_map_command(
    map_path: Annotated[
        Path,
        typer.Argument(
            metavar="MAP",
            help="map.npz (or its folder), map.ply, or a GeoTIFF of `undertow export`.",
        ),
    ],
    ground_truth: Annotated[
        Path,
        typer.Argument(
            metavar="TRUTH",
            help="Ground truth: a PLY cloud (undertow's frame), an XYZ file (x y z per line) or "
            "a GeoTIFF bathymetry (band 1).",
        ),
    ],
    threshold: Annotated[
        float | None,
        typer.Option(
            help="Occupied if mean > threshold, in (0, 1); default: the threshold the map was "
            "made with (mapping.occupied_threshold; 0.5 for maps that do not record it). A "
            "map.npz only: a map.ply holds the cells already thresholded when it was written."
        ),
    ] = None,
    origin: Annotated[
        str | None,
        typer.Option(
            metavar="LAT,LON",
            help="WGS 84 position of the map's origin, for a truth (or map) with a projected CRS; "
            "as `undertow export --origin`.",
        ),
    ] = None,
    utm: Annotated[
        str | None,
        typer.Option(
            metavar="E,N,ZONE",
            help="The map's origin as easting, northing and a UTM zone (32N) or EPSG code; as "
            "`undertow export --utm`.",
        ),
    ] = None,
    truth_z: Annotated[
        str | None,
        typer.Option(
            help="depth | elevation: the sign of an XYZ or GeoTIFF truth's z (default: detected "
            "and stated; elevation is negative down)."
        ),
    ] = None,
    truth_frame: Annotated[
        str | None,
        typer.Option(
            help="local | projected: an XYZ truth's columns, x y z of undertow's frame or E N z "
            "of the --origin/--utm CRS (default: projected when the coordinates pass 100 km)."
        ),
    ] = None,
    iho_order: EvaluatedOrder = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print every metric as JSON.")] = False,
) -> None:
    """Judge a map against a ground truth: cloud-to-cloud distance (CloudCompare's C2C) and
    occupied cells (the paper's Table IV), the reverse distance, the surface's RMSE, bias and
    coverage, accuracy, completeness and F-score at 5, 10 and 20 cm, and the depth std's
    calibration (share of the true floor within 1 and 2 sigma).

    Example: `undertow evaluate map runs/a10/map runs/a10/ground_truth.ply --json`
    """
    from ..commands.mapping import evaluate_map_file

    result = evaluate_map_file(map_path, ground_truth, threshold, origin=origin, utm=utm,
                               truth_z=truth_z, truth_frame=truth_frame,
                               iho_order=iho_order)  # fmt: skip
    print_warnings(result.warnings)
    for line in result.notes:
        err.print(f"note: {line}", highlight=False, soft_wrap=True)
    values = result.to_dict()
    if as_json:
        print_json(values)
        return
    for line in map_score_lines(values):
        console.print(line, highlight=False, soft_wrap=True)


def _num(value, digits: int = 4, unit: str = "") -> str:
    if value is None or (isinstance(value, float) and value != value):
        return "n/a"
    return f"{value:.{digits}f}{unit}"


def _pct(value) -> str:
    return "n/a" if value is None or value != value else f"{100 * value:.1f} %"


def map_score_lines(v: dict) -> list[str]:
    """The human-readable table of `undertow evaluate map` from its flat result."""
    from ..mapping.surface import STD_KINDS

    taus = ("5cm", "10cm", "20cm")

    def per_tau(name: str) -> str:
        return "  ".join(f"{t:>4} {_num(v.get(f'{name}_{t}'), 3)}" for t in taus)

    threshold = "n/a" if v["threshold"] is None else f"{v['threshold']:g}"
    calibration = (
        f"{_pct(v['within_1sigma'])} within 1 sigma, {_pct(v['within_2sigma'])} within 2 sigma "
        f"(a true std: 68.3 %, 95.4 %), mean |z| {_num(v['mean_abs_z'], 2)}, "
        f"{v['calibrated_columns']} columns"
        + (f"; std: {STD_KINDS[v['std_kind']]}" if v.get("std_kind") in STD_KINDS else "")
        if v["calibrated_columns"] is not None
        else "n/a (the map holds no depth std)"
    )
    return [
        f"{'C2C map -> truth':<22} mean {_num(v['c2c_mean_m'], unit=' m')}, median "
        f"{_num(v['c2c_median_m'], unit=' m')}, RMSE {_num(v['c2c_rmse_m'], unit=' m')}",
        f"{'occupied cells':<22} {v['occupied_cells']}",
        f"{'truth -> map':<22} mean {_num(v['coverage_mean_m'], unit=' m')} "
        f"({v['ground_truth_in_footprint']} truth points in the map's footprint)",
        f"{'surface':<22} RMSE {_num(v['surface_rmse_m'], unit=' m')}, bias "
        f"{_num(v['surface_bias_m'], unit=' m')}, coverage {_num(v['coverage'], 3)} of "
        f"{v['surveyed_columns']} surveyed columns",
        f"{'accuracy (precision)':<22} {per_tau('precision')}",
        f"{'completeness (recall)':<22} {per_tau('recall')}",
        f"{'F-score':<22} {per_tau('fscore')}",
        f"{'calibration':<22} {calibration}",
        f"{'threshold':<22} {threshold} ({v['threshold_from']})",
        *(
            [f"{'IHO S-44 order':<22} {v['iho_order']} ({v['withheld_columns']} columns withheld)"]
            if v.get("iho_order")
            else []
        ),
    ]
