"""OctoMap octrees of an occupancy map, for octovis, octomap_server and ROS planners.

OctoMap (Hornung et al. 2013, "OctoMap: an efficient probabilistic 3D mapping framework based
on octrees", Autonomous Robots 34(3)) stores per leaf the log-odds
L = log(p / (1 - p)) of occupancy. We write one leaf per mapped cell with p the BKI posterior
mean E[theta_*] = alpha_* / (alpha_* + beta_*) (``eq:mean_var``), so L = log(alpha / beta).

Two file kinds, chosen by the suffix:

- ``.ot`` (full): every leaf keeps its float32 log-odds, so readers get the BKI mean back
  (to float32) and can apply their own threshold.
- ``.bt`` (binary, the compact kind every OctoMap tool reads): two bits per node,
  occupied / free only; readers set occupied leaves to the clamping maximum (p = 0.971) and
  free ones to the minimum (p = 0.1192). We classify with undertow's rule, occupied iff
  E[theta] > threshold, before writing, so the file's occupied set is the map's.

OctoMap keys are k = floor(c / res) + 2^15 per axis (16-bit), with centre
(k - 2^15 + 1/2) res: undertow's cell i lands on key i + 2^15 exactly, and a map must fit in
|i| < 2^15 cells (3.2 km at 0.1 m) around the origin.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..._util.atomic import atomic_path
from ...errors import ConfigError, DataError
from ...occupancy import OCCUPIED_THRESHOLD, OccupancyMap
from ._require import require
from .frames import cells_in_frame

#: OctoMap's key offset (tree depth 16): key = cell index + 2^15
KEY_OFFSET = 2**15
#: the suffixes OctoMap reads and what they hold
SUFFIXES = {".bt": "binary (occupied/free)", ".ot": "full (log-odds per leaf)"}
#: log-odds clamping bounds of the written tree: wide enough that the BKI mean is kept
_CLAMP = 1e-6


def write_octomap(path, occupancy_map: OccupancyMap, threshold: float = OCCUPIED_THRESHOLD,
                  frame: str = "enu") -> Path:  # fmt: skip
    """Write every mapped cell of ``occupancy_map`` as an OctoMap leaf in ``frame`` ("enu":
    x east, y north, z up, as ROS and octovis show it; "ned": undertow's axes); ``.bt`` keeps
    occupied (mean > ``threshold``) / free, ``.ot`` the log-odds of the mean. Atomic."""
    octomap = require("octomap", "OctoMap output")

    path = Path(path)
    kind = path.suffix.lower()
    if kind not in SUFFIXES:
        raise ConfigError(f"{path}: an OctoMap file ends in .bt (binary) or .ot (full)")
    cells = cells_in_frame(occupancy_map.cells, frame)
    if len(cells) and (cells.min() < -KEY_OFFSET or cells.max() >= KEY_OFFSET):
        span = KEY_OFFSET * occupancy_map.resolution
        raise DataError(
            f"{path}: the map reaches beyond OctoMap's +-{span:g} m around the origin at "
            f"{occupancy_map.resolution:g} m cells"
        )
    log_odds = np.log(occupancy_map.alpha) - np.log(occupancy_map.beta)  # log(p / (1 - p))
    tree = octomap.OcTree(occupancy_map.resolution)
    tree.setClampingThresMin(_CLAMP)
    tree.setClampingThresMax(1.0 - _CLAMP)
    if kind == ".bt":
        occupied = occupancy_map.mean > threshold
        log_odds = np.where(occupied, tree.getClampingThresMaxLog(), tree.getClampingThresMinLog())
    centres = (cells + 0.5) * occupancy_map.resolution
    for centre, value in zip(centres, log_odds.tolist(), strict=True):
        tree.updateNode(centre, 0.0, True).setLogOdds(value)
    tree.updateInnerOccupancy()
    with atomic_path(path) as tmp:
        written = (
            tree.writeBinary(str(tmp).encode()) if kind == ".bt" else tree.write(str(tmp).encode())
        )
        if not written:
            raise DataError(f"{path}: OctoMap could not write the file")
    return path
