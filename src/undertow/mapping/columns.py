"""The ``tpu`` mapper's per-column uncertainties: :class:`ColumnGrid`.

Beside the map's cells, the ``tpu`` mapper sums per (x, y) column, with the weight each hit
leaves there, w_i = w k(|dx|; l_x) k(|dy|; l_y) (its weight w and kernel across the floor,
the sparse kernel of ``eq:kernel`` at the column's centre, as the map's product kernel weighs
the hit's cells: :mod:`undertow.mapping.tpu`), the hits' evidence and its uncertainties
(:data:`~undertow.occupancy.COLUMN_SUMS`):

    W = sum_i w_i,   V = sum_i w_i sigma_v,i^2,   X = sum_i w_i sigma_x,i^2,
    Y = sum_i w_i sigma_y,i^2,   R = sum_i w_i s_r,i^2,   U = sum_i w_i^2 s_r,i^2,
    Q = sum_i w_i r_s,i^2,   D_x = sum_i w_i dx_i^2,   D_y = sum_i w_i dy_i^2,
    L = sum_i w_i c_i,

sigma_v,i the hit's vertical standard deviation (pose, range, waves, a wide beam's
shortfall), sigma_x,i and sigma_y,i its horizontal ones (the pose's and a wide beam's
footprint and the range noise's horizontal share), s_r,i its range's own noise in depth
(s_rz of :mod:`undertow.mapping.tpu`), r_s,i its range when a sonar's (else 0), dx_i and
dy_i the column centre's offset from it and c_i the variance of the three cells it was put on
(:data:`~undertow.mapping.tpuscatter.HIT_PARTS`). The surface reads them as the column
depth's standard deviation (:mod:`undertow.mapping.depth_std`). The sums are kept in a second
:class:`~undertow.mapping.grid.ChunkedGrid` of the map's resolution: cells (i, j, 0 .. 3) hold
W, V, X, Y as alpha mass and cells (i, j, 0 .. 5) the other six as beta mass (float32, as the
map's masses; a column's ten sums in one chunk), written by :func:`add_column_sums` (one
kernel evaluation per column for all of them); it spills as the map's grid does, with an
eighth of its resident budget. Cells (i, j, 4 .. 7) hold the two deepest intervals a sonar's
cone carved free in the column as alpha mass (:mod:`undertow.mapping.carve`, written by
:func:`~undertow.mapping.carve.add_carve`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..occupancy import CARVE_FIELDS, COLUMN_SUMS, ColumnStats, column_keys
from .carve import ALPHA_SUMS, FIRST_CELL, add_carve, carve_inputs, decode, encode
from .chunks import CHUNK_SHIFT, find_or_insert
from .grid import ChunkedGrid
from .kernels import sincos
from .tpuscatter import TpuHits

#: the share of the map's resident budget the column sums may hold in memory
RESIDENT_SHARE = 1 / 8
#: the columns a hit's sums reach: within this fraction of its kernel's length, where the
#: kernel is above 0.75 % of its peak (k(0.75 l) = 1/6 - 1/(2 pi)); a column beyond it holds
#: less than 0.2 % of the kernel's mass across the floor (0.1 % beyond 0.75 l along each axis)
SUPPORT = 0.75


class ColumnGrid:
    """Sums per column of the ``tpu`` mapper's hits (module doc)."""

    def __init__(self, resolution: float, resident_bytes: float | None = None) -> None:
        self.resolution = float(resolution)
        budget = None if resident_bytes is None else resident_bytes * RESIDENT_SHARE
        self.grid = ChunkedGrid(self.resolution, resident_bytes=budget)

    def add_hits(self, hits: TpuHits, extent) -> None:
        """Add hits given as :class:`~undertow.mapping.tpuscatter.TpuHits` (the ray path);
        ``extent``: a box holding them (:func:`~undertow.mapping.tpuscatter.tpu_extent`'s)."""
        self._add(hits.x, hits.y, hits.l, hits.weight, hits.var_v, hits.parts, extent,
                  hits.reach)  # fmt: skip

    def add_written(self, x, y, lx, ly, weight, var_v, parts) -> None:
        """Add the hits of written samples, as :func:`~undertow.mapping.tpu.tpu_hit_weights`
        gives them."""
        if len(x):
            extent = (np.array([x.min(), y.min()]), np.array([x.max(), y.max()]))
            l = np.stack([lx, ly], axis=1)
            # contiguous, as the ray path gives them: one compiled add_column_sums, not two
            x, y = np.ascontiguousarray(x), np.ascontiguousarray(y)
            parts = np.ascontiguousarray(parts)
            self._add(x, y, l, weight, var_v, parts, extent, self.reach(l))

    def _add(self, x, y, l, weight, var_v, parts, extent, reach: float) -> None:
        """Add hits at (x, y) with kernel lengths l (n, 2), weights w, sigma_v^2 and the parts
        (n, 5) of :data:`~undertow.mapping.tpuscatter.HIT_PARTS`, inside the
        x-y box ``extent`` (lo, hi); ``reach`` the largest finite l (:meth:`reach`). Hits with
        a value not finite, or w or l not positive, are left out (a hit without weight adds
        nothing to the map either)."""
        n = len(x)
        if n == 0:
            return
        res = self.resolution
        self.grid.write(add_column_sums, n, (x, y, l, weight, var_v, parts, res),
                        self._box(extent), reach)  # fmt: skip

    def _box(self, extent):
        """The grid box of the column cells over the x-y box ``extent`` (lo, hi)."""
        top = (FIRST_CELL + CARVE_FIELDS) * self.resolution
        return (np.array([extent[0][0], extent[0][1], 0.0]),
                np.array([extent[1][0], extent[1][1], top]), True)  # fmt: skip

    def add_carve(self, origin, direction, r, var_v, half_angle: float, cap: float) -> None:
        """Carve the cones of sonar pings (origins (n, 3), unit axes (n, 3), ranges, the hits'
        sigma_v^2; half-angle h in rad; ``cap`` the largest reach, m):
        :mod:`undertow.mapping.carve`."""
        if half_angle <= 0 or not len(r):
            return
        origin, direction, r, margin = carve_inputs(origin, direction, r, var_v, half_angle)
        if not len(r):
            return
        end = origin + r[:, None] * direction
        reach = np.minimum(2.0 * r * math.sin(half_angle / 2.0), cap)
        extent = (end[:, :2].min(axis=0), end[:, :2].max(axis=0))
        args = (origin, direction, r, margin, math.cos(half_angle), math.sin(half_angle / 2.0),
                float(cap), self.resolution)  # fmt: skip
        self.grid.write(add_carve, len(r), args, self._box(extent), float(reach.max()))

    @staticmethod
    def reach(l) -> float:
        """The largest kernel length of ``l`` (m; 0 when none is finite)."""
        finite = l[np.isfinite(l)]
        return float(finite.max()) if finite.size else 0.0

    def add_stats(self, stats: ColumnStats | None) -> None:
        """Add sums already made (a prior map's), to a grid that holds no carved intervals yet
        (those are kept, not added)."""
        if stats is None or not len(stats):
            return
        n = len(stats)
        carve = encode(stats.carve) if stats.carve is not None else np.zeros((n, CARVE_FIELDS))
        values = np.hstack([stats.sums[:, :ALPHA_SUMS], carve])  # alpha: cells 0 .. 7
        ranged = np.zeros_like(values)  # beta: the other sums, cells 0 .. 5
        ranged[:, : len(COLUMN_SUMS) - ALPHA_SUMS] = stats.sums[:, ALPHA_SUMS:]
        k = values.shape[1]
        cells = np.column_stack([np.repeat(stats.cells, k, axis=0),
                                 np.tile(np.arange(k), len(stats))])  # fmt: skip
        self.grid.add_mass(cells, values.reshape(-1), ranged.reshape(-1))

    def stats(self) -> ColumnStats:
        """The sums per column (:class:`~undertow.occupancy.ColumnStats`, with the carved
        intervals), columns sorted by (i, j), those without hits left out. Read part by part (a
        column's cells are in one chunk, so in one part): 80 bytes a column at the end, not the
        grid's readout of every cell whole."""
        k = len(COLUMN_SUMS)
        n = FIRST_CELL + CARVE_FIELDS
        columns, values = [], []
        for cells, alpha, beta in self.grid.iter_cells():
            ok = (cells[:, 2] >= 0) & (cells[:, 2] < n)
            cells, alpha, beta = cells[ok], alpha[ok], beta[ok]
            part, first, inverse = np.unique(column_keys(cells), return_index=True,
                                             return_inverse=True)  # fmt: skip
            total = np.zeros((len(part), n + k - ALPHA_SUMS))
            row = inverse.reshape(-1)
            total[row, cells[:, 2]] = alpha  # each (i, j, c) once in a part
            ranged = cells[:, 2] < k - ALPHA_SUMS
            total[row[ranged], n + cells[ranged, 2]] = beta[ranged]
            keep = total[:, 0] > 0
            columns.append(cells[first[keep], :2])
            values.append(total[keep])
        if not columns:
            return ColumnStats(np.zeros((0, 2), np.int64), np.zeros((0, k)),
                               np.zeros((0, CARVE_FIELDS)))  # fmt: skip
        columns, values = np.concatenate(columns), np.concatenate(values)
        order = np.lexsort((columns[:, 1], columns[:, 0]))
        values = values[order]
        sums = np.hstack([values[:, :ALPHA_SUMS], values[:, n:]])
        return ColumnStats(columns[order], sums, decode(values[:, FIRST_CELL:n]))


@njit(cache=True, inline="always")
def _kernel(d, l):
    """The sparse kernel of ``eq:kernel`` (sigma_0 = 1) at distance d >= 0, length l."""
    if d >= l:
        return 0.0
    r = d / l
    sn, cs = sincos(2.0 * math.pi * r)
    return (2.0 + cs) * (1.0 - r) / 3.0 + sn / (2.0 * math.pi)


@njit(cache=True)
def add_column_sums(start, x, y, l, weight, var_v, parts, res, table_keys, table_vals,
                    chunk_keys, n_chunks, alpha, beta):  # fmt: skip
    """From hit ``start``: add (w, w sigma_v^2, w sigma_x^2, w sigma_y^2) k to the alpha mass
    of cells (i, j, 0 .. 3) and (w s_rz^2 k, (w k)^2 s_rz^2, w r_s^2 k, w dx^2 k, w dy^2 k,
    w c k) to the beta mass of cells (i, j, 0 .. 5) (``parts``: sigma_x^2, sigma_y^2, s_rz^2,
    r_s^2 and c per hit, :data:`~undertow.mapping.tpuscatter.HIT_PARTS`; dx, dy the column
    centre's offset from the hit), k = k(|dx|; l_x) k(|dy|; l_y), of every column (i, j)
    whose centre ((i + 1/2) res,
    ...) lies within :data:`SUPPORT` of the hit's kernel lengths (module doc). A hit starts
    only when the chunk arrays have room for every chunk it may place; returns the first hit
    without that room (the caller grows the arrays and resumes there), or n."""
    kx, ky = np.empty(0), np.empty(0)
    last_x, last_y, last = np.int64(1) << 40, np.int64(0), -1  # the last chunk found
    m = np.empty(4)
    for s in range(start, x.shape[0]):
        lx, ly, w = l[s, 0], l[s, 1], weight[s]
        m[0], m[1] = w, w * var_v[s]
        m[2], m[3] = w * parts[s, 0], w * parts[s, 1]
        ind, ind2, far = w * parts[s, 2], w * w * parts[s, 2], w * parts[s, 3]
        lat = w * parts[s, 4]
        if not (
            w > 0.0
            and lx > 0.0
            and ly > 0.0
            and np.isfinite(x[s])
            and np.isfinite(y[s])
            and np.isfinite(m[1])
            and np.isfinite(m[2])
            and np.isfinite(m[3])
            and np.isfinite(ind2)
            and np.isfinite(far)
            and np.isfinite(lat)
        ):
            continue
        rx, ry = SUPPORT * lx, SUPPORT * ly
        i0 = int(math.ceil((x[s] - rx) / res - 0.5))
        i1 = int(math.floor((x[s] + rx) / res - 0.5))
        j0 = int(math.ceil((y[s] - ry) / res - 0.5))
        j1 = int(math.floor((y[s] + ry) / res - 0.5))
        if i1 < i0 or j1 < j0:
            continue
        spans = ((i1 >> CHUNK_SHIFT) - (i0 >> CHUNK_SHIFT) + 1) * (
            (j1 >> CHUNK_SHIFT) - (j0 >> CHUNK_SHIFT) + 1
        )
        if n_chunks[0] + spans > chunk_keys.shape[0]:  # room for every chunk it may place
            return s
        if kx.shape[0] < i1 - i0 + 1:
            kx = np.empty(2 * (i1 - i0 + 1))
        if ky.shape[0] < j1 - j0 + 1:
            ky = np.empty(2 * (j1 - j0 + 1))
        for i in range(i0, i1 + 1):
            kx[i - i0] = _kernel(abs((i + 0.5) * res - x[s]), lx)
        for j in range(j0, j1 + 1):
            ky[j - j0] = _kernel(abs((j + 0.5) * res - y[s]), ly)
        for cx in range(i0 >> CHUNK_SHIFT, (i1 >> CHUNK_SHIFT) + 1):
            ia, ib = max(i0, cx << CHUNK_SHIFT), min(i1, ((cx + 1) << CHUNK_SHIFT) - 1)
            for cy in range(j0 >> CHUNK_SHIFT, (j1 >> CHUNK_SHIFT) + 1):
                ja, jb = max(j0, cy << CHUNK_SHIFT), min(j1, ((cy + 1) << CHUNK_SHIFT) - 1)
                if cx != last_x or cy != last_y:
                    last = find_or_insert(cx, cy, 0, table_keys, table_vals, chunk_keys,
                                          n_chunks)  # fmt: skip
                    last_x, last_y = cx, cy
                for i in range(ia, ib + 1):
                    wx = kx[i - i0]
                    if wx == 0.0:
                        continue
                    ox = (i + 0.5) * res - x[s]
                    for j in range(ja, jb + 1):
                        k = wx * ky[j - j0]
                        oy = (j + 0.5) * res - y[s]
                        cell = alpha[last, i & 7, j & 7]
                        for c in range(4):
                            cell[c] += m[c] * k
                        ranged = beta[last, i & 7, j & 7]
                        ranged[0] += ind * k
                        ranged[1] += ind2 * k * k
                        ranged[2] += far * k
                        ranged[3] += w * k * ox * ox
                        ranged[4] += w * k * oy * oy
                        ranged[5] += lat * k
    return x.shape[0]
