"""The ``tpu`` mapper's per-column uncertainties: :class:`ColumnGrid`.

Beside the map's cells, the ``tpu`` mapper sums per (x, y) column, with the weights w_i its
hits leave there (the same across-floor kernel, weight and lengths as the map's cells:
:mod:`undertow.mapping.tpu`), the hits' evidence and its uncertainties (:data:`~undertow.
occupancy.COLUMN_SUMS`):

    W = sum_i w_i,   V = sum_i w_i sigma_v,i^2,   X = sum_i w_i (c l_x,i)^2,
    Y = sum_i w_i (c l_y,i)^2,

sigma_v,i the hit's vertical standard deviation (pose, range, waves, a wide beam's shortfall)
and c l_x,i, c l_y,i the standard deviations of its kernel across the floor (c =
:data:`~undertow.mapping.tpu.KERNEL_STD`; the pose's and a wide beam's horizontal
uncertainty, at least the base kernel's): how far from where it was placed the map spreads
it. The surface reads V / W, X / W and Y / W as the column's vertical and horizontal
uncertainty (:func:`~undertow.mapping.surface.evidence_surface`). The sums are float32, as
the map's masses.

They are kept in a second :class:`~undertow.mapping.grid.ChunkedGrid` of the map's resolution
whose cells (i, j, c) hold sum c of column (i, j) as alpha mass: each hit is scattered as its
lattice is (:func:`~undertow.mapping.tpuscatter.tpu_scatter_slab`, or the generic product
scatter for written samples), with its vertical cells replaced by the cells c = 0 .. 3 and
their weights by w sigma^2 (the vertical kernel, half a cell, keeps each in its own cell). The
grid spills as the map's does, with an eighth of its resident budget.
"""

from __future__ import annotations

import numpy as np

from ..occupancy import COLUMN_SUMS, ColumnStats
from .grid import ChunkedGrid, points_extent
from .kernels import MODE_PRODUCT
from .samples import Samples
from .tpu import KERNEL_STD, tpu_hit_weights
from .tpuscatter import TpuHits, tpu_extent

#: the share of the map's resident budget the column sums may hold in memory
RESIDENT_SHARE = 1 / 8


class ColumnGrid:
    """Sums per column of the ``tpu`` mapper's hits (module doc)."""

    def __init__(self, resolution: float, resident_bytes: float | None = None) -> None:
        self.resolution = float(resolution)
        budget = None if resident_bytes is None else resident_bytes * RESIDENT_SHARE
        self.grid = ChunkedGrid(self.resolution, resident_bytes=budget)

    def _channels(self, n: int) -> np.ndarray:
        """The cells' centres z of the sums c = 0 .. 3, (n, 4)."""
        return np.tile((np.arange(len(COLUMN_SUMS)) + 0.5) * self.resolution, (n, 1))

    def add_rays(self, rays, hits: TpuHits, cap: float) -> None:
        """Add the hits of ``rays`` (:class:`~undertow.mapping.samples.Rays`; their free
        samples are not scattered) with their :class:`TpuHits`."""
        n = len(hits.x)
        if n == 0:
            return
        spread = (KERNEL_STD * hits.l) ** 2
        masses = np.stack([hits.weight, hits.weight * hits.var_v, hits.weight * spread[:, 0],
                           hits.weight * spread[:, 1]], axis=1)  # fmt: skip
        masses = np.where(np.isfinite(masses), masses, 0.0)
        z = self._channels(n)
        hits_only = rays._replace(rows=np.zeros(n + 1, dtype=rays.rows.dtype))
        zero = np.zeros((n, 2))
        for part in (slice(0, 3), slice(3, 4)):  # three cells a pass: a hit's lattice
            w = np.concatenate([masses[:, part], zero], axis=1)[:, :3]
            zz = np.concatenate([z[:, part], z[:, :2]], axis=1)[:, :3]
            pass_hits = hits._replace(z=np.ascontiguousarray(zz), w=np.ascontiguousarray(w))
            lo, hi, finite, count = tpu_extent(hits_only.origin, hits_only.direction,
                                               hits_only.rows, hits_only.f, pass_hits.x,
                                               pass_hits.y, pass_hits.z, pass_hits.w)  # fmt: skip
            if count:
                self.grid.scatter_tpu(hits_only, pass_hits, cap, (lo, hi, finite), count)

    def add_samples(self, samples: Samples, cap: float, **settings) -> None:
        """Add the hits of written ``samples`` (the generic product scatter; ``settings`` as
        :func:`~undertow.mapping.tpu.tpu_training`'s)."""
        x, y, lx, ly, weight, var_v = tpu_hit_weights(samples, **settings)
        n = len(x)
        if n == 0:
            return
        masses = np.stack([weight, weight * var_v, weight * (KERNEL_STD * lx) ** 2,
                           weight * (KERNEL_STD * ly) ** 2], axis=1).reshape(-1)  # fmt: skip
        points = np.stack([np.repeat(x, len(COLUMN_SUMS)), np.repeat(y, len(COLUMN_SUMS)),
                           self._channels(n).reshape(-1)], axis=1)  # fmt: skip
        lengths = np.repeat(np.stack([lx, ly, np.full(n, self.resolution / 2)], 1),
                            len(COLUMN_SUMS), axis=0)  # fmt: skip
        keep = np.isfinite(masses) & (masses > 0)
        caps = np.full(3, cap)
        training = Samples.from_points(points[keep], np.ones(int(keep.sum())), masses[keep],
                                       lengths[keep] / caps)  # fmt: skip
        if len(training):
            self.grid.scatter(MODE_PRODUCT, training.points, training.label, training.sigma0,
                              training.pose_variance, (np.zeros(3), np.ones(3)), np.zeros(3),
                              caps, points_extent(training.points))  # fmt: skip

    def add_stats(self, stats: ColumnStats) -> None:
        """Add sums already made (a prior map's)."""
        if stats is None or not len(stats):
            return
        k = len(COLUMN_SUMS)
        cells = np.column_stack([np.repeat(stats.cells, k, axis=0),
                                 np.tile(np.arange(k), len(stats))])  # fmt: skip
        mass = stats.sums.reshape(-1)
        self.grid.add_mass(cells, mass, np.zeros_like(mass))

    def stats(self) -> ColumnStats:
        """The sums per column (:class:`~undertow.occupancy.ColumnStats`)."""
        cells, alpha, _ = self.grid.cells()
        k = len(COLUMN_SUMS)
        ok = (cells[:, 2] >= 0) & (cells[:, 2] < k)
        cells, alpha = cells[ok], alpha[ok]
        columns, inverse = np.unique(cells[:, :2], axis=0, return_inverse=True)
        sums = np.zeros((len(columns), k))
        np.add.at(sums, (inverse.reshape(-1), cells[:, 2]), alpha)
        return ColumnStats(columns, sums)
