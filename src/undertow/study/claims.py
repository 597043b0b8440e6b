"""The paper's claims as data: what each compares, how, and why it does (not) hold.

A :class:`Claim` names the paper's statement, the quantities it compares (typed paths into one
seed's result of :func:`undertow.study.pipeline.run_seed`), the comparison, and an ``explain``
function that writes why it does (not) hold from the MEASURED values: every number in an
explanation is formatted at run time from a measured or a paper value, none is typed in. A
claim that holds by construction of the simulator says so in ``by_construction``.

A quantity missing from a result is an error (:class:`MissingQuantity`, naming the claim and
the path), never a silent "not evaluable". Table I claims compare fixed wave conditions; they
apply only where the study ran those conditions (:meth:`Claim.applies`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from numbers import Real
from typing import Literal, get_args

from ..evaluation.surface import TAUS, tau_key
from ..log import G0
from . import paper

#: Placeholder in a quantity's path for the wave condition a claim is read in.
CONDITION = "<condition>"

Filter = Literal[
    "baseline", "be", "an", "proposed", "proposed+scale", "proposed+auto", "adaptive-r"
]  # fmt: skip
Axis = Literal[
    "x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "yaw_rad", "vx_m_s", "vy_m_s", "vz_m_s"
]  # fmt: skip
MapRun = Literal["csm/baseline", "csm/proposed", "bki/proposed", "adaptive/proposed"]
#: The F-score's threshold the claims read (the middle of the benchmark's thresholds).
TAU = TAUS[len(TAUS) // 2]
_TAU_TEXT = f"{TAU * 100:g} cm"
FSCORE = f"fscore_{tau_key(TAU)}"
#: The map metrics a claim can read, and how prose names them.
_MAP_METRIC_LABELS = {
    "c2c_mean_m": "C2C",
    "c2c_median_m": "median C2C",
    "occupied_cells": "occupied cells",
    "surface_rmse_m": "surface RMSE",
    FSCORE: f"F-score ({_TAU_TEXT})",
}
MapMetric = str
_AXIS_NAMES = {"x_m": "x", "y_m": "y", "z_m": "z", "roll_rad": "roll", "pitch_rad": "pitch",
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


def _checked(value: str, kind) -> str:
    if value not in get_args(kind):
        raise ValueError(f"{value!r} is not one of {get_args(kind)}")
    return value


def _unit(key: str) -> str:
    return next(unit for suffix, unit in _UNITS if key.endswith(suffix))


def rmse(variant: Filter, axis: Axis) -> Quantity:
    """RMSE along the trajectory of one filter variant (Tables II and III)."""
    path = ("localization", CONDITION, _checked(variant, Filter), "rmse", _checked(axis, Axis))
    return Quantity(f"{_AXIS_NAMES[axis]} RMSE of {variant}", path, _unit(axis))


def mean_std(variant: Filter, axis: Literal["x_m", "y_m", "yaw_rad", "vx_m_s"]) -> Quantity:
    """The filter's own standard deviation of one state, averaged along the trajectory."""
    path = ("localization", CONDITION, _checked(variant, Filter), "mean_std", axis)
    return Quantity(f"mean {_AXIS_NAMES[axis]} std of {variant}", path, _unit(axis))


def map_metric(run: MapRun, metric: MapMetric, scenario: bool = False) -> Quantity:
    """A metric of one map of Table IV (C2C, occupied cells, surface RMSE, F-score at 10 cm),
    in a wave condition or (``scenario``) in a mapping scenario."""
    if metric not in _MAP_METRIC_LABELS:
        raise ValueError(f"{metric!r} is not one of {tuple(_MAP_METRIC_LABELS)}")
    where = ("map_scenarios", CONDITION, "mapping") if scenario else ("mapping", CONDITION)
    path = (*where, _checked(run, MapRun), metric)
    unit = {"occupied_cells": "cells", FSCORE: ""}.get(metric, "m")
    return Quantity(f"{_MAP_METRIC_LABELS[metric]} of {run}", path, unit)


def scenario_quantity(label: str, *path: str, unit: str = "") -> Quantity:
    """A number of a mapping scenario's result (``path`` below ``map_scenarios/<scenario>``)."""
    return Quantity(label, ("map_scenarios", CONDITION, *path), unit)


def table1(condition: str, key: str, label: str, axis: str | None = None) -> Quantity:
    """A Table I value (characterization) of ``condition`` (``CONDITION``: the claim's)."""
    path = ("table1", condition, key) + ((axis,) if axis else ())
    where = "" if condition == CONDITION else f" ({condition})"
    return Quantity(f"{label}{where}", path, _unit(key))


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


def _because(why_not: Explain | None = None, why: Explain | None = None) -> Explain:
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


def _mm(value_m: float) -> str:
    return f"{value_m * 1e3:.2f} mm"


def _quantized_c2c(m: Measured) -> str:
    """C2C's quantization, from the measured median C2C of the maps the claim compares."""
    res = paper.GRID_RESOLUTION_M
    runs = []
    for q in (*m.claim.left, *m.claim.right):
        if q.path[-2] not in runs:
            runs.append(q.path[-2])
    medians = ", ".join(m.text(map_metric(run, "c2c_median_m")) for run in runs)
    return (
        f"C2C is quantized by the {res:g} m grid (occupied cell centres sit at fixed offsets "
        f"from a flat floor: {medians})"
    )


def _flat_floor(m: Measured) -> str:
    y = (rmse("baseline", "y_m"), rmse("proposed", "y_m"))
    return (
        f"the simulated floor is flat: a lateral pose error ({m.text(y[0])}, {m.text(y[1])}) "
        "moves map points along the floor, not away from it, and the barometer keeps the depth "
        f"error at {_mm(m[rmse('baseline', 'z_m')])} (z RMSE of baseline), so C2C cannot see "
        "the baseline's y and yaw drift (the paper's basin scan has walls and slopes that can)"
    )


def _quantized_maps(m: Measured) -> str:
    values = [m[q] for q in (*m.claim.left, *m.claim.right)]
    return (
        f"{_quantized_c2c(m)}, so the maps differ by {_mm(max(values) - min(values))} and "
        "sampling noise decides"
    )


def _headline_accuracy(m: Measured) -> str:
    a, b = m[C2C["adaptive/proposed"]], m[C2C["csm/baseline"]]
    return (
        "neither half of the paper's gain can show here: the simulated floor is flat, so the "
        "baseline's lateral (y, yaw) error moves CSM points along the floor, not away from it "
        f"(see the CSM claim), and {_quantized_c2c(m)}, so both maps sit at about "
        f"{(a + b) / 2:.3f} m and differ by {_mm(abs(a - b))}"
    )


def _drift_calibration(m: Measured) -> str:
    return (
        "the DR drift mu_b comes from the calm run's calibration; a drift that differs from it "
        "is absorbed only slowly by the bias random walk"
    )


def _heading(m: Measured) -> str:
    yaw = (rmse("be", "yaw_rad"), rmse("baseline", "yaw_rad"))
    return f"the y error follows the heading error ({m.text(yaw[0])} vs {m.text(yaw[1])})"


def _small_wave_noise(m: Measured) -> str:
    return (
        f"where the wave noise at the DVL's depth is small ({m.text(EXTRA_VX)}), the added "
        "variance is small and its effect is within the seed-to-seed spread"
    )


def _scale_left_uncorrected(m: Measured) -> str:
    return (
        f"the {m.text(SCALE)} is left uncorrected in every variant, as the paper leaves the "
        "DVL's offset, so the along-track x error stays"
    )


def _scale_corrected(m: Measured) -> str:
    return f"correcting the DVL velocities by the {m.text(SCALE)} removes the planted offset"


def _wave_speed(m: Measured) -> str:
    """Phase speed by the deep-water dispersion relation omega^2 = g k (the basin is deep for
    these waves: tanh(k h) ~ 1): c = omega / k = g / omega, omega = 2 pi f."""
    f_short, f_long = (m[FREQUENCY[c]] for c in ("wave-a0.10-f1.00", "wave-a0.10-f0.75"))
    c_short, c_long = (G0 / (2 * math.pi * f) for f in (f_short, f_long))
    return (
        "the simulator's wave noise scales with the orbital velocity at the DVL's depth (an "
        f"assumption), which for the same amplitude is larger for the longer {f_long:.2f} Hz "
        "waves because they decay less with depth (linear theory); the paper explains its "
        "opposite finding by shorter waves being faster, but by the deep-water dispersion "
        f"relation c = g / omega the {f_short:.2f} Hz waves travel at {c_short:.2f} m/s and "
        f"the {f_long:.2f} Hz waves at {c_long:.2f} m/s"
    )


def _amplitude(m: Measured) -> str:
    return (
        "the orbital velocity, and with it the simulated wave noise, grows in proportion to "
        "the wave amplitude (linear theory)"
    )


FREQUENCY = {
    c: table1(c, "frequency_hz", "measured wave frequency")
    for c in ("wave-a0.10-f1.00", "wave-a0.10-f0.75")
}
_X_OFFSET = (
    "the simulator plants a DVL scale-factor error (the DVL's configured sound speed c_set "
    "differs from the water's true c, so every velocity is scaled by c_set / c): an along-track "
    "x offset that no filter of the paper can remove, none having a scale state"
)
_SCALE_FACTOR = (
    "the planted error is a pure scale factor c_set / c (see the x error claim), which the "
    "calm-run calibration estimates and the proposed+scale variant divides out"
)


def _claim(claim_id: str, summary: str, left, comparison: Comparison, right, explain: Explain,
           by_construction: str | None = None) -> Claim:  # fmt: skip
    """A claim with the paper's words for it (:data:`undertow.study.paper.STATEMENTS`); a side
    that is one quantity may be given bare."""
    left, right = (side if isinstance(side, tuple) else (side,) for side in (left, right))
    statement = paper.STATEMENTS[claim_id]
    return Claim(claim_id, summary, statement, left, comparison, right, explain, by_construction)


LESS, MORE = Comparison("<"), Comparison(">")
VX_STD = {c: table1(c, "dvl_std_m_s", "vx std", "vx")
          for c in ("wave-a0.10-f1.00", "wave-a0.10-f0.75", "wave-a0.05-f0.75")}  # fmt: skip

#: The paper's qualitative claims on Tables II-IV, each read in every wave condition.
CLAIMS: tuple[Claim, ...] = (
    _claim("bias_estimation_reduces_yaw_error", "bias estimation removes the heading drift",
           rmse("be", "yaw_rad"), LESS, rmse("baseline", "yaw_rad"),
           _because(_drift_calibration)),
    _claim("bias_estimation_reduces_y_error", "bias estimation removes the y error",
           rmse("be", "y_m"), LESS, rmse("baseline", "y_m"), _because(_heading)),
    _claim("added_noise_reduces_velocity_error", "added noise improves the velocity error",
           rmse("an", "vx_m_s"), LESS, rmse("baseline", "vx_m_s"), _because(_small_wave_noise)),
    _claim("added_noise_widens_covariance", "added noise widens the covariance in waves",
           mean_std("an", "vx_m_s"), MORE, mean_std("baseline", "vx_m_s"), _because()),
    _claim("x_error_not_removed_by_filter",
           "the x error (the DVL's along-track offset) stays with the proposed filter",
           rmse("proposed", "x_m"), Comparison("within", 0.1), rmse("baseline", "x_m"),
           _because(why=_scale_left_uncorrected), by_construction=_X_OFFSET),
    _claim("proposed_filter_improves_csm_map", "the proposed filter improves the CSM map",
           C2C["csm/proposed"], LESS, C2C["csm/baseline"], _because(_flat_floor)),
    _claim("adaptive_bki_most_accurate",
           "adaptive BKI is the most accurate map (of CSM, BKI and adaptive BKI)",
           C2C["adaptive/proposed"], LESS, (C2C["bki/proposed"], C2C["csm/proposed"]),
           _because(_quantized_maps)),
    _claim("bki_denser_than_csm", "both BKI maps are denser than CSM",
           (CELLS["bki/proposed"], CELLS["adaptive/proposed"]), MORE, CELLS["csm/proposed"],
           _because()),
    _claim("adaptive_fewer_cells_than_bki", "adaptive BKI has fewer occupied cells than BKI",
           CELLS["adaptive/proposed"], LESS, CELLS["bki/proposed"], _because()),
    _claim("adaptive_proposed_more_accurate_than_csm_baseline",
           "Table IV headline: adaptive BKI with the proposed filter is more accurate than CSM "
           "with the baseline filter",
           C2C["adaptive/proposed"], LESS, C2C["csm/baseline"], _because(_headline_accuracy)),
    _claim("adaptive_proposed_denser_than_csm_baseline",
           "Table IV headline: adaptive BKI with the proposed filter is denser than CSM with the "
           "baseline filter",
           CELLS["adaptive/proposed"], MORE, CELLS["csm/baseline"], _because()),
    _claim("scale_calibration_removes_x_error",
           "beyond the paper: calibrating the DVL scale factor removes most of the x error",
           rmse("proposed+scale", "x_m"), Comparison("<", 0.5), rmse("proposed", "x_m"),
           _because(why=_scale_corrected), by_construction=_SCALE_FACTOR),
)  # fmt: skip

#: The paper's reading of its Table I (section IV-B), on the simulated Table I.
TABLE1_CLAIMS: tuple[Claim, ...] = (
    _claim("shorter_waves_more_dvl_noise",
           "shorter waves give larger DVL noise (vx std, same amplitude)",
           VX_STD["wave-a0.10-f1.00"], MORE, VX_STD["wave-a0.10-f0.75"], _because(_wave_speed)),
    _claim("smaller_amplitude_less_dvl_noise",
           "smaller waves give smaller DVL noise (vx std, same frequency)",
           VX_STD["wave-a0.05-f0.75"], LESS, VX_STD["wave-a0.10-f0.75"],
           _because(why=_amplitude)),
)  # fmt: skip


def _auto_close(m: Measured) -> str:
    return "the onboard estimate's condition adds nearly the noise the probe's condition adds"


def _auto_far(m: Measured) -> str:
    return (
        "the onboard estimate's condition differs from the probe's enough to change the added "
        "noise (the wave-estimate figure and table show where)"
    )


def _adaptive_r(m: Measured) -> str:
    return (
        "adaptive R learns the noise from innovations that also carry the model's own errors "
        "(the constant-velocity motion model and the bias states), so it lags a change and "
        "mixes the two"
    )


def _wave_model_wins(m: Measured) -> str:
    return "the characterized wave noise is the right R from the first measurement on"


def changing_sea_quantity(scenario: str, run: str, key: str) -> Quantity:
    """vx RMSE (``vx_m_s``) or the NEES's relative deviation from its dimension,
    |NEES / dim - 1| (``nees_deviation``), of one run of a changing-sea scenario."""
    if key == "vx_m_s":
        return Quantity(f"vx RMSE of {run}", ("changing_sea", scenario, "localization", run,
                                              "rmse", key), "m/s")  # fmt: skip
    if key == "nees_mean":
        path = ("changing_sea", scenario, "localization", run, key)
        return Quantity(f"NEES of {run}", path, "")
    path = ("changing_sea", scenario, "localization", run, key)
    return Quantity(f"NEES deviation from its dimension of {run}", path, "")


FIXED_RUNS = ("fixed calm", "fixed wave-a0.10-f1.00", "fixed wave-a0.10-f0.75",
              "fixed wave-a0.05-f0.75")  # fmt: skip


def _fixed_extra(run: str) -> Quantity | None:
    """The characterized extra vx std of a fixed run's condition (None for calm: no extra)."""
    condition = run.removeprefix("fixed ")
    if condition == "calm":
        return None
    return table1(condition, "dvl_extra_std_m_s", "characterized extra vx std", "vx")


def _changing_sea_claims(scenario: str) -> tuple[Claim, ...]:
    def q(run, key):
        return changing_sea_quantity(scenario, run, key)

    def vx_why_not(m: Measured) -> str:
        """Whether the fixed runs' vx RMSE falls or rises with their added noise, measured."""
        extra = {r: (0.0 if _fixed_extra(r) is None else m[_fixed_extra(r)]) for r in FIXED_RUNS}
        order = sorted(FIXED_RUNS, key=extra.get)
        errors = [m[q(r, "vx_m_s")] for r in order]
        trend = "falls" if errors[-1] < errors[0] else "rises"
        listed = ", ".join(f"{r.removeprefix('fixed ')} {e:.4f} m/s" for r, e in
                           zip(order, errors, strict=True))  # fmt: skip
        why = (
            "the motion model predicts this run's velocity better than the DVL does (the "
            "vehicle holds still), so over-stating R lowers the RMSE"
            if trend == "falls"
            else "the DVL's wave-frequency signal is real motion the filter should follow (the "
            "vehicle rides the orbit), so under-stating R lowers the RMSE"
        )
        return (
            f"across the fixed conditions, from the least added noise to the most, the vx RMSE "
            f"{trend} ({listed}): {why}; with the default process noise the RMSE-best R is not "
            "the true noise, which the NEES (the consistency claim) checks instead"
        )

    def nees_why_not(m: Measured) -> str:
        auto = m[q("proposed+auto", "nees_mean")]
        best = min(FIXED_RUNS, key=lambda r: m[q(r, "nees_deviation")])
        return (
            f"the pose NEES is {auto:.2f} with --wave auto and {m[q(best, 'nees_mean')]:.2f} "
            f"with {best}: far from its dimension for every run, it is set by the position and "
            "heading terms here, not by the velocity noise the wave condition changes"
        )

    def why(m: Measured) -> str:
        return "only the followed noise is right in every part of the run"

    return tuple(
        Claim(f"changing_sea_auto_beats_fixed_{key.split('_')[0]}:{scenario}",
              f"{scenario}: --wave auto beats every fixed condition ({label})",
              paper.STATEMENTS[f"changing_sea_auto_beats_fixed_{key.split('_')[0]}"],
              (q("proposed+auto", key),), LESS, tuple(q(r, key) for r in FIXED_RUNS),
              _because(why_not, why))
        for key, label, why_not in (("vx_m_s", "vx RMSE", vx_why_not),
                                    ("nees_deviation", "NEES consistency", nees_why_not))
    )  # fmt: skip


_AXES = {"y": "y_m", "yaw": "yaw_rad", "vx": "vx_m_s"}
#: Beyond the paper, read in every wave condition: the onboard wave estimate, adaptive R.
FIELD_CLAIMS: tuple[Claim, ...] = (
    *(_claim(f"wave_auto_close_to_true_{a}",
             f"--wave auto is as accurate as the probe's condition ({a} RMSE)",
             rmse("proposed+auto", axis), Comparison("within", 0.10), rmse("proposed", axis),
             _because(_auto_far, _auto_close)) for a, axis in _AXES.items()),
    *(_claim(f"wave_auto_better_than_baseline_{a}",
             f"--wave auto beats the baseline ({a} RMSE)",
             rmse("proposed+auto", axis), LESS, rmse("baseline", axis),
             _because(_auto_far, _auto_close)) for a, axis in _AXES.items()),
    _claim("wave_model_beats_adaptive_r",
           "the proposed filter beats adaptive-r (vx RMSE)",
           rmse("proposed", "vx_m_s"), LESS, rmse("adaptive-r", "vx_m_s"),
           _because(_adaptive_r, _wave_model_wins)),
)  # fmt: skip
CHANGING_SEA_CLAIMS: tuple[Claim, ...] = (
    *_changing_sea_claims("changing-sea-carriage"),
    *_changing_sea_claims("changing-sea-survey"),
)


# --- Table IV on the mapping scenarios (beyond the paper's flat basin) --------------------------


def _scenario_rmse(variant: str, axis: str) -> Quantity:
    path = ("localization", variant, "rmse", axis)
    return scenario_quantity(f"{_AXIS_NAMES[axis]} RMSE of {variant}", *path, unit=_unit(axis))


SLOPE = scenario_quantity("RMS floor slope", "floor", "rms_slope")


def _lateral(m: Measured) -> str:
    """The filters' lateral errors and the depth error they make on this floor (slope x y)."""
    y = {v: m[_scenario_rmse(v, "y_m")] for v in ("baseline", "proposed")}
    yaw = {v: m[_scenario_rmse(v, "yaw_rad")] for v in ("baseline", "proposed")}
    slope = m[SLOPE]
    return (
        f"y RMSE baseline {y['baseline']:.4f} m / proposed {y['proposed']:.4f} m (yaw "
        f"{yaw['baseline']:.4f} / {yaw['proposed']:.4f} rad); on this floor ({m.text(SLOPE)}) "
        f"a lateral error d moves the mapped depth by about slope x d: "
        f"{_mm(slope * y['baseline'])} for the baseline, {_mm(slope * y['proposed'])} for the "
        "proposed filter"
    )


def _runs(m: Measured) -> list[str]:
    runs = []
    for q in (*m.claim.left, *m.claim.right):
        run = q.path[-2]
        if run not in runs:
            runs.append(run)
    return runs


_PRECISION, _RECALL = f"precision_{tau_key(TAU)}", f"recall_{tau_key(TAU)}"


def _map_facts(m: Measured) -> str:
    """Per map compared: cells, surface RMSE and bias, precision and recall at tau."""
    parts = []
    for run in _runs(m):

        def v(key, run=run):
            return m[scenario_quantity(key, "mapping", run, key)]

        parts.append(
            f"{run}: {v('occupied_cells'):.0f} cells, surface RMSE {v('surface_rmse_m'):.4f} m "
            f"(bias {v('surface_bias_m'):+.4f} m), precision {v(_PRECISION):.3f} / recall "
            f"{v(_RECALL):.3f} at {_TAU_TEXT}, coverage {v('coverage'):.3f}"
        )
    return "; ".join(parts)


def _filter_why(m: Measured) -> str:
    return f"{_lateral(m)}; {_map_facts(m)}"


def _filter_why_not(m: Measured) -> str:
    y_base = m[_scenario_rmse("baseline", "y_m")]
    gap = m[SLOPE] * y_base
    own = m[scenario_quantity("surface RMSE", "mapping", "csm/proposed", "surface_rmse_m")]
    reason = (
        f"the baseline's lateral error makes {_mm(gap)} of depth error, less than the maps' own "
        f"surface error ({_mm(own)} for csm/proposed), so the grid, the sonar noise and the "
        "mapper decide"
        if gap < own
        else "this metric does not follow the lateral error here"
    )
    return f"{reason}: {_lateral(m)}; {_map_facts(m)}"


def _mapper_why(m: Measured) -> str:
    return _map_facts(m)


def _mapper_why_not(m: Measured) -> str:
    """Which map wins by this claim's metric instead, and the maps' facts."""
    left = m.claim.left[0]
    others = [(q, m[q]) for q in (*m.claim.left, *m.claim.right)]
    better = min if m.claim.comparison.relation == "<" else max
    best, value = better(others, key=lambda item: item[1])
    lead = (
        f"{best.label} is the best ({value:.4f})"
        if best is not left
        else f"{left.label} wins against some but not every map or seed"
    )
    return f"{lead}; {_map_facts(m)}"


_ACCURACY = ("c2c_mean_m", "surface_rmse_m", FSCORE)


def _scenario_claim(base: str, summary: str, left: tuple, right: tuple, metric: str,
                    why, why_not) -> Claim:  # fmt: skip
    """A Table IV claim (the paper's ``base``) read on the mapping scenarios by ``metric``."""
    relation = MORE if metric == FSCORE else LESS
    if metric == "occupied_cells":
        relation = MORE if "denser" in base else LESS
    lq = tuple(map_metric(r, metric, scenario=True) for r in left)
    rq = tuple(map_metric(r, metric, scenario=True) for r in right)
    label = _MAP_METRIC_LABELS[metric]
    return Claim(f"{base}:{metric}", f"{summary} ({label})", paper.STATEMENTS[base], lq,
                 relation, rq, _because(why_not, why))  # fmt: skip


def _map_scenario_claims() -> tuple[Claim, ...]:
    accuracy = (
        ("proposed_filter_improves_csm_map", "the proposed filter improves the CSM map",
         ("csm/proposed",), ("csm/baseline",), _filter_why, _filter_why_not),
        ("adaptive_bki_most_accurate", "adaptive BKI is the most accurate map",
         ("adaptive/proposed",), ("bki/proposed", "csm/proposed"), _mapper_why, _mapper_why_not),
        ("adaptive_proposed_more_accurate_than_csm_baseline",
         "headline: adaptive BKI + proposed filter beats CSM + baseline filter",
         ("adaptive/proposed",), ("csm/baseline",), _filter_why, _filter_why_not),
    )  # fmt: skip
    density = (
        ("bki_denser_than_csm", "both BKI maps are denser than CSM",
         ("bki/proposed", "adaptive/proposed"), ("csm/proposed",)),
        ("adaptive_fewer_cells_than_bki", "adaptive BKI has fewer occupied cells than BKI",
         ("adaptive/proposed",), ("bki/proposed",)),
        ("adaptive_proposed_denser_than_csm_baseline",
         "headline: adaptive BKI + proposed filter is denser than CSM + baseline filter",
         ("adaptive/proposed",), ("csm/baseline",)),
    )  # fmt: skip
    out = [
        _scenario_claim(base, summary, left, right, metric, why, why_not)
        for base, summary, left, right, why, why_not in accuracy
        for metric in _ACCURACY
    ]
    out += [
        _scenario_claim(base, summary, left, right, "occupied_cells", _mapper_why, _mapper_why_not)
        for base, summary, left, right in density
    ]
    return tuple(out)  # fmt: skip


#: The paper's Table IV claims on the mapping scenarios, each accuracy claim by C2C (the
#: paper's metric), the surface RMSE and the F-score at :data:`TAU`; read in every mapping
#: scenario.
MAP_SCENARIO_CLAIMS: tuple[Claim, ...] = _map_scenario_claims()


def evaluate_seed(result: Mapping) -> tuple[dict, dict]:
    """One seed's verdicts: ({claim: {condition or mapping scenario: bool}}, {Table I or
    changing-sea claim: bool}); claims whose conditions or scenarios the study did not run are
    left out."""
    conditions = list(result["localization"])
    claims = {
        c.id: {k: c.holds_in(result, k) for k in conditions} for c in (*CLAIMS, *FIELD_CLAIMS)
    }
    scenarios = list(result.get("map_scenarios") or {})
    claims.update({c.id: {k: c.holds_in(result, k) for k in scenarios}
                   for c in MAP_SCENARIO_CLAIMS if scenarios})  # fmt: skip
    run = list(result["table1"])
    once = {c.id: c.holds_in(result) for c in TABLE1_CLAIMS if c.applies(run)}
    once.update({c.id: c.holds_in(result) for c in CHANGING_SEA_CLAIMS if sea_applies(c, result)})
    return claims, once


def sea_applies(claim: Claim, result: Mapping) -> bool:
    """A changing-sea claim applies where its scenario ran with every fixed condition it
    compares (the study's wave conditions)."""
    scenario = claim.left[0].path[1]
    ran = result.get("changing_sea", {}).get(scenario, {}).get("localization", {})
    return all(run in ran for run in FIXED_RUNS)
