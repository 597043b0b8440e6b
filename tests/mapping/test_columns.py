"""The tpu map's per-column sums (mapping/columns.py) and the surface's propagated depth std
(mapping/surface.py's propagated_std): closed forms on a plane and on hits of one
uncertainty, the sums carried through map.npz and a prior, and the spread kept for maps
without them."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import DataError, ReaderError
from undertow.mapping import make_mapper
from undertow.mapping.samples import expand
from undertow.mapping.surface import Surface, evidence_surface, map_surface, propagated_std
from undertow.mapping.tpu import KERNEL_STD
from undertow.occupancy import ColumnStats, OccupancyMap

RES = 0.1


def test_on_a_plane_the_std_is_the_vertical_and_the_horizontal_uncertainty_through_the_slope():
    """s^2 = V/W + (X/W) g_x^2 + (Y/W) g_y^2 with g the plane's slope: central differences
    inside, one-sided at the edges and beside a hole, exact on a plane."""
    ny, nx, gx, gy = 6, 7, 0.3, -0.12
    j, i = np.mgrid[0:ny, 0:nx]
    x0, y0 = 2.05, -0.45  # column (20, -5)'s centre
    depth = 3.0 + gx * (x0 + RES * i) + gy * (y0 + RES * j)
    coverage = np.ones((ny, nx), bool)
    coverage[2, 3] = False  # a hole: its neighbours take one-sided differences
    depth[~coverage] = np.nan
    surface = Surface(x0, y0, RES, depth, np.full((ny, nx), 9.0), coverage)
    w = np.linspace(0.2, 1.0, ny * nx)
    var_v, var_x, var_y = 4e-4, 0.09, 0.01
    cells = np.stack([20 + i.reshape(-1), -5 + j.reshape(-1)], axis=1)
    stats = ColumnStats(cells, np.stack([w, w * var_v, w * var_x, w * var_y], axis=1))
    out = propagated_std(surface, stats)
    expected = np.sqrt(var_v + var_x * gx**2 + var_y * gy**2)
    np.testing.assert_allclose(out.std[coverage], expected, rtol=1e-9)
    assert out.std[2, 3] == 9.0  # no data: left as it was
    assert np.array_equal(out.depth, surface.depth, equal_nan=True)
    alone = Surface(x0, y0, RES, depth[:1, :1], np.full((1, 1), 9.0), coverage[:1, :1])
    assert propagated_std(alone, stats).std[0, 0] == pytest.approx(np.sqrt(var_v))  # no slope


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
    np.testing.assert_allclose(means[:, 2], (KERNEL_STD * 0.1) ** 2, rtol=1e-5)  # at l_0


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
    a = ColumnStats([[0, 0], [1, 0]], [[1, 2, 3, 4], [1, 1, 1, 1]])
    b = ColumnStats([[1, 0], [5, 5]], [[2, 2, 2, 2], [3, 3, 3, 3]])
    merged = ColumnStats.merged([a, None, b])
    np.testing.assert_array_equal(merged.cells, [[0, 0], [1, 0], [5, 5]])
    np.testing.assert_array_equal(merged.sums, [[1, 2, 3, 4], [3, 3, 3, 3], [3, 3, 3, 3]])
    with pytest.raises(DataError, match="2 columns but 1 rows"):
        ColumnStats([[0, 0], [1, 1]], [[1, 2, 3, 4]])
