"""Sparse kernels of the paper and the numba scatter kernels that apply them to a chunked grid.

Public (numpy, for users and tests):

- :func:`sparse_kernel` -- ``eq:kernel``, the sparse kernel of Melkumyan and Ramos:
  k(d) = sigma_0 [ (2 + cos(2 pi d / l)) (1 - d / l) / 3 + sin(2 pi d / l) / (2 pi) ] for d < l,
  and 0 for d >= l.
- :func:`product_kernel` -- ``eq:decom_kernel`` combined as in ``eq:new_conc_params_alpha``:
  k(m_*, m_i) = sigma_0 prod_j k_j(|d_j|), d_j = <m_* - m_i, e_j>, with k_j the unit-sigma_0
  kernel of ``eq:kernel`` at length scale l_j. Two readings where the paper is loose: sigma_0 is
  applied ONCE to the product (the paper's k_j each carry sigma_0, which would give sigma_0^3),
  and the per-axis distance is |d_j| (the signed d_j would make the kernel one-sided and not
  sparse). The support is the box |d_j| < l_j, so off the axes it differs from the radial kernel.

Numba, plain arrays: the scatter kernel loops over training samples and adds each sample's
kernel weight to the cells inside its compact support, found by index arithmetic (cell index
i = floor(p / res), centre (i + 1/2) res); the grid is a hash of dense 8^3 chunks in plain arrays
(:mod:`undertow.mapping.chunks`). A scatter is two passes: :func:`insert_chunks` places every
chunk the supports touch (returning the first sample it could not place when the chunk arrays
are full; the caller grows them and resumes), then :func:`scatter_slab` adds the mass with the
table read only, so several threads can run it at once (:meth:`~undertow.mapping.grid.
ChunkedGrid.scatter`, :func:`~undertow.mapping.threads.run_parts`), each owning a slab
of cells along x or y (:func:`slab_splits`) and walking all samples in order: every cell
receives the same terms in the same order whatever the slabs, so the map is the same bit
for bit. :func:`count_chunks` counts the chunks a scatter would touch (the grid's memory
estimate).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .chunks import (
    CHUNK,
    CHUNK_SHIFT,
    chunk_box,
    find,
    find_or_insert,
    home_slot,
    pack_key,
    same_box,
    set_box,
)

MODE_PRODUCT, MODE_RADIAL, MODE_CELL = 0, 1, 2
ALL_CELLS = 1 << 62  # slab bounds (-ALL_CELLS, ALL_CELLS) hold every cell
_TWO_PI = 2.0 * np.pi


def sparse_kernel(d, length_scale, sigma0: float = 1.0) -> np.ndarray:
    """``eq:kernel``: s0 [(2 + cos 2 pi d/l)(1 - d/l)/3 + sin(2 pi d/l)/(2 pi)]; 0 if d >= l."""
    d = np.abs(np.asarray(d, dtype=float))
    r = d / np.asarray(length_scale, dtype=float)
    a = _TWO_PI * r
    k = (2.0 + np.cos(a)) * (1.0 - r) / 3.0 + np.sin(a) / _TWO_PI
    return sigma0 * np.where(r < 1.0, k, 0.0)


def product_kernel(delta, length_scales, sigma0: float = 1.0) -> np.ndarray:
    """``eq:decom_kernel`` in product form: sigma_0 prod_j k(|d_j|; l_j) (sigma_0 applied once).

    ``delta`` (..., 3) is m_* - m_i, ``length_scales`` broadcastable to it.
    """
    delta = np.asarray(delta, dtype=float)
    return sigma0 * np.prod(sparse_kernel(delta, length_scales), axis=-1)


@njit(cache=True, inline="always")
def _k1(d, l):
    """Unit-sigma_0 sparse kernel of ``eq:kernel`` at distance d >= 0."""
    if d >= l:
        return 0.0
    r = d / l
    a = _TWO_PI * r
    return (2.0 + np.cos(a)) * (1.0 - r) / 3.0 + np.sin(a) / _TWO_PI


# (sin x, cos x) by fdlibm's kernels (Sun Microsystems 1993, as in FreeBSD's msun k_sin.c, k_cos.c
# and e_rem_pio2.c): x = k pi/2 + y with |y| <= pi/4 (pi/2 split in a 33-bit head, so k pi/2 is
# exact for |k| < 2^20, and a tail), then the minimax polynomials of sin and cos on [-pi/4, pi/4]
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
_PIO2_HI, _PIO2_LO = 1.57079632673412561417e00, 6.07710050650619224932e-11
_TWO_OVER_PI, _THIRD, _INV_2PI = 2.0 / np.pi, 1.0 / 3.0, 1.0 / _TWO_PI


@njit(cache=True, inline="always")
def sincos(x):
    """(sin x, cos x) for |x| < 2^20 pi / 2, within about 1 ulp of libm (fdlibm's kernels; one
    range reduction and no call for both)."""
    k = np.floor(x * _TWO_OVER_PI + 0.5)
    y = (x - k * _PIO2_HI) - k * _PIO2_LO
    z = y * y
    s = y + y * z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    c = 1.0 - 0.5 * z + z * z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    q = np.int64(k) & 3
    if q == 0:
        return s, c
    if q == 1:
        return c, -s
    if q == 2:
        return -s, -c
    return -c, s


@njit(cache=True, inline="always")
def _support(s, mode, points, variance, var_lo, var_hi, l_min, l_max, res, lengths, lo, cnt,
             j0=0, j1=3):  # fmt: skip
    """Sample s's support box along axes j0 .. j1 - 1 (first cell ``lo[j]``, cells ``cnt[j]``);
    ``lengths[j]`` gets l_ij of ``eq:lengthscale_1`` (l_min in the other modes)."""
    for j in range(j0, j1):
        lengths[j] = l_min[j]
        span = var_hi[j] - var_lo[j]
        if mode == MODE_PRODUCT and span > 0.0:
            v = min(max((variance[s, j] - var_lo[j]) / span, 0.0), 1.0)
            lengths[j] = v * (l_max[j] - l_min[j]) + l_min[j]
        p = points[s, j] / res
        if mode == MODE_CELL:
            lo[j] = np.int64(np.floor(p))
            cnt[j] = 1
            continue
        lj = lengths[j] if mode == MODE_PRODUCT else l_min[0]
        r = lj / res
        i0 = np.int64(np.floor(p - r - 0.5)) + 1
        i1 = np.int64(np.ceil(p + r - 0.5)) - 1
        if i1 < i0:
            i1 = i0
        lo[j] = i0
        cnt[j] = i1 - i0 + 1


@njit(cache=True, inline="always")
def _support_weights(s, mode, points, res, lo, cnt, w):
    """Per axis j, at the support's cell centres: |d_j| (radial mode: the kernel takes the
    norm) or 1 (cell mode)."""
    for j in range(3):
        if mode == MODE_CELL:
            w[j, 0] = 1.0
            continue
        p = points[s, j] / res
        for a in range(cnt[j]):
            w[j, a] = abs((lo[j] + a + 0.5) - p) * res  # distance to the cell centre


@njit(cache=True, inline="always")
def _add_cell(alpha, beta, ci, offset, k, y):
    """k y to alpha and k (1 - y) to beta of cell ``offset`` of chunk ``ci`` (hits, y = 1, touch
    only alpha; free samples, y = 0, only beta)."""
    if y != 0.0:
        alpha[ci, offset] += k * y
    if y != 1.0:
        beta[ci, offset] += k * (1.0 - y)


@njit(cache=True, inline="always")
def _add_sample(s, mode, label, sigma0, l0, lo, cnt, w, a0, a1, b0, b1, chunks, c0, alpha, beta):
    """Add sample s's weighted label (radial or cell mode, weights of :func:`_support_weights`)
    to the cells lo + (a, b, c) of its support with a in [a0, a1), b in [b0, b1) (the whole
    support: [0, cnt)), in the chunks ``chunks`` (indexed from chunk ``c0``); ``alpha`` and
    ``beta`` are (chunks, CHUNK^3), cell (x, y, z) of a chunk at x CHUNK^2 + y CHUNK + z. Hits
    (y = 1) touch only alpha, free samples (y = 0) only beta."""
    y = label[s]
    sig = 1.0 if mode == MODE_CELL else sigma0[s]
    lx, ly, lz, nz, c0x, c0y, c0z = lo[0], lo[1], lo[2], cnt[2], c0[0], c0[1], c0[2]
    for a in range(a0, a1):
        wa = w[0, a]
        ix = lx + a
        cx = (ix >> CHUNK_SHIFT) - c0x
        ox = (ix & 7) << 6
        for b in range(b0, b1):
            wb = w[1, b]
            iy = ly + b
            cy = (iy >> CHUNK_SHIFT) - c0y
            oxy = ox | ((iy & 7) << 3)
            for c in range(nz):
                wc = w[2, c]
                k = _k1(np.sqrt(wa * wa + wb * wb + wc * wc), l0) if mode == MODE_RADIAL else 1.0
                if k <= 0.0:
                    continue
                iz = lz + c
                _add_cell(alpha, beta, chunks[cx, cy, (iz >> CHUNK_SHIFT) - c0z], oxy | (iz & 7),
                          k * sig, y)  # fmt: skip


@njit(cache=True, nogil=True)
def insert_chunks(start, stop, mode, points, variance, var_lo, var_hi, l_min, l_max, res,
                  held_keys, held_vals, table_keys, table_vals, chunk_keys, n_chunks):  # fmt: skip
    """Insert into the table every chunk the supports of samples start..stop - 1 touch that
    the table ``held`` (keys, values; only read) does not hold, in the order the samples first
    touch them (the pass before :func:`scatter_slab`; ``held`` the table itself for one pass,
    the grid's for a part of the samples on a thread, :meth:`~undertow.mapping.grid.ChunkedGrid.
    place`); returns ``stop`` when done, else the first sample whose chunks did not fit (the
    caller grows the arrays and resumes there)."""
    lo = np.zeros(3, np.int64)
    cnt = np.zeros(3, np.int64)
    lengths = np.empty(3)
    box = np.full(6, -1, np.int64)
    for s in range(start, stop):
        _support(s, mode, points, variance, var_lo, var_hi, l_min, l_max, res, lengths, lo, cnt)
        c0x, c0y, c0z = lo[0] >> CHUNK_SHIFT, lo[1] >> CHUNK_SHIFT, lo[2] >> CHUNK_SHIFT
        ncx = ((lo[0] + cnt[0] - 1) >> CHUNK_SHIFT) - c0x + 1
        ncy = ((lo[1] + cnt[1] - 1) >> CHUNK_SHIFT) - c0y + 1
        ncz = ((lo[2] + cnt[2] - 1) >> CHUNK_SHIFT) - c0z + 1
        if same_box(box, c0x, c0y, c0z, ncx, ncy, ncz):
            continue
        for a in range(ncx):
            for b in range(ncy):
                for c in range(ncz):
                    cx, cy, cz = c0x + a, c0y + b, c0z + c
                    if (find(cx, cy, cz, held_keys, held_vals) >= 0
                            or find(cx, cy, cz, table_keys, table_vals) >= 0):  # fmt: skip
                        continue  # placed (probing first: find_or_insert costs more a call)
                    if find_or_insert(cx, cy, cz, table_keys, table_vals, chunk_keys,
                                      n_chunks) < 0:  # fmt: skip
                        return s
        set_box(box, c0x, c0y, c0z, ncx, ncy, ncz)
    return stop


@njit(cache=True)
def _scratch(l_min, l_max, res):
    """Per-thread work arrays of the slab kernels: w (3, cells per support axis), lo, cnt,
    lengths, the chunk box (``chunks`` and its first chunk ``c0``; ``box`` none yet: counts -1)
    and the step rotations ``rot`` of :func:`_scatter_product`."""
    max_len = max(l_max[0], l_max[1], l_max[2], l_min[0], l_min[1], l_min[2])
    nmax = int(np.ceil(2.0 * max_len / res)) + 3
    ncm = (nmax >> CHUNK_SHIFT) + 2
    return (np.zeros((3, nmax)), np.zeros(3, np.int64), np.zeros(3, np.int64), np.empty(3),
            np.empty((ncm, ncm, ncm), np.int64), np.zeros(3, np.int64), np.full(6, -1, np.int64),
            np.full((3, 3), np.nan))  # fmt: skip


@njit(cache=True, nogil=True)  # other threads (links, Dask tiles) run meanwhile
def scatter_slab(axis, first, stop, mode, points, label, sigma0, variance, var_lo, var_hi,
                  l_min, l_max, res, table_keys, table_vals, alpha, beta):  # fmt: skip
    """Add k(m_*, m_i) y_i to alpha and k(m_*, m_i)(1 - y_i) to beta (``eq:alpha_param``,
    ``eq:beta_param``; ``eq:new_conc_params_*`` in product mode) for every sample, in the cells
    whose index along ``axis`` (0 or 1) is in [first, stop) (the slab; everything with
    first, stop = -ALL_CELLS, ALL_CELLS). Every chunk touched must already be in the table
    (:func:`insert_chunks`).

    mode 0: sigma_0 prod_j k(|d_j|; l_ij) with l_ij from ``eq:lengthscale_1``:
    l_ij = s~_ij^2 (l_max_j - l_min_j) + l_min_j,
    s~_ij^2 = clip((s_ij^2 - lo_j) / (hi_j - lo_j), 0, 1) (0 where hi_j <= lo_j)
    (:func:`_scatter_product`); mode 1: sigma_0 k(||d||; l_min_0); mode 2: weight 1 in the
    sample's own cell (counting sensor model). Samples are applied in order, so each cell's
    sums do not depend on how the cells are cut into slabs.
    """
    if mode == MODE_PRODUCT:
        _scatter_product(axis, first, stop, points, label, sigma0, variance, var_lo, var_hi,
                         l_min, l_max, res, table_keys, table_vals, alpha, beta)  # fmt: skip
        return
    w, lo, cnt, lengths, chunks, c0, box, _ = _scratch(l_min, l_max, res)
    alpha = alpha.reshape(alpha.shape[0], CHUNK**3)
    beta = beta.reshape(beta.shape[0], CHUNK**3)
    for s in range(points.shape[0]):
        # the slab's part of the support along `axis` first: the other axes only when in it
        _support(s, mode, points, variance, var_lo, var_hi, l_min, l_max, res, lengths, lo, cnt,
                 axis, axis + 1)  # fmt: skip
        u0 = max(first - lo[axis], 0)
        u1 = min(stop - lo[axis], cnt[axis])
        if u0 >= u1:
            continue
        _support(s, mode, points, variance, var_lo, var_hi, l_min, l_max, res, lengths, lo, cnt)
        _support_weights(s, mode, points, res, lo, cnt, w)
        chunk_box(lo, cnt, box, c0, chunks, table_keys, table_vals)
        a0, a1, b0, b1 = (u0, u1, 0, cnt[1]) if axis == 0 else (0, cnt[0], u0, u1)
        _add_sample(s, mode, label, sigma0, lengths[0], lo, cnt, w, a0, a1, b0, b1, chunks, c0,
                    alpha, beta)  # fmt: skip


@njit(cache=True, nogil=True)
def _scatter_product(axis, first, stop, points, label, sigma0, variance, var_lo, var_hi, l_min,
                     l_max, res, table_keys, table_vals, alpha, beta):  # fmt: skip
    """:func:`scatter_slab` in product mode (the adaptive kernel), in its own loop: numba did
    not specialize the shared loop on a constant mode, and this runs about twice as fast as the
    shared loop did. The per-axis kernels are written out here: as an inlined helper writing
    ``w`` they ran about 1.5x slower."""
    w, lo, cnt, lengths, chunks, c0, box, rot = _scratch(l_min, l_max, res)
    alpha = alpha.reshape(alpha.shape[0], CHUNK**3)
    beta = beta.reshape(beta.shape[0], CHUNK**3)
    for s in range(points.shape[0]):
        _support(s, MODE_PRODUCT, points, variance, var_lo, var_hi, l_min, l_max, res, lengths,
                 lo, cnt, axis, axis + 1)  # fmt: skip
        u0 = max(first - lo[axis], 0)  # the slab's part of the support along `axis`
        u1 = min(stop - lo[axis], cnt[axis])
        if u0 >= u1:
            continue
        _support(s, MODE_PRODUCT, points, variance, var_lo, var_hi, l_min, l_max, res, lengths,
                 lo, cnt)  # fmt: skip
        # w[j, a] = k(|d_a|; l_j) (``eq:kernel``, unit sigma_0) at the support's cell centres
        # along axis j, d_a = d_0 + a res. The angles 2 pi d_a / l_j are equally spaced, so
        # cos and sin follow by the angle-addition recurrence from those of the first angle
        # (:func:`sincos`) and of the step; with sin(2 pi |d| / l) = sign(d) sin(2 pi d / l)
        # this is ``eq:kernel`` to rounding. ``rot[j]`` caches (l, cos, sin) of the step: the
        # samples of one ray share their length scales.
        for j in range(3):
            lj = lengths[j]
            d0 = (lo[j] + 0.5 - points[s, j] / res) * res
            if rot[j, 0] != lj:
                step = _TWO_PI * res / lj
                rot[j, 0], rot[j, 1], rot[j, 2] = lj, np.cos(step), np.sin(step)
            cd, sd = rot[j, 1], rot[j, 2]
            inv_l = 1.0 / lj
            sn, cs = sincos(_TWO_PI * d0 * inv_l)
            for a in range(cnt[j]):
                d = d0 + a * res
                r = abs(d) * inv_l
                if r >= 1.0:
                    w[j, a] = 0.0
                else:
                    w[j, a] = (2.0 + cs) * (1.0 - r) * _THIRD + (sn if d >= 0.0 else -sn) * _INV_2PI
                cs, sn = cs * cd - sn * sd, sn * cd + cs * sd
        chunk_box(lo, cnt, box, c0, chunks, table_keys, table_vals)
        a0, a1, b0, b1 = (u0, u1, 0, cnt[1]) if axis == 0 else (0, cnt[0], u0, u1)
        # scalars, not array reads, in the loops: the stores to alpha/beta could alias them
        y, sig, lx, ly, lz, nz = label[s], sigma0[s], lo[0], lo[1], lo[2], cnt[2]
        c0x, c0y, c0z = c0[0], c0[1], c0[2]
        for a in range(a0, a1):
            wa = w[0, a]
            if wa <= 0.0:
                continue
            ix = lx + a
            cx = (ix >> CHUNK_SHIFT) - c0x
            ox = (ix & 7) << 6
            for b in range(b0, b1):
                wb = w[1, b]
                if wb <= 0.0:
                    continue
                iy = ly + b
                cy = (iy >> CHUNK_SHIFT) - c0y
                oxy = ox | ((iy & 7) << 3)
                wab = wa * wb
                for c in range(nz):
                    k = wab * w[2, c]
                    if k <= 0.0:
                        continue
                    iz = lz + c
                    _add_cell(alpha, beta, chunks[cx, cy, (iz >> CHUNK_SHIFT) - c0z],
                              oxy | (iz & 7), k * sig, y)  # fmt: skip


@njit(cache=True)
def slab_splits(points, res, parts, p_lo, p_hi):
    """(axis, splits) for :func:`scatter_slab` on several threads: the horizontal axis along
    which the samples' cells spread most, and ``parts`` + 1 cell-index boundaries along it
    (open at both ends) at the quantiles of the samples' cells, so each slab gets about as
    many samples; ``p_lo``, ``p_hi``: the points' extent
    (:func:`~undertow.mapping.grid.points_extent`)."""
    n = points.shape[0]
    lo0, hi0, lo1, hi1 = p_lo[0], p_hi[0], p_lo[1], p_hi[1]
    axis = 0 if hi0 - lo0 >= hi1 - lo1 else 1
    first = np.int64(np.floor((lo0 if axis == 0 else lo1) / res))
    width = np.int64(np.floor((hi0 if axis == 0 else hi1) / res)) - first + 1
    splits = np.empty(parts + 1, np.int64)
    splits[0], splits[parts] = -ALL_CELLS, ALL_CELLS
    if width > 4 * n + 4096:  # sparse: sort the indices instead of counting them
        index = np.sort(np.floor(points[:, axis] / res))
        for t in range(1, parts):
            splits[t] = np.int64(index[(t * n) // parts])
        return axis, splits
    counts = np.zeros(width, np.int64)
    for s in range(n):
        counts[np.int64(np.floor(points[s, axis] / res)) - first] += 1
    t, seen = 1, 0
    for i in range(width):
        seen += counts[i]
        while t < parts and seen * parts >= t * n:
            splits[t] = first + i + 1
            t += 1
    return axis, splits


@njit(cache=True)
def count_chunks(mode, points, variance, var_lo, var_hi, l_min, l_max, res, table_keys, n,
                  limit):  # fmt: skip
    """Number of distinct chunks the scatter kernel would touch (the supports of ``points``,
    computed as in :func:`scatter_slab`), counting on from ``n`` chunks already in ``table_keys``
    (a key-only hash set, size a power of two > 2 ``limit``); stops once it exceeds ``limit``."""
    mask = table_keys.shape[0] - 1
    lo = np.zeros(3, np.int64)
    cnt = np.zeros(3, np.int64)
    hi = np.zeros(3, np.int64)
    lengths = np.empty(3)
    for s in range(points.shape[0]):
        _support(s, mode, points, variance, var_lo, var_hi, l_min, l_max, res, lengths, lo, cnt)
        for j in range(3):
            hi[j] = (lo[j] + cnt[j] - 1) >> CHUNK_SHIFT
            lo[j] = lo[j] >> CHUNK_SHIFT
        for cx in range(lo[0], hi[0] + 1):
            for cy in range(lo[1], hi[1] + 1):
                for cz in range(lo[2], hi[2] + 1):
                    key = pack_key(cx, cy, cz)
                    slot = home_slot(key, mask)
                    while table_keys[slot] != -1 and table_keys[slot] != key:
                        slot = (slot + 1) & mask
                    if table_keys[slot] == -1:
                        table_keys[slot] = key
                        n += 1
                        if n > limit:
                            return n
    return n
