"""The ground truth a map is judged against, read from a user's file into the map's frame.

Formats, by suffix: ``.ply`` a point cloud in undertow's frame (x north, y east, z down, as
`undertow simulate` writes ``ground_truth.ply``); ``.tif``/``.tiff`` a GeoTIFF whose band 1 is
the surface (a surveyed bathymetry, or `undertow export`'s depth); anything else an XYZ text
file (:mod:`undertow.io.xyz`).

Frames (:mod:`undertow.io.export.transfer`). A GeoTIFF without a CRS is in undertow's local
frame (east = y, north = x, as the export writes it); with one, in its CRS. An XYZ file's
columns are ``x y z`` of the local frame, or ``E N z`` (easting, northing) of a projected CRS:
the projected reading is chosen when the median |first| or |second| column exceeds
:data:`PROJECTED_M` (no local survey reaches 100 km from its origin; UTM eastings are over
166 km), or by ``truth_frame``; its CRS is the georeference's (``--origin``/``--utm``), else the
map's (a georeferenced GeoTIFF map). Between the local frame and a CRS the map's georeference is
needed; without it the error says what to add.

Sign of z (XYZ, GeoTIFF; a PLY is z down). The truth's values are depth (positive down) or
elevation (negative down, depth = -z): `undertow export`'s files say depth (tag
``UNDERTOW_DEPTH``); otherwise more than half of the values below zero means elevation. The
choice is one line in the notes; ``truth_z`` overrides it.

A GeoTIFF truth is a heightfield (:meth:`undertow.mapping.surface.Surface.at` on its pixels,
bilinear, a point of the map's frame taken to the file's frame first) and, for the
cloud-to-cloud metrics, the cloud of its pixel centres; only the part near the map is read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConfigError, DataError
from ..io.export.geotiff import SUFFIXES
from ..io.export.geotiff_read import geotiff_crs, read_geotiff_grid
from ..io.export.transfer import ORIGIN_OPTIONS, frame_name, transfer
from ..io.ply import read_ply
from ..io.xyz import read_xyz
from ..mapping.surface import Surface

TRUTH_Z = ("depth", "elevation")
TRUTH_FRAMES = ("local", "projected")
#: an XYZ coordinate beyond this (m, median of a column) is read as projected
PROJECTED_M = 100_000.0
#: band units read as metres
_METRES = {None, "", "m", "metre", "meter", "metres", "meters"}


@dataclass(frozen=True, eq=False)
class Truth:
    """The truth in the map's frame: ``cloud`` (N, 3) (z depth, positive down) and, for a
    GeoTIFF, ``height`` (a heightfield z(x, y)); ``kind`` ply | xyz | geotiff; ``z``: how its
    values were read (None for a PLY); ``notes``: the choices made, one line each."""

    cloud: np.ndarray
    height: object | None
    kind: str
    z: str | None
    notes: list[str] = field(default_factory=list)

    @property
    def reference(self):
        """What :func:`~undertow.evaluation.surface.evaluate_surface` takes: the heightfield,
        else the cloud."""
        return self.height if self.height is not None else self.cloud


def truth_kind(path) -> str:
    """ply, geotiff or xyz, by the file's suffix."""
    suffix = Path(path).suffix.lower()
    return "ply" if suffix == ".ply" else "geotiff" if suffix in SUFFIXES else "xyz"


def check_truth_options(kind: str, truth_z: str | None, truth_frame: str | None) -> None:
    """ConfigError for a ``truth_z`` or ``truth_frame`` that is not one of the choices or does
    not apply to a truth of ``kind``."""
    if truth_z is not None and truth_z not in TRUTH_Z:
        raise ConfigError(f"--truth-z {truth_z!r}: expected {' or '.join(TRUTH_Z)}")
    if truth_frame is not None and truth_frame not in TRUTH_FRAMES:
        raise ConfigError(f"--truth-frame {truth_frame!r}: expected {' or '.join(TRUTH_FRAMES)}")
    if truth_z is not None and kind == "ply":
        raise ConfigError("--truth-z applies to an XYZ or GeoTIFF truth; a PLY is z down")
    if truth_frame is not None and kind != "xyz":
        raise ConfigError(
            "--truth-frame applies to an XYZ truth; a PLY is in undertow's frame and a GeoTIFF "
            "carries its CRS (none: undertow's frame)"
        )


def z_sign(values: np.ndarray, truth_z: str | None, tagged: bool, name: str):
    """(z, note): how the truth's values are read, depth or elevation (the module doc)."""
    if truth_z is not None:
        return truth_z, f"{name}: z read as {truth_z} (--truth-z)"
    if tagged:
        return "depth", f"{name}: z read as depth, positive down (its UNDERTOW_DEPTH tag)"
    finite = values[np.isfinite(values)]
    share = float(np.mean(finite < 0)) if finite.size else 0.0
    z = "elevation" if share > 0.5 else "depth"
    how = "negative down, depth = -z" if z == "elevation" else "positive down"
    other = "depth" if z == "elevation" else "elevation"
    return z, (
        f"{name}: z read as {z}, {how} ({share:.0%} of the values are negative); "
        f"--truth-z {other} to override"
    )


def load_truth(path, frame=None, georef=None, *, truth_z: str | None = None,
               truth_frame: str | None = None, near=None) -> Truth:  # fmt: skip
    """The truth of ``path`` in the map's ``frame`` (None: undertow's local frame, else a
    pyproj CRS) with the map's ``georef`` (or None); ``near`` = (x_min, x_max, y_min, y_max) of
    the map in its frame bounds what of a GeoTIFF is read. Checks in the module doc; a truth
    with no point is a DataError naming the file."""
    kind = truth_kind(path)
    check_truth_options(kind, truth_z, truth_frame)
    try:
        if kind == "geotiff":
            return _geotiff_truth(Path(path), frame, georef, truth_z, near)
        if kind == "xyz":
            return _xyz_truth(Path(path), frame, georef, truth_z, truth_frame)
        points = np.asarray(read_ply(path)[0], dtype=float).reshape(-1, 3)
        if len(points) == 0:
            raise DataError(f"{path}: the ground-truth cloud has no points")
        x, y = transfer(points[:, 0], points[:, 1], None, frame, georef)
        return Truth(np.column_stack([x, y, points[:, 2]]), None, kind, None)
    except ConfigError as exc:  # a missing origin: name the file
        message = str(exc)
        raise ConfigError(message if str(path) in message else f"{path}: {message}") from None


def _xyz_truth(path: Path, frame, georef, truth_z, truth_frame) -> Truth:
    points = read_xyz(path)
    z, z_note = z_sign(points[:, 2], truth_z, False, str(path))
    depth = -points[:, 2] if z == "elevation" else points[:, 2]
    large = max(np.median(np.abs(points[:, 0])), np.median(np.abs(points[:, 1])))
    projected = truth_frame == "projected" or (truth_frame is None and large > PROJECTED_M)
    how = f"median |x|, |y| {'over' if projected else 'within'} {PROJECTED_M / 1000:g} km"
    how = "--truth-frame" if truth_frame else how
    if not projected:
        x, y = transfer(points[:, 0], points[:, 1], None, frame, georef)
        note = f"{path}: columns read as x north, y east of undertow's local frame ({how})"
        return Truth(np.column_stack([x, y, depth]), None, "xyz", z, [note, z_note])
    crs = georef.crs if georef is not None else frame
    if crs is None:
        raise ConfigError(
            f"{path}: eastings and northings of a projected CRS ({how}): give {ORIGIN_OPTIONS}, "
            "or --truth-frame local"
        )
    x, y = transfer(points[:, 1], points[:, 0], crs, frame, georef)
    note = f"{path}: columns read as E N of {frame_name(crs)} ({how})"
    return Truth(np.column_stack([x, y, depth]), None, "xyz", z, [note, z_note])


def _bounds(near, frame, target, georef):
    """(west, south, east, north) in ``target`` of the box ``near`` of ``frame``, grown by a
    tenth of its size (at least 1 m), traced along its edges (a projection bends them)."""
    if near is None:
        return None
    x0, x1, y0, y1 = near
    grow = max(0.1 * max(x1 - x0, y1 - y0), 1.0)
    x0, x1, y0, y1 = x0 - grow, x1 + grow, y0 - grow, y1 + grow
    t = np.linspace(0.0, 1.0, 17)
    xs = np.concatenate([x0 + t * (x1 - x0), np.full(17, x1), x1 - t * (x1 - x0), np.full(17, x0)])
    ys = np.concatenate([np.full(17, y0), y0 + t * (y1 - y0), np.full(17, y1), y1 - t * (y1 - y0)])
    north, east = transfer(xs, ys, frame, target, georef)
    return float(east.min()), float(north.min()), float(east.max()), float(north.max())


def _geotiff_truth(path: Path, frame, georef, truth_z, near) -> Truth:
    source = geotiff_crs(path)
    if (source is None) != (frame is None) and georef is None:
        raise ConfigError(
            f"{path} is in {frame_name(source)}, the map in {frame_name(frame)}: give "
            + ORIGIN_OPTIONS
        )
    grid = read_geotiff_grid(path, _bounds(near, frame, source, georef))
    unit = list(grid.units.values())[0]
    if unit not in _METRES:
        raise ConfigError(f"{path}: band 1 is in {unit!r}; expected metres")
    values = grid.band(1)
    if not np.isfinite(values).any():
        raise DataError(f"{path}: band 1 has no data near the map")
    z, z_note = z_sign(values, truth_z, "UNDERTOW_DEPTH" in grid.tags, str(path))
    depth = -values if z == "elevation" else values
    surface = Surface(grid.x0, grid.y0, grid.resolution, depth, np.nan, np.isfinite(depth))
    pts = surface.points()
    x, y = transfer(pts[:, 0], pts[:, 1], source, frame, georef)

    def height(qx, qy):
        fx, fy = transfer(qx, qy, frame, source, georef)
        return surface.at(fx, fy)

    note = f"{path}: band 1 on {frame_name(source)}"
    return Truth(np.column_stack([x, y, pts[:, 2]]), height, "geotiff", z, [note, z_note])
