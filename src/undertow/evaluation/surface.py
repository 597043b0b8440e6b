"""Map metrics the grid does not quantize: the bathymetric surface error and accuracy,
completeness and F-score of the map's surface against the true floor.

The map's surface is :func:`undertow.mapping.surface.map_surface` (per column the expected first
occupied depth d_ij). The true floor is either a heightfield z(x, y) (a callable) or a
ground-truth point cloud, gridded by :func:`~undertow.mapping.surface.surface_from_points` and
interpolated bilinearly. The surveyed area A is a set of columns of the map's grid: those that
hold any of the ``area`` points given (e.g. where the sensors' beams hit the floor), by default
those of the ground-truth cloud.

- Bathymetric surface error, over the map's covered columns C where the truth is defined:
  e_ij = d_ij - z(x_ij, y_ij) (z down, so e > 0: the map is too deep);
  RMSE = sqrt(mean e^2), bias = mean e, coverage = |C & A| / |A|.
- Accuracy, completeness, F-score at a distance threshold tau (Knapitsch et al., "Tanks and
  Temples: benchmarking large-scale scene reconstruction", ACM TOG 36(4) 2017, sec. 4): with
  the map points M (the map's surface sampled every ``spacing`` within its covered columns)
  and the ground-truth points G (the cloud, or the heightfield sampled the same way),
  precision P(tau) = |{m in M : min_g |m - g| < tau}| / |M|,
  recall R(tau) = |{g in G_A : min_m |g - m| < tau}| / |G_A| (G_A: ground truth inside A),
  F(tau) = 2 P R / (P + R). Distances are Euclidean (3-D) nearest-neighbour distances, so on a
  slope a vertical offset delta counts as about delta / sqrt(1 + |grad z|^2).
- Calibration of the map's depth standard deviation s_ij, over the columns K of C inside A
  where the truth is defined and s_ij is finite and > 0 (``calibrated_columns`` = |K|):
  within_k = |{ij in K : |e_ij| <= k s_ij}| / |K| for k = 1, 2 (``within_1sigma``,
  ``within_2sigma``) and mean_abs_z = mean over K of |e_ij| / s_ij. A depth std that means what
  it says (the true floor N(d_ij, s_ij^2) about the map's depth) gives within_1 = erf(1 / sqrt 2)
  = 0.683, within_2 = erf(sqrt 2) = 0.954 and mean_abs_z = sqrt(2 / pi) = 0.798; smaller
  shares: the std is too small (overconfident), larger: too large.

:func:`hull_area` is a surveyed area when no log says where the beams fell: the map's columns
inside the convex hull of its covered cells (of their squares, so that a column on the hull is
inside it) where the truth is defined.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import ConvexHull, Delaunay, cKDTree

from ..errors import DataError
from ..mapping.surface import Surface, surface_from_points

#: The distance thresholds of the F-score (m).
TAUS = (0.05, 0.10, 0.20)
Heightfield = Callable[[np.ndarray, np.ndarray], np.ndarray]


def tau_key(tau: float) -> str:
    """The result key of a threshold: 0.05 -> '5cm'."""
    return f"{tau * 100:g}cm"


@dataclass(frozen=True)
class SurfaceEvaluation:
    """Surface metrics, distances in m; ``precision``/``recall``/``fscore`` by :func:`tau_key`."""

    surface_rmse_m: float
    surface_bias_m: float
    coverage: float
    covered_columns: int
    surveyed_columns: int
    precision: dict = field(default_factory=dict)
    recall: dict = field(default_factory=dict)
    fscore: dict = field(default_factory=dict)
    within_1sigma: float = float("nan")
    within_2sigma: float = float("nan")
    mean_abs_z: float = float("nan")
    calibrated_columns: int = 0

    def to_dict(self) -> dict:
        """Flat: surface_rmse_m, surface_bias_m, coverage, ..., fscore_5cm, precision_5cm, ...,
        within_1sigma, within_2sigma, mean_abs_z, calibrated_columns."""
        out = {k: getattr(self, k) for k in ("surface_rmse_m", "surface_bias_m", "coverage",
                                             "covered_columns", "surveyed_columns")}  # fmt: skip
        for name in ("fscore", "precision", "recall"):
            out.update({f"{name}_{k}": v for k, v in getattr(self, name).items()})
        out.update({k: getattr(self, k) for k in CALIBRATION_KEYS})
        return out


#: the calibration's result keys (the module doc's equations)
CALIBRATION_KEYS = ("within_1sigma", "within_2sigma", "mean_abs_z", "calibrated_columns")


def _truth(truth):
    """(heightfield callable, ground-truth cloud or None, the cloud's k-d tree or None)."""
    if callable(truth):
        return truth, None, None
    cloud = np.asarray(truth, dtype=float)
    if cloud.ndim != 2 or cloud.shape[1] != 3 or len(cloud) == 0:
        raise DataError(f"ground truth: shape {cloud.shape}, expected (N, 3) points or z(x, y)")
    if not np.all(np.isfinite(cloud)):
        raise DataError("ground truth: non-finite coordinates")
    tree = cKDTree(cloud)
    return surface_from_points(cloud, cloud_spacing(cloud)).at, cloud, tree


def truth_heightfield(truth) -> Heightfield:
    """The true floor as a heightfield z(x, y): ``truth`` itself if callable, else the
    (N, 3) ground-truth cloud gridded at its own spacing and interpolated bilinearly."""
    return _truth(truth)[0]


def cloud_spacing(cloud: np.ndarray) -> float:
    """The cloud's point spacing in x-y: the median nearest-neighbour distance (of up to 5000
    points), for gridding it."""
    xy = cloud[:, :2]
    sample = xy[np.random.default_rng(0).choice(len(xy), min(len(xy), 5000), replace=False)]
    d = cKDTree(xy).query(sample, k=2)[0][:, 1] if len(xy) > 1 else np.zeros(0)
    d = d[d > 0]
    return float(np.median(d)) if d.size else 1.0


def _column_index(surface: Surface, xy: np.ndarray) -> np.ndarray:
    """(K, 2) integer column (i, j) of points on the surface's grid (may lie outside it)."""
    return np.rint((xy - (surface.x0, surface.y0)) / surface.resolution).astype(np.int64)


def _sub_points(surface: Surface, columns: np.ndarray, n: int) -> np.ndarray:
    """(K n^2, 2) x-y points on an n x n sub-grid of each column (i, j), cell-centred."""
    offsets = ((np.arange(n) + 0.5) / n - 0.5) * surface.resolution
    ox, oy = (a.ravel() for a in np.meshgrid(offsets, offsets, indexing="xy"))
    cx = surface.x0 + surface.resolution * columns[:, 0]
    cy = surface.y0 + surface.resolution * columns[:, 1]
    return np.stack([(cx[:, None] + ox).ravel(), (cy[:, None] + oy).ravel()], axis=1)


def _area_columns(surface: Surface, area, cloud) -> np.ndarray:
    """The surveyed columns A (unique (i, j)): those of the ``area`` points, else of the cloud,
    else the map's own covered columns."""
    if area is None:
        area = cloud[:, :2] if cloud is not None else surface.points()[:, :2]
    xy = np.asarray(area, dtype=float)
    if xy.ndim != 2 or xy.shape[1] < 2:
        raise DataError(f"area: shape {xy.shape}, expected (N, 2) x-y points")
    if len(xy) == 0:
        return np.zeros((0, 2), np.int64)
    return np.unique(_column_index(surface, xy[:, :2]), axis=0)


def evaluate_surface(surface: Surface, truth: Heightfield | np.ndarray, area=None,
                     taus=TAUS, spacing: float | None = None) -> SurfaceEvaluation:  # fmt: skip
    """The module doc's metrics of ``surface`` against ``truth`` (a heightfield z(x, y) or an
    (N, 3) ground-truth cloud) over the surveyed ``area`` ((N, 2+) x-y points; default: the
    cloud's x-y, or for a heightfield the map's covered columns, coverage then 1).
    ``spacing`` (default resolution / 4) samples the map's surface, and a heightfield truth,
    for accuracy and completeness."""
    res = surface.resolution
    spacing = res / 4 if spacing is None else float(spacing)
    if not spacing > 0:
        raise DataError(f"spacing {spacing}: expected > 0")
    height, cloud, tree = _truth(truth)
    surveyed = _area_columns(surface, area, cloud)
    j, i = np.nonzero(surface.coverage)
    in_area = int(_in_columns(surveyed, np.stack([i, j], axis=1)).sum())
    mp = surface.points()
    error = mp[:, 2] - np.asarray(height(mp[:, 0], mp[:, 1]), dtype=float) if len(mp) else mp
    error = error[np.isfinite(error)] if len(mp) else np.zeros(0)
    n_sub = max(1, int(np.ceil(res / spacing - 1e-9)))
    map_pts = _surface_samples(surface, n_sub)
    gt_all, gt_area = _truth_points(surface, height, cloud, surveyed, n_sub)
    tree = tree if tree is not None else (cKDTree(gt_all) if len(gt_all) else None)
    d_map = tree.query(map_pts, k=1)[0] if len(map_pts) and tree is not None else np.zeros(0)
    d_gt = np.full(len(gt_area), np.inf)  # nothing mapped: no ground truth point is reached
    if len(map_pts) and len(gt_area):
        d_gt = cKDTree(map_pts).query(gt_area, k=1)[0]
    precision, recall, fscore = {}, {}, {}
    for tau in taus:
        key = tau_key(tau)
        p, r = _fraction_below(d_map, tau), _fraction_below(d_gt, tau)
        precision[key], recall[key] = p, r
        fscore[key] = _fscore(p, r)
    nan = float("nan")
    return SurfaceEvaluation(
        surface_rmse_m=float(np.sqrt(np.mean(error**2))) if error.size else nan,
        surface_bias_m=float(np.mean(error)) if error.size else nan,
        coverage=in_area / len(surveyed) if len(surveyed) else nan,
        covered_columns=int(surface.coverage.sum()),
        surveyed_columns=int(len(surveyed)),
        precision=precision,
        recall=recall,
        fscore=fscore,
        **calibration(surface, height, surveyed),
    )


def calibration(surface: Surface, height: Heightfield, surveyed: np.ndarray) -> dict:
    """The module doc's calibration of ``surface.std`` against the heightfield ``height`` over
    the covered columns among ``surveyed`` ((K, 2) column indices (i, j)): within_1sigma,
    within_2sigma, mean_abs_z (NaN when no column qualifies), calibrated_columns."""
    j, i = np.nonzero(surface.coverage)
    inside = _in_columns(np.stack([i, j], axis=1), surveyed)
    i, j = i[inside], j[inside]
    x = surface.x0 + surface.resolution * i
    y = surface.y0 + surface.resolution * j
    error = surface.depth[j, i] - np.asarray(height(x, y), dtype=float)
    sigma = surface.std[j, i]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(error) & np.isfinite(sigma) & (sigma > 0)
    z = np.abs(error[ok]) / sigma[ok]
    nan = float("nan")
    return {
        "within_1sigma": float(np.mean(z <= 1.0)) if z.size else nan,
        "within_2sigma": float(np.mean(z <= 2.0)) if z.size else nan,
        "mean_abs_z": float(np.mean(z)) if z.size else nan,
        "calibrated_columns": int(z.size),
    }


def hull_area(surface: Surface, truth: Heightfield | np.ndarray) -> np.ndarray:
    """The (K, 2) centres of the surface's columns inside the convex hull of the squares of its
    covered cells where the truth (a heightfield or an (N, 3) cloud, as :func:`evaluate_surface`
    takes it) is defined: a surveyed area for :func:`evaluate_surface` when no log says where
    the beams fell."""
    centres = surface.points()[:, :2]
    if not len(centres):
        return np.zeros((0, 2))
    half = surface.resolution / 2
    corners = centres[:, None, :] + half * np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]])
    corners = np.unique(corners.reshape(-1, 2), axis=0)
    hull = Delaunay(corners[ConvexHull(corners).vertices])  # squares: never degenerate
    x, y = surface.centres()
    xy = np.stack([x.ravel(), y.ravel()], axis=1)
    xy = xy[hull.find_simplex(xy) >= 0]
    z = np.asarray(truth_heightfield(truth)(xy[:, 0], xy[:, 1]), dtype=float)
    return xy[np.isfinite(z)]


def _fraction_below(d: np.ndarray, tau: float) -> float:
    """Fraction of distances below tau (NaN for none)."""
    return float(np.mean(d < tau)) if d.size else float("nan")


def _fscore(p: float, r: float) -> float:
    """F = 2 P R / (P + R); 0 when both are 0 or a map without points (P undefined) reaches
    nothing (R = 0); NaN when R is undefined (no ground truth in the area)."""
    if r != r:
        return float("nan")
    p = 0.0 if p != p else p
    return 2 * p * r / (p + r) if p + r > 0 else 0.0


def _surface_samples(surface: Surface, n_sub: int) -> np.ndarray:
    """The map's surface sampled on an n_sub x n_sub sub-grid of every covered column."""
    j, i = np.nonzero(surface.coverage)
    if not i.size:
        return np.zeros((0, 3))
    xy = _sub_points(surface, np.stack([i, j], axis=1), n_sub)
    z = surface.at(xy[:, 0], xy[:, 1])
    ok = np.isfinite(z)
    return np.column_stack([xy[ok], z[ok]])


def _truth_points(surface: Surface, height, cloud, surveyed, n_sub):
    """(all ground-truth points, those inside the surveyed columns): the cloud, or the
    heightfield sampled like the map over the surveyed and covered columns (grown by one)."""
    if cloud is not None:
        cols = _column_index(surface, cloud[:, :2])
        inside = _in_columns(cols, surveyed)
        return cloud, cloud[inside]
    j, i = np.nonzero(surface.coverage)
    grown = [np.stack([i + di, j + dj], axis=1) for di in (-1, 0, 1) for dj in (-1, 0, 1)]
    columns = np.unique(np.concatenate([surveyed, *grown]), axis=0)
    xy = _sub_points(surface, columns, n_sub)
    z = np.asarray(height(xy[:, 0], xy[:, 1]), dtype=float)
    pts = np.column_stack([xy, z])[np.isfinite(z)]
    inside = _in_columns(_column_index(surface, pts[:, :2]), surveyed)
    return pts, pts[inside]


def _in_columns(cols: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Whether each (i, j) of ``cols`` is one of ``columns``."""
    if not len(columns) or not len(cols):
        return np.zeros(len(cols), bool)
    lo = np.minimum(cols.min(axis=0), columns.min(axis=0))
    width = int(max(cols[:, 1].max(), columns[:, 1].max()) - lo[1]) + 1
    key = (cols[:, 0] - lo[0]) * width + (cols[:, 1] - lo[1])
    ref = (columns[:, 0] - lo[0]) * width + (columns[:, 1] - lo[1])
    return np.isin(key, ref)
