"""The ``tpu`` mapper's scatter straight from the rays, without writing their samples out.

:func:`~undertow.mapping.tpu.tpu_training` turns the samples of R rays (:class:`~undertow.mapping.
samples.RaySamples`: ray i's hit o + r v, its free samples o + (k f) v) into the samples the
product kernel scatters: the free samples first, ray by ray (length scales l_0, l_0, r_g / 2,
weight sigma_0), then each hit's three vertical cells z_c - r_g, z_c, z_c + r_g (r_g the
resolution) with the hit's own across-floor lengths l_x, l_y and weights sigma_0 (l_0 / l_x)
(l_0 / l_y) (s_rz^2 / sigma_v^2) w_c, the cells of weight 0 left out (the equations are
:mod:`undertow.mapping.tpu`'s). Here:

- :func:`hit_lattice` computes, per hit, its sigmas (pose, footprint, range noise, and the
  wave's s_w, whose three exponentials numpy computes, as :func:`~undertow.mapping.tpu.wave_std`
  does: numba's exp differs from numpy's in the last bit), lengths, three cells and weights in
  one compiled pass, with the floating-point operations of
  :func:`~undertow.mapping.tpu.hit_sigmas` and :func:`~undertow.mapping.tpu.tpu_training` in
  the same order (||m - o|| summed as (x^2 + y^2) + z^2, as numpy's norm does);
- :func:`tpu_scatter_slab` scatters those samples in that order with the block kernels of
  :mod:`undertow.mapping.rayscatter` (:func:`~undertow.mapping.rayscatter.block_weights`,
  :func:`~undertow.mapping.rayscatter.block_cells`), which compute each sample's support and
  kernel weights with the operations of :func:`~undertow.mapping.kernels.scatter_slab`. A
  sample's length along axis j is the one the generic scatter takes from the lengths it is
  given (l_j / cap as the variance, bounds (0, 1), l_min 0, l_max cap:
  ``min(max(l_j / cap, 0), 1) cap``), so the map is the same bit for bit, its chunks placed in
  the same order (``tests/mapping/test_tpuscatter.py``).

What it saves: writing every sample and its length scales (the free samples alone are about
20 per beam), numpy's passes over the hits, and the checks of
:meth:`~undertow.mapping.samples.Samples.from_points`.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numba import njit

from .chunks import CHUNK_SHIFT, find, find_or_insert, pack_key
from .depth_wave import depth_wave_terms, swell_variance
from .rayscatter import (
    BLOCK,
    PLACED_CACHE,
    block_cells,
    block_weights,
    free_coordinates,
    ray_meets,
)
from .samples import SENSOR_SONAR
from .tpu import KERNEL_STD, wavenumbers

_TWO_PI = 2.0 * np.pi
#: what :attr:`TpuHits.parts` holds per hit: its horizontal variances sigma_x^2 and sigma_y^2,
#: its range's own noise in depth s_rz^2 = s_r'^2 v_z^2, its range squared when it is a
#: sonar's (0 for the others: the shortfall s_d = r (sec(b / 2) - 1) scales with it) and the
#: variance v r^2 of its three cells about its depth (:func:`~undertow.mapping.tpu.lattice_weights`)
HIT_PARTS = ("var_x", "var_y", "var_r", "sonar_r2", "var_lattice")
_NO_WAVE = (np.zeros((2, 0)), np.zeros(0))  # hit_lattice's exponentials without a wave


class TpuHits(NamedTuple):
    """Per hit (ray) i: the point's x, y (o + r v), its lengths along x and y as the scatter
    takes them (``l``, (R, 2)), its three cells' z (R, 3) and weights (R, 3; 0: left out); the
    free samples' lengths (3,), as the scatter takes them; the hit's weight (R,), its
    vertical variance sigma_v^2 (R,) and the parts of its uncertainty the column sums keep
    (R, 5: :data:`HIT_PARTS`); and the largest finite length of ``l`` (m, 0 when none
    is), the reach of the hits' column sums."""

    x: np.ndarray
    y: np.ndarray
    l: np.ndarray
    z: np.ndarray
    w: np.ndarray
    l_free: np.ndarray
    weight: np.ndarray
    var_v: np.ndarray
    parts: np.ndarray
    reach: float


class HitConstants(NamedTuple):
    """What :func:`hit_lattice` takes from the mapper's settings (the same for every batch):
    the range noise s_0 and its fraction per metre per sensor (DVL, sonar, multibeam), the
    sensor taken for an unknown code, tan(b / 2) of the sonar's beam width b, l_0, the largest
    length, the cap the scatter divides by, the resolution and the free samples' lengths."""

    s0: np.ndarray
    fraction: np.ndarray
    unknown: int
    tan_half: float
    base: float
    max_length: float
    cap: float
    res: float
    l_free: np.ndarray


@lru_cache(maxsize=64)
def hit_constants(resolution: float, base_length: float, max_length: float, range_std: tuple,
                  range_std_fraction: float, beam_width_deg: float) -> HitConstants:  # fmt: skip
    """:class:`HitConstants` of the settings (computed once per distinct settings: a ping's
    call does not pay for them)."""
    res = float(resolution)
    cap = max(float(max_length), res / 2)
    s0 = np.asarray(range_std, float)
    fraction = np.array([0.0, range_std_fraction, range_std_fraction])
    tan_half = float(np.tan(np.deg2rad(beam_width_deg) / 2.0))
    l_free = (np.array([base_length, base_length, res / 2]) / cap) * cap
    return HitConstants(s0, fraction, int(np.argmax(s0)), tan_half, float(base_length),
                        float(max_length), cap, res, l_free)  # fmt: skip


def tpu_hits(rays, *, resolution: float, base_length: float, max_length: float, range_std,
             range_std_fraction: float, sonar_beam_width_deg: float = 0.0,
             wave=None, depth_wave=None) -> TpuHits:  # fmt: skip
    """:class:`TpuHits` of ``rays`` (:class:`~undertow.mapping.samples.Rays`), the arguments
    as :func:`~undertow.mapping.tpu.tpu_training`'s (the same values, bit for bit)."""
    k = hit_constants(float(resolution), float(base_length), float(max_length),
                      tuple(float(v) for v in range_std), float(range_std_fraction),
                      float(sonar_beam_width_deg))  # fmt: skip
    frequency = wave[1] if wave is not None else depth_wave[1] if depth_wave is not None else 0
    if not frequency:
        e, m = _NO_WAVE
    else:  # the exponentials by numpy, as wave_std takes them (numba's differ in the last bit)
        args = wave_arguments(rays.origin, rays.direction, rays.r, 2.0 * np.pi * float(frequency),
                              k.res)  # fmt: skip
        e, m = np.exp(args[:2]), np.expm1(args[2])
    amplitude = 0.0 if wave is None else float(wave[0])
    swell = depth_wave_terms(depth_wave)
    *out, weight, var_v, parts, reach = hit_lattice(rays.origin, rays.direction, rays.r, rays.var,
                                                    rays.sig, rays.sensor, e, m, amplitude, swell,
                                                    k.s0, k.fraction, k.unknown, k.tan_half,
                                                    k.base, k.max_length, k.cap, k.res)  # fmt: skip
    return TpuHits(*out, k.l_free, weight, var_v, parts, reach)


@njit(cache=True, error_model="numpy")
def wave_arguments(origin, direction, r, omega, res):
    """(3, R): per hit the arguments of :func:`~undertow.mapping.tpu.wave_std`'s exponentials,
    -k d, -k (2 h - d) and -2 k h, with h its depth rounded to the grid (at least one cell),
    d the sensor's depth clipped to [0, h], k the wavenumber of omega in depth h (computed
    once per depth met in a row)."""
    n = r.shape[0]
    out = np.empty((3, n))
    last_h, k = np.nan, 0.0
    for i in range(n):
        z = origin[i, 2] + r[i] * direction[i, 2]  # the hit's depth, as written
        h = max(np.rint(z / res) * res, res)
        if h != last_h:
            last_h, k = h, wavenumbers(omega, np.array([h]))[0]
        d = min(max(origin[i, 2], 0.0), h)
        out[0, i], out[1, i], out[2, i] = -k * d, -k * (2.0 * h - d), -2.0 * k * h
    return out


@njit(cache=True, inline="always")
def _wave_std(e1, e2, m, amplitude):
    """s_w = a K_s / sqrt(2), K_s = (e1 - e2) / -m, NaN read as 0 and infinities as the
    largest floats (numpy's nan_to_num)."""
    k_s = (e1 - e2) / -m
    if k_s != k_s:
        k_s = 0.0
    elif np.isinf(k_s):
        k_s = np.finfo(np.float64).max if k_s > 0 else -np.finfo(np.float64).max
    return amplitude * k_s / np.sqrt(2.0)


@njit(cache=True, error_model="numpy")
def hit_lattice(origin, direction, r, var, sig, sensor, e, m, amplitude, swell, s0, fraction,
                unknown, tan_half, base, max_length, cap, res):  # fmt: skip
    """(x, y, l (R, 2), z (R, 3), w (R, 3), weight, var_v, parts) of :class:`TpuHits`: per ray
    the hit m = o + r v; the wave's s_w (:func:`_wave_std` of the exponentials ``e`` (2, R)
    and ``m`` (R,) of :func:`wave_arguments`' arguments; 0 where ``e`` is empty: no wave);
    the swell's share of the pose's depth variance
    (:func:`~undertow.mapping.depth_wave.swell_variance` of K_p = (e_1 + e_2) / (2 + m) and
    ``swell``, the a, cos(omega Delta), R of
    :func:`~undertow.mapping.depth_wave.depth_wave_terms`); its range ||m - o||,
    s_r' = hypot(s_0 + f ||m - o||, s_w) along the beam v = (m - o) / ||m - o|| (vertical at
    range 0), its depth share s_rz = s_r' |v_z|, the footprint s_b (the sonar:
    ||m - o|| tan(b / 2) / 2) and shortfall s_d (the sonar: ||m - o|| (sec(b / 2) - 1)),
    sigma_x,y = sqrt(s_x,y^2 + s_b^2 + s_r'^2 v_x,y^2), sigma_v = sqrt(s_z^2 + s_rz^2 + s_d^2),
    l_x,y = clip(sigma / c, l_0, l_cap), the weight and the lattice of
    :mod:`undertow.mapping.tpu` (``unknown``: the sensor taken for a code outside 0 .. 2),
    the parts of :data:`HIT_PARTS`; and the largest finite l as the scatter takes it
    (:attr:`TpuHits.reach`)."""
    n = r.shape[0]
    shortfall = np.sqrt(1.0 + tan_half * tan_half) - 1.0  # sec(b / 2) - 1
    hx, hy = np.empty(n), np.empty(n)
    hl, hz, hw = np.empty((n, 2)), np.empty((n, 3)), np.empty((n, 3))
    h_weight, h_var, h_parts = np.empty(n), np.empty(n), np.zeros((n, 5))
    reach = 0.0
    for i in range(n):
        m0 = origin[i, 0] + r[i] * direction[i, 0]
        m1 = origin[i, 1] + r[i] * direction[i, 1]
        m2 = origin[i, 2] + r[i] * direction[i, 2]
        d0, d1, d2 = m0 - origin[i, 0], m1 - origin[i, 1], m2 - origin[i, 2]
        rng = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
        s = np.int64(sensor[i])
        s = s if 0 <= s < 3 else unknown
        s_w, var_z = 0.0, var[i, 2]
        if e.shape[1] == n:
            s_w = _wave_std(e[0, i], e[1, i], m[i], amplitude)
            k_p = (e[0, i] + e[1, i]) / (2.0 + m[i])
            var_z = var_z + swell_variance(var_z, k_p, swell[0], swell[1], swell[2])
        s_range = np.hypot(s0[s] + fraction[s] * rng, s_w)
        a0, a1, a2 = 0.0, 0.0, 1.0  # the beam's v_x^2, v_y^2, v_z^2
        r2 = rng * rng
        if r2 > 0:
            a0, a1, a2 = d0 * d0 / r2, d1 * d1 / r2, d2 * d2 / r2
        s_r = s_range * np.sqrt(a2)
        s_range2 = s_range * s_range
        s_b2, s_d2 = 0.0, 0.0
        if s == SENSOR_SONAR:
            s_b = rng * tan_half / 2.0
            s_b2 = s_b * s_b
            s_d = rng * shortfall
            s_d2 = s_d * s_d
            h_parts[i, 3] = rng * rng
        sx = np.sqrt(var[i, 0] + s_b2 + s_range2 * a0)
        sy = np.sqrt(var[i, 1] + s_b2 + s_range2 * a1)
        sv = np.sqrt(var_z + s_r * s_r + s_d2)
        lx = min(max(sx / KERNEL_STD, base), max_length)
        ly = min(max(sy / KERNEL_STD, base), max_length)
        precision = s_r * s_r / (sv * sv) if sv > 0 else 1.0
        weight = sig[i] * (base / lx) * (base / ly) * precision
        hx[i], hy[i] = m0, m1
        hl[i, 0] = min(max(lx / cap, 0.0), 1.0) * cap  # as the generic scatter takes it
        hl[i, 1] = min(max(ly / cap, 0.0), 1.0) * cap
        # the lattice (tpu.lattice_weights)
        zc = (np.floor(m2 / res) + 0.5) * res
        u = (m2 - zc) / res
        au = abs(u)
        t = sv / res
        v = min(au * (1.0 - au) + t * t, 1.0 - u * u)
        w_minus = max((u * u + v - u) / 2.0, 0.0)
        w_plus = max((u * u + v + u) / 2.0, 0.0)
        w_zero = max(1.0 - w_minus - w_plus, 0.0)
        h_parts[i, 4] = v * res * res
        hz[i, 0], hz[i, 1], hz[i, 2] = zc + res * -1.0, zc + res * 0.0, zc + res * 1.0
        hw[i, 0], hw[i, 1], hw[i, 2] = weight * w_minus, weight * w_zero, weight * w_plus
        h_weight[i], h_var[i] = weight, sv * sv
        h_parts[i, 0], h_parts[i, 1], h_parts[i, 2] = sx * sx, sy * sy, s_r * s_r
        for j in range(2):
            if np.isfinite(hl[i, j]):
                reach = max(reach, hl[i, j])
    return hx, hy, hl, hz, hw, h_weight, h_var, h_parts, reach


@njit(cache=True, error_model="numpy")
def tpu_extent(origin, direction, rows, f, hx, hy, hz, hw):
    """(min (3,), max (3,), all finite, samples) of the samples :func:`tpu_scatter_slab`
    scatters (the free samples, the hits' cells of weight > 0), as
    :func:`~undertow.mapping.grid.points_extent` of them written out (along a ray the free
    samples' coordinates are monotone in k: its first and last are the extremes)."""
    n_rays = hx.shape[0]
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    finite, count = True, 0
    p = np.empty(3)
    for i in range(n_rays):
        last = rows[i + 1] - rows[i] - 1
        count += last + 1
        for k in (0, last):
            if k <= last:
                for j in range(3):
                    p[j] = origin[i, j] + (k * f) * direction[i, j]
                finite = _widen(p, lo, hi) and finite
        for c in range(3):
            if hw[i, c] > 0.0:
                p[0], p[1], p[2] = hx[i], hy[i], hz[i, c]
                finite = _widen(p, lo, hi) and finite
                count += 1
    return lo, hi, finite, count


@njit(cache=True, inline="always")
def _widen(p, lo, hi):
    """Widen [lo, hi] to hold p; whether p is finite."""
    ok = True
    for j in range(3):
        lo[j], hi[j] = min(lo[j], p[j]), max(hi[j], p[j])
        ok = ok and np.isfinite(p[j])
    return ok


@njit(cache=True, inline="always")
def _rotation(lj, res, rot, j):
    """rot[j] = (l, cos and sin of the step 2 pi res / l, l / res, 1 / l), recomputed only
    when l changes (as ``rayscatter``'s ray scales)."""
    if rot[j, 0] != lj:
        step = _TWO_PI * res / lj
        rot[j, 0], rot[j, 1], rot[j, 2] = lj, np.cos(step), np.sin(step)
        rot[j, 3], rot[j, 4] = lj / res, 1.0 / lj


@njit(cache=True, nogil=True, error_model="numpy")
def tpu_scatter_slab(start, axis, first, stop, origin, direction, rows, f, sig, l_free, hx, hy,
                     hl, hz, hw, res, cap, table_keys, table_vals, chunk_keys, n_chunks, alpha,
                     beta, place):  # fmt: skip
    """The scatter of :func:`~undertow.mapping.kernels.scatter_slab` (product mode) of the tpu
    samples (module doc) from sample row ``start`` (rows rows[0] .. rows[R] - 1: the free
    samples, as ``expand`` numbers them; rows[R] + 3 i + c: hit i's cell c), in the cells
    whose index along ``axis`` is in [first, stop). Every chunk touched must be placed
    (:func:`tpu_insert_chunks`) unless ``place`` (one thread): then each chunk is placed as
    the generic scatter places it, and the row returned is the first whose chunks did not fit
    (the caller grows the arrays and resumes there), the last row + 1 when done."""
    n_rays = hx.shape[0]
    alpha, beta = alpha.reshape(-1), beta.reshape(-1)
    widest = int(np.ceil(2.0 * cap / res)) + 3
    span = (widest >> CHUNK_SHIFT) + 2  # chunks a support spans per axis, at most
    chunks, offsets = np.empty(span**3, np.int64), np.empty((2, 3, widest, BLOCK), np.uint64)
    box = np.full(6, -1, np.int64)
    pts, scales, sigs = np.empty((3, BLOCK)), np.empty((4, 3, BLOCK)), np.empty(BLOCK)
    scratch, where = np.empty((4, BLOCK)), np.empty(BLOCK, np.int64)
    first_cell, count = np.empty((3, BLOCK), np.int64), np.empty((3, BLOCK), np.int64)
    w = np.empty((3, widest, BLOCK))
    free_rot, rot = np.full((3, 5), np.nan), np.full((3, 5), np.nan)
    for j in range(3):
        _rotation(l_free[j], res, free_rot, j)
    _rotation(l_free[2], res, rot, 2)  # the cells' vertical length is the free samples'
    for j in range(3):  # the free samples' axes and lengths, in every column until the hits
        for q in range(4):
            scales[q, j, :] = free_rot[j, q + 1]
    free_end = rows[n_rays]
    total, row = free_end + 3 * n_rays, start
    ray = np.searchsorted(rows, start, side="right") - 2 if start < free_end else n_rays
    while row < total:
        n, hit = 0, row >= free_end
        while not hit and n < BLOCK and row < free_end:  # free samples, ray after ray
            if row >= rows[ray + 1]:  # the next ray with free samples
                ray += 1
                while rows[ray + 1] == rows[ray]:
                    ray += 1
            k0 = row - rows[ray]
            m = min(BLOCK - n, rows[ray + 1] - row)
            row += m
            if not ray_meets(ray, k0, m, origin, direction, f, l_free[axis], axis, res, first,
                             stop):  # fmt: skip
                continue  # (a slab thread: none of these samples reaches its cells)
            free_coordinates(ray, k0, m, n, origin, direction, f, pts)
            for t in range(m):
                sigs[n + t], where[n + t] = sig[ray], row - m + t
            n += m
        while hit and n < BLOCK and row < total:  # the hits' cells of weight > 0
            i, c = (row - free_end) // 3, (row - free_end) % 3
            row += 1
            if not hw[i, c] > 0.0:
                continue
            _rotation(hl[i, 0], res, rot, 0)
            _rotation(hl[i, 1], res, rot, 1)
            pts[0, n], pts[1, n], pts[2, n] = hx[i], hy[i], hz[i, c]
            for j in range(3):
                for q in range(4):
                    scales[q, j, n] = rot[j, q + 1]
            sigs[n], where[n] = hw[i, c], row - 1
            n += 1
        if n == 0:
            continue
        block_weights(n, pts, scales, res, span, first_cell, count, w, offsets, scratch)
        b = block_cells(n, hit, sigs, axis, first, stop, first_cell, count, w, offsets, chunks,
                        span, box, place, table_keys, table_vals, chunk_keys, n_chunks, alpha,
                        beta)  # fmt: skip
        if b >= 0:
            return where[b]
    return total


@njit(cache=True, nogil=True, error_model="numpy")
def tpu_insert_chunks(start, stop, origin, direction, rows, f, l_free, hx, hy, hl, hz, hw, res,
                      held_keys, held_vals, table_keys, table_vals, chunk_keys,
                      n_chunks):  # fmt: skip
    """:func:`~undertow.mapping.kernels.insert_chunks` of the tpu sample rows start..stop - 1
    (rows as :func:`tpu_scatter_slab`'s; ``held`` as there), the same chunks in the same order:
    ``stop`` when done, else the first row whose chunks did not fit (the caller grows the
    arrays and resumes there). As :func:`~undertow.mapping.rayscatter.ray_insert_chunks`:
    ray by ray (each ray's lengths and position taken once), a sample's chunks looked at only
    when its box differs from the previous sample's, and a small cache of the chunks placed
    before the tables are probed (:func:`~undertow.mapping.chunks.find`, then inserted on a
    miss). (The box's loop is written out in both: as a shared compiled helper, numba counts
    references to its array arguments on every call, which made this pass 1.5x slower.)"""
    n_rays = hx.shape[0]
    free_end = rows[n_rays]
    p, ratio = np.empty(3), np.empty(3)
    lo, hi = np.zeros(3, np.int64), np.zeros(3, np.int64)
    box = np.full(6, -1, np.int64)  # the previous sample's chunks (lo, hi)
    placed = np.full(PLACED_CACHE, -1, np.int64)  # keys of chunks placed, by their low bits
    first_ray = np.searchsorted(rows, start, side="right") - 1 if start < free_end else n_rays
    for seg in range(first_ray, n_rays + 1):  # ray by ray the free samples, then the hits' cells
        if seg < n_rays:
            if rows[seg] >= stop:
                break
            t0, t1 = max(start - rows[seg], 0), min(rows[seg + 1], stop) - rows[seg]
            for j in range(3):
                ratio[j] = l_free[j] / res
        else:
            t0, t1 = max(start - free_end, 0), min(3 * n_rays, stop - free_end)
        for t in range(t0, t1):
            if seg < n_rays:  # free sample o + (t f) v
                for j in range(3):
                    p[j] = (origin[seg, j] + (t * f) * direction[seg, j]) / res
            else:  # hit i's cell c
                i, c = t // 3, t % 3
                if not hw[i, c] > 0.0:
                    continue
                p[0], p[1], p[2] = hx[i] / res, hy[i] / res, hz[i, c] / res
                ratio[0], ratio[1], ratio[2] = hl[i, 0] / res, hl[i, 1] / res, l_free[2] / res
            for j in range(3):  # the support as kernels._support takes it
                first = np.int64(np.floor(p[j] - ratio[j] - 0.5)) + 1
                last = np.int64(np.ceil(p[j] + ratio[j] - 0.5)) - 1
                lo[j], hi[j] = first >> CHUNK_SHIFT, max(last, first) >> CHUNK_SHIFT
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
                            return (rows[seg] if seg < n_rays else free_end) + t
                        placed[slot] = key
            box[:3], box[3:] = lo, hi
    return stop
