"""The map's implied seafloor surface and the surface metrics, on closed-form cases."""

import math

import numpy as np
import pytest

from undertow.errors import DataError
from undertow.evaluation.surface import TAUS, evaluate_surface, tau_key
from undertow.mapping.surface import Surface, map_surface, surface_from_points
from undertow.occupancy import OccupancyMap

RES = 0.1


def _map(cells, means, evidence=50.0):
    """A map whose cells have the given mean occupancies (alpha + beta = evidence)."""
    means = np.asarray(means, float)
    return OccupancyMap(np.asarray(cells), means * evidence, (1 - means) * evidence, RES,
                        1e-10, 1e-10)  # fmt: skip


def _plane_surface(depth_fn, nx=40, ny=20, x0=0.05, y0=0.05, res=RES):
    xs, ys = x0 + res * np.arange(nx), y0 + res * np.arange(ny)
    x, y = np.meshgrid(xs, ys, indexing="xy")
    depth = depth_fn(x, y)
    return Surface(x0, y0, res, depth, np.zeros_like(depth), np.isfinite(depth))


def _grid_cloud(depth_fn, x1, y1, spacing=0.025):
    xs, ys = np.arange(0, x1 + 1e-9, spacing), np.arange(0, y1 + 1e-9, spacing)
    x, y = (a.ravel() for a in np.meshgrid(xs, ys, indexing="ij"))
    return np.stack([x, y, depth_fn(x, y)], axis=1)


# --- the implied surface -----------------------------------------------------------------------


def test_one_occupied_cell_gives_its_centre_and_the_uniform_spread():
    s = map_surface(_map([[3, 4, 20]], [0.9]))
    assert s.shape == (1, 1) and s.x0 == pytest.approx(0.35) and s.y0 == pytest.approx(0.45)
    assert s.depth[0, 0] == pytest.approx(2.05)
    assert s.std[0, 0] == pytest.approx(RES / math.sqrt(12))


def test_first_occupied_depth_is_the_expectation_down_the_column():
    p = np.array([0.3, 0.8, 0.6])  # shallowest first; a gap (k = 21) carries no evidence
    z = (np.array([20, 22, 23]) + 0.5) * RES
    prob = p * np.cumprod(np.r_[1.0, 1 - p[:-1]])
    depth = np.sum(prob * z) / prob.sum()
    var = np.sum(prob * (z - depth) ** 2) / prob.sum() + RES**2 / 12
    cells = [[0, 0, 23], [0, 0, 20], [0, 0, 22]]  # order in the map does not matter
    s = map_surface(_map(cells, p[[2, 0, 1]]))
    assert s.depth[0, 0] == pytest.approx(depth) and s.std[0, 0] == pytest.approx(math.sqrt(var))
    # a floor shared by two cells sits between their centres, not on one of them
    shared = map_surface(_map([[0, 0, 20], [0, 0, 21]], [0.6, 0.6])).depth[0, 0]
    assert 2.05 < shared < 2.15


def test_a_column_with_no_cell_above_the_threshold_holds_no_data():
    s = map_surface(_map([[0, 0, 5], [2, 1, 5], [2, 1, 6]], [0.9, 0.3, 0.4]))
    assert s.shape == (2, 3) and s.coverage.sum() == 1 and s.coverage[0, 0]
    assert np.isnan(s.depth[1, 2]) and np.isnan(s.at(0.25, 0.15))
    assert map_surface(_map([[0, 0, 5]], [0.3]), threshold=0.2).coverage.all()


def test_at_is_bilinear_inside_and_nan_outside_and_over_gaps():
    s = _plane_surface(lambda x, y: 3.0 + 0.2 * x - 0.1 * y)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0.05, 3.95, 200), rng.uniform(0.05, 1.95, 200)
    assert np.allclose(s.at(x, y), 3.0 + 0.2 * x - 0.1 * y)
    assert np.isnan(s.at(-0.01, 1.0)) and np.isnan(s.at(1.0, 2.01))
    depth = s.depth.copy()
    depth[5, 10] = np.nan
    gap = Surface(s.x0, s.y0, RES, depth, s.std, np.isfinite(depth))
    assert np.isnan(gap.at(1.05, 0.55)) and np.isfinite(gap.at(1.14, 0.55))


def test_a_gridded_regular_cloud_interpolates_its_plane_exactly():
    plane = lambda x, y: 4.0 + 0.3 * x + 0.05 * y  # noqa: E731
    s = surface_from_points(_grid_cloud(plane, 2.0, 1.0), 0.025)
    x, y = np.random.default_rng(1).uniform(0, 2, 100), np.random.default_rng(2).uniform(0, 1, 100)
    assert np.allclose(s.at(x, y), plane(x, y))


# --- the metrics ---------------------------------------------------------------------------------


@pytest.mark.parametrize("d", [0.07, -0.15, 0.0])
def test_a_plane_offset_by_d(d):
    """RMSE = |d|, bias = d, and the F-score steps from 0 to 1 where tau passes |d|."""
    flat = lambda x, y: np.full(np.shape(x), 2.0)  # noqa: E731
    s = _plane_surface(lambda x, y: flat(x, y) + d)
    for truth in (flat, _grid_cloud(flat, 4.0, 2.0)):
        e = evaluate_surface(s, truth)
        assert e.surface_rmse_m == pytest.approx(abs(d)) and e.surface_bias_m == pytest.approx(d)
        for tau in TAUS:
            expected = 1.0 if tau > abs(d) else 0.0
            assert e.fscore[tau_key(tau)] == pytest.approx(expected, abs=1e-9), (truth, tau)
            assert e.precision[tau_key(tau)] == pytest.approx(expected, abs=1e-9)
    assert evaluate_surface(s, flat).coverage == 1.0


def test_a_map_missing_half_the_area():
    flat = lambda x, y: np.full(np.shape(x), 2.0)  # noqa: E731
    cloud = _grid_cloud(flat, 3.99, 1.99)  # the surveyed area: 40 x 20 columns
    half = _plane_surface(lambda x, y: np.where(x < 2.0, 2.0, np.nan))
    e = evaluate_surface(half, cloud)
    assert e.coverage == pytest.approx(0.5) and e.surveyed_columns == 800
    assert e.surface_rmse_m == pytest.approx(0.0, abs=1e-12)
    for tau in TAUS:  # recall: the covered half, plus the band within tau of its edge
        recall = (2.0 + tau) / 4.0
        assert e.precision[tau_key(tau)] == 1.0
        assert e.recall[tau_key(tau)] == pytest.approx(recall, abs=0.01)
        assert e.fscore[tau_key(tau)] == pytest.approx(2 * recall / (1 + recall), abs=0.01)
    # the same with a heightfield truth and the surveyed area given as points
    area = _grid_cloud(flat, 3.99, 1.99)[:, :2]
    e = evaluate_surface(half, flat, area=area)
    assert e.coverage == pytest.approx(0.5) and e.recall["10cm"] == pytest.approx(0.525, abs=0.01)


def test_a_tilted_plane_offset_vertically_is_closer_than_the_offset_in_3d():
    g, d = 0.5, 0.1
    plane = lambda x, y: 3.0 + g * x  # noqa: E731
    s = _plane_surface(lambda x, y: plane(x, y) + d)
    normal = d / math.sqrt(1 + g * g)  # the perpendicular distance between the planes
    e = evaluate_surface(s, plane, taus=(0.99 * normal, 1.03 * normal))
    assert e.surface_rmse_m == pytest.approx(d) and e.surface_bias_m == pytest.approx(d)
    assert list(e.precision.values()) == pytest.approx([0.0, 1.0], abs=0.02)


def test_a_lateral_shift_on_a_slope_shows_as_depth_error():
    """A map shifted by dx on a floor of slope g errs by g dx in depth (flat: not at all)."""
    g, dx = 0.2, 0.3
    plane = lambda x, y: 3.0 + g * x  # noqa: E731
    shifted = _plane_surface(lambda x, y: plane(x - dx, y))
    e = evaluate_surface(shifted, plane)
    assert e.surface_rmse_m == pytest.approx(g * dx) and e.surface_bias_m == pytest.approx(-g * dx)


def test_a_map_with_no_surface_scores_zero_and_bad_truth_is_one_error():
    empty = map_surface(_map([[0, 0, 5]], [0.1]))
    cloud = _grid_cloud(lambda x, y: np.full(np.shape(x), 2.0), 1.0, 1.0)
    e = evaluate_surface(empty, cloud)
    assert e.coverage == 0.0 and e.fscore["10cm"] == 0.0 and math.isnan(e.surface_rmse_m)
    with pytest.raises(DataError, match="ground truth"):
        evaluate_surface(empty, np.zeros((3, 2)))
    assert set(e.to_dict()) >= {"surface_rmse_m", "coverage", "fscore_5cm", "recall_20cm"}


def test_the_surface_error_figure_draws_each_map(tmp_path):
    from undertow.report.figures_map import plot_surface_error

    flat = lambda x, y: np.full(np.shape(x), 2.0)  # noqa: E731
    maps = {"offset": _plane_surface(lambda x, y: flat(x, y) + 0.05),
            "half": _plane_surface(lambda x, y: np.where(x < 2.0, 2.0, np.nan))}  # fmt: skip
    path = plot_surface_error(tmp_path / "err.png", maps, _grid_cloud(flat, 4.0, 2.0))
    assert path.is_file() and path.stat().st_size > 1000
    with pytest.raises(DataError, match="no maps"):
        plot_surface_error(tmp_path / "none.png", {}, flat)


def test_an_empty_map_has_an_empty_surface():
    s = map_surface(_map(np.zeros((0, 3), int), np.zeros(0)))
    assert s.shape == (0, 0) and np.isnan(s.at([0.0, 1.0], 0.0)).all()


def test_occupied_only_leaves_cells_below_the_threshold_out_of_the_column():
    occ = _map([[0, 0, 10], [0, 0, 20]], [0.4, 0.9])  # a doubtful cell 1 m above the floor
    assert map_surface(occ).depth[0, 0] == pytest.approx((0.4 * 1.05 + 0.6 * 0.9 * 2.05) / 0.94)
    assert map_surface(occ, occupied_only=True).depth[0, 0] == pytest.approx(2.05)
