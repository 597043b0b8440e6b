"""The vocabulary of the paper's claims: typed quantities (paths into one seed's result of
:func:`undertow.study.pipeline.run_seed`), comparisons, measured values, the :class:`Claim`
record and its builder :func:`claim` (with the paper's words for it), and the quantities the
claims read. The claims themselves are :mod:`undertow.study.claims` (the paper's tables) and
:mod:`undertow.study.scenario_claims` (the changing sea and the rough seabeds).

A quantity missing from a result is an error (:class:`MissingQuantity`, naming the claim and
the path), never a silent "not evaluable".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from numbers import Real
from typing import Literal, get_args

from ..evaluation.surface import TAUS, tau_key
from . import paper

#: Placeholder in a quantity's path for the wave condition a claim is read in.
CONDITION = "<condition>"

Filter = Literal[
    "baseline", "be", "an", "proposed", "proposed+scale", "proposed+auto", "adaptive-r",
    "proposed+recorded", "proposed+consistent",
]  # fmt: skip
Axis = Literal[
    "x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "yaw_rad", "vx_m_s", "vy_m_s", "vz_m_s"
]  # fmt: skip
MapRun = Literal[
    "csm/baseline", "csm/proposed", "bki/proposed", "adaptive/proposed", "tpu/proposed",
    "tpu/proposed+recorded", "tpu/proposed+consistent",
]  # fmt: skip
#: The F-score's threshold the claims read (the middle of the benchmark's thresholds).
TAU = TAUS[len(TAUS) // 2]
TAU_TEXT = f"{TAU * 100:g} cm"
FSCORE = f"fscore_{tau_key(TAU)}"
#: The map metrics a claim can read, and how prose names them.
MAP_METRIC_LABELS = {
    "c2c_mean_m": "C2C",
    "c2c_median_m": "median C2C",
    "occupied_cells": "occupied cells",
    "surface_rmse_m": "surface RMSE",
    FSCORE: f"F-score ({TAU_TEXT})",
    "within_1sigma": "share of the true floor within 1 sigma",
    "within_2sigma": "share of the true floor within 2 sigma",
}
MapMetric = str
AXIS_NAMES = {"x_m": "x", "y_m": "y", "z_m": "z", "roll_rad": "roll", "pitch_rad": "pitch",
               "yaw_rad": "yaw", "vx_m_s": "vx", "vy_m_s": "vy", "vz_m_s": "vz"}  # fmt: skip
_UNITS = (("_m_s", "m/s"), ("_rad", "rad"), ("_hz", "Hz"), ("_m", "m"))
#: An explanation: the measured values of a claim in, why it does (not) hold out.
Explain = Callable[["Measured"], str]


class MissingQuantity(LookupError):
    """A claim reads a quantity that the result does not hold (a bug, not a verdict)."""


@dataclass(frozen=True)
class Quantity:
    """One number of a seed's result: ``path`` from the result's top (``CONDITION`` stands for
    the condition the claim is read in), ``label`` how prose names it, ``unit`` its unit."""

    label: str
    path: tuple[str, ...]
    unit: str

    def where(self, condition: str | None) -> tuple[str, ...]:
        """The path with ``CONDITION`` replaced by ``condition``."""
        return tuple(condition if key == CONDITION else key for key in self.path)

    def read(self, result: Mapping, condition: str | None, claim: str) -> Real:
        """The value at :meth:`where` in ``result``; :class:`MissingQuantity` if absent."""
        node = result
        path = self.where(condition)
        for key in path:
            if not isinstance(node, Mapping) or key not in node:
                raise MissingQuantity(f"claim {claim!r}: the result has no {'/'.join(path)}")
            node = node[key]
        if not isinstance(node, Real) or isinstance(node, bool):
            raise MissingQuantity(f"claim {claim!r}: {'/'.join(path)} is not a number")
        return node

    def format(self, value: float) -> str:
        """``label value unit`` (cells as integers, the rest to four decimals)."""
        if self.unit == "cells":
            return f"{self.label} {value:.0f}"
        return f"{self.label} {value:.4f} {self.unit}".rstrip()


def checked(value: str, kind) -> str:
    if value not in get_args(kind):
        raise ValueError(f"{value!r} is not one of {get_args(kind)}")
    return value


def unit_of(key: str) -> str:
    return next(unit for suffix, unit in _UNITS if key.endswith(suffix))


def rmse(variant: Filter, axis: Axis) -> Quantity:
    """RMSE along the trajectory of one filter variant (Tables II and III)."""
    path = ("localization", CONDITION, checked(variant, Filter), "rmse", checked(axis, Axis))
    return Quantity(f"{AXIS_NAMES[axis]} RMSE of {variant}", path, unit_of(axis))


def mean_std(variant: Filter, axis: Literal["x_m", "y_m", "yaw_rad", "vx_m_s"]) -> Quantity:
    """The filter's own standard deviation of one state, averaged along the trajectory."""
    path = ("localization", CONDITION, checked(variant, Filter), "mean_std", axis)
    return Quantity(f"mean {AXIS_NAMES[axis]} std of {variant}", path, unit_of(axis))


def map_metric(run: MapRun, metric: MapMetric, scenario: bool = False) -> Quantity:
    """A metric of one map of Table IV (C2C, occupied cells, surface RMSE, F-score at 10 cm),
    in a wave condition or (``scenario``) in a mapping scenario."""
    if metric not in MAP_METRIC_LABELS:
        raise ValueError(f"{metric!r} is not one of {tuple(MAP_METRIC_LABELS)}")
    where = ("map_scenarios", CONDITION, "mapping") if scenario else ("mapping", CONDITION)
    path = (*where, checked(run, MapRun), metric)
    unit = {"occupied_cells": "cells", FSCORE: "", "within_1sigma": "",
            "within_2sigma": ""}.get(metric, "m")  # fmt: skip
    return Quantity(f"{MAP_METRIC_LABELS[metric]} of {run}", path, unit)


def scenario_quantity(label: str, *path: str, unit: str = "") -> Quantity:
    """A number of a mapping scenario's result (``path`` below ``map_scenarios/<scenario>``)."""
    return Quantity(label, ("map_scenarios", CONDITION, *path), unit)


def table1(condition: str, key: str, label: str, axis: str | None = None) -> Quantity:
    """A Table I value (characterization) of ``condition`` (``CONDITION``: the claim's)."""
    path = ("table1", condition, key) + ((axis,) if axis else ())
    where = "" if condition == CONDITION else f" ({condition})"
    return Quantity(f"{label}{where}", path, unit_of(key))


def calibration(key: Literal["dvl_scale_factor"], label: str) -> Quantity:
    """A value of the calm-run calibration (one per seed)."""
    return Quantity(label, ("calibration", key), "")


@dataclass(frozen=True)
class Comparison:
    """``left R right`` for every pair of values: ``"<"``: left < factor * right, ``">"``:
    left > factor * right, ``"within"``: |left - right| < factor * right."""

    relation: Literal["<", ">", "within"]
    factor: float = 1.0

    def holds(self, left: Real, right: Real) -> bool:
        scaled = right if self.factor == 1 else self.factor * right
        if self.relation == "<":
            return bool(left < scaled)
        if self.relation == ">":
            return bool(left > scaled)
        return bool(abs(left - right) < scaled)

    def describe(self) -> str:
        if self.relation == "within":
            return f"within {self.factor:.0%} of"
        return self.relation if self.factor == 1 else f"{self.relation} {self.factor:g} times"


@dataclass(frozen=True)
class Measured:
    """What an explanation reads: the mean over seeds of any quantity in one condition
    (``None`` for claims that name their conditions), and the seeds where the claim holds."""

    claim: Claim
    results: tuple[Mapping, ...]
    condition: str | None
    verdicts: tuple[bool, ...]

    @property
    def holds(self) -> int:
        return sum(self.verdicts)

    @property
    def n(self) -> int:
        return len(self.verdicts)

    def __getitem__(self, quantity: Quantity) -> float:
        values = [quantity.read(r, self.condition, self.claim.id) for r in self.results]
        return math.fsum(values) / len(values)

    def text(self, quantity: Quantity) -> str:
        return quantity.format(self[quantity])

    def compared(self) -> str:
        """The claim's quantities with their measured values, e.g. ``a 0.1 m vs b 0.2 m``."""
        return " vs ".join(self.text(q) for q in (*self.claim.left, *self.claim.right))


@dataclass(frozen=True)
class Claim:
    """One claim of the paper: ``left comparison right`` (for every pair), read per seed."""

    id: str
    summary: str  # what is tested, in words
    statement: str  # the paper's words (or what goes beyond the paper)
    left: tuple[Quantity, ...]
    comparison: Comparison
    right: tuple[Quantity, ...]
    explain: Explain
    by_construction: str | None = None

    @property
    def test(self) -> str:
        """The comparison in words, from the quantities' labels."""
        left, right = (" and ".join(q.label for q in side) for side in (self.left, self.right))
        each = "each of " if len(self.right) > 1 else ""
        return f"{left} {self.comparison.describe()} {each}{right}"

    def conditions(self) -> set[str]:
        """The wave conditions the claim names itself (Table I claims)."""
        return {q.path[1] for q in (*self.left, *self.right)} - {CONDITION}

    def applies(self, conditions_run: Sequence[str]) -> bool:
        """Whether the study ran every condition the claim names."""
        return self.conditions() <= set(conditions_run)

    def holds_in(self, result: Mapping, condition: str | None = None) -> bool:
        """The verdict in one seed's result (``condition``: where ``CONDITION`` points)."""
        left = [q.read(result, condition, self.id) for q in self.left]
        right = [q.read(result, condition, self.id) for q in self.right]
        return all(self.comparison.holds(a, b) for a in left for b in right)

    def measure(self, results: Sequence[Mapping], condition: str | None = None) -> Measured:
        """Verdicts over ``results`` and what :attr:`explain` reads."""
        verdicts = tuple(self.holds_in(r, condition) for r in results)
        return Measured(self, tuple(results), condition, verdicts)


def because(why_not: Explain | None = None, why: Explain | None = None) -> Explain:
    """An explanation: the measured comparison, then why it holds (``why``; default: as the
    paper reports) or why it does not (``why_not``) where it does not hold in every seed."""

    def explain(m: Measured) -> str:
        if m.holds == m.n:
            return f"{m.compared()}: {why(m) if why else 'as the paper reports'}"
        return f"{m.compared()}: {why_not(m) if why_not else 'not explained yet'}"

    return explain


# --- quantities the claims and explanations read ----------------------------------------------

EXTRA_VX = table1(CONDITION, "dvl_extra_std_m_s", "characterized extra vx std", "vx")
SCALE = calibration("dvl_scale_factor", "calibrated DVL scale factor")
C2C = {run: map_metric(run, "c2c_mean_m") for run in get_args(MapRun)}
CELLS = {run: map_metric(run, "occupied_cells") for run in get_args(MapRun)}


def claim(claim_id: str, summary: str, left, comparison: Comparison, right, explain: Explain,
           by_construction: str | None = None) -> Claim:  # fmt: skip
    """A claim with the paper's words for it (:data:`undertow.study.paper.STATEMENTS`); a side
    that is one quantity may be given bare."""
    left, right = (side if isinstance(side, tuple) else (side,) for side in (left, right))
    statement = paper.STATEMENTS[claim_id]
    return Claim(claim_id, summary, statement, left, comparison, right, explain, by_construction)


LESS, MORE = Comparison("<"), Comparison(">")


def mm(value_m: float) -> str:
    """A length in millimetres, two decimals (explanations)."""
    return f"{value_m * 1e3:.2f} mm"
