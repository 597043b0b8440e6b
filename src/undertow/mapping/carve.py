"""The sonar's cone carved free: where a wide beam's first return says no floor can be.

A single-beam sonar (a Ping2: full beam width b = 25 deg) reports the range r of the first echo
above its threshold: the nearest surface anywhere in its cone, not the floor on its axis. Placed
on the axis (:mod:`undertow.mapping.tpu`), a return from a step's top or a rock's flank when the
axis is over the deeper floor beside it widens the relief by up to the footprint's radius, r
tan(b / 2) (0.55 m at 2.5 m). What the same return also says is that nothing lies nearer than r
inside the cone: the sonar's free space, the cone's interior of Elfes' sonar occupancy maps (A.
Elfes, "Sonar-based real-world mapping and navigation", IEEE J. Robotics and Automation 3(3),
1987; H. Moravec and A. Elfes, "High resolution maps from wide angle sonar", ICRA 1985). A ping
over the floor just beside a step carves the cells where its neighbours put the step's top.

For a ping from o along the unit axis v (z down) with half-angle h = b / 2, a column's vertical
line through (x, y) (horizontal distance rho from o, rho < r) is inside the cone from depth

    T = o_z + t,  t the larger root of (v_z^2 - c^2) t^2 + 2 a v_z t + a^2 - rho^2 c^2 = 0

(a = (x - o_x) v_x + (y - o_y) v_y, c = cos h: where the angle between (x - o_x, y - o_y, t) and
v is h), down to the sphere of radius r about o, at depth o_z + sqrt(r^2 - rho^2). Every point
between is inside the cone nearer than r: free. With a margin kappa sigma for the range and the
pose's depth (sigma^2 = sigma_v^2 - s_d^2, the hit's vertical variance without the shortfall s_d
that this geometry replaces; kappa = :data:`KAPPA`), the ping clears the column from T down to

    F = o_z + sqrt(r^2 - rho^2) - kappa sigma,

when F > T. A ping whose axis is tilted from the vertical by h or more (v_z <= c) carves nothing:
its cone holds a horizontal direction and the vertical lines are not cut as above.

A cone wider than the tpu kernel's largest support (``max_length``, 2 m: a Ping2 beyond 9 m)
carves only within that distance of its axis' end on x and on y.

Per column the map keeps the two deepest such intervals (F_1 >= F_2, with their tops T_1, T_2),
cells (i, j, 4 .. 7) of the :class:`~undertow.mapping.columns.ColumnGrid` (stored as depth +
:data:`OFFSET`, so that 0 is "none" and the grid's spill and take-back, which add a chunk to an
empty one, keep them). A hit's mass lies on the three cells around it
(:mod:`undertow.mapping.tpu`), so a cell of centre depth z holds mass of hits within 3 r / 2 of
z (r the resolution); it is carved when all of them lie inside both intervals,
max(T_1, T_2) <= z - 3 r / 2 and z + 3 r / 2 <= F_2 (a floor hit's upper cell is not carved by
the floor's own free space). Two pings must agree, so one spurious long range (a second bottom
echo) clears nothing. Taking the two deepest is conservative: the cells it carves are free by
two pings' cones; some that a vote of all the pings would carve stay. The surface leaves carved
cells out (:func:`~undertow.mapping.surface.evidence_surface`). The floor right beside a step
stays as it was: a cone that reaches it reaches the step's top too, so its return is the top.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .chunks import CHUNK_SHIFT, find_or_insert
from .tpu import shortfall

#: the margin kept above the sphere of the range, in the hit's range-and-depth standard deviations
KAPPA = 3.0
#: the stored values are depths plus this (m), so that a cell at zero means "no interval"
OFFSET = 1000.0
#: the column sums kept as alpha mass in cells (i, j, 0 ..): the first four (the other six
#: are kept as beta mass, :mod:`undertow.mapping.columns`)
ALPHA_SUMS = 4
#: the first of the four column cells (F_1, T_1, F_2, T_2) the intervals take in the ColumnGrid
FIRST_CELL = ALPHA_SUMS


def carve_inputs(origin, direction, r, var_v, half_angle: float):
    """The rays a ping's cone carves (module doc) from per-hit origins (n, 3), unit axes (n, 3),
    ranges, vertical variances sigma_v^2 (with the shortfall) and the half-angle h (rad):
    (origin, direction, r, margin kappa sigma) of those with finite values, r > 0 and an axis
    within h of the vertical."""
    origin, direction = np.asarray(origin, float), np.asarray(direction, float)
    r, var_v = np.asarray(r, float), np.asarray(var_v, float)
    s_d = shortfall(r, math.tan(half_angle))
    margin = KAPPA * np.sqrt(np.maximum(var_v - s_d * s_d, 0.0))
    ok = (np.isfinite(origin).all(axis=1) & np.isfinite(direction).all(axis=1)
          & np.isfinite(r) & (r > 0) & np.isfinite(margin)
          & (direction[:, 2] > math.cos(half_angle)))  # fmt: skip
    return origin[ok], direction[ok], r[ok], margin[ok]


@njit(cache=True, inline="always")
def column_interval(ox, oy, oz, vx, vy, vz, r, margin, c, x, y):
    """(T, F) of the column through (x, y) for one ping (module doc); F <= T when it carves
    nothing there."""
    dx, dy = x - ox, y - oy
    rho2 = dx * dx + dy * dy
    if rho2 >= r * r:
        return 0.0, -1.0
    a = dx * vx + dy * vy
    qa = vz * vz - c * c
    qb = 2.0 * a * vz
    qc = a * a - rho2 * c * c
    disc = qb * qb - 4.0 * qa * qc
    t = (-qb + math.sqrt(disc)) / (2.0 * qa) if disc > 0.0 else max(-a / vz, 0.0)
    return oz + max(t, 0.0), oz + math.sqrt(r * r - rho2) - margin


@njit(cache=True)
def add_carve(start, origin, direction, r, margin, cos_half, sin_quarter, cap, res, table_keys,
              table_vals, chunk_keys, n_chunks, alpha, beta):  # fmt: skip
    """From ping ``start``: keep, per column whose centre ((i + 1/2) res, ...) the ping's cone
    reaches (within the chord 2 r sin(h / 2) of its axis' end on x and on y, and within ``cap``:
    the tpu kernel's largest support, which bounds the cost and the tiles' halo as it does the
    hits'), the two deepest intervals (T, F) in cells (i, j, FIRST_CELL ..) (module doc). A
    ping starts only when the chunk arrays have
    room for every chunk it may place; returns the first ping without that room, or n."""
    last_x, last_y, chunk = np.int64(1) << 40, np.int64(0), -1  # the last chunk found
    for s in range(start, r.shape[0]):
        ox, oy, oz = origin[s, 0], origin[s, 1], origin[s, 2]
        vx, vy, vz = direction[s, 0], direction[s, 1], direction[s, 2]
        mx, my, reach = ox + r[s] * vx, oy + r[s] * vy, min(2.0 * r[s] * sin_quarter, cap)
        i0 = int(math.ceil((mx - reach) / res - 0.5))
        i1 = int(math.floor((mx + reach) / res - 0.5))
        j0 = int(math.ceil((my - reach) / res - 0.5))
        j1 = int(math.floor((my + reach) / res - 0.5))
        if i1 < i0 or j1 < j0:
            continue
        spans = ((i1 >> CHUNK_SHIFT) - (i0 >> CHUNK_SHIFT) + 1) * (
            (j1 >> CHUNK_SHIFT) - (j0 >> CHUNK_SHIFT) + 1
        )
        if n_chunks[0] + spans > chunk_keys.shape[0]:
            return s
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                x, y = (i + 0.5) * res, (j + 0.5) * res
                top, bottom = column_interval(ox, oy, oz, vx, vy, vz, r[s], margin[s],
                                              cos_half, x, y)  # fmt: skip
                if not bottom > top:
                    continue
                if i >> CHUNK_SHIFT != last_x or j >> CHUNK_SHIFT != last_y:
                    last_x, last_y = i >> CHUNK_SHIFT, j >> CHUNK_SHIFT
                    chunk = find_or_insert(last_x, last_y, 0, table_keys, table_vals,
                                           chunk_keys, n_chunks)  # fmt: skip
                keep_deepest(alpha[chunk, i & 7, j & 7], top + OFFSET, bottom + OFFSET)
    return r.shape[0]


@njit(cache=True, inline="always")
def keep_deepest(cell, top, bottom):
    """Insert the interval (top, bottom) among the two deepest held in ``cell[FIRST_CELL:]``
    (F_1, T_1, F_2, T_2, by F; 0: none)."""
    k = FIRST_CELL
    if bottom > cell[k]:
        cell[k + 2], cell[k + 3] = cell[k], cell[k + 1]
        cell[k], cell[k + 1] = bottom, top
    elif bottom > cell[k + 2]:
        cell[k + 2], cell[k + 3] = bottom, top


def carved(depth: np.ndarray, intervals: np.ndarray, resolution: float) -> np.ndarray:
    """Whether a cell of the map's grid (``resolution`` r) at centre depth ``depth`` (n,) is
    carved by its column's ``intervals`` (n, 4: F_1, T_1, F_2, T_2 in metres, NaN where none):
    every hit that can have put mass on it lies inside both, max(T_1, T_2) <= z - 3 r / 2 and
    z + 3 r / 2 <= F_2 (module doc)."""
    intervals = np.asarray(intervals, float)
    top = np.maximum(intervals[:, 1], intervals[:, 3])
    reach = 1.5 * float(resolution)
    with np.errstate(invalid="ignore"):
        return (depth - reach >= top) & (depth + reach <= intervals[:, 2])


def decode(stored: np.ndarray) -> np.ndarray:
    """The intervals in metres from the grid's stored values (NaN where none)."""
    stored = np.asarray(stored, float)
    return np.where(stored > 0, stored - OFFSET, np.nan)


def encode(intervals: np.ndarray) -> np.ndarray:
    """The grid's stored values of intervals in metres (0 where NaN)."""
    intervals = np.asarray(intervals, float)
    return np.where(np.isfinite(intervals), intervals + OFFSET, 0.0)
