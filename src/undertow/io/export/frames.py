"""Axes of exported clouds and octrees: undertow's NED world frame or east-north-up.

undertow's world frame is x north (along the tank), y east (right), z down, origin at the still
water surface (docs/conventions.md). GIS, LAS readers and ROS (REP 103, "Standard Units of
Measure and Coordinate Conventions") expect x east, y north, z up. Both frames are right-handed;
ENU = P NED with P = [[0, 1, 0], [1, 0, 0], [0, 0, -1]], so (e, n, u) = (y, x, -z).

On the grid, cell index i = floor(p / res) with centre (i + 1/2) res; under P the cell
(i, j, k) becomes (j, i, -k - 1), whose centre is exactly P times the old centre, so an export in
ENU keeps every cell on the grid (no resampling).
"""

from __future__ import annotations

import numpy as np

from ...errors import ConfigError

FRAMES = ("enu", "ned")


def check_frame(frame: str) -> str:
    """``frame`` if it is one of :data:`FRAMES`, else one ConfigError line."""
    if frame not in FRAMES:
        raise ConfigError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
    return frame


def cells_in_frame(cells: np.ndarray, frame: str) -> np.ndarray:
    """Integer cell indices (M, 3) of undertow's NED grid in ``frame``: (j, i, -k - 1) for
    ENU, unchanged for NED."""
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 3)
    if check_frame(frame) == "ned":
        return cells.copy()
    return np.column_stack([cells[:, 1], cells[:, 0], -cells[:, 2] - 1])


def points_in_frame(points: np.ndarray, frame: str) -> np.ndarray:
    """Points (M, 3) of undertow's NED frame in ``frame``: (y, x, -z) for ENU."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if check_frame(frame) == "ned":
        return points.copy()
    return np.column_stack([points[:, 1], points[:, 0], -points[:, 2]])
