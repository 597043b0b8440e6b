"""Aggregation over Monte Carlo seeds: Student-t intervals of the mean and claim fractions.

For the n values x_1..x_n a leaf takes over the seeds that have it,

    mean = (1/n) sum_i x_i,    s = sqrt( sum_i (x_i - mean)^2 / (n - 1) ),
    95 % interval of the mean:  mean -/+ t_{0.975, n-1} s / sqrt(n),

with t_{0.975, n-1} the 0.975 quantile of Student's t with n - 1 degrees of freedom. With n = 1,
s is undefined (``std`` is ``None``) and the interval collapses to [mean, mean]. Every number
returned is a plain float, int or ``None`` (for NaN/inf), so the result is JSON-safe.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from numbers import Real
from typing import Any

import numpy as np
from scipy import stats as _scipy_stats

from ..errors import DataError

LEAF_KEYS = ("mean", "std", "ci95_low", "ci95_high", "n")


def aggregate(results: Iterable[Mapping]) -> dict:
    """Same nesting as the per-seed dicts, each numeric leaf replaced by :func:`summarize` of it.

    A leaf is numeric when it is a real number other than a bool (bools, strings, ``None`` and
    lists are skipped; use :func:`claim_fraction` for yes/no results). A leaf missing from some
    seeds is aggregated over the seeds that have it (``n`` says how many). NaN or inf values are
    kept, so a seed that diverged shows as ``None`` statistics instead of vanishing. Raises
    :class:`DataError` if a key holds a number in one seed and a dict in another.
    """
    leaves: dict[tuple, list[float]] = {}
    nodes: set[tuple] = set()
    for result in results:
        if not isinstance(result, Mapping):
            raise DataError(f"aggregate needs one dict per seed, got {type(result).__name__}")
        _collect(result, (), leaves, nodes)
    clash = next((path for path in leaves if path in nodes), None)
    if clash is not None:
        where = "/".join(map(str, clash))
        raise DataError(f"'{where}' is a number in some seeds and a dict in others")
    out: dict = {}
    for path, values in leaves.items():
        node = out
        for key in path[:-1]:
            node = node.setdefault(key, {})
        node[path[-1]] = summarize(values)
    return out


def summarize(values: Iterable[float]) -> dict:
    """{"mean", "std", "ci95_low", "ci95_high", "n"} of the values (formulas in the module doc)."""
    x = np.asarray(list(values), dtype=float)
    n = int(x.size)
    if n == 0:
        return {"mean": None, "std": None, "ci95_low": None, "ci95_high": None, "n": 0}
    mean = float(np.mean(x))
    if n == 1:
        std, half = math.nan, 0.0
    else:
        std = float(np.std(x, ddof=1))
        half = float(_scipy_stats.t.ppf(0.975, n - 1)) * std / math.sqrt(n)
    return {
        "mean": _safe(mean),
        "std": _safe(std),
        "ci95_low": _safe(mean - half),
        "ci95_high": _safe(mean + half),
        "n": n,
    }


def claim_fraction(verdicts: Iterable[bool]) -> dict:
    """{"holds": k, "n": n, "fraction": k / n} of n per-seed verdicts, k of them true;
    ``fraction`` is ``None`` when there is no verdict (a claim whose conditions were not run)."""
    verdicts = list(verdicts)
    if any(not isinstance(v, bool | np.bool_) for v in verdicts):
        raise DataError(f"claim verdicts must be booleans, got {verdicts}")
    holds, n = int(sum(verdicts)), len(verdicts)
    return {"holds": holds, "n": n, "fraction": holds / n if n else None}


def format_cell(leaf: Mapping, decimals: int = 3) -> str:
    """``"mean [ci95_low, ci95_high]"`` of an aggregated leaf, ``"n/a"`` for missing numbers."""

    def fmt(value: Any) -> str:
        return "n/a" if value is None else f"{value:.{decimals}f}"

    return f"{fmt(leaf.get('mean'))} [{fmt(leaf.get('ci95_low'))}, {fmt(leaf.get('ci95_high'))}]"


def cell(stat: dict | None, digits: int = 3) -> str:
    """'mean' for one seed, 'mean [lo, hi]' (95 % CI of the mean) for several; '-' if absent."""
    if not stat or stat.get("mean") is None:
        return "-"
    mean = f"{stat['mean']:.{digits}f}"
    if stat.get("n", 1) > 1 and stat.get("ci95_low") is not None:
        return f"{mean} [{stat['ci95_low']:.{digits}f}, {stat['ci95_high']:.{digits}f}]"
    return mean


def _collect(node: Mapping, path: tuple, leaves: dict, nodes: set) -> None:
    for key, value in node.items():
        here = (*path, key)
        if isinstance(value, Mapping):
            nodes.add(here)
            _collect(value, here, leaves, nodes)
        elif isinstance(value, Real) and not isinstance(value, bool | np.bool_):
            leaves.setdefault(here, []).append(float(value))


def _safe(value: float) -> float | None:
    return value if math.isfinite(value) else None
