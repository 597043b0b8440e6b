"""Aggregation over seeds against scipy's Student-t interval and simple counting facts."""

import json
import math

import numpy as np
import pytest
from scipy import stats as scipy_stats

from undertow.errors import DataError, UndertowError
from undertow.study.stats import aggregate, claim_fraction, format_cell, summarize


@pytest.mark.parametrize("n", [2, 3, 10, 57])
def test_interval_matches_scipy_t_interval(n):
    x = np.random.default_rng(n).normal(3.0, 2.0, size=n)
    leaf = aggregate([{"a": {"b": float(v)}} for v in x])["a"]["b"]
    low, high = scipy_stats.t.interval(0.95, n - 1, loc=x.mean(), scale=scipy_stats.sem(x))
    assert leaf["n"] == n
    assert leaf["mean"] == pytest.approx(x.mean(), rel=1e-12)
    assert leaf["std"] == pytest.approx(x.std(ddof=1), rel=1e-12)
    assert leaf["ci95_low"] == pytest.approx(low, rel=1e-10)
    assert leaf["ci95_high"] == pytest.approx(high, rel=1e-10)


def test_two_values_closed_form():
    # x = {0, 2}: mean 1, s = sqrt(2), half-width = t_{0.975,1} * sqrt(2)/sqrt(2) = 12.7062...
    leaf = summarize([0.0, 2.0])
    assert leaf["std"] == pytest.approx(math.sqrt(2))
    assert leaf["ci95_high"] - 1.0 == pytest.approx(12.706204736, rel=1e-9)


def test_constant_values_give_zero_width_interval():
    leaf = summarize([4.0] * 5)
    assert leaf == {"mean": 4.0, "std": 0.0, "ci95_low": 4.0, "ci95_high": 4.0, "n": 5}


def test_single_seed_is_json_safe():
    out = aggregate([{"rmse": {"x_m": 0.25}}])
    leaf = out["rmse"]["x_m"]
    assert leaf == {"mean": 0.25, "std": None, "ci95_low": 0.25, "ci95_high": 0.25, "n": 1}
    assert json.loads(json.dumps(out, allow_nan=False)) == out


def test_nesting_preserved_and_non_numeric_skipped():
    seeds = [
        {"seed": s, "name": "calm", "ok": True, "claims": {"c": False}, "none": None,
         "loc": {"be": {"rmse": {"x_m": 1.0 + s, "y_m": np.float32(2.0)}}, "n": np.int64(s)}}
        for s in range(4)
    ]  # fmt: skip
    out = aggregate(seeds)
    assert set(out) == {"seed", "loc"}
    assert set(out["loc"]) == {"be", "n"}
    assert set(out["loc"]["be"]["rmse"]) == {"x_m", "y_m"}
    assert out["loc"]["be"]["rmse"]["x_m"]["mean"] == pytest.approx(2.5)
    assert out["loc"]["n"]["mean"] == pytest.approx(1.5)
    for leaf in (out["seed"], out["loc"]["be"]["rmse"]["y_m"], out["loc"]["n"]):
        assert set(leaf) == {"mean", "std", "ci95_low", "ci95_high", "n"}
    json.dumps(out, allow_nan=False)


def test_partial_leaves_use_the_seeds_that_have_them():
    seeds = [{"a": 1.0, "b": {"c": 10.0}}, {"a": 3.0}, {"a": 5.0, "b": {"c": 20.0}}, {}]
    out = aggregate(seeds)
    assert out["a"]["n"] == 3 and out["a"]["mean"] == pytest.approx(3.0)
    assert out["b"]["c"]["n"] == 2 and out["b"]["c"]["mean"] == pytest.approx(15.0)
    low, high = scipy_stats.t.interval(0.95, 1, loc=15.0, scale=scipy_stats.sem([10.0, 20.0]))
    assert (out["b"]["c"]["ci95_low"], out["b"]["c"]["ci95_high"]) == pytest.approx((low, high))


def test_non_finite_values_show_as_none_not_dropped():
    leaf = aggregate([{"a": 1.0}, {"a": float("nan")}, {"a": 2.0}])["a"]
    assert leaf["n"] == 3
    assert leaf["mean"] is None and leaf["ci95_low"] is None


def test_empty_input_and_structure_clash():
    assert aggregate([]) == {}
    with pytest.raises(DataError, match="'a/b' is a number in some seeds and a dict"):
        aggregate([{"a": {"b": 1.0}}, {"a": {"b": {"c": 2.0}}}])
    with pytest.raises(UndertowError):
        aggregate([{"a": 1.0}, [1.0]])


def test_claim_fraction_counts_the_verdicts():
    assert claim_fraction([True, False, True, True]) == {"holds": 3, "n": 4, "fraction": 0.75}
    assert claim_fraction(np.array([True, False])) == {"holds": 1, "n": 2, "fraction": 0.5}
    # no verdict (a claim whose conditions were not run): no fraction
    assert claim_fraction([]) == {"holds": 0, "n": 0, "fraction": None}
    with pytest.raises(DataError, match="booleans"):  # a missing value is not a verdict
        claim_fraction([True, None])


def test_format_cell():
    assert format_cell(summarize([0.0, 2.0]), 2) == "1.00 [-11.71, 13.71]"
    assert format_cell(summarize([0.5]), 1) == "0.5 [0.5, 0.5]"
    assert format_cell(summarize([]), 3) == "n/a [n/a, n/a]"
