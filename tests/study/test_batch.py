"""run_batch: same results whatever the scheduler, failures kept apart, clear connection errors.

The functions run by the batch live at module level so that worker processes can import them.
"""

import socket
import time
import warnings

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.study.batch import BatchResult, run_batch

#: opens sockets on 127.0.0.1 (servers it starts)
pytestmark = pytest.mark.network

SEEDS = [5, 0, 3, 1, 4, 2]


def seeded_metrics(seed: int, scale: float = 1.0) -> dict:
    """Something that depends on the seed only (numpy's default_rng)."""
    x = np.random.default_rng(seed).normal(size=1000) * scale
    return {"seed": seed, "rmse": {"x_m": float(np.sqrt(np.mean(x**2)))}, "first": float(x[0])}


def fails_on_three(seed: int, scale: float = 1.0) -> dict:
    if seed == 3:
        raise ValueError(f"seed {seed} diverged")
    return seeded_metrics(seed, scale)


def expected(seeds, scale=1.0):
    return {s: seeded_metrics(s, scale) for s in sorted(seeds)}


@pytest.fixture(scope="module")
def cluster_address():
    """One LocalCluster of worker processes for this module (a few seconds to start)."""
    from distributed import LocalCluster

    with warnings.catch_warnings():  # its health-check HTTP server may fall back from 8787
        warnings.filterwarnings("ignore", message="Port .* is already in use")
        cluster = LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        )
    with cluster:
        yield cluster.scheduler_address


def test_sync_results_ordered_by_seed_with_progress():
    calls = []
    out = run_batch(seeded_metrics, SEEDS, scheduler="sync", args=(2.0,),
                    progress=lambda done, total: calls.append((done, total)))  # fmt: skip
    assert isinstance(out, BatchResult) and out.ok and out.scheduler == "sync"
    assert list(out.results) == sorted(SEEDS)
    assert out.results == expected(SEEDS, 2.0)
    assert calls == [(k, len(SEEDS)) for k in range(1, len(SEEDS) + 1)]
    assert out.wall_s >= 0.0


def test_threads_gives_the_same_results():
    calls = []
    out = run_batch(
        seeded_metrics, SEEDS, scheduler="threads", progress=lambda d, t: calls.append(d)
    )
    assert out.scheduler == "threads" and out.failures == {}
    assert list(out.results) == sorted(SEEDS)
    assert out.results == expected(SEEDS)
    assert sorted(calls) == list(range(1, len(SEEDS) + 1))


@pytest.mark.slow
def test_process_cluster_gives_the_same_results(cluster_address):
    calls = []
    out = run_batch(seeded_metrics, SEEDS, scheduler=cluster_address, args=(2.0,),
                    progress=lambda done, total: calls.append((done, total)))  # fmt: skip
    assert out.scheduler.startswith(cluster_address) and out.workers == 2
    assert list(out.results) == sorted(SEEDS)
    assert out.results == expected(SEEDS, 2.0)
    assert sorted(calls) == [(k, len(SEEDS)) for k in range(1, len(SEEDS) + 1)]


@pytest.mark.parametrize(
    "scheduler", ["sync", "threads", pytest.param("cluster", marks=pytest.mark.slow)]
)
def test_failing_seed_is_reported_and_the_others_kept(scheduler, request):
    if scheduler == "cluster":
        scheduler = request.getfixturevalue("cluster_address")
    out = run_batch(fails_on_three, SEEDS, scheduler=scheduler)
    assert list(out.failures) == [3]
    message = out.failures[3]
    assert message.startswith("ValueError: seed 3 diverged")
    assert "test_batch.py" in message and "fails_on_three" in message and "\n" not in message
    assert out.results == expected([s for s in SEEDS if s != 3])
    assert not out.ok


@pytest.mark.slow
def test_local_cluster_created_and_closed_inside_the_call():
    out = run_batch(seeded_metrics, [7, 8], scheduler="local")
    assert out.scheduler.startswith("local") and 1 <= out.workers <= 2
    assert out.results == expected([7, 8])


@pytest.mark.slow
def test_unreachable_scheduler_is_one_line_error_quickly():
    with socket.socket() as sock:  # a free port nobody listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    start = time.perf_counter()
    with pytest.raises(ConfigError, match="cannot reach the Dask scheduler") as info:
        run_batch(seeded_metrics, [1], scheduler=address, connect_timeout_s=2.0)
    assert time.perf_counter() - start < 6.0
    assert address in str(info.value) and "\n" not in str(info.value)


def test_user_errors():
    with pytest.raises(ConfigError, match="unknown scheduler 'lcoal'"):
        run_batch(seeded_metrics, [1], scheduler="lcoal")
    with pytest.raises(ConfigError, match="unknown scheduler 4"):
        run_batch(seeded_metrics, [1], scheduler=4)
    with pytest.raises(ConfigError, match="module-level function"):
        run_batch(lambda seed: seed, [1], scheduler="local")
    with pytest.raises(ConfigError, match="seeds must be integers"):
        run_batch(seeded_metrics, [1.5], scheduler="sync")
    empty = run_batch(seeded_metrics, [], scheduler="local")
    assert empty.results == {} and empty.failures == {}


def test_lambdas_are_fine_in_process():
    out = run_batch(lambda seed: seed * 2, [2, 1, 2], scheduler="threads")
    assert out.results == {1: 2, 2: 4}


def test_missing_dask_gives_install_hint(monkeypatch):
    monkeypatch.setitem(__import__("sys").modules, "distributed", None)  # import -> ImportError
    with pytest.raises(ConfigError, match=r"pip install 'undertow\[dask\]'"):
        run_batch(seeded_metrics, [1], scheduler="threads")
    assert run_batch(seeded_metrics, [1], scheduler="sync").results == expected([1])
