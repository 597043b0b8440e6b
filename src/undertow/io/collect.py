"""Helpers shared by the readers: counted warnings and row accumulators that turn per-message
values into time-ordered :mod:`undertow.log` streams.

Every recoverable problem (NaN values, time going backwards, duplicates, invalid beams that
carried a distance) is counted in :class:`Notes`; :meth:`Notes.finish` emits one
``warnings.warn`` per kind and returns the lines stored in ``Log.metadata['warnings']``.
"""

from __future__ import annotations

import math
import os
import stat
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

from ..errors import ReaderError
from ..log import Dvl
from ..robot import A50_UNITS

#: what one malformed line, message or field of untrusted input can raise while being decoded:
#: bad values (ValueError, TypeError, KeyError, AttributeError, IndexError), numbers too large
#: for a float or infinities made integers (OverflowError), absurdly nested JSON (RecursionError)
MALFORMED = (
    ValueError,
    TypeError,
    KeyError,
    AttributeError,
    IndexError,
    OverflowError,
    RecursionError,
)

_KINDS = (
    (stat.S_ISFIFO, "a named pipe"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def check_regular(path: Path, directory_ok: bool = False) -> None:
    """ReaderError unless ``path`` is a regular file (or a directory when ``directory_ok``):
    named pipes, devices and sockets are refused before opening (reading a FIFO blocks)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise ReaderError(f"{path}: no such file or directory") from None
    except (OSError, ValueError) as exc:
        raise ReaderError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    if stat.S_ISREG(mode) or (directory_ok and stat.S_ISDIR(mode)):
        return
    kind = next((name for test, name in _KINDS if test(mode)), "an unsupported file type")
    what = "a log file or a ROS 2 bag directory" if directory_ok else "a regular file"
    raise ReaderError(f"{path}: is {kind}, not {what} (refused before opening)")


def read_regular_bytes(path: Path) -> bytes:
    """The bytes of the regular file ``path``; a missing, special (:func:`check_regular`),
    unreadable or too large file is one ReaderError line naming it."""
    if not path.exists():
        raise ReaderError(f"{path}: no such file")
    check_regular(path)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ReaderError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    except MemoryError:
        raise ReaderError(f"{path}: too large to read into memory") from None


class Notes:
    """Counted notes about recoverable problems met while reading ``source``."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.counts: Counter[str] = Counter()
        self.details: dict[str, str] = {}
        self.statements: list[str] = []

    def state(self, line: str) -> None:
        """A one-off statement of a choice made while reading (no count), e.g. the time base."""
        if line not in self.statements:
            self.statements.append(line)

    def add(self, kind: str, n: int = 1, detail: str = "") -> None:
        if n <= 0:
            return
        self.counts[kind] += n
        if detail and kind not in self.details:
            self.details[kind] = detail

    def lines(self) -> list[str]:
        """One line per statement and per kind of note: source, kind, count and the first
        occurrence."""
        lines = [f"{self.source}: {line}" for line in self.statements]
        for kind, n in self.counts.items():
            extra = f" (first: {self.details[kind]})" if kind in self.details else ""
            lines.append(f"{self.source}: {kind}: {n}{extra}")
        return lines

    def finish(self) -> list[str]:
        """Warn once per kind of note; return the messages (for ``Log.metadata['warnings']``)."""
        lines = self.lines()
        for line in lines:
            warnings.warn(line, stacklevel=3)
        return lines


def time_order(t: np.ndarray, stream: str, notes: Notes) -> np.ndarray:
    """Indices that keep finite times and sort them (stable), noting what was changed."""
    t = np.asarray(t, dtype=np.float64)
    keep = np.flatnonzero(np.isfinite(t))
    notes.add(f"{stream}: messages with a non-finite time dropped", t.size - keep.size)
    tk = t[keep]
    if tk.size > 1 and np.any(np.diff(tk) < 0):
        notes.add(
            f"{stream}: messages with time going backwards (sorted by time)",
            int(np.sum(np.diff(tk) < 0)),
        )
        keep = keep[np.argsort(tk, kind="stable")]
    return keep


def count_nan_rows(notes: Notes, stream: str, *arrays) -> None:
    """Note the rows holding a NaN in any of ``arrays`` (values kept as NaN)."""
    bad = None
    for arr in arrays:
        arr = np.asarray(arr, dtype=np.float64)
        rows = (
            np.isnan(arr.reshape(arr.shape[0], -1)).any(axis=1) if arr.size else np.zeros(0, bool)
        )
        bad = rows if bad is None else bad | rows
    if bad is not None:
        notes.add(f"{stream}: messages with NaN values (kept as NaN)", int(bad.sum()))


def beam_columns(beams, by_id: bool = True) -> tuple[list, list, list]:
    """(range, valid, velocity) of the four beam columns from (id, radial velocity, distance,
    valid) per beam: placed by A50 beam id 0..3 (``by_id``; other ids are skipped) or in order;
    a beam reported invalid has its range NaN, an absent one NaN values and valid False."""
    rng, ok, vel = [math.nan] * 4, [False] * 4, [math.nan] * 4
    for k, (bid, bvel, dist, bvalid) in enumerate(beams):
        col = int(bid) if by_id else k
        if not 0 <= col < 4:
            continue
        ok[col] = bool(bvalid)
        vel[col] = float(bvel)
        rng[col] = float(dist) if bvalid else math.nan
    return rng, ok, vel


def report_altitude(altitude) -> float:
    """The altitude kept of a report: NaN for a missing or negative one (the A50 sends -1)."""
    return float(altitude) if altitude is not None and altitude >= 0 else math.nan


class DvlRows:
    """Accumulates DVL reports (one :meth:`append` per message) and builds a :class:`Dvl`.

    Quirks applied here for every source: altitude < 0 (the A50 sends -1) -> NaN; a beam
    reported invalid -> its range NaN and ``beam_valid`` False (the row is kept); the velocity
    is kept as reported whatever its validity flag.
    """

    def __init__(self) -> None:
        self.t: list[float] = []
        self.velocity: list[tuple] = []
        self.valid: list[bool] = []
        self.fom: list[float] = []
        self.covariance: list = []
        self.altitude: list[float] = []
        self.beam_id: list = []
        self.beam_unit: list = []
        self.beam_range: list = []
        self.beam_valid: list = []
        self.beam_velocity: list = []
        self.extra: dict[str, list] = {}

    def __len__(self) -> int:
        return len(self.t)

    def append(
        self,
        t,
        velocity,
        valid,
        fom=np.nan,
        covariance=None,
        altitude=np.nan,
        beams=(),
        beam_units=None,
        **extra,
    ) -> None:
        """Add one report. ``beams``: (id, radial velocity, distance, valid) per beam; A50 beam
        ids 0..3 place the beam in that column with the A50 geometry unless ``beam_units``
        (4, 3) is given (then beams fill columns in order)."""
        ids, units = np.arange(4), A50_UNITS if beam_units is None else np.asarray(beam_units)
        rng, ok, vel = beam_columns(beams, by_id=beam_units is None)
        self.t.append(float(t))
        self.velocity.append(tuple(velocity))
        self.valid.append(bool(valid))
        self.fom.append(float(fom))
        self.covariance.append(np.full((3, 3), np.nan) if covariance is None else covariance)
        self.altitude.append(report_altitude(altitude))
        self.beam_id.append(ids)
        self.beam_unit.append(units)
        self.beam_range.append(rng)
        self.beam_valid.append(ok)
        self.beam_velocity.append(vel)
        for key, value in extra.items():
            self.extra.setdefault(key, []).append(value)

    def build(self, notes: Notes, stream: str = "dvl") -> tuple[Dvl, np.ndarray]:
        """The Dvl stream (time-ordered) and the row order used (to align ``extra``)."""
        order = time_order(np.array(self.t), stream, notes)
        if order.size == 0 and self.t:
            notes.add(f"{stream}: no message with a finite time (stream dropped)")
        velocity = np.array(self.velocity, dtype=np.float64).reshape(-1, 3)
        count_nan_rows(notes, stream, velocity)
        cov = np.array(self.covariance, dtype=np.float64).reshape(-1, 3, 3)
        dvl = Dvl(
            t=np.array(self.t)[order],
            velocity=velocity[order],
            valid=np.array(self.valid, bool)[order],
            fom=np.array(self.fom)[order],
            covariance=cov[order],
            altitude=np.array(self.altitude)[order],
            beam_id=np.array(self.beam_id, np.int64).reshape(-1, 4)[order],
            beam_unit=np.array(self.beam_unit, np.float64).reshape(-1, 4, 3)[order],
            beam_range=np.array(self.beam_range).reshape(-1, 4)[order],
            beam_valid=np.array(self.beam_valid, bool).reshape(-1, 4)[order],
            beam_velocity=np.array(self.beam_velocity).reshape(-1, 4)[order],
        )
        return dvl, order
