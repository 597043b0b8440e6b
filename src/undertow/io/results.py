"""Result folders: written all at once (to a temporary sibling, then renamed), replaced only
when asked (see :func:`undertow._util.atomic.output_folder`)."""

from __future__ import annotations

from pathlib import Path

import yaml

from .._util.atomic import output_folder
from .._util.plain import to_plain
from ..trajectory import Trajectory
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
