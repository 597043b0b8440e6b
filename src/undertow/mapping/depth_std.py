"""The depth standard deviation of a ``tpu`` map's evidence surface: the propagated
uncertainty of each column's hits (:func:`propagated_std`).

A column's depth d is the weighted mean of its hits' depths z_i, d = sum_i w_i z_i / W, with
the column's sums (:class:`~undertow.occupancy.ColumnStats`, :mod:`undertow.mapping.columns`)
W = sum w_i, V = sum w_i sigma_v,i^2, X = sum w_i sigma_x,i^2, Y = sum w_i sigma_y,i^2,
R = sum w_i s_r,i^2, U = sum w_i^2 s_r,i^2, Q = sum w_i r_s,i^2, D_x = sum w_i dx_i^2,
D_y = sum w_i dy_i^2 (dx_i, dy_i the offset of the column's centre from hit i) and
L = sum w_i v_i r^2 (the variance of the three cells the mapper put hit i on). A hit's
error is the sum of parts that the column's hits share and parts that are its own, and the
variance of a weighted mean adds them so (the usual rule for a weighted mean of correlated
and independent errors):

    s^2 = (V - R - Q e_b^2) / W                     the shared vertical part (the pose's depth)
        + U / W^2                                   the range noise, averaged over the hits
        + (Q / W) e(beta)^2                         a wide beam's shortfall on this slope
        + (X / W) (dd/dx)^2 + (Y / W) (dd/dy)^2     the horizontal uncertainty through the slope
        + max(S - (L + V') / W - (D_x / W) (dd/dx)^2 - (D_y / W) (dd/dy)^2, 0)  relief left out,

    V' = V - Q e_b^2 + Q e(beta)^2                  the hits' own variance at this slope.

- **Shared.** sigma_v,i^2 = s_z^2 + s_rz^2 + s_d^2 (:mod:`undertow.mapping.tpu`): the pose's
  depth variance s_z^2 is one error for the hits of a pass, so it is not averaged (the
  weighted mean of variances it shares).
- **Averaged.** s_rz^2, the depth share of the range's own noise in these waves (the echo
  sounder's and the waves' acoustic term: independent from ping to ping, as a sensor's noise
  is), falls as sum w^2 / W^2 = 1 / n_eff with the effective number of hits n_eff.
- **Shortfall.** A wide beam's first return is the nearest floor in its cone, above the floor
  on its axis by r (sec beta - 1) on a plane of slope beta (X. Lurton, "An Introduction to
  Underwater Acoustics", 2nd ed. 2010, sec. 8.2). The mapper weighs each sonar hit by the
  largest such shortfall, e_b = sec(b / 2) - 1 (b the beam width); the surface knows the
  floor's slope, so it takes e(beta) = sec(min(beta, b / 2)) - 1, beta = atan |grad d|, and
  removes the mapper's e_b from the shared part (Q = sum w r_s^2 over the sonar's hits).
- **Slope.** A hit placed sigma_x off carries the floor's slope into depth, sigma_x dd/dx:
  the TVU' = sqrt(TVU^2 + (THU tan(slope))^2) of hydrography (Hare, Eakins and Amante,
  "Modelling bathymetric uncertainty", International Hydrographic Review 6, 2011; IHO S-44
  6th ed. 2020). sigma_x is the pose's and a wide beam's footprint, not the kernel's base
  length (which smooths the floor but misplaces no hit).
- **Relief left out.** S = sum_k w_k (z_k - d)^2 / sum_k w_k is the spread of the column's
  cell evidence about d; less the cells' own spread about each hit (L / W) it is the hits'
  scatter, sum_i w_i (z_i - d)^2 / W. Where they scatter more than their own uncertainties
  (V' / W) and a plane's tilt across where they lie (D_x / W, D_y / W) explain, the floor has
  relief the kernel averaged, or the hits carry pose errors their covariance left out; that
  excess is added (CUBE compares soundings with their hypothesis likewise: Calder and Mayer,
  "Automatic processing of high-rate, high-density multibeam echosounder data", G3 4(6) 2003).
  The hits' own variance V' takes a wide beam's shortfall at the slope, e(beta), as the std
  above does, not the mapper's e_b: first returns that scatter more than this slope's
  shortfall explains come from relief inside the footprint (ripples, stones) the surface
  smooths away, which puts the beam's axis hits short by more than e(beta).

The slopes dd/dx and dd/dy are central differences of the surface's depths (one-sided beside
a column without data, 0 with neither neighbour). A map written before the last six sums
reads them as zeros: s^2 = V / W + slope terms + the relief above V / W.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def propagated_std(surface, columns, beam_width_deg: float = 0.0, spread=None):
    """``surface`` (a :class:`~undertow.mapping.surface.Surface`) with its std replaced by the
    module doc's s, from ``columns`` (a :class:`~undertow.occupancy.ColumnStats`; a column no
    hit landed in takes the nearest one's), the map's sonar ``beam_width_deg`` b and the
    evidence's ``spread`` S per column (an array of the surface's shape; None: 0, no
    relief)."""
    ny, nx = surface.shape
    res = surface.resolution
    held = columns.sums[:, 0] > 0
    if not held.any() or not surface.coverage.any():
        return surface
    j, i = np.nonzero(surface.coverage)
    i0 = int(round(surface.x0 / res - 0.5))
    j0 = int(round(surface.y0 / res - 0.5))
    nearest = cKDTree(columns.cells[held]).query(np.stack([i + i0, j + j0], axis=1))[1]
    sums = np.full((ny, nx, columns.sums.shape[1]), np.nan)
    sums[j, i] = columns.sums[held][nearest]
    gx, gy = _slope(surface.depth, 1, res), _slope(surface.depth, 0, res)
    spread = np.zeros((ny, nx)) if spread is None else spread
    var = column_variance(np.moveaxis(sums, -1, 0), gx, gy, spread, beam_width_deg)
    std = np.where(surface.coverage & np.isfinite(var), np.sqrt(np.maximum(var, 0.0)),
                   surface.std)  # fmt: skip
    return type(surface)(surface.x0, surface.y0, res, surface.depth, std, surface.coverage,
                         "propagated")  # fmt: skip


def column_variance(sums, gx, gy, spread, beam_width_deg: float):
    """s^2 of the module doc from the sums (W, V, X, Y, R, U, Q, D_x, D_y, L: the
    :data:`~undertow.occupancy.COLUMN_SUMS`, each an array of the slopes' shape), the slopes
    (gx, gy) and the evidence's spread S."""
    w, v, x, y, r, u, q, dx, dy, lattice = sums
    half = np.deg2rad(beam_width_deg) / 2.0
    e_b = 1.0 / np.cos(half) - 1.0
    beta = np.minimum(np.arctan(np.hypot(gx, gy)), half)
    e_beta2 = (1.0 / np.cos(beta) - 1.0) ** 2
    shortfall = (q / w) * e_beta2
    shared = np.maximum(v - r - q * e_b * e_b, 0.0) / w
    slope = (x / w) * gx * gx + (y / w) * gy * gy
    plane = (dx / w) * gx * gx + (dy / w) * gy * gy
    own = v - q * e_b * e_b + q * e_beta2  # V': the hits' own variance, shortfall at beta
    relief = np.maximum(spread - (lattice + own) / w - plane, 0.0)
    return shared + u / (w * w) + shortfall + slope + relief


def _slope(depth: np.ndarray, axis: int, res: float) -> np.ndarray:
    """dd/d(axis) of a depth grid by central differences, one-sided where a neighbour has no
    data, 0 where neither has."""
    ahead = np.full(depth.shape, np.nan)
    behind = np.full(depth.shape, np.nan)
    inner = [slice(None)] * 2
    outer = [slice(None)] * 2
    inner[axis], outer[axis] = slice(1, None), slice(None, -1)
    diff = depth[tuple(inner)] - depth[tuple(outer)]
    ahead[tuple(outer)] = diff  # d[k + 1] - d[k] at k
    behind[tuple(inner)] = diff  # d[k] - d[k - 1] at k
    both = np.stack([ahead, behind])
    n = np.sum(np.isfinite(both), axis=0)
    total = np.nansum(both, axis=0)
    return np.where(n > 0, total / np.maximum(n, 1), 0.0) / res
