"""The adaptive kernel's scatter straight from the rays, without writing their samples out.

:func:`~undertow.mapping.samples.expand` lays the training samples of R rays out as every ray's
hit first (rows 0 .. R - 1), then ray by ray its free samples (rows ``rows[i]`` ..
``rows[i + 1] - 1``). Ray i (origin o, direction v, range r, pose variance s^2, sigma_0) gives

    hit m = o + r v (label 1),   free samples m_k = o + (k f) v, k = 0 .. rows[i + 1] - rows[i] - 1
    (label 0),

and each sample adds sigma_0 prod_j k(|d_j|; l_j) (``eq:new_conc_params_alpha`` /
``eq:new_conc_params_beta`` with the unit kernels of ``eq:kernel``) to alpha (a hit) or beta (a
free sample) of the cells of its support box, l_j = s~_j^2 (l_max_j - l_min_j) + l_min_j
(``eq:lengthscale_1``, s~_j^2 = clip((s_j^2 - lo_j) / (hi_j - lo_j), 0, 1)). The kernels here
compute each sample where it is used, in the same order and with the same floating-point
operations as :func:`~undertow.mapping.kernels.insert_chunks` and
:func:`~undertow.mapping.kernels.scatter_slab` on the written samples, so the map is the same bit
for bit (``tests/mapping/test_rayscatter.py``). What they save:

- writing and reading every sample (65 bytes each: point, variance, label, sigma_0, ray, sensor);
- work the samples of one ray share (their length scales), and per-sample branches: the
  supports and kernel weights of a block of samples (of one ray or several) are computed in
  loops the compiler vectorizes (the sine and cosine by fdlibm's kernels, as
  :func:`~undertow.mapping.kernels.scatter_slab` takes them, with the quadrant chosen without
  branches, :func:`sincos_lanes`), and the cell loop adds a zero where a weight is not positive
  instead of branching (x + 0 = x for every x but -0, which no sum of masses is);
- on one thread, a separate pass placing the chunks: the scatter places each chunk as it
  reaches it, probing the table read-only first (:func:`~undertow.mapping.chunks.find`);
- on several threads (:func:`~undertow.mapping.threads.run_parts`, each owning a slab of
  cells), the chunks are placed first (:func:`ray_insert_chunks`, a small cache remembering
  the chunks placed), and each thread skips the runs of free samples whose supports miss its
  slab.

Chunks are placed in the order the samples first touch them, as
:func:`~undertow.mapping.kernels.insert_chunks` places them, so the chunk arrays (and the order
of :meth:`~undertow.mapping.grid.ChunkedGrid.cells`) are the same too.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .chunks import CHUNK, CHUNK_SHIFT, find, find_or_insert, lookup, pack_key
from .kernels import ALL_CELLS

BLOCK = 64  # samples whose supports and weights are computed together
PLACED_CACHE = 512  # direct-mapped cache of placed chunks: 8 x 8 x 8 chunk coordinates

_TWO_PI = 2.0 * np.pi
_THIRD, _INV_2PI = 1.0 / 3.0, 1.0 / _TWO_PI
# fdlibm's kernels (Sun Microsystems 1993; FreeBSD msun k_sin.c, k_cos.c, e_rem_pio2.c), the
# coefficients of undertow.mapping.kernels' sine and cosine
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
_PIO2_HI, _PIO2_LO = 1.57079632673412561417e00, 6.07710050650619224932e-11
_TWO_OVER_PI = 2.0 / np.pi


@njit(cache=True, inline="always", error_model="numpy")
def sincos_lanes(x):
    """(sin x, cos x) for |x| < 2^20 pi / 2 with the operations of the mapping kernels' fdlibm
    sine and cosine (x = k pi/2 + y, |y| <= pi/4, minimax polynomials on y), the quadrant k mod 4
    chosen by selects instead of branches so that a loop over x vectorizes: (s, c), (c, -s),
    (-s, -c), (-c, s) for k mod 4 = 0, 1, 2, 3."""
    k = np.floor(x * _TWO_OVER_PI + 0.5)
    y = (x - k * _PIO2_HI) - k * _PIO2_LO
    z = y * y
    s = y + y * z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    c = 1.0 - 0.5 * z + z * z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    q = np.int64(k)
    odd = (q & 1) != 0
    s1 = c if odd else s
    c1 = s if odd else c
    return (-s1 if (q & 2) != 0 else s1), (-c1 if ((q + 1) & 2) != 0 else c1)


@njit(cache=True, inline="always", error_model="numpy")
def _length_scale(s2, lo, hi, l_min, l_max):
    """``eq:lengthscale_1`` along one axis for pose variance s2, bounds lo, hi (l_min where
    hi <= lo). Scalars only: numba counts references to arrays passed to inlined helpers, which
    costs more than the helper in a loop."""
    span = hi - lo
    if span > 0.0:
        return min(max((s2 - lo) / span, 0.0), 1.0) * (l_max - l_min) + l_min
    return l_min


@njit(cache=True, inline="always", error_model="numpy")
def _ray_scales(i, var, var_lo, var_hi, l_min, l_max, res, lengths, rot):
    """Ray i's length scales l_j (``eq:lengthscale_1``) into ``lengths``, and rot[j] = (l,
    cos and sin of the step 2 pi res / l, l / res, 1 / l), recomputed only when l changes."""
    for j in range(3):
        lj = _length_scale(var[i, j], var_lo[j], var_hi[j], l_min[j], l_max[j])
        lengths[j] = lj
        if rot[j, 0] != lj:
            step = _TWO_PI * res / lj
            rot[j, 0], rot[j, 1], rot[j, 2] = lj, np.cos(step), np.sin(step)
            rot[j, 3], rot[j, 4] = lj / res, 1.0 / lj


@njit(cache=True, inline="always", error_model="numpy")
def free_coordinates(ray, k0, m, n, origin, direction, f, pts):
    """Free samples k0 .. k0 + m - 1 of ``ray`` into block columns n .. n + m - 1: the points
    o + (k f) v."""
    for j in range(3):
        o, v = origin[ray, j], direction[ray, j]
        for t in range(m):
            pts[j, n + t] = o + ((k0 + t) * f) * v


@njit(cache=True, inline="always", error_model="numpy")
def free_points(ray, k0, m, n, origin, direction, f, rot, pts, scales):
    """:func:`free_coordinates`, and the samples' kernel axes and lengths (``rot``: (3, 5), the
    ray's rotation and lengths as :func:`block_weights` reads them)."""
    free_coordinates(ray, k0, m, n, origin, direction, f, pts)
    for j in range(3):
        for q in range(4):
            scales[q, j, n : n + m] = rot[j, q + 1]


@njit(cache=True, inline="always", error_model="numpy")
def ray_meets(i, k0, m, origin, direction, f, lj, axis, res, first, stop):
    """Whether the supports of ray i's free samples k0 .. k0 + m - 1 reach the cells [first,
    stop) along ``axis``: their coordinates along it are monotone in k, so their supports span
    the first sample's to the last sample's."""
    e0 = origin[i, axis] + (k0 * f) * direction[i, axis]
    e1 = origin[i, axis] + ((k0 + m - 1) * f) * direction[i, axis]
    top = max(e0, e1)
    last = max(_last_cell(top, lj, res), _first_cell(top, lj, res))
    return last >= first and _first_cell(min(e0, e1), lj, res) < stop


@njit(cache=True, inline="always", error_model="numpy")
def _first_cell(p, lj, res):
    """First cell of the support along one axis of a sample at coordinate p (``_support``)."""
    return np.int64(np.floor(p / res - lj / res - 0.5)) + 1


@njit(cache=True, inline="always", error_model="numpy")
def _last_cell(p, lj, res):
    """Last cell of the support (before the at-least-one-cell rule of ``_support``)."""
    return np.int64(np.ceil(p / res + lj / res - 0.5)) - 1


@njit(cache=True, nogil=True, error_model="numpy")
def ray_insert_chunks(start, stop, origin, direction, r, var, rows, f, var_lo, var_hi, l_min,
                      l_max, res, held_keys, held_vals, table_keys, table_vals, chunk_keys,
                      n_chunks):  # fmt: skip
    """:func:`~undertow.mapping.kernels.insert_chunks` (product mode) of the rays' sample rows
    start..stop - 1 (module doc), ``held`` as there: returns ``stop`` when done, else the first
    row whose chunks did not fit (the caller grows the chunk arrays and resumes there)."""
    n_rays = r.shape[0]
    ratio = np.empty(3)  # l_j / res of the current ray
    lo, hi = np.zeros(3, np.int64), np.zeros(3, np.int64)
    box = np.full(6, -1, np.int64)
    placed = np.full(PLACED_CACHE, -1, np.int64)  # keys of chunks placed, by their low bits
    for seg in range(-1, n_rays):  # the hits (rows 0 .. R - 1), then ray by ray the free samples
        if seg >= 0 and rows[seg] >= stop:
            break
        t0, t1 = (
            (start, min(n_rays, stop))
            if seg < 0
            else (max(start - rows[seg], 0), min(rows[seg + 1], stop) - rows[seg])
        )
        for t in range(t0, t1):
            ray, k = (t, -1) if seg < 0 else (seg, t)
            if seg < 0 or t == t0:
                for j in range(3):
                    ratio[j] = _length_scale(var[ray, j], var_lo[j], var_hi[j], l_min[j],
                                             l_max[j]) / res  # fmt: skip
            x = r[ray] if k < 0 else k * f  # the hit o + r v, free samples o + (k f) v
            for j in range(3):  # the support as _support takes it
                p = (origin[ray, j] + x * direction[ray, j]) / res
                first = np.int64(np.floor(p - ratio[j] - 0.5)) + 1
                last = np.int64(np.ceil(p + ratio[j] - 0.5)) - 1
                lo[j] = first >> CHUNK_SHIFT
                hi[j] = max(last, first) >> CHUNK_SHIFT
            if (box[0] == lo[0] and box[1] == lo[1] and box[2] == lo[2] and box[3] == hi[0]
                    and box[4] == hi[1] and box[5] == hi[2]):  # fmt: skip
                continue  # the previous sample's chunks
            for cx in range(lo[0], hi[0] + 1):
                for cy in range(lo[1], hi[1] + 1):
                    for cz in range(lo[2], hi[2] + 1):
                        key = pack_key(cx, cy, cz)
                        slot = ((cx & 7) << 6) | ((cy & 7) << 3) | (cz & 7)
                        if placed[slot] == key:
                            continue
                        if (find(cx, cy, cz, held_keys, held_vals) < 0
                                and find(cx, cy, cz, table_keys, table_vals) < 0
                                and find_or_insert(cx, cy, cz, table_keys, table_vals,
                                                   chunk_keys, n_chunks) < 0):  # fmt: skip
                            return t if seg < 0 else rows[seg] + t
                        placed[slot] = key
            box[:3], box[3:] = lo, hi
    return stop


@njit(cache=True, inline="always", error_model="numpy")
def block_weights(n, pts, scales, res, span, first_cell, count, w, offsets, scratch):
    """Supports (first cell, cells per axis) and unit kernel weights of the n samples of a
    block (coordinates ``pts[j, b]``; ``scales[:, j, b]``: the cosine and sine of the step
    2 pi res / l, l / res and 1 / l, l the sample's length scale along axis j), as
    :func:`~undertow.mapping.kernels.scatter_slab` computes them per sample: w[j, a, b] =
    k(|d0 + a res|; l) at the support's cell centres along axis j, d0 the first centre's
    offset, the angles advanced by the angle-addition recurrence (each quotient is the one
    ``scatter_slab`` takes, computed once); and where those cells sit: ``offsets[0, j, a, b]``
    the chunk relative to the support's first (times span^2, span, 1 for x, y, z: an index
    into the support's chunks, flat), ``offsets[1, j, a, b]`` the cell within its chunk
    (times CHUNK^2, CHUNK, 1)."""
    sn, cs, d0s, cells = scratch[0], scratch[1], scratch[2], scratch[3]
    for j in range(3):
        widest = 1
        for b in range(n):
            p = pts[j, b] / res
            rr = scales[2, j, b]
            i0 = np.int64(np.floor(p - rr - 0.5)) + 1
            i1 = np.int64(np.ceil(p + rr - 0.5)) - 1
            first_cell[j, b] = i0
            count[j, b] = max(i1, i0) - i0 + 1
            widest = max(widest, count[j, b])
            cells[b] = p
        for b in range(n):
            d0 = (first_cell[j, b] + 0.5 - cells[b]) * res
            sn[b], cs[b] = sincos_lanes(_TWO_PI * d0 * scales[3, j, b])
            d0s[b] = d0
        for a in range(widest):
            for b in range(n):
                d = d0s[b] + a * res
                rel = abs(d) * scales[3, j, b]
                s, c = sn[b], cs[b]
                v = (2.0 + c) * (1.0 - rel) * _THIRD + (s if d >= 0.0 else -s) * _INV_2PI
                w[j, a, b] = 0.0 if rel >= 1.0 else v
                cd, sd = scales[0, j, b], scales[1, j, b]
                cs[b] = c * cd - s * sd
                sn[b] = s * cd + c * sd
        step = span ** (2 - j)
        shift = CHUNK_SHIFT * (2 - j)
        for a in range(widest):
            for b in range(n):
                i = first_cell[j, b] + a
                offsets[0, j, a, b] = (
                    (i >> CHUNK_SHIFT) - (first_cell[j, b] >> CHUNK_SHIFT)
                ) * step
                offsets[1, j, a, b] = (i & (CHUNK - 1)) << shift


@njit(cache=True, inline="always", error_model="numpy")
def block_cells(n, hit, sig, axis, first, stop, first_cell, count, w, offsets, chunks, span,
                 box, place, table_keys, table_vals, chunk_keys, n_chunks, alpha,
                 beta):  # fmt: skip
    """Add each of the block's n samples' weight sigma_0 w_x w_y w_z to alpha (hits) or beta
    (free samples, both flat: cell offset o of chunk c at c CHUNK^3 + o) of its support's cells
    in the slab [first, stop) along ``axis``, skipping the cells whose weights are not positive
    (as ``scatter_slab``). The chunks of the support box (``chunks``, span^3, flat) are looked
    up once per box, and placed first with ``place``; ``offsets`` as :func:`block_weights`
    (unsigned: no negative-index handling in the loop). Returns -1, or the first sample whose
    chunks did not fit (nothing of it added)."""
    cube = np.uint64(CHUNK**3)
    for b in range(n):
        u0 = max(first - first_cell[axis, b], 0)
        u1 = min(stop - first_cell[axis, b], count[axis, b])
        if u0 >= u1:
            continue
        lx, ly, lz = first_cell[0, b], first_cell[1, b], first_cell[2, b]
        nx, ny, nz = count[0, b], count[1, b], count[2, b]
        c0x, c0y, c0z = lx >> CHUNK_SHIFT, ly >> CHUNK_SHIFT, lz >> CHUNK_SHIFT
        ncx = ((lx + nx - 1) >> CHUNK_SHIFT) - c0x + 1
        ncy = ((ly + ny - 1) >> CHUNK_SHIFT) - c0y + 1
        ncz = ((lz + nz - 1) >> CHUNK_SHIFT) - c0z + 1
        if not (box[0] == c0x and box[1] == c0y and box[2] == c0z and box[3] == ncx
                and box[4] == ncy and box[5] == ncz):  # fmt: skip
            box[0] = -1  # (until every chunk of the box is found)
            for p in range(ncx):
                for q in range(ncy):
                    for s in range(ncz):
                        if place:
                            ci = find(c0x + p, c0y + q, c0z + s, table_keys, table_vals)
                            if ci < 0:  # a new chunk
                                ci = find_or_insert(c0x + p, c0y + q, c0z + s, table_keys,
                                                    table_vals, chunk_keys, n_chunks)  # fmt: skip
                            if ci < 0:
                                return b
                        else:
                            ci = lookup(c0x + p, c0y + q, c0z + s, table_keys, table_vals)
                        chunks[(p * span + q) * span + s] = ci
            box[0], box[1], box[2], box[3], box[4], box[5] = c0x, c0y, c0z, ncx, ncy, ncz
        a0, a1, b0, b1 = (u0, u1, 0, ny) if axis == 0 else (0, nx, u0, u1)
        sg = sig[b]
        for c in range(nz):  # each cell gets one term per sample: any loop order is exact
            wc = w[2, c, b]
            if wc <= 0.0:  # (scatter_slab skips each of these cells: w_x w_y w_z <= 0 or w_y <= 0)
                continue
            for a in range(a0, a1):
                wa = w[0, a, b]
                if wa <= 0.0:
                    continue
                row = offsets[0, 0, a, b] + offsets[0, 2, c, b]
                off = offsets[1, 0, a, b] | offsets[1, 2, c, b]
                for q in range(np.uint64(b0), np.uint64(b1)):
                    k = wa * w[1, q, b] * wc  # > 0 where scatter_slab adds it (w_x, w_z > 0)
                    # a zero added leaves the sum as it is (module doc): no branch
                    mass = k * sg if k > 0.0 else 0.0
                    cell = np.uint64(chunks[row + offsets[0, 1, q, b]]) * cube + (
                        off | offsets[1, 1, q, b]
                    )
                    if hit:
                        alpha[cell] += mass
                    else:
                        beta[cell] += mass
    return -1


@njit(cache=True, nogil=True, error_model="numpy")
def ray_scatter_slab(start, axis, first, stop, origin, direction, r, var, sig, rows, f, var_lo,
                     var_hi, l_min, l_max, res, table_keys, table_vals, chunk_keys, n_chunks,
                     alpha, beta, place):  # fmt: skip
    """:func:`~undertow.mapping.kernels.scatter_slab` (product mode, the adaptive kernel) of
    the rays' samples (module doc) from sample row ``start``, in the cells whose index along
    ``axis`` is in [first, stop). Every chunk touched must be placed (:func:`ray_insert_chunks`)
    unless ``place`` (one thread): then each chunk is placed where
    :func:`~undertow.mapping.kernels.insert_chunks` would place it, and the row returned is
    the first whose chunks did not fit (the caller grows the arrays and resumes there), rows[R]
    when done. Samples are applied in ``expand``'s row order, in blocks of :data:`BLOCK` (the
    hits of BLOCK rays, or BLOCK free samples, of as many rays as it takes: the compiler's
    vector loops want full blocks)."""
    n_rays = r.shape[0]
    alpha, beta = alpha.reshape(-1), beta.reshape(-1)
    widest = int(np.ceil(2.0 * max(l_max.max(), l_min.max()) / res)) + 3
    span = (widest >> CHUNK_SHIFT) + 2  # chunks a support spans per axis, at most
    chunks, offsets = np.empty(span**3, np.int64), np.empty((2, 3, widest, BLOCK), np.uint64)
    box = np.full(6, -1, np.int64)
    # per sample: the point, (cos, sin of the step, l / res, 1 / l) per axis, sigma_0
    pts, scales, sigs = np.empty((3, BLOCK)), np.empty((4, 3, BLOCK)), np.empty(BLOCK)
    scratch = np.empty((4, BLOCK))
    first_cell, count = np.empty((3, BLOCK), np.int64), np.empty((3, BLOCK), np.int64)
    w = np.empty((3, widest, BLOCK))
    lengths, rot = np.empty(3), np.full((3, 5), np.nan)  # l, cos, sin of the step, l / res, 1 / l
    total, row = rows[n_rays], start
    ray = -1 if start < n_rays else np.searchsorted(rows, start, side="right") - 2
    while row < total:
        n, hit = 0, row < n_rays
        if hit:  # the hits of BLOCK rays, each ray its own length scales
            n = min(BLOCK, n_rays - row)
            for b in range(n):
                _ray_scales(row + b, var, var_lo, var_hi, l_min, l_max, res, lengths, rot)
                sigs[b] = sig[row + b]
                for j in range(3):
                    pts[j, b] = origin[row + b, j] + r[row + b] * direction[row + b, j]
                    for q in range(4):
                        scales[q, j, b] = rot[j, q + 1]
            row += n
        while not hit and n < BLOCK and row < total:  # free samples, ray after ray
            if row >= rows[ray + 1]:  # the next ray with free samples
                ray += 1
                while rows[ray + 1] == rows[ray]:
                    ray += 1
                _ray_scales(ray, var, var_lo, var_hi, l_min, l_max, res, lengths, rot)
            k0 = row - rows[ray]
            m = min(BLOCK - n, rows[ray + 1] - row)
            row += m
            if not ray_meets(ray, k0, m, origin, direction, f, lengths[axis], axis, res, first,
                              stop):  # fmt: skip
                continue  # (a slab thread: none of these samples reaches its cells)
            free_points(ray, k0, m, n, origin, direction, f, rot, pts, scales)
            sigs[n : n + m] = sig[ray]
            n += m
        if n == 0:
            continue
        block_weights(n, pts, scales, res, span, first_cell, count, w, offsets, scratch)
        b = block_cells(n, hit, sigs, axis, first, stop, first_cell, count, w, offsets, chunks,
                         span, box, place, table_keys, table_vals, chunk_keys, n_chunks, alpha,
                         beta)  # fmt: skip
        if b >= 0:  # (one thread, everything its slab: the block's rows are row - n ..)
            return row - n + b
    return rows[n_rays]


@njit(cache=True, error_model="numpy")
def ray_extent(origin, direction, r, rows, f):
    """(min (3,), max (3,), all finite) of the rays' samples (at least one ray), as
    :func:`~undertow.mapping.grid.points_extent` of the written samples: along a ray the
    coordinates o + (k f) v are monotone in k (each rounding is), so the extremes lie at its
    hit, its first and its last free sample."""
    n_rays = r.shape[0]
    lo = np.empty(3)
    hi = np.empty(3)
    finite = True
    for j in range(3):
        lo[j] = origin[0, j] + r[0] * direction[0, j]
        hi[j] = lo[j]
    for i in range(n_rays):
        last = rows[i + 1] - rows[i] - 1
        for k in (-1, 0, last):
            if k > last:
                continue
            x = r[i] if k < 0 else k * f  # the hit o + r v, free samples o + (k f) v
            for j in range(3):
                v = origin[i, j] + x * direction[i, j]
                if v < lo[j]:
                    lo[j] = v
                elif v > hi[j]:
                    hi[j] = v
                elif v != v:
                    finite = False
    return lo, hi, finite


@njit(cache=True, error_model="numpy")
def ray_slab_splits(origin, direction, r, rows, f, res, parts, p_lo, p_hi):
    """(axis, splits) for :func:`ray_scatter_slab` on several threads, as
    :func:`~undertow.mapping.kernels.slab_splits` chooses them (the horizontal axis along which
    the samples spread most, cut at the quantiles of their cells), each ray's samples counted
    at its segment's midpoint (the splits only share the work out: any splits give the same
    map)."""
    n_rays = r.shape[0]
    axis = 0 if p_hi[0] - p_lo[0] >= p_hi[1] - p_lo[1] else 1
    first = np.int64(np.floor(p_lo[axis] / res))
    width = np.int64(np.floor(p_hi[axis] / res)) - first + 1
    splits = np.empty(parts + 1, np.int64)
    splits[0], splits[parts] = -ALL_CELLS, ALL_CELLS
    index = np.empty(n_rays, np.int64)
    weight = np.empty(n_rays, np.int64)
    for i in range(n_rays):  # (the midpoint lies within the samples' extent)
        mid = origin[i, axis] + 0.5 * r[i] * direction[i, axis]
        index[i] = min(max(np.int64(np.floor(mid / res)), first), first + width - 1)
        weight[i] = rows[i + 1] - rows[i] + 1
    total = weight.sum()
    if width > 4 * n_rays + 4096:  # sparse: sort the midpoints instead of counting them
        order = np.argsort(index)
    else:
        counts = np.zeros(width, np.int64)
        for i in range(n_rays):
            counts[index[i] - first] += weight[i]
        index = first + np.arange(width)
        weight, order = counts, np.arange(width)
    t, seen = 1, 0
    for i in order:
        seen += weight[i]
        while t < parts and seen * parts >= t * total:
            splits[t] = index[i] + 1
            t += 1
    return axis, splits
