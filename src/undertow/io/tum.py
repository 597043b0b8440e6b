"""TUM trajectory files (readable by evo): one line ``t tx ty tz qx qy qz qw`` per pose.

Orientation is roll, pitch, yaw (rad) in memory and a quaternion (x, y, z, w) in the file
(:func:`undertow.rotations.rpy_to_quaternion`). Numbers are written with full precision
(``repr``), lines starting with ``#`` are comments. Writes are atomic. Reading treats every line
as untrusted: a malformed line (not 8 numbers) or a pose with a non-finite time is skipped and
counted (one warning naming the first line), poses out of time order are sorted (counted); a file
with no usable pose is one :class:`~undertow.errors.ReaderError` line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._util.atomic import atomic_write_text
from ..errors import DataError, ReaderError
from ..log import GroundTruth
from ..rotations import quaternion_to_rpy, rpy_to_quaternion
from .collect import Notes, check_regular, time_order


def write_tum(path, t, position, orientation_rpy) -> Path:
    """Write poses (N times, (N,3) positions, (N,3) roll-pitch-yaw) as a TUM file."""
    path = Path(path)
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    position = np.asarray(position, dtype=np.float64)
    rpy = np.asarray(orientation_rpy, dtype=np.float64)
    n = t.size
    if position.shape != (n, 3) or rpy.shape != (n, 3):
        raise DataError(
            f"write_tum {path}: expected ({n}, 3) position and orientation, got "
            f"{position.shape} and {rpy.shape}"
        )
    q = rpy_to_quaternion(rpy).reshape(n, 4)
    rows = np.column_stack([t, position, q])
    text = "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in rows)
    atomic_write_text(path, "# t tx ty tz qx qy qz qw\n" + text)
    return path


def read_tum(path) -> GroundTruth:
    """The poses of a TUM file: t, position (N, 3) and orientation roll-pitch-yaw (N, 3), as a
    :class:`~undertow.log.GroundTruth` (a TUM file holds poses only: no velocity, no
    covariance)."""
    path = Path(path)
    if not path.exists():
        raise ReaderError(f"{path}: no such file")
    check_regular(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ReaderError(f"{path}: cannot read TUM file: {exc}") from None
    notes = Notes(str(path))
    rows = []
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.replace(",", " ").split()
        try:
            if len(fields) != 8:
                raise ValueError(f"{len(fields)} fields, expected 8 (t tx ty tz qx qy qz qw)")
            rows.append([float(v) for v in fields])
        except ValueError as exc:
            notes.add("malformed TUM lines skipped", 1, f"line {number}: {exc}")
    with np.errstate(all="ignore"):
        arr = np.array(rows, dtype=np.float64).reshape(-1, 8)
        arr = arr[time_order(arr[:, 0], "poses", notes)]
        if not len(arr):
            raise ReaderError(f"{path}: no usable pose in TUM file ({'; '.join(notes.lines())})")
        rpy = quaternion_to_rpy(arr[:, 4:8])
    notes.finish()
    return GroundTruth(t=arr[:, 0], position=arr[:, 1:4], orientation=rpy)
