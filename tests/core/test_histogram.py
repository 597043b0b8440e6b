"""The bounded-memory figures of a stream of durations against numpy on the values kept."""

import math

import numpy as np

from undertow._util.histogram import BINS, HI, LO, Durations, percentile_of


def test_figures_match_numpy_within_one_bin():
    rng = np.random.default_rng(3)
    values = rng.lognormal(np.log(2e-3), 0.8, 20_000)  # latencies around 2 ms
    d = Durations()
    for part in np.array_split(values, 7):  # added in pieces
        d.add(part)
    r = (HI / LO) ** (1.0 / BINS)
    half_bin = math.sqrt(r)
    assert d.n == values.size
    assert d.min == values.min() and d.max == values.max()
    assert math.isclose(d.mean(), values.mean(), rel_tol=1e-12)
    assert math.isclose(d.std(), values.std(), rel_tol=1e-9)
    for q in (1, 50, 99, 99.9):
        exact = np.percentile(values, q, method="inverted_cdf")  # the nearest rank
        assert exact / half_bin <= d.percentile(q) <= exact * half_bin


def test_out_of_range_and_empty_and_differences():
    d = Durations()
    assert d.summary_ms() == {"n": 0} and d.percentile(50) is None
    d.add([1e-9, np.nan, np.inf, 1e3])  # below LO, not finite (dropped), above HI
    assert d.n == 2 and d.percentile(0.1) == LO and d.percentile(100) == HI
    before = d.snapshot()
    d.add(np.full(10, 5e-3))
    between = percentile_of(d.snapshot() - before, 50)
    assert abs(between / 5e-3 - 1) < 0.006  # only what came between the two snapshots
