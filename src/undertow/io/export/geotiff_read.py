"""GeoTIFF grids read back: the bathymetry `undertow export` writes (:mod:`.geotiff`: bands
depth, std, coverage) or any north-up raster whose band 1 is a surface (a surveyed bathymetry).

A raster's geotransform (a, b, c, d, e, f) puts pixel (row, col) at the centre
(east, north) = (c + (col + 1/2) a, f + (row + 1/2) e); only north-up grids (b = d = 0) of square
pixels (|a| = |e|) are read, in any row and column order. The grid is returned in the layout of
undertow's surfaces (:class:`undertow.mapping.surface.Surface`): cell (j, i) centred at
x = x0 + i R (north) and y = y0 + j R (east), so that for raster rows north to south and columns
west to east (a > 0, e < 0, GeoTIFF's usual order):

    grid[j, i] = raster[rows - 1 - i, j],   x0 = f - (rows - 1/2) R,   y0 = c + R / 2,

the inverse of :func:`.raster.resample_surface`'s layout. A file without a CRS is in undertow's
local frame (east = y, north = x, as the export writes it); with one, x and y are its northing
and easting. No data is NaN: the band's nodata value, its mask, and any non-finite value.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import ReaderError
from ..collect import check_regular
from ._require import require
from .geotiff import BANDS

#: relative tolerance on square pixels (|a| = |e|)
_SQUARE = 1e-6


@dataclass(frozen=True, eq=False)
class GeoTiffGrid:
    """Bands (ny, nx) float, NaN without data, by name (the band's description, else
    ``band1``, ``band2``, ...), on the grid of the module doc; ``crs``: a pyproj CRS, or None
    (undertow's local frame); ``tags``: the file's metadata; ``units``: per band name."""

    path: Path
    x0: float
    y0: float
    resolution: float
    bands: dict[str, np.ndarray]
    crs: object | None
    tags: dict = field(default_factory=dict)
    units: dict = field(default_factory=dict)

    def band(self, index: int) -> np.ndarray:
        """The ``index``-th band (1-based, as GDAL counts)."""
        return list(self.bands.values())[index - 1]

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(x north, y east) of every cell centre, each (ny, nx)."""
        ny, nx = self.band(1).shape
        xs = self.x0 + self.resolution * np.arange(nx)
        ys = self.y0 + self.resolution * np.arange(ny)
        return np.meshgrid(xs, ys, indexing="xy")


def _one_line(exc: Exception) -> str:
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__


def _check_transform(path: Path, t) -> None:
    """ReaderError unless the geotransform is north-up with square pixels (a file without one
    reads as the identity, which places nothing: refused)."""
    if t.is_identity:
        raise ReaderError(f"{path}: no geotransform, so no pixel has a position")
    if t.b != 0 or t.d != 0:
        raise ReaderError(
            f"{path}: a rotated or sheared raster (geotransform {tuple(t)[:6]}); expected a "
            "north-up grid (gdalwarp it to one)"
        )
    a, e = abs(t.a), abs(t.e)
    if not (a > 0 and math.isfinite(a) and abs(a - e) <= _SQUARE * a):
        raise ReaderError(
            f"{path}: pixels of {a:g} x {e:g}; expected square pixels (gdalwarp -tr R R)"
        )


def _window(src, bounds):
    """The pixel window (rasterio Window) of the file holding ``bounds`` = (west, south, east,
    north) in its CRS, clipped to the file; the whole file without bounds."""
    from rasterio.windows import Window

    if bounds is None:
        return Window(0, 0, src.width, src.height)
    west, south, east, north = bounds
    inverse = ~src.transform
    cols, rows = zip(*(inverse @ (x, y) for x in (west, east) for y in (south, north)), strict=True)
    c0 = min(max(math.floor(min(cols)), 0), src.width)
    c1 = min(max(math.ceil(max(cols)), 0), src.width)
    r0 = min(max(math.floor(min(rows)), 0), src.height)
    r1 = min(max(math.ceil(max(rows)), 0), src.height)
    return Window(c0, r0, c1 - c0, r1 - r0)


def _read(src, bounds):
    """(bands (count, rows, cols) float NaN without data, the window's transform)."""
    window = _window(src, bounds)
    # the window's transform (not rasterio's window_transform, which warns under affine 2.4)
    transform = src.transform @ src.transform.translation(window.col_off, window.row_off)
    if window.width == 0 or window.height == 0:
        return np.zeros((src.count, 0, 0)), transform
    masked = src.read(window=window, masked=True)
    values = np.ma.filled(masked.astype(np.float64), np.nan)
    values[~np.isfinite(values)] = np.nan
    return values, transform


def read_geotiff_grid(path, bounds: tuple[float, float, float, float] | None = None,
                      ) -> GeoTiffGrid:  # fmt: skip
    """The bands of the GeoTIFF ``path`` on undertow's grid (the module doc), only the part
    within ``bounds`` = (west, south, east, north) in the file's CRS when given (a survey larger
    than the map). An unreadable file, a rotated grid or non-square pixels are one ReaderError
    line naming the file."""
    path = Path(path)
    if not path.exists():
        raise ReaderError(f"{path}: no such file")
    check_regular(path)
    rasterio = require("rasterio", "reading a GeoTIFF")
    try:
        with warnings.catch_warnings(), rasterio.open(path) as src:
            warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
            _check_transform(path, src.transform)
            values, t = _read(src, bounds)
            names = [d or f"band{k}" for k, d in enumerate(src.descriptions, start=1)]
            units = dict(zip(names, src.units, strict=True))
            tags, crs_wkt = src.tags(), None if src.crs is None else src.crs.to_wkt()
    except ReaderError:
        raise
    except MemoryError:
        raise ReaderError(f"{path}: too large to read into memory") from None
    except Exception as exc:  # rasterio raises its own error classes for every bad file
        raise ReaderError(f"{path}: not a readable GeoTIFF: {_one_line(exc)}") from None
    if t.a < 0:  # columns east to west
        values, t = values[:, :, ::-1], t @ t.translation(values.shape[2], 0) @ t.scale(-1, 1)
    if t.e > 0:  # rows south to north
        values, t = values[:, ::-1, :], t @ t.translation(0, values.shape[1]) @ t.scale(1, -1)
    rows = values.shape[1]
    grid = {name: band[::-1, :].T.copy() for name, band in zip(names, values, strict=True)}
    crs = None if crs_wkt is None else require("pyproj", "a GeoTIFF with a CRS").CRS(crs_wkt)
    return GeoTiffGrid(path, t.f - (rows - 0.5) * abs(t.e), t.c + 0.5 * t.a, abs(t.a), grid,
                       crs, tags, units)  # fmt: skip


def geotiff_crs(path):
    """The CRS of the GeoTIFF ``path`` (a pyproj CRS) or None, without reading its pixels."""
    path = Path(path)
    if not path.exists():
        raise ReaderError(f"{path}: no such file")
    check_regular(path)
    rasterio = require("rasterio", "reading a GeoTIFF")
    try:
        with rasterio.open(path) as src:
            crs_wkt = None if src.crs is None else src.crs.to_wkt()
    except Exception as exc:  # rasterio raises its own error classes for every bad file
        raise ReaderError(f"{path}: not a readable GeoTIFF: {_one_line(exc)}") from None
    return None if crs_wkt is None else require("pyproj", "a GeoTIFF with a CRS").CRS(crs_wkt)


def read_map_geotiff(path, bounds=None) -> GeoTiffGrid:
    """A bathymetry written by `undertow export` (bands named depth, std and coverage, the
    depth positive down): ReaderError naming the bands it has otherwise."""
    grid = read_geotiff_grid(path, bounds)
    if not set(BANDS) <= set(grid.bands):
        raise ReaderError(
            f"{grid.path}: bands {', '.join(grid.bands)}; a map GeoTIFF has bands "
            f"{', '.join(BANDS)} as `undertow export` writes them"
        )
    return grid
