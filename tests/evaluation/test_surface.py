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


# --- calibration of the depth std ----------------------------------------------------------------


def _noisy_surface(truth, sigma, error, nx=100, ny=100, res=RES):
    """A surface over nx x ny columns whose depth is truth + error and std sigma (arrays
    (ny, nx) or scalars)."""
    x0 = y0 = res / 2
    x, y = np.meshgrid(x0 + res * np.arange(nx), y0 + res * np.arange(ny), indexing="xy")
    depth = truth(x, y) + error
    return Surface(x0, y0, res, depth, np.broadcast_to(sigma, depth.shape), np.isfinite(depth))


@pytest.mark.parametrize("scale", [0.5, 1.0, 2.0])
def test_gaussian_errors_fall_within_k_sigma_at_the_normal_shares(scale):
    """Errors e ~ N(0, s^2) with s varying by column, the map reporting a s: |e| <= k a s
    with probability erf(k a / sqrt 2), and E|e| / (a s) = sqrt(2 / pi) / a; within a 4-sigma
    binomial (and normal) tolerance over 10^4 columns."""
    plane = lambda x, y: 3.0 + 0.1 * x - 0.2 * y  # noqa: E731
    rng = np.random.default_rng(7)
    s = rng.uniform(0.02, 0.3, (100, 100))
    surface = _noisy_surface(plane, scale * s, s * rng.standard_normal(s.shape))
    e = evaluate_surface(surface, plane)
    n = e.calibrated_columns
    assert n == 10_000
    for k, got in ((1, e.within_1sigma), (2, e.within_2sigma)):
        p = math.erf(k * scale / math.sqrt(2))
        assert got == pytest.approx(p, abs=4 * math.sqrt(p * (1 - p) / n) + 1e-12)
    mean, spread = math.sqrt(2 / math.pi), math.sqrt(1 - 2 / math.pi)
    assert e.mean_abs_z == pytest.approx(mean / scale, abs=4 * spread / scale / math.sqrt(n))
    assert e.to_dict()["within_2sigma"] == e.within_2sigma


def test_calibration_counts_exactly_the_qualifying_columns():
    """Column errors |e| / s set to 0.5, 1 (on the 1-sigma edge: inside), 1.5 and 3 in known
    numbers; columns with std 0 or NaN, without truth or outside the area do not enter."""
    plane = lambda x, y: np.where(x < 3.0, 2.0, np.nan)  # noqa: E731  no truth from x = 3 m
    nx, ny = 40, 10
    ratio = np.tile(np.repeat([0.5, 1.0, 1.5, 3.0], 10), (ny, 1))  # 10 columns of each along x
    sigma = np.full((ny, nx), 0.25)  # binary fractions: the 1-sigma edge is exact
    sigma[0, 0], sigma[0, 1] = 0.0, np.nan  # two columns of ratio 0.5 that do not count
    sign = np.where(np.arange(nx) % 2, 1.0, -1.0)
    surface = _noisy_surface(plane, sigma, sign * ratio * 0.25, nx=nx, ny=ny)
    e = evaluate_surface(surface, plane)
    # x < 3 m: the first 30 columns along x (ratios 0.5, 1, 1.5), 10 rows, minus the two
    n = 30 * ny - 2
    assert e.calibrated_columns == n
    assert e.within_1sigma == pytest.approx((20 * ny - 2) / n)
    assert e.within_2sigma == 1.0
    assert e.mean_abs_z == pytest.approx((0.5 * (10 * ny - 2) + 1.0 * 10 * ny + 1.5 * 10 * ny) / n)
    # the surveyed area: only the ratio-1.5 columns (x in [2, 3) m)
    xs = 0.05 + RES * np.arange(20, 30)
    area = np.stack(np.meshgrid(xs, 0.05 + RES * np.arange(ny)), axis=-1).reshape(-1, 2)
    e = evaluate_surface(surface, plane, area=area)
    assert e.calibrated_columns == 10 * ny and e.within_1sigma == 0.0 and e.within_2sigma == 1.0
    # no std anywhere: nothing to calibrate
    flat = _noisy_surface(plane, np.nan, 0.0, nx=nx, ny=ny)
    e = evaluate_surface(flat, plane)
    assert e.calibrated_columns == 0 and math.isnan(e.within_1sigma) and math.isnan(e.mean_abs_z)


def test_hull_area_is_the_hull_of_the_mapped_cells_where_the_truth_is_defined():
    """An L of covered cells (x in [0, 2], y in [0, 1] plus x in [0, 1], y in [1, 2]) on a 3 x 3 m
    grid: the hull of their squares also holds the triangle between the arms (x + y < 3), not
    the far corner; where the truth is undefined (y > 1.5) no column is surveyed."""
    from undertow.evaluation.surface import hull_area

    def l_shape(x, y):
        return np.where(((y < 1.0) | (x < 1.0)) & (x < 2.0) & (y < 2.0), 2.0, np.nan)

    surface = _plane_surface(l_shape, nx=30, ny=30)
    flat = lambda x, y: np.full(np.shape(x), 2.0)  # noqa: E731
    x, y = surface.centres()
    for truth, defined in (
        (flat, np.ones_like(x, bool)),
        (lambda x, y: np.where(y < 1.5, 2.0, np.nan), y < 1.5),
    ):
        kept = hull_area(surface, truth)
        expected = (x < 2.0) & (y < 2.0) & (x + y < 3.0 + 1e-9) & defined  # the edge: inside
        got = np.zeros_like(expected)
        got[
            np.rint((kept[:, 1] - 0.05) / RES).astype(int),
            np.rint((kept[:, 0] - 0.05) / RES).astype(int),
        ] = True
        np.testing.assert_array_equal(got, expected)
        assert len(kept) == expected.sum()
    cloud = _grid_cloud(flat, 3.0, 3.0, spacing=0.05)
    assert len(hull_area(surface, cloud)) == ((x < 2.0) & (y < 2.0) & (x + y < 3.0 + 1e-9)).sum()
    assert hull_area(map_surface(_map([[0, 0, 5]], [0.1])), flat).shape == (0, 2)
