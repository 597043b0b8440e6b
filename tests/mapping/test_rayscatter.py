"""The adaptive scatter straight from the rays (mapping/rayscatter.py) against the scatter of the
written samples (mapping/kernels.py): the same chunks in the same order and the same alpha and
beta, bit for bit, on one thread and on several; and its parts against their references."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from conftest import multibeam_fan, numba_threads, same_map

from undertow.mapping import grid as grid_module
from undertow.mapping import make_mapper
from undertow.mapping.grid import points_extent
from undertow.mapping.rayscatter import ray_extent, ray_slab_splits, sincos_lanes
from undertow.mapping.samples import RaySamples, Samples, expand

BOUNDS = ((1e-4, 1e-4, 1e-4), (1.1e-3, 1.1e-3, 2e-4))


def _fan(seed: int, pings: int = 6, beams: int = 96):
    """Multibeam fans (120 deg across track, small roll/pitch) 1.75 m over a wavy floor, one
    pose variance per ping, as the benchmark's: rays (origin, direction, range, variance, sigma)."""
    rng = np.random.default_rng(seed)
    o, v, r, var = multibeam_fan(rng, pings, beams, seed, 1.3e-3)
    return o, v, r, var, np.full(len(r), 0.6)


def _random_rays(seed: int, n: int = 400):
    """Rays in every direction (not unit: expand does not ask), ranges from under one free step
    to 3 m (no free sample, a few, many), variances in and beyond the bounds, negative cells."""
    rng = np.random.default_rng(seed)
    o = rng.normal(0, 2.0, (n, 3)) + [-1.3, 2.2, -4.0]
    v = rng.normal(0, 1, (n, 3))
    r = rng.choice([0.05, 0.3, 1.0, 3.0], n) * rng.uniform(0.5, 1.5, n)
    var = np.repeat(rng.uniform(0, 1.5e-3, (n // 7 + 1, 3)), 7, axis=0)[:n]
    return o, v, r, var, rng.uniform(0.5, 1.0, n)


def _samples(rays, written: bool):
    """The rays' samples as expand gives them (kept as rays) or written out (plain Samples)."""
    o, v, r, var, sig = rays
    samples = expand(o, v, r, var, sig, np.zeros(len(r), np.int8), 0.1, {})
    assert isinstance(samples, RaySamples)
    if written:
        fields = ("points", "label", "sigma0", "pose_variance", "ray", "sensor")
        return Samples(*(getattr(samples, name) for name in fields))
    return samples


def _map(batches, written: bool, bounds=BOUNDS, threads: int = 1):
    with numba_threads(threads):
        mapper = make_mapper("adaptive", variance_bounds=bounds)
        for rays in batches:  # the grid starts small and grows in between and within batches
            mapper.integrate(_samples(rays, written))
        return mapper


@pytest.mark.parametrize("bounds", [BOUNDS, None])  # fixed bounds, and the session's
@pytest.mark.parametrize("make", [_fan, _random_rays])
def test_the_rays_give_the_written_samples_map_bit_for_bit(make, bounds):
    batches = [make(seed) for seed in range(3)]
    written, rays = _map(batches, True, bounds), _map(batches, False, bounds)
    assert written.grid.n_chunks > 64  # grown, and resumed after each growth
    assert same_map(written, rays)
    occupancy = rays.occupancy()
    assert len(occupancy) > 1000 and np.all(occupancy.alpha >= rays.alpha0)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one numba thread")
@pytest.mark.parametrize("make", [_fan, _random_rays])
def test_the_rays_on_two_threads_give_the_serial_map_bit_for_bit(monkeypatch, make):
    """Slabs of cells on numba's threads, the chunks placed in a pass before (the path of large
    batches, forced here on small ones)."""
    batches = [make(seed) for seed in range(3)]
    serial = _map(batches, True)
    monkeypatch.setattr(grid_module, "RAY_PARALLEL_MIN_SAMPLES", 1)
    assert same_map(serial, _map(batches, False, threads=2))


def test_ray_samples_are_the_written_samples():
    """RaySamples writes its samples when read: the rows expand always wrote, and its length
    and hit count without writing them."""
    o, v, r, var, sig = _random_rays(5, 60)
    samples = expand(o, v, r, var, sig, np.arange(60) % 3, 0.1, {"x": 1})
    n_free = np.where(r >= 0.1, np.floor((r - 0.1) / 0.1 + 1e-9).astype(int) + 1, 0)
    assert len(samples) == 60 + n_free.sum() and samples.n_hits == 60
    assert samples._written is None and samples.dropped == {"x": 1}
    np.testing.assert_array_equal(samples.points[:60], o + r[:, None] * v)
    assert np.array_equal(samples.label, np.r_[np.ones(60), np.zeros(n_free.sum())])
    ray = samples.ray
    assert np.array_equal(ray, np.r_[np.arange(60), np.repeat(np.arange(60), n_free)])
    np.testing.assert_array_equal(samples.pose_variance, var[ray])
    np.testing.assert_array_equal(samples.sensor, (np.arange(60) % 3)[ray])
    free = ray[60:]
    k = np.arange(60, len(samples)) - samples.rays.rows[free]  # s = k f along the ray
    np.testing.assert_array_equal(samples.points[60:], o[free] + (k * 0.1)[:, None] * v[free])
    assert samples.n_hits == int(np.sum(samples.label > 0.5))


@pytest.mark.parametrize("make", [_fan, _random_rays])
def test_ray_extent_is_the_samples_extent(make):
    rays = make(2)
    o, v, r, _, _ = rays
    samples = _samples(rays, False)
    lo, hi, finite = ray_extent(o, v, r, samples.rays.rows, 0.1)
    want = points_extent(samples.points)
    assert finite == want[2] and np.array_equal(lo, want[0]) and np.array_equal(hi, want[1])


def test_ray_slab_splits_cut_the_fan_across_track_into_ordered_slabs():
    rays = _fan(3, pings=4, beams=200)
    samples = _samples(rays, False)
    o, v, r, _, _ = rays
    extent = ray_extent(o, v, r, samples.rays.rows, 0.1)
    axis, splits = ray_slab_splits(o, v, r, samples.rays.rows, 0.1, 0.1, 4, *extent[:2])
    assert axis == 1  # the fan spreads across track (y)
    assert splits[0] < -(1 << 60) and splits[-1] > 1 << 60 and np.all(np.diff(splits) >= 0)
    index = np.floor(samples.points[:, 1] / 0.1)
    counts = np.histogram(index, np.r_[index.min(), splits[1:-1], index.max() + 1])[0]
    assert counts.min() > 0.15 * len(samples)  # midpoints stand for their rays: roughly even


def test_sincos_lanes_is_the_kernels_sincos_bit_for_bit():
    """The branch-free quadrant choice returns the very values of the scatter's sin/cos, so the
    weights are the same bit for bit."""
    from undertow.mapping.kernels import sincos

    x = np.concatenate([np.linspace(-40.0, 40.0, 20_001), np.pi / 4 * np.arange(-64, 65),
                        np.nextafter(np.pi / 4 * np.arange(-64, 65), np.inf)])  # fmt: skip
    got = np.array([sincos_lanes(v) for v in x])
    want = np.array([sincos(v) for v in x])
    assert np.array_equal(got.view(np.int64), want.view(np.int64))
