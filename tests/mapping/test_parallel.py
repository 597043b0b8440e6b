"""The scatter on several threads (as many as numba's thread count says): each thread owns one
slab of cells, so the map is the serial map bit for bit, whatever the slabs; the slab splitter
balances the samples; the parts run at once, in a forked child too."""

from __future__ import annotations

import multiprocessing
import threading
import time

import numba
import numpy as np
import pytest

from undertow.mapping import make_mapper
from undertow.mapping import threads as threads_module
from undertow.mapping.grid import points_extent
from undertow.mapping.kernels import slab_splits
from undertow.mapping.samples import Samples
from undertow.mapping.threads import run_parts

BOUNDS = ((1e-4, 1e-4, 1e-4), (1.1e-3, 1.1e-3, 2e-4))


def _samples(seed: int, n: int = 6000, spread=(3.0, 0.5, 1.0), centre=(-1.3, 2.2, -4.0)):
    """Random samples around ``centre`` (negative cell indices included), rays of 20 samples
    sharing their variance (as the free samples of one beam do)."""
    rng = np.random.default_rng(seed)
    points = np.asarray(centre) + rng.normal(0, 1, (n, 3)) * spread
    variance = np.repeat(rng.uniform(0, 1.5e-3, (n // 20 + 1, 3)), 20, axis=0)[:n]
    label = (rng.random(n) < 0.15).astype(float)
    return Samples(points, label, rng.uniform(0.5, 1.0, n), variance, np.arange(n) // 20,
                   np.zeros(n, np.int8))  # fmt: skip


def _mapper(method):
    return make_mapper(method, **({"variance_bounds": BOUNDS} if method == "adaptive" else {}))


def _map(method, batches, threads):
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        mapper = _mapper(method)
        for b in batches:
            mapper.integrate(b)
        return mapper.occupancy()
    finally:
        numba.set_num_threads(before)


def _same(a, b) -> bool:
    return (np.array_equal(a.cells, b.cells) and np.array_equal(a.alpha, b.alpha)
            and np.array_equal(a.beta, b.beta))  # fmt: skip


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one numba thread")
@pytest.mark.parametrize("method", ["adaptive", "bki", "csm"])
@pytest.mark.parametrize("spread", [(3.0, 0.5, 1.0), (0.5, 3.0, 1.0)])  # slabs along x, along y
def test_two_threads_give_the_serial_map_bit_for_bit(method, spread):
    batches = [_samples(seed, spread=spread) for seed in range(3)]  # the grid grows in between
    serial, parallel = _map(method, batches, 1), _map(method, batches, 2)
    assert len(serial) > 1000 and _same(serial, parallel)


@pytest.mark.parametrize("parts", [2, 3, 5])
def test_any_slabs_give_the_same_map(monkeypatch, parts):
    """More slabs than threads are run in turn by the threads; still the same map."""
    batches = [_samples(7)]
    serial = _map("adaptive", batches, 1)
    monkeypatch.setattr(threads_module, "parallel_parts", lambda n: parts)
    assert _same(serial, _map("adaptive", batches, 1))


def test_slab_splits_balance_the_samples():
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.normal(0, 5, 20000), rng.normal(0, 1, 20000), np.zeros(20000)])
    axis, splits = slab_splits(points, 0.1, 4, *points_extent(points)[:2])
    assert axis == 0 and splits[0] < -(1 << 60) and splits[-1] > 1 << 60
    index = np.floor(points[:, 0] / 0.1)
    counts = [
        np.sum((index >= a) & (index < b)) for a, b in zip(splits[:-1], splits[1:], strict=True)
    ]
    assert sum(counts) == 20000 and max(counts) - min(counts) < 0.02 * 20000
    # sparse spread (wider than 4 n + 4096 cells): the sorted path, same balance
    far = np.column_stack([np.arange(100) * 1e3, np.zeros(100), np.zeros(100)])
    axis, splits = slab_splits(far, 0.1, 2, *points_extent(far)[:2])
    index = np.floor(far[:, 0] / 0.1)
    assert axis == 0 and np.sum(index < splits[1]) == 50


def test_concurrent_integrations_each_get_their_serial_map():
    """Two threads integrating into two mappers at once: one takes the parallel kernel, the
    other the serial one (no nested thread pools); both maps are exact."""
    batches = {k: [_samples(10 + k)] for k in range(2)}
    expected = {k: _map("adaptive", batches[k], 1) for k in range(2)}
    got = {}

    def run(k):
        got[k] = _map("adaptive", batches[k] * 1, numba.config.NUMBA_NUM_THREADS)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(_same(got[k], expected[k]) for k in range(2))


@pytest.mark.parametrize("parts", [2, 3, 7])
def test_parallel_expand_gives_the_serial_samples(monkeypatch, parts):
    """The rays' samples built on several threads (each ray writing its own rows) are the
    serial ones, row for row, with rays of very different lengths and rays with no free
    samples."""
    from undertow.mapping.samples import expand

    rng = np.random.default_rng(parts)
    n = 500
    rays = {"origin": rng.normal(0, 3, (n, 3)), "direction": rng.normal(0, 1, (n, 3)),
            "r": rng.choice([0.05, 0.3, 2.0, 9.0], n), "var": rng.uniform(0, 1e-3, (n, 3)),
            "sig": rng.uniform(0.5, 1, n),
            "sensor": rng.integers(0, 3, n).astype(np.int8)}  # fmt: skip
    monkeypatch.setattr(threads_module, "parallel_parts", lambda n: 1)
    serial = expand(**rays, f=0.1, dropped={})
    serial.points  # noqa: B018 (written when read: now, on one thread)
    monkeypatch.setattr(threads_module, "parallel_parts", lambda n: parts)
    threaded = expand(**rays, f=0.1, dropped={})
    assert len(serial) > 2048
    for name in ("points", "label", "sigma0", "pose_variance", "ray", "sensor"):
        assert np.array_equal(getattr(serial, name), getattr(threaded, name)), name


def _parts_at_once(parts: int = 2) -> list[int]:
    """Runs ``parts`` parts that each wait for all the others (a barrier with a timeout: parts
    run in turn would break it), returns the parts seen."""
    barrier, seen = threading.Barrier(parts, timeout=10), []
    run_parts(lambda t: seen.append(t) or barrier.wait(), parts)
    return sorted(seen)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one numba thread")
def test_the_parts_run_at_once_and_a_parts_error_comes_after_every_part_is_done():
    assert _parts_at_once() == [0, 1]
    done = []

    def part(t):
        if t == 1:
            raise ValueError("part 1 failed")
        time.sleep(0.05)
        done.append(t)

    with pytest.raises(ValueError, match="part 1 failed"):
        run_parts(part, 3)
    assert sorted(done) == [0, 2]


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one numba thread")
def test_a_forked_child_runs_its_parts_on_threads_of_its_own():
    """The parent's pool threads are not in a forked child (a Dask worker, a tile process):
    the child makes its own pool instead of queueing parts no thread takes."""
    assert _parts_at_once() == [0, 1]  # the parent's pool exists now
    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.apply_async(_parts_at_once).get(timeout=60) == [0, 1]
