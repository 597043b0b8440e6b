"""TUM trajectory files (readable by evo): one line ``t tx ty tz qx qy qz qw`` per pose.

Orientation is roll, pitch, yaw (rad) in memory and a quaternion (x, y, z, w) in the file
(:func:`undertow.rotations.rpy_to_quaternion`). Numbers are written with full precision
(``repr``), lines starting with ``#`` are comments. Writes are atomic. Reading treats every line
as untrusted: a malformed line (not 8 numbers) or a pose with a non-finite time is skipped and
counted (one warning naming the first line), poses out of time order are sorted (counted); a file
with no usable pose is one :class:`~undertow.errors.ReaderError` line.

**Extended format** (undertow's, for a trajectory with its uncertainty): 14 columns per line,
the 8 above then the standard deviations of the pose, ``sx sy sz`` (m) and ``sroll spitch syaw``
(rad), in the file's own axes, taken as independent (a diagonal covariance)::

    # t tx ty tz qx qy qz qw sx sy sz sroll spitch syaw
    12.5 1.0 2.0 0.5 0.0 0.0 0.0 1.0 0.05 0.05 0.02 0.01 0.01 0.03

The first data line's field count (8 or 14) sets the file's layout (the header comment is
written for the reader, not needed); a line of another count is malformed (skipped, counted). A
non-finite or negative standard deviation is one :class:`~undertow.errors.DataError` line naming
the file and line. evo reads only the 8-column format.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._util.atomic import atomic_write_text
from ..errors import DataError, ReaderError
from ..log import GroundTruth
from ..rotations import quaternion_to_rpy, rpy_to_quaternion
from .collect import Notes, check_regular, time_order

TUM_COLUMNS = ("t", "tx", "ty", "tz", "qx", "qy", "qz", "qw")
#: the extended format's standard deviations (m, rad), after the 8 TUM columns
STD_COLUMNS = ("sx", "sy", "sz", "sroll", "spitch", "syaw")


@dataclass(frozen=True, eq=False)
class TumPoses:
    """The poses of a TUM file: times ``t`` (N,), ``position`` (N, 3), ``orientation``
    roll-pitch-yaw (N, 3), and in the extended format ``std`` (N, 6) (sx, sy, sz in m, sroll,
    spitch, syaw in rad; None for an 8-column file)."""

    t: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    std: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.size)


def write_tum(path, t, position, orientation_rpy, std=None) -> Path:
    """Write poses (N times, (N,3) positions, (N,3) roll-pitch-yaw) as a TUM file; with ``std``
    (N, 6) standard deviations, the extended 14-column format (see the module doc)."""
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
    columns = [t, position, rpy_to_quaternion(rpy).reshape(n, 4)]
    names = TUM_COLUMNS
    if std is not None:
        std = np.asarray(std, dtype=np.float64)
        if std.shape != (n, 6) or not np.all(np.isfinite(std) & (std >= 0)):
            raise DataError(f"write_tum {path}: std must be ({n}, 6), finite and >= 0")
        columns, names = [*columns, std], TUM_COLUMNS + STD_COLUMNS
    rows = np.column_stack(columns)
    text = "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in rows)
    atomic_write_text(path, f"# {' '.join(names)}\n" + text)
    return path


def read_tum(path) -> GroundTruth:
    """The poses of a TUM file: t, position (N, 3) and orientation roll-pitch-yaw (N, 3), as a
    :class:`~undertow.log.GroundTruth` (no velocity; the standard deviations of an extended
    file are left out: :func:`read_tum_poses` has them)."""
    poses = read_tum_poses(path)
    return GroundTruth(t=poses.t, position=poses.position, orientation=poses.orientation)


def read_tum_poses(path) -> TumPoses:
    """The poses of a TUM file, 8 or 14 columns (see the module doc): malformed lines and
    non-finite times skipped and counted, poses sorted by time (a non-finite position or
    quaternion is kept, as NaN)."""
    path = Path(path)
    if not path.exists():
        raise ReaderError(f"{path}: no such file")
    check_regular(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ReaderError(f"{path}: cannot read TUM file: {exc}") from None
    notes = Notes(str(path))
    arr, numbers = _parse(lines, notes)
    width = arr.shape[1]
    if width > 8:
        _check_std(path, arr[:, 8:], numbers)
    with np.errstate(all="ignore"):
        arr = arr[time_order(arr[:, 0], "poses", notes)]
        if not len(arr):
            raise ReaderError(f"{path}: no usable pose in TUM file ({'; '.join(notes.lines())})")
        rpy = quaternion_to_rpy(arr[:, 4:8])
    notes.finish()
    std = arr[:, 8:] if width > 8 else None
    return TumPoses(t=arr[:, 0], position=arr[:, 1:4], orientation=rpy, std=std)


def _parse(lines: list[str], notes: Notes) -> tuple[np.ndarray, np.ndarray]:
    """(rows (N, 8 or 14), their line numbers) of the data lines: the first data line's field
    count, 14 (the extended format) or else 8, is the layout; other lines are malformed."""
    width, rows, numbers = None, [], []
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.replace(",", " ").split()
        if width is None:
            width = len(TUM_COLUMNS + STD_COLUMNS) if len(fields) == 14 else len(TUM_COLUMNS)
        try:
            if len(fields) != width:
                names = " ".join((TUM_COLUMNS + STD_COLUMNS)[:width])
                raise ValueError(f"{len(fields)} fields, expected {width} ({names})")
            rows.append([float(v) for v in fields])
            numbers.append(number)
        except ValueError as exc:
            notes.add("malformed TUM lines skipped", 1, f"line {number}: {exc}")
    arr = np.array(rows, dtype=np.float64).reshape(-1, width or len(TUM_COLUMNS))
    return arr, np.array(numbers, dtype=np.int64)


def _check_std(path: Path, std: np.ndarray, numbers: np.ndarray) -> None:
    """One DataError line at the first row whose standard deviations are not finite and >= 0."""
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(~np.all(np.isfinite(std) & (std >= 0), axis=1))
    if bad.size:
        k = bad[0]
        values = " ".join(f"{v:g}" for v in std[k])
        raise DataError(
            f"{path}: line {numbers[k]}: standard deviations {' '.join(STD_COLUMNS)} must be "
            f"finite and >= 0, got {values}"
        )
