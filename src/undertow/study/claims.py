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
from collections.abc import Mapping

from ..log import G0
from . import paper
from .claim_model import (
    C2C,
    CELLS,
    EXTRA_VX,
    LESS,
    MORE,
    SCALE,
    Claim,
    Comparison,
    Measured,
    because,
    claim,
    map_metric,
    mean_std,
    mm,
    rmse,
    table1,
)
from .scenario_claims import CHANGING_SEA_CLAIMS, FIELD_CLAIMS, FIXED_RUNS, MAP_SCENARIO_CLAIMS


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
        f"error at {mm(m[rmse('baseline', 'z_m')])} (z RMSE of baseline), so C2C cannot see "
        "the baseline's y and yaw drift (the paper's basin scan has walls and slopes that can)"
    )


def _quantized_maps(m: Measured) -> str:
    values = [m[q] for q in (*m.claim.left, *m.claim.right)]
    return (
        f"{_quantized_c2c(m)}, so the maps differ by {mm(max(values) - min(values))} and "
        "sampling noise decides"
    )


def _headline_accuracy(m: Measured) -> str:
    a, b = m[C2C["adaptive/proposed"]], m[C2C["csm/baseline"]]
    return (
        "neither half of the paper's gain can show here: the simulated floor is flat, so the "
        "baseline's lateral (y, yaw) error moves CSM points along the floor, not away from it "
        f"(see the CSM claim), and {_quantized_c2c(m)}, so both maps sit at about "
        f"{(a + b) / 2:.3f} m and differ by {mm(abs(a - b))}"
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


VX_STD = {c: table1(c, "dvl_std_m_s", "vx std", "vx")
          for c in ("wave-a0.10-f1.00", "wave-a0.10-f0.75", "wave-a0.05-f0.75")}  # fmt: skip

#: The paper's qualitative claims on Tables II-IV, each read in every wave condition.
CLAIMS: tuple[Claim, ...] = (
    claim("bias_estimation_reduces_yaw_error", "bias estimation removes the heading drift",
           rmse("be", "yaw_rad"), LESS, rmse("baseline", "yaw_rad"),
           because(_drift_calibration)),
    claim("bias_estimation_reduces_y_error", "bias estimation removes the y error",
           rmse("be", "y_m"), LESS, rmse("baseline", "y_m"), because(_heading)),
    claim("added_noise_reduces_velocity_error", "added noise improves the velocity error",
           rmse("an", "vx_m_s"), LESS, rmse("baseline", "vx_m_s"), because(_small_wave_noise)),
    claim("added_noise_widens_covariance", "added noise widens the covariance in waves",
           mean_std("an", "vx_m_s"), MORE, mean_std("baseline", "vx_m_s"), because()),
    claim("x_error_not_removed_by_filter",
           "the x error (the DVL's along-track offset) stays with the proposed filter",
           rmse("proposed", "x_m"), Comparison("within", 0.1), rmse("baseline", "x_m"),
           because(why=_scale_left_uncorrected), by_construction=_X_OFFSET),
    claim("proposed_filter_improves_csm_map", "the proposed filter improves the CSM map",
           C2C["csm/proposed"], LESS, C2C["csm/baseline"], because(_flat_floor)),
    claim("adaptive_bki_most_accurate",
           "adaptive BKI is the most accurate map (of CSM, BKI and adaptive BKI)",
           C2C["adaptive/proposed"], LESS, (C2C["bki/proposed"], C2C["csm/proposed"]),
           because(_quantized_maps)),
    claim("bki_denser_than_csm", "both BKI maps are denser than CSM",
           (CELLS["bki/proposed"], CELLS["adaptive/proposed"]), MORE, CELLS["csm/proposed"],
           because()),
    claim("adaptive_fewer_cells_than_bki", "adaptive BKI has fewer occupied cells than BKI",
           CELLS["adaptive/proposed"], LESS, CELLS["bki/proposed"], because()),
    claim("adaptive_proposed_more_accurate_than_csm_baseline",
           "Table IV headline: adaptive BKI with the proposed filter is more accurate than CSM "
           "with the baseline filter",
           C2C["adaptive/proposed"], LESS, C2C["csm/baseline"], because(_headline_accuracy)),
    claim("adaptive_proposed_denser_than_csm_baseline",
           "Table IV headline: adaptive BKI with the proposed filter is denser than CSM with the "
           "baseline filter",
           CELLS["adaptive/proposed"], MORE, CELLS["csm/baseline"], because()),
    claim("scale_calibration_removes_x_error",
           "beyond the paper: calibrating the DVL scale factor removes most of the x error",
           rmse("proposed+scale", "x_m"), Comparison("<", 0.5), rmse("proposed", "x_m"),
           because(why=_scale_corrected), by_construction=_SCALE_FACTOR),
)  # fmt: skip

#: The paper's reading of its Table I (section IV-B), on the simulated Table I.
TABLE1_CLAIMS: tuple[Claim, ...] = (
    claim("shorter_waves_more_dvl_noise",
           "shorter waves give larger DVL noise (vx std, same amplitude)",
           VX_STD["wave-a0.10-f1.00"], MORE, VX_STD["wave-a0.10-f0.75"], because(_wave_speed)),
    claim("smaller_amplitude_less_dvl_noise",
           "smaller waves give smaller DVL noise (vx std, same frequency)",
           VX_STD["wave-a0.05-f0.75"], LESS, VX_STD["wave-a0.10-f0.75"],
           because(why=_amplitude)),
)  # fmt: skip


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
