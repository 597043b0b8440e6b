"""A depth surface resampled onto a north-up raster: the grid a GeoTIFF holds.

The surface (any object with ``x0, y0, resolution, depth, std, coverage`` as
:class:`undertow.mapping.surface.Surface`: cell (row j, column i) centred at
(x0 + i r, y0 + j r) in undertow's local frame, x north, y east, depth z down) is read as
piecewise constant over its cells. An output cell of size R is sampled at s x s points on a
regular sub-grid, s = ceil(R / r) (one point, its centre, when R <= r), each taking the value of
the surface cell it falls in. Over the n of those points that fall in cells with data, with
depths d_m and standard deviations s_m:

    coverage = n / s^2                      (fraction of the output cell with data)
    depth    = (1/n) sum_m d_m
    std^2    = (1/n) sum_m (s_m^2 + d_m^2) - depth^2

(the law of total variance: the depth at a random point of the covered part of the cell). With
R = r on the local grid the raster is the surface itself, cell for cell.

Rows run north to south and columns west to east (GeoTIFF's raster space, "PixelIsArea"), so
raster[row, col] has its centre at (east, north) = (W + (col + 1/2) R, N - (row + 1/2) R), the
affine geotransform (R, 0, W, 0, -R, N). Without a georeference, east and north are the local
y and x (so rows run from the largest x down); with one (:mod:`.georef`), the easting and
northing of its projected CRS, each sub-sample point taken back to the local frame exactly.
The raster's edges are multiples of R (of the local frame, or of the CRS).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError, DataError

#: sub-sample points per block (bounds memory: about 100 bytes each)
_BLOCK_POINTS = 2_000_000
#: the largest raster :func:`resample_surface` makes, cells
MAX_CELLS = 200_000_000
#: tolerance (in cells) when snapping the raster's edges to multiples of R
_SNAP = 1e-9


@dataclass(frozen=True, eq=False)
class Raster:
    """Bands (rows north to south, columns west to east) and the geotransform's origin: the
    north-west corner (``west``, ``north``) and the cell size ``resolution``, m."""

    depth: np.ndarray
    std: np.ndarray
    coverage: np.ndarray
    west: float
    north: float
    resolution: float

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(east, north) of every cell centre, each (rows, cols)."""
        rows, cols = self.depth.shape
        east = self.west + (np.arange(cols) + 0.5) * self.resolution
        north = self.north - (np.arange(rows) + 0.5) * self.resolution
        return np.meshgrid(east, north, indexing="xy")


def _outline(surface) -> tuple[np.ndarray, np.ndarray]:
    """Local (x, y) of points around the surface's outer cell edges (corners and edge points)."""
    ny, nx = surface.depth.shape
    r = surface.resolution
    x_lo, x_hi = surface.x0 - r / 2, surface.x0 + (nx - 0.5) * r
    y_lo, y_hi = surface.y0 - r / 2, surface.y0 + (ny - 0.5) * r
    t = np.linspace(0.0, 1.0, 17)
    xs = np.concatenate([x_lo + t * (x_hi - x_lo), np.full(17, x_hi),
                         x_hi - t * (x_hi - x_lo), np.full(17, x_lo)])  # fmt: skip
    ys = np.concatenate([np.full(17, y_lo), y_lo + t * (y_hi - y_lo),
                         np.full(17, y_hi), y_hi - t * (y_hi - y_lo)])  # fmt: skip
    return xs, ys


def _bounds(surface, resolution: float, georef) -> tuple[float, float, int, int]:
    """(west, north, rows, cols) of the raster covering the surface, edges on multiples of R."""
    xs, ys = _outline(surface)
    east, north = (ys, xs) if georef is None else georef.to_projected(xs, ys)
    west = math.floor(east.min() / resolution + _SNAP) * resolution
    east_edge = math.ceil(east.max() / resolution - _SNAP) * resolution
    south = math.floor(north.min() / resolution + _SNAP) * resolution
    north_edge = math.ceil(north.max() / resolution - _SNAP) * resolution
    cols = max(round((east_edge - west) / resolution), 1)
    rows = max(round((north_edge - south) / resolution), 1)
    return west, north_edge, rows, cols


def resample_surface(surface, resolution: float | None = None, georef=None) -> Raster:
    """The raster of ``surface`` at cell size ``resolution`` (default: the surface's), in local
    metres or, with ``georef``, in its projected CRS (equations in the module doc)."""
    r = float(surface.resolution)
    resolution = r if resolution is None else float(resolution)
    if not (math.isfinite(resolution) and resolution > 0):
        raise ConfigError(f"resolution must be a positive number of metres, got {resolution}")
    if surface.depth.size == 0 or not np.any(surface.coverage):
        raise DataError("the map has no seafloor to grid (no column above the threshold)")
    west, north, rows, cols = _bounds(surface, resolution, georef)
    if rows * cols > MAX_CELLS:
        raise ConfigError(
            f"resolution {resolution:g} m makes a raster of {rows} x {cols} cells; choose a "
            "coarser one"
        )
    sub = max(math.ceil(resolution / r - _SNAP), 1)
    offsets = (np.arange(sub) + 0.5) / sub  # sub-sample positions inside a cell, in cells
    reference = float(np.mean(surface.depth[surface.coverage]))  # sums about it: no cancellation
    sums = np.zeros((3, rows * cols))  # n, sum (d - ref), sum (s^2 + (d - ref)^2)
    block_rows = max(_BLOCK_POINTS // (cols * sub * sub), 1)
    for first in range(0, rows, block_rows):
        last = min(first + block_rows, rows)
        _accumulate(surface, sums, (first, last, cols), offsets, (west, north, resolution),
                    georef, reference)  # fmt: skip
    n = sums[0].reshape(rows, cols)
    with np.errstate(invalid="ignore", divide="ignore"):
        offset = sums[1].reshape(rows, cols) / n
        var = sums[2].reshape(rows, cols) / n - offset * offset
    std = np.sqrt(np.maximum(var, 0.0))
    return Raster(reference + offset, std, n / (sub * sub), west, north, resolution)


def _accumulate(surface, sums, block, offsets, grid, georef, reference) -> None:
    """Add the sub-samples of raster rows [first, last) (``block`` = first, last, cols) to
    ``sums``: count, sum (d - reference), sum (s^2 + (d - reference)^2)."""
    first, last, cols = block
    west, north, resolution = grid
    sub = len(offsets)
    rows_f = (np.arange(first, last)[:, None] + offsets[None, :]).reshape(-1)  # (rows*sub,)
    cols_f = (np.arange(cols)[:, None] + offsets[None, :]).reshape(-1)  # (cols*sub,)
    east_grid, north_grid = np.meshgrid(west + cols_f * resolution, north - rows_f * resolution)
    if georef is None:
        x, y = north_grid, east_grid
    else:
        x, y = georef.to_local(east_grid, north_grid)
    ny, nx = surface.depth.shape
    i = np.rint((x - surface.x0) / surface.resolution)
    j = np.rint((y - surface.y0) / surface.resolution)
    inside = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    ii = np.where(inside, i, 0).astype(np.int64)
    jj = np.where(inside, j, 0).astype(np.int64)
    hit = inside & surface.coverage[jj, ii]
    d = np.where(hit, surface.depth[jj, ii] - reference, 0.0)
    s = np.where(hit, surface.std[jj, ii], 0.0)
    # the output cell of each sub-sample: (row, col) of the raster
    out_row = np.repeat(np.arange(first, last), sub)[:, None]
    out_col = np.repeat(np.arange(cols), sub)[None, :]
    flat = np.broadcast_to(out_row * cols + out_col, hit.shape)[hit]
    size = sums.shape[1]
    sums[0] += np.bincount(flat, minlength=size)
    sums[1] += np.bincount(flat, d[hit], minlength=size)
    sums[2] += np.bincount(flat, s[hit] ** 2 + d[hit] ** 2, minlength=size)
