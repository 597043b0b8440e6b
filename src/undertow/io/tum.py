"""TUM trajectory files (readable by evo): one line ``t tx ty tz qx qy qz qw`` per pose.

Orientation is roll, pitch, yaw (rad) in memory and a quaternion (x, y, z, w) in the file
(:func:`undertow.rotations.rpy_to_quaternion`). Numbers are written with full precision
(``repr``), lines starting with ``#`` are comments. Writes are atomic.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._util.atomic import atomic_path
from ..errors import DataError, ReaderError
from ..log import GroundTruth
from ..rotations import quaternion_to_rpy, rpy_to_quaternion


def _atomic_write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


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
    _atomic_write_text(path, "# t tx ty tz qx qy qz qw\n" + text)
    return path


def read_tum(path) -> GroundTruth:
    """The poses of a TUM file: t, position (N, 3) and orientation roll-pitch-yaw (N, 3), as a
    :class:`~undertow.log.GroundTruth` (a TUM file holds poses only: no velocity, no
    covariance)."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError as exc:
        raise ReaderError(f"{path}: no such file") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise ReaderError(f"{path}: cannot read TUM file: {exc}") from exc
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
            raise ReaderError(f"{path}: line {number}: malformed TUM pose ({exc})") from exc
    if not rows:
        raise ReaderError(f"{path}: no poses in TUM file")
    arr = np.array(rows)
    rpy = quaternion_to_rpy(arr[:, 4:8])
    return GroundTruth(t=arr[:, 0], position=arr[:, 1:4], orientation=rpy)
