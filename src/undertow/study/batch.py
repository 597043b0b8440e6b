"""Monte Carlo over seeds on Dask: run ``fn(seed, *args)`` for every seed as independent tasks.

Schedulers (``run_batch(..., scheduler=...)``):

- ``None`` or ``"local"``: a :class:`distributed.LocalCluster` of worker processes on this
  machine (one single-threaded worker per CPU, at most one per seed, no dashboard), created and
  closed inside the call;
- ``"threads"``: dask's local threaded scheduler (no cluster; one thread per CPU);
- ``"sync"``: in-process and sequential, without Dask (for debugging: breakpoints work);
- anything else (``"tcp://host:port"``): the address of a running ``dask scheduler``.

Every task runs inside :func:`_run_one`, which turns an exception into a failure record, so a
seed that raises never loses the others. ``fn`` is deterministic per seed, hence the results are
the same whatever the scheduler. Dask is optional and imported only here, inside the functions.
"""

from __future__ import annotations

import logging
import os
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from .._util.dask import (
    CONNECT_TIMEOUT_S,
    check_scheduler,
    describe_exception,
    import_dask,
)
from ..errors import ConfigError


@dataclass(frozen=True)
class BatchResult:
    """Outcome of a batch: per-seed results and failures, both ordered by seed.

    ``failures[seed]`` is one line: ``"<ExceptionType>: <message> (at <file>:<line> in <func>)"``,
    the location being the last frame of the task's traceback.
    """

    results: dict[int, Any]
    failures: dict[int, str]
    scheduler: str
    wall_s: float
    workers: int = 1
    seeds: tuple[int, ...] = field(default=())

    @property
    def ok(self) -> bool:
        """True when every seed produced a result."""
        return not self.failures


def run_batch(
    fn: Callable[..., Any],
    seeds: Sequence[int],
    *,
    scheduler: str | None = None,
    args: tuple = (),
    progress: Callable[[int, int], None] | None = None,
    connect_timeout_s: float = CONNECT_TIMEOUT_S,
) -> BatchResult:
    """Run ``fn(seed, *args)`` for each distinct seed; ``progress(done, total)`` as tasks end.

    ``fn`` must be a module-level function (workers import it by name); ``args`` are sent to
    every task. Raises :class:`ConfigError` for an unknown scheduler name, a scheduler address
    that cannot be reached within ``connect_timeout_s``, a missing Dask install, or an ``fn``
    that worker processes cannot import.
    """
    unique = sorted({_as_seed(s) for s in seeds})
    args = tuple(args)
    mode = check_scheduler(scheduler)
    if not callable(fn):
        raise ConfigError(f"run_batch needs a function, got {type(fn).__name__}")
    if mode not in ("threads", "sync"):
        _check_importable(fn)
    start = time.perf_counter()
    outcomes: dict[int, tuple[bool, Any]] = {}

    def record(seed: int, outcome: tuple[bool, Any]) -> None:
        outcomes[seed] = outcome
        if progress is not None:
            progress(len(outcomes), len(unique))

    if not unique:
        label, workers = mode, 0
    elif mode == "sync":
        for seed in unique:
            record(seed, _run_one(fn, seed, args))
        label, workers = "sync", 1
    elif mode == "threads":
        workers = _run_threads(fn, unique, args, record)
        label = "threads"
    else:
        label, workers = _run_distributed(fn, unique, args, record, mode, connect_timeout_s)
    results = {s: outcomes[s][1] for s in unique if outcomes[s][0]}
    failures = {s: outcomes[s][1] for s in unique if not outcomes[s][0]}
    wall_s = time.perf_counter() - start
    return BatchResult(results, failures, label, wall_s, workers, tuple(unique))


def _run_one(fn: Callable[..., Any], seed: int, args: tuple) -> tuple[bool, Any]:
    """One task: ``(True, fn(seed, *args))``, or ``(False, one-line description)`` if it raised."""
    try:
        return True, fn(seed, *args)
    except Exception as exc:  # a failing seed must not lose the others
        return False, describe_exception(exc)


def _run_threads(fn, seeds: list[int], args: tuple, record) -> int:
    """dask.delayed tasks on the local threaded scheduler; ``record`` called as each one ends."""
    dask = import_dask()
    from dask.callbacks import Callback

    tasks = [dask.delayed(_run_one, pure=False)(fn, seed, args) for seed in seeds]
    seed_of_key = {task.key: seed for task, seed in zip(tasks, seeds, strict=True)}

    def posttask(key, result, dsk, state, worker_id):
        if key in seed_of_key:
            record(seed_of_key[key], result)

    workers = min(os.cpu_count() or 1, len(seeds))
    with Callback(posttask=posttask):
        dask.compute(*tasks, scheduler="threads", num_workers=workers)
    return workers


def _run_distributed(fn, seeds: list[int], args: tuple, record, mode: str, timeout_s: float):
    """Futures on a fresh LocalCluster (``mode == "local"``) or on the scheduler at ``mode``."""
    import_dask()
    from distributed import Client, LocalCluster, as_completed

    if mode == "local":
        workers = min(os.cpu_count() or 1, len(seeds))
        with warnings.catch_warnings():  # the health-check HTTP server falls back from 8787
            warnings.filterwarnings("ignore", message="Port .* is already in use")
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
        with cluster, Client(cluster) as client:
            _gather(client, fn, seeds, args, record, as_completed)
        return f"local ({workers} worker processes)", workers
    try:
        client = Client(mode, timeout=timeout_s)
    except (OSError, TimeoutError) as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ConfigError(f"cannot reach the Dask scheduler at {mode}: {reason}") from None
    except Exception as exc:  # something answered, but not a Dask scheduler
        raise ConfigError(
            f"no Dask scheduler at {mode} (the peer does not speak the Dask protocol: "
            f"{type(exc).__name__})"
        ) from None
    with client:
        workers = len(client.scheduler_info().get("workers", {}))
        _gather(client, fn, seeds, args, record, as_completed)
    return f"{mode} ({workers} workers)", workers


def _gather(client, fn, seeds: list[int], args: tuple, record, as_completed) -> None:
    """Submit one future per seed and collect them as they complete."""
    futures = [client.submit(_run_one, fn, seed, args, pure=False) for seed in seeds]
    seed_of = {future.key: seed for future, seed in zip(futures, seeds, strict=True)}
    for future in as_completed(futures):
        try:
            outcome = future.result()
        except Exception as exc:  # worker died, task not unpicklable, cancelled
            outcome = (False, describe_exception(exc))
        record(seed_of[future.key], outcome)
        future.release()


def _check_importable(fn) -> None:
    """Worker processes import ``fn`` by module and name: refuse lambdas and nested functions."""
    module = sys.modules.get(getattr(fn, "__module__", None) or "")
    qualname = getattr(fn, "__qualname__", "")
    target = module
    for part in qualname.split(".") if qualname else ["<none>"]:
        target = getattr(target, part, None)
    if module is None or target is not fn:
        name = getattr(fn, "__qualname__", repr(fn))
        raise ConfigError(
            f"run_batch needs a module-level function for worker processes, got {name} "
            "(pass extra values through args=...)"
        )


def _as_seed(seed) -> int:
    try:
        value = int(seed)
    except (TypeError, ValueError):
        raise ConfigError(f"seeds must be integers, got {seed!r}") from None
    if value != seed:
        raise ConfigError(f"seeds must be integers, got {seed!r}")
    return value
