"""`undertow export` as a library function: a map file in, a file in a surveyor's or robot's
format out (:mod:`undertow.io.export`), and a result saying what was written.

    >>> export_map("runs/a10/map", "bathy.tif", origin="59.91,10.75")   # doctest: +SKIP
    >>> export_map("runs/a10/map", "map.bt").summary()                  # doctest: +SKIP
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util.atomic import check_output_file
from ..errors import ConfigError
from ..evaluation.cloud import map_threshold
from ..io.export.frames import check_frame
from ..io.export.georef import from_latlon, from_projected, parse_origin, parse_utm
from ..io.export.geotiff import write_raster
from ..io.export.las import write_map_las
from ..io.export.octree import write_octomap
from ..io.export.raster import resample_surface
from ..io.ply import write_map_ply
from ..mapping.iho import check_order, withheld_notes
from ..mapping.surface import STD_KINDS, map_surface
from ..occupancy import MAP_FILE, OccupancyMap
from .common import npz_file

#: format -> the file suffixes it is written as
FORMATS = {"geotiff": (".tif", ".tiff"), "octomap": (".bt", ".ot"), "las": (".las",),
           "laz": (".laz",), "ply": (".ply",)}  # fmt: skip
#: formats that take --origin / --utm, and the ones that take a frame
GEOREFERENCED = ("geotiff", "las", "laz")
FRAMED = ("octomap", "las", "laz")


@dataclass(frozen=True)
class ExportResult:
    """What was written: ``count`` raster cells with data (geotiff), octree leaves (octomap)
    or points (las, laz, ply); ``frame``, the file's axes (the CRS line when georeferenced);
    the threshold used."""

    path: Path
    format: str
    count: int
    frame: str
    threshold: float | None
    threshold_from: str
    warnings: list[str] = field(default_factory=list)
    std_kind: str = ""  # the GeoTIFF's std band (mapping.surface.STD_KINDS)
    iho_order: str = ""  # the IHO S-44 order the GeoTIFF's columns were held to ("" none)
    notes: list[str] = field(default_factory=list)  # the choices made, one line each

    def summary(self) -> str:
        what = {"geotiff": "cells with data", "octomap": "leaves"}.get(self.format, "points")
        std = f"; std band: {STD_KINDS[self.std_kind]}" if self.std_kind in STD_KINDS else ""
        order = f"; IHO S-44 order {self.iho_order}" if self.iho_order else ""
        return f"wrote {self.path} ({self.format}: {self.count} {what}; {self.frame}{std}{order})"


def export_format(out: str | Path, fmt: str | None = None) -> str:
    """The format of ``out``: ``fmt`` (checked against the suffix) or the suffix's."""
    suffix = Path(out).suffix.lower()
    by_suffix = next((name for name, ends in FORMATS.items() if suffix in ends), None)
    if fmt is None:
        if by_suffix is None:
            raise ConfigError(f"--out {out}: give --format ({'|'.join(FORMATS)}) or a known suffix")
        return by_suffix
    if fmt not in FORMATS:
        raise ConfigError(f"--format {fmt!r}: expected one of {', '.join(FORMATS)}")
    if suffix not in FORMATS[fmt]:
        raise ConfigError(f"--out {out}: a {fmt} file ends in {' or '.join(FORMATS[fmt])}")
    return fmt


def _georeference(fmt: str, origin, utm):
    """The :class:`~undertow.io.export.georef.Georeference` of ``--origin`` or ``--utm``."""
    if origin is None and utm is None:
        return None
    if fmt not in GEOREFERENCED:
        raise ConfigError(
            f"--origin/--utm apply to {', '.join(GEOREFERENCED)}; {fmt} is written in local metres"
        )
    if origin is not None and utm is not None:
        raise ConfigError("give one of --origin LAT,LON and --utm E,N,ZONE, not both")
    if origin is not None:
        return parse_origin(origin) if isinstance(origin, str) else from_latlon(*origin)
    return parse_utm(utm) if isinstance(utm, str) else from_projected(*utm)


def _number(value) -> bool:
    """``value`` is a finite real number."""
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def _check_options(fmt: str, out: Path, resolution, threshold, frame, iho_order) -> None:
    if iho_order is not None:
        check_order(iho_order)
        if fmt != "geotiff":
            raise ConfigError(f"--iho-order applies to geotiff; {fmt} keeps the map's cells")
    if resolution is not None:
        if fmt != "geotiff":
            raise ConfigError(f"--resolution applies to geotiff; {fmt} keeps the map's cells")
        if not (_number(resolution) and resolution > 0):
            raise ConfigError(f"--resolution must be a positive number of metres, got {resolution}")
    if threshold is not None:
        if not (_number(threshold) and 0.0 < threshold < 1.0):
            raise ConfigError(f"--threshold must be in (0, 1), got {threshold}")
        if out.suffix.lower() == ".ot":
            raise ConfigError("--threshold does not apply to .ot (it keeps every probability)")
    if frame != "enu" and fmt not in FRAMED:
        raise ConfigError(f"frame applies to {', '.join(FRAMED)}, not {fmt}")
    check_frame(frame)


def export_map(map_path: str | Path, out: str | Path, fmt: str | None = None, *,
               resolution: float | None = None, origin=None, utm=None,
               threshold: float | None = None, frame: str = "enu",
               iho_order: str | None = None) -> ExportResult:  # fmt: skip
    """Write the map ``map_path`` (a ``map.npz`` or its folder) to ``out`` as ``fmt`` (one of
    :data:`FORMATS`; default from the suffix of ``out``).

    ``resolution``: GeoTIFF cell size, m (default the map's); ``origin`` ("LAT,LON" or
    (lat, lon), WGS 84) or ``utm`` ("E,N,ZONE" or (e, n, zone); ZONE "32N" or an EPSG code):
    where undertow's origin lies, for geotiff and las/laz; ``threshold``: occupied if
    mean > threshold (default: the map's own); ``frame``: "enu" or "ned" axes of octomap and
    local las/laz; ``iho_order``: the IHO S-44 order a geotiff's columns are held to when its
    std is a propagated uncertainty (:func:`~undertow.mapping.surface.map_surface`; None: its
    default, "none": every column). Every option is checked before the map is read."""
    out = Path(out)
    fmt = export_format(out, fmt)
    _check_options(fmt, out, resolution, threshold, frame, iho_order)
    georef = _georeference(fmt, origin, utm)
    if georef is not None and frame != "enu":
        raise ConfigError("a georeferenced export is east-north-up; frame must be enu")
    check_output_file(out)
    source = npz_file(map_path, "map.npz", MAP_FILE)
    if out.resolve() == source.resolve():
        raise ConfigError(f"--out {out} is the input map; write elsewhere")
    occupancy = OccupancyMap.load(source)
    used, used_from = map_threshold(occupancy, threshold)
    axes = _axes(fmt, frame, georef)
    std_kind, order, notes = "", "", []
    if fmt == "geotiff":
        surface = map_surface(occupancy, used, iho_order=iho_order)
        raster = resample_surface(surface, resolution, georef)
        write_raster(out, raster, georef, surface.std_kind, surface.iho_order)
        count = int(np.count_nonzero(raster.coverage > 0))
        std_kind, order = surface.std_kind, surface.iho_order
        notes = withheld_notes(order, surface.withheld)
    elif fmt == "octomap":
        write_octomap(out, occupancy, used, frame)
        count = len(occupancy)
        if out.suffix.lower() == ".ot":
            used, used_from = None, "not used (.ot keeps every probability)"
    elif fmt in ("las", "laz"):
        write_map_las(out, occupancy, used, georef, frame)
        count = len(occupancy.occupied(used))
    else:
        write_map_ply(out, occupancy, used)
        count = len(occupancy.occupied(used))
    return ExportResult(out, fmt, count, axes, used, used_from, std_kind=std_kind,
                        iho_order=order, notes=notes)  # fmt: skip


def _axes(fmt: str, frame: str, georef) -> str:
    """The exported file's axes, for the summary line."""
    if georef is not None:
        return georef.describe()
    if fmt == "geotiff":
        return "local metres, no CRS: east = y, north = x"
    if fmt == "ply":
        return "undertow's frame: x north, y east, z down"
    return "local metres, " + (
        "x east, y north, z up" if frame == "enu" else "x north, y east, z down"
    )
