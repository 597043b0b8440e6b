"""XYZ text point sets (a bathymetric survey, a ground-truth scan): one point ``x y z`` per line.

Fields are separated by whitespace or commas; ``#`` starts a comment (a whole line or its end);
a UTF-8 byte-order mark is ignored. The file is untrusted: a line that is not exactly three
finite numbers is skipped and counted (one warning naming the first such line), and a file with
no usable point is one :class:`~undertow.errors.ReaderError` line. The reader does not interpret
the axes or the sign of z: that is the caller's (:mod:`undertow.evaluation.truth`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import ReaderError
from .collect import MALFORMED, Notes, read_regular_bytes

#: how much of a malformed line a warning quotes
_QUOTE = 40


def parse_xyz_line(text: str) -> tuple[float, float, float] | None:
    """The point of one line, None for a blank or comment line; ValueError naming the problem
    for anything else than three finite numbers."""
    text = text.split("#", 1)[0].replace(",", " ").strip()
    if not text:
        return None
    fields = text.split()
    if len(fields) != 3:
        raise ValueError(f"{len(fields)} fields, expected 3 (x y z)")
    values = tuple(float(v) for v in fields)
    if not all(math.isfinite(v) for v in values):
        raise ValueError("a non-finite value")
    return values  # type: ignore[return-value]


def read_xyz(path) -> np.ndarray:
    """(N, 3) float points of the XYZ file ``path`` (the module doc's format); malformed lines
    are skipped with one warning, no usable point is a ReaderError."""
    path = Path(path)
    data = read_regular_bytes(path)
    text = data.decode("utf-8", errors="replace").removeprefix("\ufeff")
    notes = Notes(str(path))
    rows: list[tuple[float, float, float]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        try:
            point = parse_xyz_line(line)
        except MALFORMED as exc:
            quoted = line.strip()[:_QUOTE]
            notes.add("malformed XYZ lines skipped", 1, f"line {number} {quoted!r}: {exc}")
            continue
        if point is not None:
            rows.append(point)
    if not rows:
        why = "; ".join(notes.lines()) if notes.counts else "no line holds a point"
        raise ReaderError(f"{path}: no usable x y z point in the XYZ file ({why})")
    notes.finish()
    return np.array(rows, dtype=np.float64).reshape(-1, 3)
