"""The tpu mapper's scatter straight from the rays (mapping/tpuscatter.py) against its scatter of
the written training samples (mapping/tpu.py's tpu_training and the generic product-kernel
scatter of mapping/kernels.py, the path plain Samples take): the same chunks in the same order
and the same alpha and beta, bit for bit, with pose covariance, every sensor and a wave, on one
thread and on two."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from conftest import multibeam_fan, numba_threads, same_map

from undertow.mapping import grid as grid_module
from undertow.mapping import make_mapper
from undertow.mapping.chunks import rehash
from undertow.mapping.columns import ColumnGrid
from undertow.mapping.grid import ChunkedGrid, points_extent
from undertow.mapping.kernels import MODE_PRODUCT, insert_chunks
from undertow.mapping.samples import RaySamples, Samples, expand
from undertow.mapping.threads import PARALLEL_MIN_SAMPLES
from undertow.mapping.tpu import tpu_training, wavenumbers
from undertow.mapping.tpuscatter import tpu_extent, tpu_hits, tpu_insert_chunks
from undertow.sim.waves import wavenumber

WAVE = (0.35, 0.2)  # amplitude m, frequency Hz: s_w of centimetres at these depths
DEPTH_NOISE = (0.05, 0.1)  # the filter's depth std and interval, for the swell in the depth
SETTINGS = {"resolution": 0.1, "base_length": 0.1, "max_length": 1.7,
            "range_std": (0.005, 0.01, 0.01), "range_std_fraction": 0.005,
            "sonar_beam_width_deg": 25.0}  # fmt: skip


def _fan(seed: int, pings: int = 5, beams: int = 96):
    """Multibeam fans (120 deg across track, small roll/pitch) 1.75 m over a wavy floor, a
    pose variance per ping up to 0.006 m^2, every sensor code
    (-1 unknown, 0 DVL, 1 sonar with its footprint, 2 multibeam, 3 unknown)."""
    rng = np.random.default_rng(seed)
    o, v, r, var = multibeam_fan(rng, pings, beams, seed, [6e-3, 6e-3, 1e-3])
    sensor = rng.integers(-1, 4, len(r)).astype(np.int8)
    return o, v, r, var, rng.uniform(0.5, 1.0, len(r)), sensor


def _samples(rays, written: bool):
    """The rays' samples as expand gives them (kept as rays) or written out (plain Samples,
    which the tpu mapper scatters through tpu_training)."""
    samples = expand(*rays, 0.1, {})
    assert isinstance(samples, RaySamples)
    if written:
        fields = ("points", "label", "sigma0", "pose_variance", "ray", "sensor")
        return Samples(*(getattr(samples, name) for name in fields), origins=samples.origins)
    return samples


def _map(batches, written: bool, wave=WAVE, threads: int = 1, max_length: float = 2.0,
         swell: bool = True):  # fmt: skip
    """``wave``: the waves' range noise (None: none); ``swell``: their pressure in the depth."""
    with numba_threads(threads):
        mapper = make_mapper("tpu", wave=WAVE if wave or swell else None,
                             wave_range_noise=wave is not None, wave_depth_noise=swell,
                             depth_noise=DEPTH_NOISE, max_length=max_length)  # fmt: skip
        for rays in batches:  # the grid starts small and grows in between and within batches
            mapper.integrate(_samples(rays, written))
        return mapper


@pytest.mark.parametrize(("wave", "max_length", "swell"),
                         [(WAVE, 2.0, True), (None, 2.0, False), (WAVE, 1.7, True),
                          (None, 2.0, True), (WAVE, 2.0, False)])  # fmt: skip
def test_the_rays_give_the_written_samples_map_bit_for_bit(wave, max_length, swell):
    """(A cap of 1.7 m: l / cap * cap is not always l, as it is for 2 m.)"""
    batches = [_fan(seed) for seed in range(3)]
    written = _map(batches, True, wave, max_length=max_length, swell=swell)
    rays = _map(batches, False, wave, max_length=max_length, swell=swell)
    assert written.grid.n_chunks > 64  # grown, and resumed after each growth
    assert same_map(written, rays)
    occupancy = rays.occupancy()
    assert len(occupancy) > 1000 and np.all(occupancy.alpha >= rays.alpha0)
    if wave is not None or swell:  # a wave in play: without it the map differs
        calm = _map(batches, False, None, max_length=max_length, swell=False)
        assert not same_map(rays, calm)


def test_the_column_sums_from_the_rays_are_the_written_samples_sums():
    """The per-column sums (mapping/columns.py) by the ray scatter and by the generic scatter
    of written samples: the same columns, sums and carved intervals (to rounding: the hits'
    sigma_v^2 and weights, and the written rays' directions, are formed in two places)."""
    batches = [_fan(seed) for seed in range(3)]
    written = _map(batches, True).occupancy().columns
    rays = _map(batches, False).occupancy().columns
    assert len(rays) > 1000
    np.testing.assert_array_equal(written.cells, rays.cells)
    np.testing.assert_allclose(written.sums, rays.sums, rtol=1e-9, atol=1e-300)
    assert np.isfinite(rays.carve[:, 2]).sum() > 100  # the sonar's rays carved their cones
    np.testing.assert_allclose(written.carve, rays.carve, rtol=1e-9, atol=1e-6)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one numba thread")
def test_the_rays_on_two_threads_give_the_serial_map_bit_for_bit(monkeypatch):
    """Slabs of cells on numba's threads, the chunks placed in a pass before (the path of large
    batches, forced here on small ones)."""
    batches = [_fan(seed) for seed in range(3)]
    serial = _map(batches, True)
    monkeypatch.setattr(grid_module, "RAY_PARALLEL_MIN_SAMPLES", 1)
    parallel = _map(batches, False, threads=2)
    assert same_map(serial, parallel)
    np.testing.assert_allclose(parallel.occupancy().columns.sums,
                               serial.occupancy().columns.sums, rtol=1e-9)  # fmt: skip


def test_the_hits_and_the_extent_are_the_written_training_samples():
    """Per hit: its cells' points, lengths and weights are tpu_training's rows (the cells of
    weight 0 left out there), and the extent and count are those of the written samples."""
    rays = _fan(4)
    samples = _samples(rays, False)
    hits = tpu_hits(samples.rays, wave=WAVE, **SETTINGS)
    points, label, weight, lengths = tpu_training(_samples(rays, True), wave=WAVE, **SETTINGS)
    keep = hits.w.reshape(-1) > 0
    n_free = len(samples) - len(rays[2])
    lattice = np.stack([np.repeat(hits.x, 3), np.repeat(hits.y, 3), hits.z.reshape(-1)], 1)
    assert np.array_equal(points[n_free:], lattice[keep])
    assert np.array_equal(weight[n_free:], hits.w.reshape(-1)[keep])
    cap = SETTINGS["max_length"]
    assert np.array_equal((lengths[n_free:, :2] / cap) * cap, np.repeat(hits.l, 3, 0)[keep])
    assert np.array_equal((lengths[:n_free] / cap) * cap, np.tile(hits.l_free, (n_free, 1)))
    assert np.all(label[n_free:] == 1) and np.all(label[:n_free] == 0)
    r = samples.rays
    lo, hi, finite, n = tpu_extent(r.origin, r.direction, r.rows, r.f, hits.x, hits.y, hits.z,
                                   hits.w)  # fmt: skip
    want = points_extent(points)
    assert n == len(points) and finite and np.array_equal(lo, want[0])
    assert np.array_equal(hi, want[1])


def test_the_hits_reach_is_the_largest_finite_length_the_column_sums_would_take():
    """TpuHits.reach (compiled beside the lattice) is ColumnGrid.reach of the hits' lengths,
    a ray whose variance is not finite left out (expand refuses one; tpu_hits takes any
    rays); and the settings' constants, remembered, change with the settings."""
    o, v, r, var, sig, sensor = _fan(5)
    var[::7] *= 40.0  # lengths above l_0 and up to the cap
    rays = expand(o, v, r, var, sig, sensor, 0.1, {}).rays
    broken = rays.var.copy()
    broken[-1, 0] = np.nan  # the last: a NaN there would stay in a running max
    hits = tpu_hits(rays._replace(var=broken), **SETTINGS)
    assert not np.isfinite(hits.l).all() and hits.reach > SETTINGS["base_length"]
    assert hits.reach == ColumnGrid.reach(hits.l) == np.nanmax(hits.l)
    shorter = tpu_hits(rays, **{**SETTINGS, "max_length": 0.2})
    assert shorter.reach == ColumnGrid.reach(shorter.l) <= 0.2 < hits.reach


def test_the_compiledwavenumbers_arewavenumbers_bit_for_bit():
    depths = np.array([0.1, 0.7, 6.3, 6.8, 40.0, 400.0])
    omega = 2.0 * np.pi * 0.2
    want = np.array([float(wavenumber(omega, float(h))) for h in depths])
    assert np.array_equal(wavenumbers(omega, depths), want)


def test_the_chunks_are_placed_in_the_order_the_generic_pass_places_them():
    """tpu_insert_chunks (the pass before the slab threads) against kernels.insert_chunks of
    the written samples in one pass over all (into arrays of its own, from 16 chunks, grown
    and resumed when full, mid-ray too; written here rather than through ChunkedGrid, whose
    place is under test): rays in every direction, free samples every 0.1 m, and hits' cells whose
    supports span up to four chunks across the floor (one cell vertically, as every tpu
    sample's), far apart so that most chunks of a box are new (the order within a box counts).
    Then ChunkedGrid.place, which for many rows or several parts finds each part's new chunks
    in a table of its own and inserts them part after part (a few rows: the one pass). The same
    chunks in the same order."""
    rng = np.random.default_rng(7)
    n, res, f, cap = 300, 0.1, 0.1, 2.0
    origin = rng.uniform(-30.0, 30.0, (n, 3))
    direction = rng.normal(0.0, 1.0, (n, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    rows = np.concatenate([[0], np.cumsum(rng.integers(0, 40, n))])
    l_free = np.array([0.1, 0.1, 0.05])
    hx, hy = rng.uniform(-30.0, 30.0, n), rng.uniform(-30.0, 30.0, n)
    hz = rng.uniform(-30.0, 30.0, (n, 1)) + np.array([-res, 0.0, res])
    hl = rng.uniform(0.0, 1.5, (n, 2))
    hw = rng.uniform(0.0, 1.0, (n, 3)) * (rng.random((n, 3)) > 0.2)
    k = np.arange(rows[-1]) - np.repeat(rows[:-1], np.diff(rows))
    ray = np.repeat(np.arange(n), np.diff(rows))
    free = origin[ray] + (k * f)[:, None] * direction[ray]
    keep = hw.reshape(-1) > 0
    cells = np.stack([np.repeat(hx, 3), np.repeat(hy, 3), hz.reshape(-1)], 1)[keep]
    lengths = np.concatenate([np.tile(l_free, (len(free), 1)),
                              np.column_stack([np.repeat(hl, 3, 0), np.full((n * 3, 1),
                                              l_free[2])])[keep]])  # fmt: skip
    points = np.concatenate([free, cells])

    bounds = (np.zeros(3), np.ones(3), np.zeros(3), np.full(3, cap))

    def generic(a, b, held, into):
        return insert_chunks(a, b, MODE_PRODUCT, points, lengths / cap, *bounds, res, *held,
                             *into)  # fmt: skip

    def tpu(a, b, held, into):
        return tpu_insert_chunks(a, b, origin, direction, rows, f, l_free, hx, hy, hl, hz, hw,
                                 res, *held, *into)  # fmt: skip

    def one_pass(stop: int) -> np.ndarray:
        """The chunk keys in the order one pass places them, from arrays of 16 chunks doubled
        (and the table rehashed) whenever the pass stops."""
        keys, count, start = np.zeros((16, 3), np.int64), np.zeros(1, np.int64), 0
        while True:
            table = (np.full(4 * len(keys), -1, np.int64), np.zeros(4 * len(keys), np.int64))
            rehash(keys, count[0], *table)
            start = generic(start, stop, table, (*table, keys, count))
            if start == stop:
                return keys[: count[0]]
            keys = np.concatenate([keys, np.zeros_like(keys)])

    def placed(find_new, first: int, end: int, parts: int) -> np.ndarray:
        grid = ChunkedGrid(res, capacity=16)
        grid.place(find_new, first, end, parts)
        return grid.chunk_mass(np.arange(grid.n_chunks))[0]

    whole = one_pass(len(points))
    assert len(whole) > 2000 and len(points) >= PARALLEL_MIN_SAMPLES
    for parts in (1, 2, 3):  # the tpu pass; both passes in parts, a part's table its own
        assert np.array_equal(placed(tpu, rows[0], rows[-1] + 3 * n, parts), whole)
        assert np.array_equal(placed(generic, 0, len(points), parts), whole)
    few = PARALLEL_MIN_SAMPLES - 1
    assert np.array_equal(placed(generic, 0, few, 1), one_pass(few))
