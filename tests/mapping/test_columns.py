"""The tpu map's per-column sums (mapping/columns.py) and the surface's propagated depth std
(mapping/surface.py's propagated_std): closed forms on a plane and on hits of one
uncertainty, the sums carried through map.npz and a prior, and the spread kept for maps
without them."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import DataError, ReaderError
from undertow.mapping import make_mapper
from undertow.mapping.depth_std import propagated_std
from undertow.mapping.samples import expand
from undertow.mapping.surface import Surface, evidence_surface, map_surface
from undertow.mapping.tpu import KERNEL_STD
from undertow.occupancy import ColumnStats, OccupancyMap

RES = 0.1


def _plane_surface(gx, gy, spread):
    """A 6 x 7 plane of slopes (gx, gy) with a hole at (2, 3), its std the spread ``spread``."""
    ny, nx = 6, 7
    j, i = np.mgrid[0:ny, 0:nx]
    x0, y0 = 2.05, -0.45  # column (20, -5)'s centre
    depth = 3.0 + gx * (x0 + RES * i) + gy * (y0 + RES * j)
    coverage = np.ones((ny, nx), bool)
    coverage[2, 3] = False  # a hole: its neighbours take one-sided differences
    depth[~coverage] = np.nan
    cells = np.stack([20 + i.reshape(-1), -5 + j.reshape(-1)], axis=1)
    return Surface(x0, y0, RES, depth, np.full((ny, nx), spread), coverage), cells, coverage


def test_on_a_plane_the_std_is_the_vertical_and_the_horizontal_uncertainty_through_the_slope():
    """A map's sums of its first four (older maps): s^2 = V/W + (X/W) g_x^2 + (Y/W) g_y^2
    with g the plane's slope, central differences inside, one-sided at the edges and beside a
    hole, exact on a plane; no relief while the spread is below V / W."""
    gx, gy = 0.3, -0.12
    surface, cells, coverage = _plane_surface(gx, gy, 0.0)
    w = np.linspace(0.2, 1.0, len(cells))
    var_v, var_x, var_y = 4e-4, 0.09, 0.01
    stats = ColumnStats(cells, np.stack([w, w * var_v, w * var_x, w * var_y], axis=1))
    out = propagated_std(surface, stats)
    expected = np.sqrt(var_v + var_x * gx**2 + var_y * gy**2)
    np.testing.assert_allclose(out.std[coverage], expected, rtol=1e-9)
    assert out.std[2, 3] == 0.0  # no data: left as it was
    assert np.array_equal(out.depth, surface.depth, equal_nan=True)
    alone = Surface(surface.x0, surface.y0, RES, surface.depth[:1, :1], np.zeros((1, 1)),
                    coverage[:1, :1])  # fmt: skip
    assert propagated_std(alone, stats).std[0, 0] == pytest.approx(np.sqrt(var_v))  # no slope


def test_each_part_of_the_std_in_closed_form():
    """n hits of weight w per column, each with the pose's depth variance s_z^2, range noise
    s_r^2, a sonar's range r_s (shortfall r_s e at the mapper's e_b) and horizontal variance
    s_h^2, lying a^2 off the column's centre on average and put on cells of variance c about
    it: s^2 = s_z^2 + s_r^2 / n + r_s^2 e(beta)^2 + s_h^2 |g|^2 + max(S - c - sigma_v'^2 -
    a^2 |g|^2, 0), sigma_v'^2 the hit's variance with the shortfall of this slope."""
    gx, gy, width = 0.08, -0.05, 25.0
    e_b = 1 / np.cos(np.deg2rad(width / 2)) - 1
    beta = np.arctan(np.hypot(gx, gy))  # below b / 2: the shortfall of this slope
    s_z2, s_r2, r_s, s_h2, a2, c, n = 1e-4, 4e-4, 2.0, 0.04, 0.01, 0.003, 5
    var_v = s_z2 + s_r2 + (r_s * e_b) ** 2
    own = s_z2 + s_r2 + (r_s * (1 / np.cos(beta) - 1)) ** 2
    tilt = a2 * (gx**2 + gy**2)
    # a first returns' scatter within the mapper's a priori shortfall but beyond this slope's
    # is relief inside the footprint (the surface does not resolve it): it counts
    between = c + own + tilt + 0.5 * (var_v - own)
    cases = ((0.0, 0.0), (0.05, 0.05 - c - own - tilt), (between, 0.5 * (var_v - own)))
    for spread, relief in cases:
        surface, cells, coverage = _plane_surface(gx, gy, 0.0)
        w = np.linspace(0.2, 1.0, len(cells))
        sums = n * np.stack([w, w * var_v, w * s_h2, w * s_h2, w * s_r2, w * w * s_r2,
                             w * r_s**2, w * a2, w * a2, w * c], axis=1)  # fmt: skip
        out = propagated_std(surface, ColumnStats(cells, sums), width,
                             np.full(surface.shape, spread))  # fmt: skip
        shortfall = (r_s * (1 / np.cos(beta) - 1)) ** 2
        expected = s_z2 + s_r2 / n + shortfall + s_h2 * (gx**2 + gy**2) + relief
        np.testing.assert_allclose(out.std[coverage] ** 2, expected, rtol=1e-9)
    steep, cells, coverage = _plane_surface(0.5, 0.0, 0.0)  # atan 0.5 > b / 2: capped
    sums = n * np.stack([w, w * var_v, w * s_h2, w * s_h2, w * s_r2, w * w * s_r2,
                         w * r_s**2, w * a2, w * a2, w * c], axis=1)  # fmt: skip
    out = propagated_std(steep, ColumnStats(cells, sums), beam_width_deg=width)
    expected = s_z2 + s_r2 / n + (r_s * e_b) ** 2 + s_h2 * 0.25
    np.testing.assert_allclose(out.std[coverage] ** 2, expected, rtol=1e-9)


def _flat_floor(var, sensor=0, r=2.0):
    """Rays straight down from a grid of origins onto a flat floor at depth r, one pose
    variance (3,), one sensor."""
    xs, ys = np.meshgrid(np.arange(0.0, 1.0, 0.03), np.arange(0.0, 1.0, 0.03))
    n = xs.size
    origin = np.stack([xs.reshape(-1), ys.reshape(-1), np.zeros(n)], axis=1)
    direction = np.tile([0.0, 0.0, 1.0], (n, 1))
    return expand(origin, direction, np.full(n, r), np.tile(var, (n, 1)), np.full(n, 0.9),
                  np.full(n, sensor), 0.1, {})  # fmt: skip


def test_hits_of_one_uncertainty_give_it_back_in_every_column():
    """Whatever the weights, a column of hits with one sigma_v and one kernel spread has
    V/W = sigma_v^2 (pose z, range noise) and X/W, Y/W = (c l)^2, l = s / c clipped below
    by the base length: the kernel's spread (to float32, the grid's storage)."""
    var = np.array([0.04, 1e-6, 1e-4])
    mapper = make_mapper("tpu", resolution=RES)
    mapper.integrate(_flat_floor(var))
    stats = mapper.occupancy().columns
    assert len(stats) > 100 and np.all(stats.sums[:, 0] > 0)
    means = stats.sums[:, 1:] / stats.sums[:, :1]
    np.testing.assert_allclose(means[:, 0], 1e-4 + 0.005**2, rtol=1e-5)
    np.testing.assert_allclose(means[:, 1], 0.04, rtol=1e-5)  # sigma_x / c above l_0
    np.testing.assert_allclose(means[:, 2], 1e-6, rtol=1e-5)  # the pose's, not the kernel's
    np.testing.assert_allclose(means[:, 3], 0.005**2, rtol=1e-5)  # the range's own noise
    # sum w^2 s_r^2 / W^2 = s_r^2 / n_eff with 1 <= n_eff <= the hits the column holds
    averaged = stats.sums[:, 5] / stats.sums[:, 0] ** 2
    assert np.all(averaged <= 0.005**2 * (1 + 1e-5)) and np.all(averaged > 0.0)
    assert np.all(means[:, 5] == 0.0)  # no sonar
    # where the hits lie about the column's centre: within the sums' reach, 0.75 l
    lx, ly = 0.2 / KERNEL_STD, 0.1
    assert np.all(means[:, 6] <= (0.75 * lx) ** 2) and np.all(means[:, 7] <= (0.75 * ly) ** 2)
    assert np.median(means[:, 6]) > 4 * np.median(means[:, 7])  # the wider kernel along x


def _floor(depth_of, var):
    """DVL rays straight down from a dense grid at depth 0 onto the floor z = depth_of(x, y)."""
    xs, ys = np.meshgrid(np.arange(0.0, 2.0, 0.02), np.arange(0.0, 1.0, 0.02))
    x, y = xs.reshape(-1), ys.reshape(-1)
    origin = np.stack([x, y, np.zeros(x.size)], axis=1)
    return expand(origin, np.tile([0.0, 0.0, 1.0], (x.size, 1)), depth_of(x, y),
                  np.tile(var, (x.size, 1)), np.full(x.size, 0.9), np.zeros(x.size), 0.1,
                  {})  # fmt: skip


def test_a_plane_leaves_no_relief_and_ripples_do():
    """On a tilted plane the hits' scatter is the plane's tilt across where they lie: the
    std is the model's, sqrt(s_z^2 + s_r^2 / n_eff + s_x^2 g^2), without relief. On ripples
    of amplitude A shorter than the kernel the map averages them away, and the std grows by
    their variance, about A^2 / 2."""
    var = np.array([0.01, 0.01, 1e-4])
    g, amplitude = 0.2, 0.1

    def std_of(depth_of):
        mapper = make_mapper("tpu", resolution=RES)
        mapper.integrate(_floor(depth_of, var))
        occupancy = mapper.occupancy()
        surface = map_surface(occupancy, iho_order="none")
        x, y = surface.centres()
        inner = surface.coverage & (x > 0.5) & (x < 1.5) & (y > 0.3) & (y < 0.7)
        sums = occupancy.columns.sums
        model = 1e-4 + np.median(sums[:, 5] / sums[:, 0] ** 2)
        return surface.std[inner], model

    plane, model = std_of(lambda x, y: 2.0 + g * x)
    np.testing.assert_allclose(plane, np.sqrt(model + 0.01 * g**2), rtol=0.05)
    ripples, model = std_of(lambda x, y: 2.0 + amplitude * np.sin(2 * np.pi * x / 0.25))
    assert np.median(ripples**2 - model) == pytest.approx(amplitude**2 / 2, rel=0.3)


def test_the_sums_go_through_map_npz_and_a_prior_and_old_maps_keep_the_spread(tmp_path):
    mapper = make_mapper("tpu", resolution=RES)
    mapper.integrate(_flat_floor(np.array([0.01, 0.01, 1e-4])))
    occupancy = mapper.occupancy()
    loaded = OccupancyMap.load(occupancy.save(tmp_path / "map.npz"))
    assert np.array_equal(loaded.columns.cells, occupancy.columns.cells)
    assert np.array_equal(loaded.columns.sums, occupancy.columns.sums)
    seeded = make_mapper("tpu", resolution=RES, prior=tmp_path / "map.npz")
    seeded.integrate(_flat_floor(np.array([0.01, 0.01, 1e-4])))
    twice = seeded.occupancy().columns
    np.testing.assert_allclose(twice.sums, 2 * occupancy.columns.sums, rtol=1e-5)
    old = OccupancyMap(occupancy.cells, occupancy.alpha, occupancy.beta, RES,
                       occupancy.alpha0, occupancy.beta0, occupancy.metadata)  # fmt: skip
    spread = evidence_surface(old)
    assert np.array_equal(spread.std, map_surface(occupancy, uncertainty="spread").std,
                          equal_nan=True)  # fmt: skip
    assert (spread.std_kind, map_surface(occupancy).std_kind) == ("spread", "propagated")
    with pytest.raises(DataError, match="needs the map's column sums"):
        evidence_surface(old, uncertainty="propagated")
    with pytest.raises(DataError, match="surface uncertainty 'both'"):
        map_surface(occupancy, uncertainty="both")


def test_a_map_file_with_broken_column_sums_is_one_line_naming_it(tmp_path):
    mapper = make_mapper("tpu", resolution=RES)
    mapper.integrate(_flat_floor(np.array([0.01, 0.01, 1e-4])))
    occupancy = mapper.occupancy()
    path = occupancy.save(tmp_path / "map.npz")
    with np.load(path) as d:
        arrays = {k: d[k] for k in d.files}
    arrays["column_sums"] = arrays["column_sums"][:-1]  # one row short
    np.savez(tmp_path / "broken.npz", **arrays)
    with pytest.raises(ReaderError, match=r"broken.npz: not an undertow map \(ColumnStats"):
        OccupancyMap.load(tmp_path / "broken.npz")
    with np.load(path) as d:
        arrays = {k: d[k] for k in d.files}
    arrays["column_carve"] = arrays["column_carve"][:, :3]  # the sonar's intervals cut short
    np.savez(tmp_path / "carve.npz", **arrays)
    with pytest.raises(ReaderError, match=r"carve.npz: not an undertow map \(ColumnStats"):
        OccupancyMap.load(tmp_path / "carve.npz")


def test_column_sums_merge_column_by_column():
    a = ColumnStats([[0, 0], [1, 0]], [np.arange(1.0, 11.0), np.ones(10)])
    b = ColumnStats([[1, 0], [5, 5]], [np.full(10, 2.0), np.full(10, 3.0)])
    merged = ColumnStats.merged([a, None, b])
    np.testing.assert_array_equal(merged.cells, [[0, 0], [1, 0], [5, 5]])
    np.testing.assert_array_equal(merged.sums, [np.arange(1.0, 11.0), [3] * 10, [3] * 10])
    with pytest.raises(DataError, match="2 columns but 1 rows"):
        ColumnStats([[0, 0], [1, 1]], [[1, 2, 3, 4]])


def test_sums_without_carved_intervals_seed_a_grid_whole():
    """A prior's sums with no carved intervals (or a map's of before them) go into the column
    grid and come back: the four alpha sums, the six beta sums, no interval."""
    from undertow.mapping.columns import ColumnGrid

    grid = ColumnGrid(RES)
    sums = np.arange(1.0, 21.0).reshape(2, 10)
    grid.add_stats(ColumnStats([[3, -4], [7, 2]], sums))
    back = grid.stats()
    np.testing.assert_array_equal(back.cells, [[3, -4], [7, 2]])
    np.testing.assert_allclose(back.sums, sums, rtol=1e-6)  # float32 storage
    assert np.isnan(back.carve).all()
