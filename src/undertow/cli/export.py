"""The export command: a map in the formats surveyors and robots use."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ._app import app, err, user_errors


@app.command("export")
@user_errors
def export_command(
    map_path: Annotated[Path, typer.Argument(metavar="MAP", help="map.npz or its folder.")],
    out: Annotated[Path, typer.Option("--out", help="Output file.")],
    format_: Annotated[
        str | None,
        typer.Option(
            "--format",
            help="geotiff (.tif) | octomap (.bt occupied/free, .ot probabilities) | las | laz | "
            "ply; default: from the --out suffix.",
        ),
    ] = None,
    resolution: Annotated[
        float | None, typer.Option(help="geotiff only: cell size, m (default: the map's).")
    ] = None,
    origin: Annotated[
        str | None,
        typer.Option(
            metavar="LAT,LON",
            help="geotiff, las, laz: WGS 84 position of the map's origin; written in its UTM zone.",
        ),
    ] = None,
    utm: Annotated[
        str | None,
        typer.Option(
            metavar="E,N,ZONE",
            help="geotiff, las, laz: the map's origin as easting, northing and a UTM zone (32N, "
            "32S) or the EPSG code of a projected CRS (EPSG:25832).",
        ),
    ] = None,
    threshold: Annotated[
        float | None,
        typer.Option(help="Occupied if mean > threshold, in (0, 1); default: the map's own."),
    ] = None,
    iho_order: Annotated[
        str | None,
        typer.Option(
            help="geotiff only: keep the columns whose depth meets this IHO S-44 order "
            "(exclusive | special | 1a | 1b | 2 | none; default 1a) when the std band is a "
            "propagated uncertainty (a tpu map): 1.96 std <= sqrt(a^2 + (b depth)^2).",
        ),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary on stderr.")] = False,
) -> None:
    """Write a map as a GeoTIFF bathymetric grid (depth, std, coverage), an OctoMap octree
    (octovis, ROS), a LAS/LAZ cloud of occupied cells (mean and variance as extra dimensions)
    or a PLY cloud. GeoTIFF and LAS are georeferenced with --origin or --utm, in local metres
    otherwise; axes and conventions: docs/export.md.

    Example: `undertow export runs/a10/map --out bathy.tif --resolution 0.5 --origin
    59.9081,10.7528`
    """
    from ..commands.export import export_map

    result = export_map(map_path, out, format_, resolution=resolution, origin=origin, utm=utm,
                        threshold=threshold, iho_order=iho_order)  # fmt: skip
    for line in result.warnings:
        err.print(f"[yellow]warning:[/] {line}", highlight=False, soft_wrap=True)
    if not quiet:
        for line in result.notes:
            err.print(line, highlight=False, soft_wrap=True)
        err.print(result.summary(), highlight=False, soft_wrap=True)
