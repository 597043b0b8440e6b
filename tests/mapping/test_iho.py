"""A surface held to an IHO S-44 order (mapping/iho.py, surface.held_to_order): the allowed TVU
against S-44's formula worked by hand, the 1.96-sigma test at its boundary, and a tpu map whose
two survey patches have closed-form depth stds (a flat floor: s^2 = s_z^2 + s_r^2), one inside
Order 1a and one outside it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import survey_patches
from survey_patches import FLOOR, GOOD, POOR, RES, S_R, expected_std

from undertow.errors import ConfigError
from undertow.mapping.iho import IHO_ORDERS, Z95, allowed_tvu, check_order, meets_order
from undertow.mapping.surface import Surface, held_to_order, map_surface


def test_the_allowed_tvu_is_s44s_formula():
    """sqrt(a^2 + (b d)^2) with S-44 6th ed. Table 1's constants, by hand."""
    assert allowed_tvu(0.0, "1a") == pytest.approx(0.5)
    assert allowed_tvu(100.0, "1a") == pytest.approx(math.sqrt(0.25 + 1.3**2))
    assert allowed_tvu(40.0, "special") == pytest.approx(math.sqrt(0.0625 + 0.3**2))
    assert allowed_tvu(-40.0, "special") == allowed_tvu(40.0, "special")  # z up, same bound
    assert allowed_tvu(10.0, "exclusive") == pytest.approx(math.sqrt(0.15**2 + 0.075**2))
    assert allowed_tvu(10.0, "2") == pytest.approx(math.sqrt(1.0 + 0.23**2))
    assert IHO_ORDERS["1a"] == IHO_ORDERS["1b"]  # they differ in coverage, not in TVU


def test_a_depth_meets_the_order_up_to_its_95_percent_bound():
    d = np.full(5, 20.0)
    bound = allowed_tvu(20.0, "special") / Z95
    std = np.array([0.5 * bound, bound * (1 - 1e-9), bound * (1 + 1e-9), np.nan, 0.0])
    assert meets_order(d, std, "special").tolist() == [True, True, False, False, True]
    assert meets_order(d, std, "none").all()
    assert Z95 == pytest.approx(1.959964, abs=1e-6)  # the normal's two-sided 95 % quantile


@pytest.mark.parametrize("bad", ["3", "order 1", ""])
def test_an_unknown_order_is_one_line(bad):
    with pytest.raises(ConfigError, match="IHO order .*: expected one of exclusive, special"):
        check_order(bad)
    assert check_order(" Special ") == "special"


def test_held_to_order_withholds_the_failing_columns():
    depth = np.array([[3.0, 3.0, np.nan], [3.0, 3.0, 3.0]])
    std = np.array([[0.1, 0.3, np.nan], [0.2, 0.26, 0.25]])
    s = Surface(0.0, 0.0, RES, depth, std, np.isfinite(depth), "propagated")
    held = held_to_order(s, "1a")  # bound sqrt(0.25 + 0.039^2) / 1.96 = 0.2559
    assert held.coverage.tolist() == [[True, False, False], [True, False, True]]
    assert held.withheld == 2 and held.iho_order == "1a"
    assert np.isnan(held.depth[0, 1]) and np.isnan(held.std[1, 1])
    np.testing.assert_array_equal(held.depth[held.coverage], s.depth[held.coverage])
    assert held_to_order(s, "none") is s


@pytest.fixture(scope="module")
def two_patches():
    return survey_patches.two_patches()


def test_a_tpu_map_keeps_the_patch_inside_order_1a(two_patches):
    every = map_surface(two_patches, iho_order="none")
    held = map_surface(two_patches)  # the default: Order 1a
    x, y = every.centres()
    poor = every.coverage & (x > 2.0)
    good = every.coverage & (x < 2.0)
    assert poor.sum() > 50 and good.sum() > 50
    # the closed forms: flat floor, one kind of hit per patch, the range noise averaged
    np.testing.assert_allclose(every.std[good], expected_std(x[good], y[good], GOOD), rtol=1e-4)
    np.testing.assert_allclose(every.std[poor], expected_std(x[poor] - 3.0, y[poor], POOR),
                               rtol=1e-4)  # fmt: skip
    assert (every.std[good] < math.hypot(GOOD, S_R)).all()  # averaged: below one hit's
    assert Z95 * POOR > allowed_tvu(FLOOR, "1a") > Z95 * math.hypot(GOOD, S_R)
    assert held.iho_order == "1a" and every.iho_order == ""
    assert held.withheld == poor.sum()
    np.testing.assert_array_equal(held.coverage, good)
    np.testing.assert_array_equal(held.depth[good], every.depth[good])
    # Exclusive Order (0.15 m at 2 m: 0.0766 m of std) still keeps the good patch
    assert map_surface(two_patches, iho_order="exclusive").withheld == poor.sum()


def test_an_order_leaves_a_std_that_is_not_a_propagated_uncertainty_alone(two_patches):
    """The first-occupied surface's std (and a paper mapper's) is no TPU: no order applies."""
    first = map_surface(two_patches, estimator="first-occupied", iho_order="exclusive")
    assert first.iho_order == "" and first.withheld == 0
    spread = map_surface(two_patches, uncertainty="spread", iho_order="1a")
    assert spread.iho_order == "" and spread.coverage.sum() > 100
