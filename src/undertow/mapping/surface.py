"""The seafloor surface an occupancy map implies: one depth (and its spread) per (x, y) column.

For a column of the map's grid, let k = 1..K run over the cells the map holds in it, from the
shallowest down (z down), with centre depths z_k and mean occupancies
p_k = E[theta_k] = alpha_k / (alpha_k + beta_k) (the paper's ``eq:mean_var``). Reading the column
from the surface down, the first occupied cell is k with probability

    P_k = p_k prod_{j<k} (1 - p_j),

and the seafloor depth the map implies is that distribution's mean, with the first occupied
depth taken uniform within its cell (height r, the grid resolution):

    d = sum_k z_k P_k / sum_k P_k,
    s^2 = sum_k (z_k - d)^2 P_k / sum_k P_k + r^2 / 12.

Normalizing by sum_k P_k = 1 - prod_k (1 - p_k) conditions on the column holding a surface at
all. Cells the map does not hold carry no evidence and do not stop the column (p = 0). Every
cell the map holds counts by its mean alone, whatever its evidence, as the paper's occupied
cells do (BKI kernel tails with little mass count in full: a map's artefact is the map's). A
column with no cell above the occupancy threshold holds no data (NaN). The depth is not
quantized to cell centres: it moves continuously with the cells' occupancies (a floor between
two cells shares its occupancy between them). Between columns, :meth:`Surface.at` interpolates
bilinearly.

**The evidence surface** (:func:`evidence_surface`, the default for a ``tpu`` map, whose hits
carry their total propagated uncertainty: :mod:`undertow.mapping.tpu`): per column, with
each cell's hit evidence w_k = alpha_k - alpha_0 (the kernel-weighted hits it received),

    d = sum_k w_k z_k / sum_k w_k,

the mean of where the hits say the floor is. Its standard deviation s is, by default, the
**propagated uncertainty** of the column's hits (the map's :class:`~undertow.occupancy.
ColumnStats`: :mod:`undertow.mapping.columns`; the equations in
:mod:`undertow.mapping.depth_std`): the pose's depth uncertainty the hits share, their range
noise averaged over them, a wide beam's shortfall on the floor's slope, their horizontal
uncertainty carried through that slope (hydrography's TVU' = sqrt(TVU^2 + (THU
tan(slope))^2)), and the relief their scatter shows beyond all that.

The **spread** (``uncertainty="spread"``; the std of a map without column sums, written
before them) is where the hits' evidence lies about d,

    s^2 = max(sum_k w_k (z_k - d)^2 / sum_k w_k - f (1 - f) r^2, 0),  f = frac(d / r - 1/2):

the tpu mapper places each hit
on the cells with its depth and its vertical variance kept, plus the least variance a
distribution on cells of size r can have with that mean, f (1 - f) r^2; the same term,
taken at the column's mean, is removed again (exact for a column of hits at one depth; for
hits spread over several cells it is small next to their spread). The spread adds the hits'
scatter to their modelled variance, which counts their noise twice where they agree, and
the floor's relief under a wide kernel where they do not. The free-space evidence
(beta_k) decides, with alpha_k, which columns hold data: those with a cell whose mean
occupancy exceeds the threshold, as for the first-occupied surface. It does not reweight
the hits: a cell's mean is a ratio of the hit and free evidence it received, and weighting
a hit's three cells by it would move the hit's depth.

**Held to an IHO order** (:func:`held_to_order`, what :func:`map_surface` does to a surface
whose std is the propagated uncertainty): a column keeps its data only where its depth meets
an IHO S-44 order, 1.96 s <= sqrt(a^2 + (b d)^2) (:mod:`undertow.mapping.iho`); the others
are counted in :attr:`Surface.withheld`.

:func:`surface_from_points` grids a point set (a ground-truth scan, an XYZ file) into the same
:class:`Surface` form: per cell, the shallowest point (the first surface seen from above).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import DataError
from ..occupancy import OCCUPIED_THRESHOLD, OccupancyMap, column_keys
from .carve import carved
from .depth_std import propagated_std
from .iho import DEFAULT_IHO_ORDER, NO_ORDER, check_order, meets_order


@dataclass(frozen=True, eq=False)
class Surface:
    """A depth grid: cell (row j, column i) has its centre at (x0 + i res, y0 + j res).

    ``depth`` (ny, nx) m, z down, NaN where there is no data; ``std`` (ny, nx) m, the depth's
    standard deviation (NaN where no data); ``coverage`` (ny, nx) bool, where there is data;
    ``std_kind``: what the std is (:data:`STD_KINDS`; "" when not said); ``iho_order``: the
    IHO S-44 order the columns were held to ("" none, :mod:`undertow.mapping.iho`) and
    ``withheld`` how many columns with data failed it and were left out."""

    x0: float
    y0: float
    resolution: float
    depth: np.ndarray
    std: np.ndarray
    coverage: np.ndarray
    std_kind: str = ""
    iho_order: str = ""
    withheld: int = 0

    def __post_init__(self) -> None:
        depth = np.asarray(self.depth, dtype=float)
        if depth.ndim != 2:
            raise DataError(f"Surface.depth: shape {depth.shape}, expected (ny, nx)")
        std = np.broadcast_to(np.asarray(self.std, dtype=float), depth.shape).copy()
        coverage = np.broadcast_to(np.asarray(self.coverage, dtype=bool), depth.shape).copy()
        if not (self.resolution > 0 and np.isfinite(self.resolution)):
            raise DataError(f"Surface.resolution: {self.resolution}, expected a positive number")
        object.__setattr__(self, "depth", depth)
        object.__setattr__(self, "std", std)
        object.__setattr__(self, "coverage", coverage & np.isfinite(depth))
        object.__setattr__(self, "resolution", float(self.resolution))
        object.__setattr__(self, "x0", float(self.x0))
        object.__setattr__(self, "y0", float(self.y0))

    @property
    def shape(self) -> tuple[int, int]:
        return self.depth.shape

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of every cell centre, each (ny, nx)."""
        ny, nx = self.shape
        xs = self.x0 + self.resolution * np.arange(nx)
        ys = self.y0 + self.resolution * np.arange(ny)
        return np.meshgrid(xs, ys, indexing="xy")

    def points(self) -> np.ndarray:
        """(K, 3) cell centres with data, at their depth."""
        x, y = self.centres()
        c = self.coverage
        return np.stack([x[c], y[c], self.depth[c]], axis=1)

    def at(self, x, y) -> np.ndarray:
        """Depth at (x, y) (any broadcastable shapes): bilinear between the four nearest cell
        centres, z = sum_c w_c z_c / sum_c w_c over the corners c with data (w_c the bilinear
        weights), so a point inside a covered cell near an uncovered one still gets a depth.
        NaN where the cell containing (x, y) has no data or lies outside the grid."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        ny, nx = self.shape
        if nx == 0 or ny == 0:
            return np.full(x.shape, np.nan)
        fx = (x - self.x0) / self.resolution
        fy = (y - self.y0) / self.resolution
        near_i, near_j = np.rint(fx), np.rint(fy)
        inside = (near_i >= 0) & (near_i < nx) & (near_j >= 0) & (near_j < ny)
        ni = np.clip(near_i, 0, nx - 1).astype(np.int64)
        nj = np.clip(near_j, 0, ny - 1).astype(np.int64)
        inside &= self.coverage[nj, ni]
        i0 = np.clip(np.floor(fx), 0, max(nx - 2, 0)).astype(np.int64)
        j0 = np.clip(np.floor(fy), 0, max(ny - 2, 0)).astype(np.int64)
        wx = np.clip(fx - i0, 0.0, 1.0)
        wy = np.clip(fy - j0, 0.0, 1.0)
        i1, j1 = np.minimum(i0 + 1, nx - 1), np.minimum(j0 + 1, ny - 1)
        total = np.zeros(x.shape)
        weight = np.zeros(x.shape)
        for jj, ii, w in ((j0, i0, (1 - wx) * (1 - wy)), (j0, i1, wx * (1 - wy)),
                          (j1, i0, (1 - wx) * wy), (j1, i1, wx * wy)):  # fmt: skip
            z = self.depth[jj, ii]
            ok = np.isfinite(z)
            total += np.where(ok, w * np.where(ok, z, 0.0), 0.0)
            weight += np.where(ok, w, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = total / weight
        return np.where(inside & (weight > 0), out, np.nan)


def _columns(cells: np.ndarray):
    """Order of cells by (i, j, k), and each cell's column's first position in that order."""
    order = np.lexsort((cells[:, 2], cells[:, 1], cells[:, 0]))
    ij = cells[order, :2]
    new = np.ones(len(order), bool)
    new[1:] = np.any(ij[1:] != ij[:-1], axis=1)
    starts = np.flatnonzero(new)
    return order, starts


#: How a surface is read from the cells: the first-occupied expectation, or the hit evidence
SURFACE_ESTIMATORS = ("first-occupied", "evidence")
#: What a surface's std is, by :attr:`Surface.std_kind`
STD_KINDS = {
    "propagated": "the hits' propagated uncertainty (vertical, and horizontal x slope)",
    "spread": "the spread of the hits' evidence in the column",
    "first-occupied": "the spread of the first occupied depth",
    "points": "the spread of the points in the cell",
}


def default_estimator(occupancy: OccupancyMap) -> str:
    """The surface estimator of a map: ``evidence`` for a ``tpu`` map (its metadata's method),
    ``first-occupied`` for the others (the paper's mappers, as the reproduction reads them)."""
    return "evidence" if occupancy.metadata.get("method") == "tpu" else "first-occupied"


def map_surface(occupancy: OccupancyMap, threshold: float = OCCUPIED_THRESHOLD, *,
                occupied_only: bool = False, estimator: str | None = None,
                uncertainty: str | None = None,
                iho_order: str | None = None) -> Surface:  # fmt: skip
    """The seafloor surface ``occupancy`` implies (equations in the module doc): per column a
    depth d and its standard deviation s; no data where no cell's mean exceeds ``threshold``.
    ``estimator``: ``first-occupied`` (the expected first occupied depth), ``evidence``
    (:func:`evidence_surface`) or None (:func:`default_estimator` of the map). The grid is the
    map's (cell i has centre (i + 1/2) res), over the bounding box of the map's columns.
    ``occupied_only``: only the occupied cells (mean > threshold, the paper's map points) enter
    the expectation; cells below the threshold then neither stop a column nor pull its depth
    up. ``uncertainty``: the evidence surface's std (:func:`evidence_surface`).
    ``iho_order``: a surface whose std is the hits' propagated uncertainty keeps only the
    columns that meet this IHO S-44 order (:func:`held_to_order`; None:
    :data:`~undertow.mapping.iho.DEFAULT_IHO_ORDER`, ``"none"``: every column)."""
    order = check_order(DEFAULT_IHO_ORDER if iho_order is None else iho_order)
    estimator = default_estimator(occupancy) if estimator is None else estimator
    if estimator not in SURFACE_ESTIMATORS:
        raise DataError(f"surface estimator {estimator!r}: expected one of {SURFACE_ESTIMATORS}")
    if occupied_only:
        occupancy = occupancy.occupied(threshold)
    if len(occupancy) == 0:
        empty = np.zeros((0, 0))
        return Surface(0.0, 0.0, float(occupancy.resolution), empty, empty, empty.astype(bool))
    if estimator == "evidence":
        surface = evidence_surface(occupancy, threshold, uncertainty=uncertainty)
        return held_to_order(surface, order) if surface.std_kind == "propagated" else surface
    return _first_occupied(occupancy, threshold)


def held_to_order(surface: Surface, order: str) -> Surface:
    """``surface`` with only the columns whose depth d and std s meet the IHO S-44 ``order``,
    z_95 s <= sqrt(a^2 + (b d)^2) (:func:`~undertow.mapping.iho.meets_order`); the others
    lose their data and are counted in ``withheld``. ``"none"`` returns it unchanged."""
    if check_order(order) == NO_ORDER:
        return surface
    keep = surface.coverage & meets_order(surface.depth, surface.std, order)
    withheld = int(np.count_nonzero(surface.coverage & ~keep))
    return replace(surface, depth=np.where(keep, surface.depth, np.nan),
                   std=np.where(keep, surface.std, np.nan), coverage=keep, iho_order=order,
                   withheld=surface.withheld + withheld)  # fmt: skip


def _first_occupied(occupancy: OccupancyMap, threshold: float) -> Surface:
    """The first-occupied surface of a non-empty map (module doc)."""
    res = float(occupancy.resolution)
    order, starts = _columns(occupancy.cells)
    cells = occupancy.cells[order]
    p = np.clip(occupancy.mean[order], 0.0, 1.0)
    z = (cells[:, 2] + 0.5) * res
    # log prod_{j<k} (1 - p_j) within each column: an exclusive cumulative sum restarted per column
    log_free = np.log1p(-np.minimum(p, 1.0 - 1e-15))
    cum = np.cumsum(log_free)
    before = cum - log_free
    lengths = np.diff(np.append(starts, len(p)))
    before -= np.repeat(before[starts], lengths)
    weight = p * np.exp(before)
    total = np.add.reduceat(weight, starts)
    mean_z = np.add.reduceat(weight * z, starts) / np.where(total > 0, total, 1.0)
    spread = np.add.reduceat(weight * (z - np.repeat(mean_z, lengths)) ** 2, starts)
    var = spread / np.where(total > 0, total, 1.0) + res * res / 12.0
    covered = np.maximum.reduceat(p, starts) > threshold
    return _grid(cells[starts, :2], covered, mean_z, var, res, "first-occupied")


def _grid(ij, covered, depth_by_column, var_by_column, res: float, kind: str) -> Surface:
    """The Surface over the bounding box of the columns ``ij`` (K, 2), with data where
    ``covered``."""
    lo = ij.min(axis=0)
    nx, ny = (ij.max(axis=0) - lo + 1).tolist()
    depth = np.full((ny, nx), np.nan)
    std = np.full((ny, nx), np.nan)
    col, row = (ij - lo).T
    depth[row[covered], col[covered]] = depth_by_column[covered]
    std[row[covered], col[covered]] = np.sqrt(var_by_column[covered])
    x0, y0 = ((lo + 0.5) * res).tolist()
    return Surface(x0, y0, res, depth, std, np.isfinite(depth), kind)


def evidence_surface(occupancy: OccupancyMap, threshold: float = OCCUPIED_THRESHOLD, *,
                     uncertainty: str | None = None) -> Surface:  # fmt: skip
    """The evidence surface of ``occupancy`` (module doc): per column the mean d of the
    cells' hit evidence w_k = alpha_k - alpha_0 and its standard deviation s, the hits'
    propagated uncertainty (``uncertainty="propagated"``, the default for a map with
    :class:`~undertow.occupancy.ColumnStats`) or the evidence's spread with the least
    variance of a distribution on cells of size r with mean d removed (``"spread"``, the
    default without them); data where a cell's mean exceeds ``threshold`` and the column
    holds evidence."""
    uncertainty = _uncertainty(occupancy, uncertainty)
    res = float(occupancy.resolution)
    if len(occupancy) == 0:
        empty = np.zeros((0, 0))
        return Surface(0.0, 0.0, res, empty, empty, empty.astype(bool))
    order, starts = _columns(occupancy.cells)
    cells = occupancy.cells[order]
    p = np.clip(occupancy.mean[order], 0.0, 1.0)
    w = np.maximum(occupancy.alpha[order] - occupancy.alpha0, 0.0)
    z = (cells[:, 2] + 0.5) * res
    cut = carved_cells(cells, z, occupancy.columns, res)
    p[cut], w[cut] = 0.0, 0.0
    lengths = np.diff(np.append(starts, len(p)))
    total = np.add.reduceat(w, starts)
    safe = np.where(total > 0, total, 1.0)
    d = np.add.reduceat(w * z, starts) / safe
    spread = np.add.reduceat(w * (z - np.repeat(d, lengths)) ** 2, starts) / safe
    f = d / res - 0.5
    f -= np.floor(f)
    var = np.maximum(spread - f * (1.0 - f) * res * res, 0.0)
    covered = (np.maximum.reduceat(p, starts) > threshold) & (total > 0)
    surface = _grid(cells[starts, :2], covered, d, var, res, "spread")
    if uncertainty == "spread":
        return surface
    width = float(occupancy.metadata.get("sonar_beam_width_deg", 0.0) or 0.0)
    raw = np.full(surface.shape, np.nan)  # the spread before the lattice's least is removed
    col, row = (cells[starts, :2] - cells[starts, :2].min(axis=0)).T
    raw[row[covered], col[covered]] = spread[covered]
    return propagated_std(surface, occupancy.columns, width, raw)


def carved_cells(cells: np.ndarray, z: np.ndarray, columns, resolution: float) -> np.ndarray:
    """Which of ``cells`` (n, 3; centre depths ``z``) a sonar's cone carved free (the map's
    :attr:`~undertow.occupancy.ColumnStats.carve`, :func:`~undertow.mapping.carve.carved`);
    none when the map keeps no intervals."""
    out = np.zeros(len(cells), bool)
    if columns is None or columns.carve is None or not len(columns) or not len(cells):
        return out
    key = column_keys(columns.cells)
    order = np.argsort(key, kind="stable")
    find = column_keys(cells)
    at = np.clip(np.searchsorted(key[order], find), 0, len(key) - 1)
    row = order[at]
    held = key[row] == find
    out[held] = carved(z[held], columns.carve[row[held]], resolution)
    return out


#: The depth std of the evidence surface: the hits' propagated uncertainty, or their spread
UNCERTAINTIES = ("propagated", "spread")


def _uncertainty(occupancy: OccupancyMap, uncertainty: str | None) -> str:
    """The checked ``uncertainty`` of :func:`evidence_surface` (None: its default)."""
    if uncertainty is None:
        return "spread" if occupancy.columns is None else "propagated"
    if uncertainty not in UNCERTAINTIES:
        raise DataError(f"surface uncertainty {uncertainty!r}: expected one of {UNCERTAINTIES}")
    if uncertainty == "propagated" and occupancy.columns is None:
        raise DataError(
            "surface uncertainty 'propagated' needs the map's column sums (a tpu map written "
            "by this version); use 'spread'"
        )
    return uncertainty


def surface_from_points(points, resolution: float, origin: tuple[float, float] | None = None,
                        ) -> Surface:  # fmt: skip
    """Grid a point set (N, 3) into a :class:`Surface` of cell size ``resolution``: per cell the
    shallowest point's depth (the first surface seen from above), ``std`` the spread (standard
    deviation) of the cell's depths. ``origin`` is the centre of cell (0, 0) (default: the
    points' smallest x and y, so a regular grid of that spacing maps one point per cell and
    :meth:`Surface.at` interpolates it bilinearly)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise DataError(f"surface_from_points: shape {pts.shape}, expected (N, 3) with N > 0")
    if not np.all(np.isfinite(pts)):
        raise DataError("surface_from_points: non-finite coordinates")
    if not resolution > 0:
        raise DataError(f"surface_from_points: resolution {resolution}, expected > 0")
    x0, y0 = pts[:, :2].min(axis=0) if origin is None else (float(origin[0]), float(origin[1]))
    ij = np.rint((pts[:, :2] - (x0, y0)) / resolution).astype(np.int64)
    lo = ij.min(axis=0)
    ij -= lo
    nx, ny = (ij.max(axis=0) + 1).tolist()
    flat = ij[:, 1] * nx + ij[:, 0]
    depth = np.full(ny * nx, np.inf)
    np.minimum.at(depth, flat, pts[:, 2])
    count = np.bincount(flat, minlength=ny * nx)
    mean = np.bincount(flat, pts[:, 2], minlength=ny * nx) / np.maximum(count, 1)
    sq = np.bincount(flat, (pts[:, 2] - mean[flat]) ** 2, minlength=ny * nx)
    std = np.sqrt(sq / np.maximum(count, 1))
    has = count > 0
    depth[~has], std[~has] = np.nan, np.nan
    return Surface(x0 + lo[0] * resolution, y0 + lo[1] * resolution, resolution,
                   depth.reshape(ny, nx), std.reshape(ny, nx), has.reshape(ny, nx),
                   "points")  # fmt: skip
