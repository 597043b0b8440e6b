"""Sparse chunked storage of the Beta concentration parameters.

:class:`ChunkedGrid` holds the evidence mass sum_i k(m_*, m_i) y_i and sum_i k(m_*, m_i)(1 - y_i)
of ``eq:alpha_param`` / ``eq:beta_param`` in dense 8^3 chunks (float32) found through a hash of
chunk coordinates (:mod:`undertow.mapping.chunks`), so memory grows with the mapped volume, not
with the bounding box. Cell index i = floor(p / res), centre (i + 1/2) res. The priors alpha_0,
beta_0 are added when the map is read out (:class:`~undertow.occupancy.OccupancyMap`), so only
cells that received kernel mass are reported.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..errors import DataError
from .chunks import CHUNK, CHUNK_LIMIT, add_mass_to_cells, boxes_chunks, insert_keys, rehash
from .kernels import (
    ALL_CELLS,
    MODE_CELL,
    MODE_PRODUCT,
    count_chunks,
    insert_chunks,
    scatter_slab,
    slab_splits,
)
from .rayscatter import (
    ray_insert_chunks,
    ray_scatter_slab,
    ray_slab_splits,
)
from .spill import TILE, ChunkSpill, tiles_of
from .threads import PARALLEL_MIN_SAMPLES, parallel_slot, run_parts
from .tpuscatter import tpu_insert_chunks, tpu_scatter_slab


def points_extent(points: np.ndarray):
    """(min (3,), max (3,), all finite) of non-empty (N, 3) ``points``: computed once per
    integrate and shared by the memory estimate, the range check and the slab split."""
    return _extent(np.ascontiguousarray(points, dtype=float))


# bytes per chunk: alpha and beta (float32), its key, two hash slots (key, value)
CHUNK_BYTES = 2 * 4 * CHUNK**3 + 3 * 8 + 2 * 2 * 8
GROWTH_PEAK = 2.5  # growing by 1.5 holds the old and the new arrays at once
READOUT_BYTES_PER_CELL = 100  # cells(): indices, keys, alpha and beta as float64, temporaries
RAY_PARALLEL_MIN_SAMPLES = 1 << 16  # scatter_rays: fewer samples stay on the calling thread
LOW_WATER = 0.75  # a spill brings the chunks held down to this share of the resident budget
READOUT_BATCH = 8192  # chunks read out at once when some are spilled
MAX_TOUCHED = 256  # boxes kept for take_touched; beyond, they are merged into one
KEEP_TOUCHED = 16  # the latest of them whose tiles a spill keeps
SPILL_RETRY = 4  # writes over the budget before a spill that freed too little is tried again
# (or once the chunks held grew by an eighth of the budget's low water)


def peak_bytes(chunks: float, cells_bound: float) -> float:
    """Peak bytes of holding ``chunks`` chunks: the growth copy, or the chunks plus the readout
    of their cells with mass (at most ``cells_bound``)."""
    cells = min(chunks * CHUNK**3, cells_bound)
    held = chunks * CHUNK_BYTES
    return max(GROWTH_PEAK * held, held + cells * READOUT_BYTES_PER_CELL)


def load_kernels() -> None:
    """Load the kernel of a growth (the rehash; numba's cache, else a compile) now: a map
    first outgrows its table mid-run, where a live session would stall on it."""
    ChunkedGrid(1.0, capacity=8)._grow()


class ChunkedGrid:
    """Hash of dense CHUNK^3 blocks of (alpha mass, beta mass); grows by a factor 1.5.

    ``resident_bytes``: the most the chunks may hold in memory (None: no limit); beyond it the
    tiles farthest from the latest write move to a :class:`~undertow.mapping.spill.ChunkSpill`
    (a temporary file in ``spill_dir``, None: the system's) and come back before a write that
    may reach them, so the map is the same bit for bit (:mod:`undertow.mapping.spill`)."""

    def __init__(self, resolution: float, capacity: int = 64, *,
                 resident_bytes: float | None = None, spill_dir=None) -> None:  # fmt: skip
        self.resolution = float(resolution)
        self._support_cells: dict = {}  # _support by mode and length scales
        self._n = np.zeros(1, np.int64)
        self._allocate(max(int(capacity), 8))
        self._touched: list | None = None  # boxes (lo, hi) in m written since taken
        self._merged = None  # older such boxes merged into one (a view that stopped taking)
        self.resident_bytes = None if resident_bytes is None else float(resident_bytes)
        self.spill = ChunkSpill(spill_dir)
        self._writes = 0  # writes over the budget
        self._spill_again = (0, 0)  # a spill is tried again at this write or chunk count
        self._born = 0  # chunks created so far: the next chunk's birth number

    def track_touched(self) -> None:
        """Record the box each later write may touch, for :meth:`take_touched` (a live view
        that redraws only the chunks changed since its last draw)."""
        if self._touched is None:
            self._touched = []

    def _begin_write(self, extent, reach) -> int:
        """Before a write of samples in box ``extent`` with kernels of ``reach`` (m, >= the
        largest support: the largest length scale; a cell kernel reaches one cell): note the box
        widened by the reach for :meth:`take_touched`, and take back the spilled tiles the write
        may reach (the box widened by two more cells: a support's cells are rounded outwards).
        Returns the chunks held then (the chunks after it are the write's new ones)."""
        if self._touched is None and not len(self.spill):
            return self.n_chunks  # (nothing to note, nothing to take back)
        r = max(float(np.max(reach)), self.resolution)
        lo, hi = np.asarray(extent[0]) - r, np.asarray(extent[1]) + r
        if self._touched is not None:
            self._touched.append((lo, hi))
            if len(self._touched) > MAX_TOUCHED:  # a view that stopped taking them: one box
                merged = [] if self._merged is None else [self._merged]
                self._merged, self._touched = _union([*merged, *self._touched]), []
        if len(self.spill):
            span, pad = CHUNK * self.resolution, 2 * self.resolution
            tiles = self.spill.tiles_in(np.floor((lo - pad) / span).astype(np.int64),
                                        np.floor((hi + pad) / span).astype(np.int64))  # fmt: skip
            if tiles:
                self._take_back(tiles)
        return self.n_chunks

    def _end_write(self, n0: int, extent) -> None:
        """After a write: number the chunks it created (in the order the kernels created them,
        the order :meth:`cells` keeps), then spill if the chunks exceed the resident budget."""
        n1 = self.n_chunks
        if n1 > n0:
            self._birth[n0:n1] = np.arange(self._born, self._born + n1 - n0)
            self._born += n1 - n0
        if self.resident_bytes is not None and n1 * CHUNK_BYTES > self.resident_bytes:
            self._spill_far(extent)

    def _take_back(self, tiles) -> None:
        """Reinsert the chunks of spilled ``tiles`` (their mass and birth numbers)."""
        keys, births, alpha, beta = self.spill.take(tiles)
        n_before = self.n_chunks
        slots = self._insert_keys(keys)
        new = slots >= n_before
        self._alpha[slots[new]], self._beta[slots[new]] = alpha[new], beta[new]
        self._birth[slots[new]] = births[new]
        if not new.all():  # held already (created empty meanwhile): 0 + mass is the mass
            held = slots[~new]
            self._alpha[held] += alpha[~new]
            self._beta[held] += beta[~new]
            self._birth[held] = np.minimum(self._birth[held], births[~new])

    def _spill_far(self, extent) -> None:
        """Spill whole tiles, the farthest from the centre of the write box ``extent`` first,
        until the chunks held are LOW_WATER of the budget; the tiles of ``extent`` and of the
        KEEP_TOUCHED latest boxes not yet taken by :meth:`take_touched` (a view about to redraw
        them) stay. A chunk spilled before the view takes its box keeps the view's last drawing
        of it until it is written again."""
        n, span = self.n_chunks, CHUNK * self.resolution
        self._writes += 1
        target = int(LOW_WATER * self.resident_bytes / CHUNK_BYTES)
        if self._writes < self._spill_again[0] and n < self._spill_again[1]:
            return
        tiles, inverse, counts = np.unique(tiles_of(self._keys[:n]), axis=0, return_inverse=True,
                                           return_counts=True)  # fmt: skip
        inverse = inverse.reshape(-1)
        centre = (np.asarray(extent[0]) + np.asarray(extent[1])) / 2 / (span * TILE)
        far = np.linalg.norm(tiles + 0.5 - centre, axis=1)
        for lo, hi in [*(self._touched or [])[-KEEP_TOUCHED:], (extent[0], extent[1])]:
            t_lo = np.floor(np.asarray(lo) / (span * TILE))
            t_hi = np.floor(np.asarray(hi) / (span * TILE))
            far[np.all((tiles >= t_lo) & (tiles <= t_hi), axis=1)] = -1.0
        order = np.argsort(-far, kind="stable")
        order = order[far[order] >= 0]
        k = int(np.searchsorted(np.cumsum(counts[order]), n - target)) + 1
        out = np.isin(inverse, order[:k])
        # too little to spill (the rest is near the writes): again some writes or chunks later
        if out.sum() < (n - target) // 2:
            self._spill_again = (self._writes + SPILL_RETRY, n + max(target // 8, 1))
        else:
            self._spill_again = (0, 0)
        if not out.any():
            return
        gone, keep = np.flatnonzero(out), np.flatnonzero(~out)
        self.spill.put(self._keys[gone], self._birth[gone], self._alpha[gone], self._beta[gone])
        m = len(keep)
        for a in (self._keys, self._alpha, self._beta, self._birth):
            a[:m] = a[keep]
            a[m:n] = 0  # the kernels expect a new chunk's mass at zero
        self._table_keys.fill(-1)
        rehash(self._keys, m, self._table_keys, self._table_vals)
        self._n[0] = m

    def take_touched(self) -> np.ndarray:
        """Indices of the chunks that the writes since the last call may have changed (every
        chunk written, and maybe a few neighbours: the boxes are the samples' extents widened
        by the kernels' reach), sorted; the record is then cleared."""
        boxes = [*(self._touched or []), *([] if self._merged is None else [self._merged])]
        if self._touched is not None:
            self._touched, self._merged = [], None
        n = self.n_chunks
        if not boxes or n == 0:
            return np.zeros(0, np.int64)
        span = CHUNK * self.resolution
        lo = np.floor(np.array([b[0] for b in boxes]) / span).astype(np.int64)
        hi = np.floor(np.array([b[1] for b in boxes]) / span).astype(np.int64)
        count = int(np.prod(hi - lo + 1, axis=1).sum())
        if count > n:  # larger than the map: compare every chunk's key with the boxes
            keys = self._keys[:n]
            inside = np.zeros(n, bool)
            for a, b in zip(lo, hi, strict=True):
                inside |= np.all((keys >= a) & (keys <= b), axis=1)
            return np.flatnonzero(inside)
        found = boxes_chunks(lo, hi, count, self._table_keys, self._table_vals)
        return np.unique(found[found >= 0])

    def _allocate(self, capacity: int) -> None:
        self._keys = np.zeros((capacity, 3), np.int64)
        self._alpha = np.zeros((capacity, CHUNK, CHUNK, CHUNK), np.float32)
        self._beta = np.zeros((capacity, CHUNK, CHUNK, CHUNK), np.float32)
        self._birth = np.zeros(capacity, np.int64)
        size = 1 << int(np.ceil(np.log2(2 * capacity)))  # power of two, load factor <= 1/2
        self._table_keys = np.full(size, -1, np.int64)
        self._table_vals = np.zeros(size, np.int64)

    def _grow(self, chunks: int = 0) -> None:
        """Room for 1.5 times the chunks the arrays hold, or for ``chunks`` if more."""
        n = int(self._n[0])
        keys, alpha, beta, birth = self._keys, self._alpha, self._beta, self._birth
        self._allocate(max(keys.shape[0] * 3 // 2, chunks))
        self._keys[:n], self._alpha[:n], self._beta[:n] = keys[:n], alpha[:n], beta[:n]
        self._birth[:n] = birth[:n]
        rehash(self._keys, n, self._table_keys, self._table_vals)

    def _insert_keys(self, keys: np.ndarray) -> np.ndarray:
        """Insert the chunks of coordinates ``keys`` (k, 3) not held, in that order (growing
        the arrays as needed); returns each one's index."""
        slots, start = np.empty(len(keys), np.int64), 0
        while start < len(keys):
            start = insert_keys(start, keys, slots, *self._tables()[:4])
            if start < len(keys):
                self._grow()
        return slots

    def place(self, find_new, first: int, end: int, parts: int) -> None:
        """Place every chunk the sample rows first..end - 1 of a scatter touch, in the order
        one pass over them places them (the first touch). ``find_new(start, stop, held,
        into)``: a kernel of the :func:`~undertow.mapping.kernels.insert_chunks` kind, inserting
        into ``into`` (table keys, values, chunk keys, count) the chunks of rows start..stop - 1
        that the table ``held`` (keys, values) does not hold, returning the first row left when
        ``into`` is full, else ``stop``. Fewer than :data:`~undertow.mapping.threads.
        PARALLEL_MIN_SAMPLES` rows on one part (a ping): straight into the grid's table.
        Otherwise (the parts at once, :func:`~undertow.mapping.threads.run_parts`): each part, a
        range of rows, into a table of its own, the grid's only read; then the arrays grow once
        to the chunks found, and each part's new chunks are inserted into the grid's, part after
        part, those placed already by an earlier part left out: the order of one pass, as a
        chunk's first touch is in the first part that touches it."""
        if parts <= 1 and end - first < PARALLEL_MIN_SAMPLES:  # (a ping: no tables to make)
            while first < end:
                tables = self._tables()
                first = find_new(first, end, tables[:2], tables[:4])
                if first < end:
                    self._grow()
            return
        parts = max(parts, 1)
        cuts = np.linspace(first, end, parts + 1).round().astype(np.int64).tolist()
        held, found = self._tables()[:2], [None] * parts

        def part(t: int) -> None:
            found[t] = _new_chunks(find_new, cuts[t], cuts[t + 1], held)

        run_parts(part, parts)
        need = self.n_chunks + sum(len(keys) for keys in found)
        if need > self._keys.shape[0]:  # one growth to (at most) the chunks needed, not a series
            self._grow(need)
        for keys in found:
            self._insert_keys(keys)

    @property
    def n_chunks(self) -> int:
        """Chunks held in memory (:attr:`spill` has the others)."""
        return int(self._n[0])

    @property
    def nbytes(self) -> int:
        """Bytes held in memory by the storage arrays (capacity, not only the chunks in use)
        and the index of the spilled chunks."""
        arrays = (self._keys, self._alpha, self._beta, self._birth, self._table_keys,
                  self._table_vals)  # fmt: skip
        return int(sum(a.nbytes for a in arrays)) + self.spill.index_bytes

    def _tables(self):
        return (self._table_keys, self._table_vals, self._keys, self._n, self._alpha, self._beta)

    def scatter(self, mode, points, label, sigma0, variance, var_bounds, l_min, l_max,
                extent=None) -> None:  # fmt: skip
        """Place every chunk the samples touch (growing the arrays as needed), then run the
        scatter kernel: on several threads, one slab of cells each, when there are enough
        samples (:func:`~undertow.mapping.threads.parallel_slot`); the map is the same either
        way, bit for bit.
        ``extent``: :func:`points_extent` of ``points`` when the caller has it."""
        n = points.shape[0]
        if n == 0:
            return
        if extent is None:
            extent = points_extent(points)
        self._check_extent(extent)
        n0 = self._begin_write(extent, l_max)
        lo, hi = var_bounds
        res = self.resolution

        def find_new(start, stop, held, into):
            return insert_chunks(start, stop, mode, points, variance, lo, hi, l_min, l_max, res,
                                 *held, *into)  # fmt: skip

        with parallel_slot(n) as parts:
            self.place(find_new, 0, n, parts)
            tk, tv, _, _, alpha, beta = self._tables()
            args = (mode, points, label, sigma0, variance, lo, hi, l_min, l_max, res, tk, tv,
                    alpha, beta)  # fmt: skip
            if parts > 1:  # a slab of cells per part, each walking every sample in order
                axis, splits = slab_splits(points, res, parts, *extent[:2])
                run_parts(lambda t: scatter_slab(axis, splits[t], splits[t + 1], *args), parts)
            else:
                scatter_slab(0, -ALL_CELLS, ALL_CELLS, *args)
        self._end_write(n0, extent)

    def scatter_rays(self, rays, var_bounds, l_min, l_max, extent) -> None:
        """:meth:`scatter` in product mode (the adaptive kernel) of the samples of ``rays``
        (:class:`~undertow.mapping.samples.Rays`) straight from the rays
        (:mod:`undertow.mapping.rayscatter`): the same chunks in the same order and the same
        map, bit for bit. On one thread the chunks are placed as the scatter reaches them (one
        pass); on several, first. ``extent``: of the samples
        (:func:`~undertow.mapping.rayscatter.ray_extent`)."""
        self._check_extent(extent)
        n0 = self._begin_write(extent, l_max)
        n = int(rays.rows[-1])
        if n < RAY_PARALLEL_MIN_SAMPLES:  # (no thread slot to take)
            self._scatter_rays(rays, var_bounds, l_min, l_max, extent, 1)
        else:
            with parallel_slot(n, RAY_PARALLEL_MIN_SAMPLES) as parts:
                self._scatter_rays(rays, var_bounds, l_min, l_max, extent, parts)
        self._end_write(n0, extent)

    def _scatter_rays(self, rays, var_bounds, l_min, l_max, extent, parts: int) -> None:
        """:meth:`scatter_rays` on ``parts`` threads."""
        lo, hi = var_bounds
        res, n = self.resolution, int(rays.rows[-1])
        geometry = (rays.origin, rays.direction, rays.r, rays.var)
        if parts == 1:  # each chunk placed as the scatter reaches it
            start = 0
            while start < n:
                start = ray_scatter_slab(start, 0, -ALL_CELLS, ALL_CELLS, *geometry, rays.sig,
                                         rays.rows, rays.f, lo, hi, l_min, l_max, res,
                                         *self._tables(), True)  # fmt: skip
                if start < n:
                    self._grow()
            return

        def find_new(start, stop, held, into):
            return ray_insert_chunks(start, stop, *geometry, rays.rows, rays.f, lo, hi, l_min,
                                     l_max, res, *held, *into)  # fmt: skip

        self.place(find_new, 0, n, parts)
        args = (*geometry, rays.sig, rays.rows, rays.f, lo, hi, l_min, l_max, res,
                *self._tables(), False)  # fmt: skip
        self._in_ray_slabs(
            rays, extent, parts, lambda axis, a, b: ray_scatter_slab(0, axis, a, b, *args)
        )

    def scatter_tpu(self, rays, hits, cap: float, extent, n: int) -> None:
        """:meth:`scatter` in product mode of the ``tpu`` mapper's n samples of ``rays``
        (:class:`~undertow.mapping.samples.Rays`) and ``hits``
        (:class:`~undertow.mapping.tpuscatter.TpuHits`) straight from them
        (:mod:`undertow.mapping.tpuscatter`): the same chunks in the same order and the same
        map, bit for bit, as :meth:`scatter` of the written samples with l_min 0, l_max ``cap``.
        ``extent``: of the samples (:func:`~undertow.mapping.tpuscatter.tpu_extent`)."""
        self._check_extent(extent)
        n0 = self._begin_write(extent, cap)
        if n < RAY_PARALLEL_MIN_SAMPLES:  # (no thread slot to take)
            self._scatter_tpu(rays, hits, cap, extent, 1)
        else:
            with parallel_slot(n, RAY_PARALLEL_MIN_SAMPLES) as parts:
                self._scatter_tpu(rays, hits, cap, extent, parts)
        self._end_write(n0, extent)

    def _scatter_tpu(self, rays, hits, cap: float, extent, parts: int) -> None:
        """:meth:`scatter_tpu` on ``parts`` threads."""
        res, first = self.resolution, int(rays.rows[0])
        lattice = (hits.x, hits.y, hits.l, hits.z, hits.w)
        geometry = (rays.origin, rays.direction, rays.rows, rays.f)
        end = int(rays.rows[-1]) + 3 * len(hits.x)
        if parts == 1:  # each chunk placed as the scatter reaches it
            start = first
            while start < end:
                start = tpu_scatter_slab(start, 0, -ALL_CELLS, ALL_CELLS, *geometry, rays.sig,
                                         hits.l_free, *lattice, res, cap, *self._tables(),
                                         True)  # fmt: skip
                if start < end:
                    self._grow()
            return

        def find_new(start, stop, held, into):
            return tpu_insert_chunks(start, stop, *geometry, hits.l_free, *lattice, res, *held,
                                     *into)  # fmt: skip

        self.place(find_new, first, end, parts)
        args = (*geometry, rays.sig, hits.l_free, *lattice, res, cap, *self._tables(), False)
        self._in_ray_slabs(
            rays, extent, parts, lambda axis, a, b: tpu_scatter_slab(first, axis, a, b, *args)
        )

    def _in_ray_slabs(self, rays, extent, parts: int, scatter) -> None:
        """``scatter(axis, first, stop)`` for ``parts`` slabs of cells [first, stop) along
        ``axis``, cut at the quantiles of the rays' samples (``ray_slab_splits``), at once
        (:func:`~undertow.mapping.threads.run_parts`); the chunks already placed."""
        axis, splits = ray_slab_splits(rays.origin, rays.direction, rays.r, rays.rows, rays.f,
                                       self.resolution, parts, *extent[:2])  # fmt: skip
        run_parts(lambda t: scatter(axis, splits[t], splits[t + 1]), parts)

    def _check_extent(self, extent) -> None:
        """Chunk coordinates are packed in 21 bits per axis: keep |p| below that range (and
        finite); ``extent`` as :func:`points_extent`."""
        limit = (CHUNK_LIMIT - 2) * CHUNK * self.resolution
        lo, hi, finite = extent
        if not (finite and max(max(hi.tolist()), -min(lo.tolist())) < limit):
            raise DataError(f"map coordinates beyond +-{limit:.0f} m: shift the origin closer")

    def estimate_bytes(self, mode, points, variance, var_bounds, l_min, l_max,
                       limit_bytes: float, extent=None) -> int:  # fmt: skip
        """Peak bytes that scattering ``points`` (same arguments as :meth:`scatter`) and reading
        the map out would need: distinct chunks touched by the samples' supports (counting those
        already held) x :data:`CHUNK_BYTES`, with the growth copy, or the readout of every cell
        with mass. Exact chunk counting stops once the estimate exceeds ``limit_bytes``."""
        n = points.shape[0]
        if n == 0:
            return self.nbytes
        extent = points_extent(points) if extent is None else extent
        bound = self.bound_bytes(mode, n, l_min, l_max, limit_bytes, extent)
        if bound is not None:
            return bound
        held = self.n_chunks
        limit_chunks = held + int(limit_bytes // (GROWTH_PEAK * CHUNK_BYTES)) + 1
        table = np.full(1 << int(np.ceil(np.log2(2 * limit_chunks + 2))), -1, np.int64)
        rehash(self._keys, held, table, np.zeros(table.size, np.int64))
        lo, hi = var_bounds
        chunks = count_chunks(mode, points, variance, lo, hi, l_min, l_max, self.resolution,
                               table, held, limit_chunks)  # fmt: skip
        return int(peak_bytes(chunks, n * self._support(mode, l_min, l_max)[2]))

    def _support(self, mode, l_min, l_max) -> tuple:
        """(cells a sample's support spans per axis, the chunks it spans, its cells), each at
        most: up to l_max (product kernel) or l (radial kernel) either side; scalar arithmetic,
        remembered per mode and length scales, so the common case (far below the limit) costs
        a streaming call little."""
        key = (mode, *np.asarray(l_min, float).tolist(), *np.asarray(l_max, float).tolist())
        support = self._support_cells.get(key)
        if support is None:
            lo, hi = key[1:4], key[4:7]
            if mode == MODE_CELL:
                cells = (1.0, 1.0, 1.0)
            elif mode == MODE_PRODUCT:
                cells = tuple(math.ceil(2 * max(a, b) / self.resolution) + 1.0
                              for a, b in zip(lo, hi, strict=True))  # fmt: skip
            else:
                cells = (math.ceil(2 * lo[0] / self.resolution) + 1.0,) * 3
            chunks = math.prod(math.ceil(c / CHUNK) + 1.0 for c in cells)
            support = self._support_cells[key] = (cells, chunks, math.prod(cells))
        return support

    def bound_bytes(self, mode, n: int, l_min, l_max, limit_bytes: float, extent) -> int | None:
        """:meth:`estimate_bytes` of n > 0 samples of ``extent`` (:func:`points_extent`) when
        an upper bound settles it (every sample's support in new chunks, or the chunks of the
        samples' bounding box, within the limit; or one sample's support alone over it); None
        when only counting the chunks can tell."""
        cells_per_axis, chunks_per_sample, cells_per_sample = self._support(mode, l_min, l_max)
        cells_bound = float(n) * cells_per_sample
        held = self.n_chunks

        def peak(chunks: float) -> float:
            return peak_bytes(chunks, cells_bound)

        if peak(held + n * chunks_per_sample) <= limit_bytes:
            return int(peak(held + n * chunks_per_sample))  # cheapest upper bound
        p_lo, p_hi, finite = extent
        box = math.inf  # the chunks of the box (scalar arithmetic: a streaming call's cost)
        if finite:
            sides = zip(p_lo.tolist(), p_hi.tolist(), cells_per_axis, strict=True)
            box = math.prod(math.ceil(((b - a) / self.resolution + c) / CHUNK) + 1.0
                            for a, b, c in sides)  # fmt: skip
        if peak(held + min(n * chunks_per_sample, box)) <= limit_bytes:
            return int(peak(held + min(n * chunks_per_sample, box)))  # cheap upper bound
        if peak(held + chunks_per_sample) > limit_bytes:
            return int(peak(held + chunks_per_sample))  # one sample's support alone is too much
        return None

    def add_mass(self, cells, d_alpha, d_beta) -> None:
        """Add evidence mass to given cells (seeding from a prior map)."""
        if cells.shape[0] == 0:
            return
        extent = points_extent((cells + 0.5) * self.resolution)
        self.write(add_mass_to_cells, cells.shape[0], (cells, d_alpha, d_beta), extent, 0.0)

    def write(self, kernel, n: int, args: tuple, extent, reach) -> None:
        """Run a compiled writer of n items, ``kernel(start, *args, table_keys, table_vals,
        chunk_keys, n_chunks, alpha, beta)``, which returns the first item whose chunks did
        not fit (n when done): the arrays grow and it resumes there. ``extent`` of the items
        (:func:`points_extent`) and ``reach`` (m) as a scatter's, for the spill."""
        self._check_extent(extent)
        n0 = self._begin_write(extent, reach)
        start = 0
        while start < n:
            start = kernel(start, *args, *self._tables())
            if start < n:
                self._grow()
        self._end_write(n0, extent)

    def chunk_mass(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(chunk coordinates (k, 3), alpha mass (k, C, C, C), beta mass) of chunks ``idx``
        (copies; C = CHUNK: cell (i, j, l) of chunk c is cell c * C + (i, j, l))."""
        idx = np.asarray(idx, np.int64)
        return self._keys[idx], self._alpha[idx], self._beta[idx]

    def cells(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(cells (M, 3) int64, alpha mass (M,), beta mass (M,)) of cells with mass > 0, chunk by
        chunk in the order they were created (cell by cell within a chunk), spilled or not."""
        parts = list(self.iter_cells())
        if len(parts) == 1:
            return parts[0]
        return tuple(np.concatenate([p[i] for p in parts]) for i in range(3))

    def iter_cells(self, batch: int = READOUT_BATCH):
        """:meth:`cells` in parts of at most ``batch`` chunks (one part when none is spilled):
        a map larger than memory read out part by part."""
        n = self.n_chunks
        if not len(self.spill):
            yield _massed_cells(self._keys[:n], self._alpha[:n], self._beta[:n])
            return
        keys_out, births_out, slots_out = self.spill.index()
        order = np.argsort(np.concatenate([self._birth[:n], births_out]), kind="stable")
        for part in np.array_split(order, max(1, -(-len(order) // batch))):
            held = part < n
            keys = np.empty((len(part), 3), np.int64)
            keys[held], keys[~held] = self._keys[part[held]], keys_out[part[~held] - n]
            alpha = np.empty((len(part), CHUNK, CHUNK, CHUNK), np.float32)
            beta = np.empty_like(alpha)
            alpha[held], beta[held] = self._alpha[part[held]], self._beta[part[held]]
            alpha[~held], beta[~held] = self.spill.read(slots_out[part[~held] - n])
            yield _massed_cells(keys, alpha, beta)


def _new_chunks(find_new, start: int, stop: int, held) -> np.ndarray:
    """The coordinates (k, 3) of the chunks that rows start..stop - 1 touch and the table
    ``held`` does not hold, in the order first touched (:meth:`ChunkedGrid.place`): a table of
    their own, doubled and rehashed when full."""
    keys, count = np.zeros((64, 3), np.int64), np.zeros(1, np.int64)
    while True:
        table = (np.full(2 * len(keys), -1, np.int64), np.zeros(2 * len(keys), np.int64))
        rehash(keys, count[0], *table)
        start = find_new(start, stop, held, (*table, keys, count))
        if start >= stop:
            return keys[: count[0]]
        keys = np.concatenate([keys, np.zeros_like(keys)])


def _union(boxes) -> tuple[np.ndarray, np.ndarray]:
    """The box (lo, hi) around ``boxes``."""
    return (np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0))


def _massed_cells(keys, alpha, beta) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cells, alpha, beta) of the cells with mass > 0 of chunks ``keys`` (k, 3) of masses
    (k, C, C, C), in chunk then cell order."""
    c, i, j, k = np.nonzero((alpha + beta) > 0)
    cells = keys[c] * CHUNK + np.stack([i, j, k], axis=1)
    return cells, alpha[c, i, j, k].astype(float), beta[c, i, j, k].astype(float)


@njit(cache=True)
def _extent(points):
    """(min (3,), max (3,), all finite) over the rows of ``points`` (N, 3), N > 0, in one pass
    (numpy's axis-0 reductions of an (N, 3) array are many times slower)."""
    lo = points[0].copy()
    hi = points[0].copy()
    finite = True
    for i in range(points.shape[0]):
        for j in range(3):
            v = points[i, j]
            if v < lo[j]:
                lo[j] = v
            elif v > hi[j]:
                hi[j] = v
            elif v != v:
                finite = False
    return lo, hi, finite
