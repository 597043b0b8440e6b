"""Result folders: written all at once (to a temporary sibling, then renamed), replaced only
when asked (see :func:`undertow._util.atomic.output_folder`)."""

from __future__ import annotations

from pathlib import Path

import yaml

from .._util.atomic import output_folder
from .._util.plain import to_plain
from ..occupancy import OccupancyMap
from ..trajectory import Trajectory
from .ply import write_map_ply
from .tum import write_tum


def save_trajectory(trajectory: Trajectory, out_dir: str | Path, overwrite: bool = False) -> Path:
    """Write ``trajectory.tum`` (evo), ``trajectory.npz`` (t, x, P) and ``config.yaml``, all
    at once (a non-empty folder is replaced only with ``overwrite``)."""
    with output_folder(out_dir, overwrite) as out:
        write_tum(out / "trajectory.tum", trajectory.t, trajectory.position, trajectory.orientation)
        trajectory.save_npz(out / "trajectory.npz")
        (out / "config.yaml").write_text(
            yaml.safe_dump(to_plain(trajectory.metadata), sort_keys=False)
        )
    return Path(out_dir)


def save_map(occupancy_map: OccupancyMap, config: dict, metadata: dict, out_dir: str | Path,
             overwrite: bool = False, *, threshold: float) -> Path:  # fmt: skip
    """Write ``map.npz``, ``map.ply`` (occupied cell centres, mean occupancy > ``threshold``,
    with mean and variance) and ``config.yaml`` (``mapping``: the mapping ``config`` the map was
    made with, ``result``: the ``metadata`` of what went into it), all at once (a non-empty
    folder is replaced only with ``overwrite``). ``occupancy_map``: an OccupancyMap, or a map
    read out part by part that writes its own (``save``, ``write_ply``: a GridOccupancy)."""
    with output_folder(out_dir, overwrite) as out:
        occupancy_map.save(out / "map.npz")
        if hasattr(occupancy_map, "write_ply"):  # a map read out part by part (GridOccupancy)
            occupancy_map.write_ply(out / "map.ply", threshold=threshold)
        else:
            write_map_ply(out / "map.ply", occupancy_map, threshold=threshold)
        doc = {"mapping": config, "result": metadata}
        (out / "config.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return Path(out_dir)
