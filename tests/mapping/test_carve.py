"""The sonar's cone carved free (mapping/carve.py): the column intervals against a brute-force
cone, the two deepest kept per column whatever the pings' order, the carved cells, the intervals
through map.npz, a prior, tiles and the spill; and on a step whose first returns are computed by
brute force over the cone, the widened step narrowed back to the floor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from undertow.mapping import make_mapper
from undertow.mapping.carve import KAPPA, carved, column_interval
from undertow.mapping.config import MappingConfig
from undertow.mapping.samples import SENSOR_SONAR, Samples, expand
from undertow.mapping.surface import map_surface
from undertow.mapping.tiled import map_tiled
from undertow.occupancy import ColumnStats, OccupancyMap, deepest_two

HALF = math.radians(12.5)  # a Ping2: 25 deg full beam width
RES = 0.1


def _inside(o, v, r, x, y, z):
    """Points (x, y, z) inside the cone from o along v (half-angle HALF) nearer than r."""
    d = np.stack([x - o[0], y - o[1], z - o[2]], axis=-1)
    n = np.linalg.norm(d, axis=-1)
    return (d @ v >= n * math.cos(HALF)) & (n < r)


@pytest.mark.parametrize("tilt_deg", [0.0, 6.0, -9.0])
def test_a_column_is_free_from_where_it_enters_the_cone_to_the_range(tilt_deg):
    """(T, F) with margin 0 is the span of the column's vertical line inside the cone and nearer
    than r, found by sampling the line; columns the cone misses give F <= T."""
    o, r = np.array([0.3, -0.2, 0.5]), 2.5
    t = math.radians(tilt_deg)
    v = np.array([math.sin(t), 0.0, math.cos(t)])
    z = np.linspace(0.5, 3.5, 30001)
    met = 0
    for x in np.linspace(-0.5, 1.2, 18):
        for y in np.linspace(-0.9, 0.6, 16):
            top, bottom = column_interval(*o, *v, r, 0.0, math.cos(HALF), x, y)
            free = z[_inside(o, v, r, np.full_like(z, x), np.full_like(z, y), z)]
            if free.size < 3:
                assert bottom <= top + 2e-4
                continue
            met += 1
            assert top == pytest.approx(free.min(), abs=2e-4)
            assert bottom == pytest.approx(free.max(), abs=2e-4)
    assert met > 20
    top, bottom = column_interval(*o, 0.0, 0.0, 1.0, r, 0.07, math.cos(HALF), o[0], o[1])
    assert (top, bottom) == pytest.approx((o[2], o[2] + r - 0.07))  # on the axis: to r - margin


def _pings(x, y, depth, var=1e-6):
    """Sonar samples straight down from (x, y, 0) with ranges ``depth`` (free samples 0.1 m)."""
    n = len(x)
    origin = np.stack([x, y, np.zeros(n)], axis=1)
    direction = np.tile([0.0, 0.0, 1.0], (n, 1))
    return expand(origin, direction, np.asarray(depth, float), np.full((n, 3), var),
                  np.full(n, 0.6), np.full(n, SENSOR_SONAR), 0.1, {})  # fmt: skip


def _stats(samples, order=None):
    mapper = make_mapper("tpu", resolution=RES)
    if order is None:
        mapper.integrate(samples)
    else:
        for k in order:
            mapper.integrate(samples[k])
    return mapper.occupancy().columns


def test_each_column_keeps_its_two_deepest_intervals_whatever_the_order():
    """Three pings on one spot, ranges 2.0, 2.4, 2.2: on the axis column the intervals end at
    r - kappa sigma for 2.4 and 2.2 (sigma: pose z, the sonar's range noise); any order of the
    pings gives the same intervals; one ping alone carves nothing (F_2 NaN)."""
    pings = [_pings(np.array([0.05]), np.array([0.05]), [r]) for r in (2.0, 2.4, 2.2)]
    stats = _stats(pings, order=[0, 1, 2])
    axis = np.flatnonzero((stats.cells == [0, 0]).all(axis=1))[0]
    sigma = [math.sqrt(1e-6 + (0.01 + 0.005 * r) ** 2) for r in (2.4, 2.2)]
    f1, t1, f2, t2 = stats.carve[axis]
    assert (f1, f2) == pytest.approx([2.4 - KAPPA * sigma[0], 2.2 - KAPPA * sigma[1]], abs=1e-4)
    assert (t1, t2) == pytest.approx((0.0, 0.0), abs=1e-4)
    for order in ([2, 1, 0], [1, 0, 2]):
        np.testing.assert_array_equal(_stats(pings, order).carve, stats.carve)
    one = _stats([pings[0]], order=[0])
    assert np.isfinite(one.carve[:, 0]).any() and np.isnan(one.carve[:, 2]).all()


def test_a_cell_is_carved_only_when_every_hit_it_can_hold_is_inside_both_intervals():
    """A cell of centre z holds mass of hits within 1.5 cells of z (the three-cell lattice):
    carved when [z - 0.15, z + 0.15] lies in both intervals (0.1 m cells)."""
    intervals = np.array([[3.0, 1.0, 2.5, 1.5]] * 6 + [[3.0, 1.0, np.nan, np.nan]])
    z = np.array([1.6, 1.65, 2.0, 2.35, 2.4, 2.9, 2.0])
    expected = [False, True, True, True, False, False, False]
    np.testing.assert_array_equal(carved(z, intervals, RES), expected)


def test_merged_columns_keep_the_two_deepest_of_all_parts():
    a = ColumnStats([[0, 0], [1, 0]], np.ones((2, 4)), [[3.0, 1.0, 2.0, 1.1], [np.nan] * 4])
    b = ColumnStats([[0, 0]], np.ones((1, 4)), [[2.5, 0.9, np.nan, np.nan]])
    merged = ColumnStats.merged([a, b])
    np.testing.assert_array_equal(merged.carve[0], [3.0, 1.0, 2.5, 0.9])
    assert np.isnan(merged.carve[1]).all()
    np.testing.assert_array_equal(merged.sums[0], [2, 2, 2, 2] + [0] * 6)  # legacy: zeros
    rows = np.array([[1.0, 0.0, 4.0, 0.5], [5.0, 0.2, np.nan, np.nan], [2.0, 0.1, 3.0, 0.3]])
    np.testing.assert_array_equal(deepest_two(rows, np.zeros(3, int), 1)[0], [5, 0.2, 4, 0.5])


def _step_depth(x, y):
    """A flat floor 3 m deep with a block 0.4 m high on it over x in [2, 2.8], y in [-1, 1]."""
    block = (x >= 2.0) & (x <= 2.8) & (np.abs(y) <= 1.0)
    return np.where(block, 2.6, 3.0)


def _first_return(o):
    """The range of the nearest floor point in the cone straight down from o: over directions
    filling the cone, the nearer of the floor plane, the block's top and its two side faces."""
    a, b = np.meshgrid(np.linspace(-HALF, HALF, 81), np.linspace(-HALF, HALF, 81))
    keep = a**2 + b**2 <= HALF**2
    d = np.stack([np.tan(a[keep]), np.tan(b[keep]), np.ones(keep.sum())], axis=1)
    d /= np.linalg.norm(d, axis=1)[:, None]
    best = (3.0 - o[2]) / d[:, 2]
    t = (2.6 - o[2]) / d[:, 2]
    p = o + t[:, None] * d
    top = (p[:, 0] >= 2.0) & (p[:, 0] <= 2.8) & (np.abs(p[:, 1]) <= 1.0)
    best = np.where(top, np.minimum(best, t), best)
    for face in (2.0, 2.8):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (face - o[0]) / d[:, 0]
        z = o[2] + t * d[:, 2]
        hit = (t > 0) & (z >= 2.6) & (z <= 3.0)
        best = np.where(hit, np.minimum(best, t), best)
    return float(best.min())


@pytest.fixture(scope="module")
def step_survey():
    """Sonar pings straight down from 0.5 m deep along three lines over the block."""
    x, y = np.meshgrid(np.arange(0.5, 4.3, 0.02), [-0.3, 0.0, 0.3])
    x, y = x.reshape(-1), y.reshape(-1)
    r = np.array([_first_return(np.array([xi, yi, 0.5])) for xi, yi in zip(x, y, strict=True)])
    origin = np.stack([x, y, np.full(len(x), 0.5)], axis=1)
    direction = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    return expand(origin, direction, r, np.full((len(x), 3), 1e-6), np.full(len(x), 0.6),
                  np.full(len(x), SENSOR_SONAR), 0.1, {})  # fmt: skip


def _surface_error(occupancy):
    """The surface's depth error per column on the line y = 0.05 (x, error), every column
    (no IHO order: the step's columns are what the carve is judged on)."""
    s = map_surface(occupancy, iho_order="none")
    x, y = s.centres()
    row = np.argmin(np.abs(y[:, 0] - 0.05))
    ok = s.coverage[row]
    return x[row, ok], s.depth[row, ok] - _step_depth(x[row, ok], 0.05)


def test_the_cone_carves_the_widened_step_back_to_the_floor(step_survey):
    """First returns from the block's top while the axis is over the floor beside it widen the
    block in the map by up to the footprint (r tan 12.5 deg, ~0.55 m). Carving brings the
    columns 0.2-0.5 m beside it back to the floor (to 5 cm) and leaves the block's top and
    the far floor as they were (to a centimetre). Closer to the step no ping can carve: a cone
    that reaches that floor reaches the block's top too, so its return is the top."""
    maps = {}
    for carve in (False, True):
        mapper = make_mapper("tpu", resolution=RES, sonar_carve=carve)
        mapper.integrate(step_survey)
        maps[carve] = mapper.occupancy()
    x, plain = _surface_error(maps[False])
    x2, cut = _surface_error(maps[True])
    np.testing.assert_array_equal(x, x2)
    beside = ((x > 1.5) & (x < 1.8)) | ((x > 3.0) & (x < 3.3))
    assert beside.sum() == 6
    assert np.all(plain[beside] < -0.1)  # the step widened without carving
    assert np.all(np.abs(cut[beside]) < 0.05)
    top = (x > 2.2) & (x < 2.6)
    assert np.all(np.abs(cut[top]) < 0.05)  # the block's top is kept
    far = (x < 1.0) | (x > 3.8)
    np.testing.assert_allclose(cut[far], plain[far], atol=0.01)  # (the step's wide kernels
    assert np.all(np.abs(cut[far]) < 0.01)  # reach these columns: moved by millimetres)
    assert maps[True].metadata["sonar_carve"] and not maps[False].metadata["sonar_carve"]


def test_the_intervals_go_through_map_npz_a_prior_and_the_tiles(step_survey, tmp_path):
    """Saved and loaded, seeded into a new map, and tiled: the same intervals; a map saved
    without them (an older map) loads without them and its surface carves nothing."""
    mapper = make_mapper("tpu", resolution=RES)
    mapper.integrate(step_survey)
    occupancy = mapper.occupancy()
    assert np.isfinite(occupancy.columns.carve[:, 2]).sum() > 50
    loaded = OccupancyMap.load(occupancy.save(tmp_path / "map.npz"))
    np.testing.assert_array_equal(loaded.columns.carve, occupancy.columns.carve)
    seeded = make_mapper("tpu", resolution=RES, prior=tmp_path / "map.npz")
    np.testing.assert_array_equal(seeded.occupancy().columns.carve, occupancy.columns.carve)
    tiled = map_tiled(step_survey, MappingConfig(method="tpu", resolution=RES), 0.8,
                      scheduler="sync").map  # fmt: skip
    np.testing.assert_array_equal(tiled.columns.cells, occupancy.columns.cells)
    np.testing.assert_allclose(tiled.columns.carve, occupancy.columns.carve, rtol=1e-12)
    with np.load(tmp_path / "map.npz") as d:
        arrays = {k: d[k] for k in d.files if k != "column_carve"}
    np.savez(tmp_path / "old.npz", **arrays)
    old = OccupancyMap.load(tmp_path / "old.npz")
    assert old.columns.carve is None
    plain = make_mapper("tpu", resolution=RES, sonar_carve=False)
    plain.integrate(step_survey)
    np.testing.assert_array_equal(map_surface(old).depth, map_surface(plain.occupancy()).depth)


def test_the_intervals_spill_and_come_back_unchanged(step_survey, tmp_path):
    whole = make_mapper("tpu", resolution=RES)
    whole.integrate(step_survey)
    small = make_mapper("tpu", resolution=RES, resident_mb=0.05)
    small.columns.grid.spill.directory = tmp_path
    for part in np.array_split(np.arange(len(step_survey.origins)), 12):
        small.integrate(_rays(step_survey, part))
    assert small.columns.grid.spill.puts > 0
    np.testing.assert_array_equal(small.occupancy().columns.carve, whole.occupancy().columns.carve)


def _rays(samples: Samples, rays: np.ndarray) -> Samples:
    """The samples of some of the rays, renumbered."""
    keep = np.isin(samples.ray, rays)
    new = np.full(len(samples.origins), -1)
    new[rays] = np.arange(len(rays))
    return Samples(samples.points[keep], samples.label[keep], samples.sigma0[keep],
                   samples.pose_variance[keep], new[samples.ray[keep]], samples.sensor[keep],
                   samples.origins[rays])  # fmt: skip
