"""A localization folder written from a trajectory on disk, chunk by chunk: the
``trajectory.tum``, ``trajectory.npz`` and ``config.yaml`` of
:func:`~undertow.io.results.save_trajectory`, from the states of a
:class:`~undertow.trajectory_chunks.TrajectoryStore` (a log too long for memory), with the same
bytes in the TUM file and the same arrays in the npz."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from .._util.atomic import atomic_path, output_folder
from .._util.plain import to_plain
from ..rotations import rpy_to_quaternion
from ..trajectory import ORIENTATION, POSITION
from ..trajectory_chunks import CHUNK_STATES, StoredTrajectory, TrajectoryStore
from .tum import TUM_COLUMNS


def write_tum_chunks(path: str | Path, store: TrajectoryStore, chunk: int = CHUNK_STATES) -> Path:
    """The TUM file of :func:`~undertow.io.tum.write_tum` (t, position, quaternion of the
    roll-pitch-yaw; ``repr`` of each value), written ``chunk`` states at a time; atomic."""
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "w") as fh:
        fh.write(f"# {' '.join(TUM_COLUMNS)}\n")
        for k0, k1 in store.chunks(chunk):
            t, x, _ = store.read(k0, k1)
            quat = rpy_to_quaternion(x[:, ORIENTATION]).reshape(k1 - k0, 4)
            rows = np.column_stack([t, x[:, POSITION], quat])
            fh.write("".join(" ".join(repr(float(v)) for v in row) + "\n" for row in rows))
    return path


def save_stored_trajectory(trajectory: StoredTrajectory, out_dir: str | Path,
                           overwrite: bool = False) -> Path:  # fmt: skip
    """``trajectory.tum``, ``trajectory.npz`` and ``config.yaml`` of a stored trajectory, all
    at once, as :func:`~undertow.io.results.save_trajectory` writes them."""
    with output_folder(out_dir, overwrite) as out:
        write_tum_chunks(out / "trajectory.tum", trajectory.store)
        trajectory.save_npz(out / "trajectory.npz")
        (out / "config.yaml").write_text(
            yaml.safe_dump(to_plain(trajectory.metadata), sort_keys=False)
        )
    return Path(out_dir)
