"""Map evaluation against a ground-truth point cloud (the paper's map metrics).

- C2C (CloudCompare's cloud-to-cloud distance): for every map point (occupied cell centre,
  mean occupancy > 0.5) the distance to its nearest ground-truth point; reported as mean,
  median and RMSE, in metres.
- Coverage: the reverse, for ground-truth points to their nearest map point, averaged. It is
  restricted to ground-truth points inside the map's xy footprint (the set of map cells' xy
  columns at the map's resolution, grown by one cell), because a map of a survey strip
  says nothing about the rest of a larger ground-truth scan.
- Map density: the number of occupied cells.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import DataError
from ..occupancy import OCCUPIED_THRESHOLD


@dataclass(frozen=True)
class MapEvaluation:
    """Map metrics, distances in metres."""

    c2c_mean_m: float
    c2c_median_m: float
    c2c_rmse_m: float
    coverage_mean_m: float
    occupied_cells: int
    ground_truth_in_footprint: int

    def to_dict(self) -> dict:
        return asdict(self)


def _cloud(name: str, points) -> np.ndarray:
    arr = np.asarray(points, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise DataError(f"{name}: shape {arr.shape}, expected (N, 3)")
    if not np.all(np.isfinite(arr)):
        raise DataError(f"{name}: non-finite coordinates")
    return arr


def _footprint_mask(map_xy: np.ndarray, gt_xy: np.ndarray, cell: float) -> np.ndarray:
    """Ground-truth points whose xy cell (size ``cell``) is a map column or next to one."""
    origin = np.minimum(map_xy.min(axis=0), gt_xy.min(axis=0))
    cols = np.floor((map_xy - origin) / cell).astype(np.int64) + 1
    keys = np.floor((gt_xy - origin) / cell).astype(np.int64) + 1
    width = int(max(cols[:, 1].max(), keys[:, 1].max())) + 3
    grown = [(cols[:, 0] + di) * width + cols[:, 1] + dj for di in (-1, 0, 1) for dj in (-1, 0, 1)]
    return np.isin(keys[:, 0] * width + keys[:, 1], np.unique(np.concatenate(grown)))


def map_threshold(occupancy_map, threshold: float | None = None) -> tuple[float, str]:
    """The occupancy threshold to evaluate a map at, and where it came from: the given one,
    else the one the map was made with (``metadata["occupied_threshold"]``), else the paper's
    0.5 (:data:`~undertow.occupancy.OCCUPIED_THRESHOLD`; maps written before it was recorded)."""
    if threshold is not None:
        return float(threshold), "--threshold"
    stored = occupancy_map.metadata.get("occupied_threshold")
    if stored is not None:
        return float(stored), "the map (mapping.occupied_threshold)"
    return (
        OCCUPIED_THRESHOLD,
        f"default {OCCUPIED_THRESHOLD:g} (the map does not record its threshold)",
    )


def evaluate_map(map_points, ground_truth_points, resolution: float | None = None) -> MapEvaluation:
    """C2C (map -> GT) statistics, GT -> map coverage within the map's footprint, map density.

    ``resolution`` sets the footprint cell size (default: the median spacing of map points,
    i.e. the map's grid size for cell centres).
    """
    mp = _cloud("map_points", map_points)
    gt = _cloud("ground_truth_points", ground_truth_points)
    if len(gt) == 0:
        raise DataError("ground_truth_points: empty cloud")
    if len(mp) == 0:
        nan = float("nan")
        return MapEvaluation(nan, nan, nan, nan, 0, 0)
    d, _ = cKDTree(gt).query(mp, k=1)
    if resolution is None:
        resolution = float(np.median(cKDTree(mp).query(mp, k=2)[0][:, 1])) if len(mp) > 1 else 1.0
        resolution = resolution if resolution > 0 else 1.0
    inside = _footprint_mask(mp[:, :2], gt[:, :2], resolution)
    cover = cKDTree(mp).query(gt[inside], k=1)[0] if inside.any() else np.array([np.nan])
    return MapEvaluation(
        c2c_mean_m=float(np.mean(d)),
        c2c_median_m=float(np.median(d)),
        c2c_rmse_m=float(np.sqrt(np.mean(d * d))),
        coverage_mean_m=float(np.mean(cover)),
        occupied_cells=int(len(mp)),
        ground_truth_in_footprint=int(inside.sum()),
    )
