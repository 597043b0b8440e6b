"""Figures of a stream of durations in bounded memory: a day of live latencies or message
spacings must not grow a list by the sample.

:class:`Durations` keeps the count, sum, sum of squares, least and largest value exactly and the
values in a histogram with logarithmic bins: bin k covers [LO r^k, LO r^(k+1)) with
r = (HI / LO)^(1 / BINS), plus one bin below LO and one at or above HI. A percentile is the
geometric centre of the bin holding the value of that rank (the nearest-rank definition), so
its relative error is at most sqrt(r) - 1 (0.6 % with the defaults) for values in [LO, HI).
The counts can be copied (:meth:`snapshot`) and two copies subtracted for the figures of what
came between (:func:`percentile_of`).
"""

from __future__ import annotations

import math

import numpy as np

LO = 1e-6  # s: 1 us
HI = 100.0  # s
BINS = 1600  # r = 1e8 ** (1 / 1600): 1.16 % per bin


def bin_edges(lo: float = LO, hi: float = HI, bins: int = BINS) -> np.ndarray:
    """The BINS + 1 edges of the logarithmic bins."""
    return np.geomspace(lo, hi, bins + 1)


_EDGES = bin_edges()
_CENTRES = np.concatenate([[LO], np.sqrt(_EDGES[:-1] * _EDGES[1:]), [HI]])


def percentile_of(counts: np.ndarray, q: float) -> float | None:
    """The q-th percentile (nearest rank: the value of rank ceil(q/100 n)) of the values a
    histogram ``counts`` (BINS + 2 entries) holds, as its bin's geometric centre; None when
    empty."""
    counts = np.asarray(counts)
    n = int(counts.sum())
    if n == 0:
        return None
    rank = max(math.ceil(q / 100.0 * n), 1)
    k = int(np.searchsorted(np.cumsum(counts), rank))
    return float(_CENTRES[k])


class Durations:
    """``d = Durations(); d.add(values); d.summary_ms()`` (module docstring)."""

    def __init__(self) -> None:
        self.counts = np.zeros(BINS + 2, np.int64)
        self.n = 0
        self.total = 0.0
        self.total_sq = 0.0
        self.min = math.inf
        self.max = -math.inf

    def add(self, values) -> None:
        v = np.asarray(values, dtype=float).reshape(-1)
        v = v[np.isfinite(v)]
        if v.size == 0:
            return
        k = np.searchsorted(_EDGES, v, side="right")  # 0: below LO, BINS + 1: at or above HI
        np.add.at(self.counts, k, 1)
        self.n += int(v.size)
        self.total += float(v.sum())
        self.total_sq += float(np.dot(v, v))
        self.min = min(self.min, float(v.min()))
        self.max = max(self.max, float(v.max()))

    def snapshot(self) -> np.ndarray:
        return self.counts.copy()

    def percentile(self, q: float) -> float | None:
        return percentile_of(self.counts, q)

    def mean(self) -> float | None:
        return self.total / self.n if self.n else None

    def std(self) -> float | None:
        """The population standard deviation (numpy's default ddof 0)."""
        if not self.n:
            return None
        mean = self.total / self.n
        return math.sqrt(max(self.total_sq / self.n - mean * mean, 0.0))

    def summary_ms(self) -> dict:
        """n, min, median, p99 and max in ms ({"n": 0} when empty)."""
        if not self.n:
            return {"n": 0}
        return {"n": self.n, "min_ms": self.min * 1e3,
                "median_ms": self.percentile(50.0) * 1e3,
                "p99_ms": self.percentile(99.0) * 1e3, "max_ms": self.max * 1e3}  # fmt: skip
