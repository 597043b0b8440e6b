"""How many threads a mapping kernel may use, and running its parts on them: one parallel kernel
at a time per process.

A scatter (:mod:`.grid`) or a sample expansion (:mod:`.samples`) of enough samples runs in parts,
each part a call of the compiled serial kernel on a slab of cells (or a range of rays), on a
process-wide pool of threads (:func:`run_parts`; the kernels release the GIL, numba's
``nogil``). How many parts: numba's thread count for the calling thread (``NUMBA_NUM_THREADS``,
``numba.set_num_threads``, :func:`scatter_threads`), the setting users already have. Only one
such kernel runs in parts at a time per process: a second caller (a Dask thread, the live
pipeline) runs the serial kernel, so the threads never outnumber the setting. (Threads of our
own rather than numba's ``parallel=True``: a prange variant of a kernel is compiled, and its
kernel optimized, a second time; for the scatters that was about 35 s of a first run.)
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor, wait
from contextlib import contextmanager

import numba

PARALLEL_MIN_SAMPLES = 2048  # below this a kernel stays on the calling thread
_PARALLEL = threading.Lock()  # the process's one parallel slot (module docstring)
_POOL: ThreadPoolExecutor | None = None  # the parts after the first run here (made when needed)
_POOL_LOCK = threading.Lock()


def _forget_pool() -> None:
    """In a forked child: the parent's pool and locks are not the child's (its threads are not
    copied)."""
    global _POOL, _POOL_LOCK, _PARALLEL
    _POOL, _POOL_LOCK, _PARALLEL = None, threading.Lock(), threading.Lock()


os.register_at_fork(after_in_child=_forget_pool)


def run_parts(call, parts: int) -> None:
    """``call(t)`` for t = 0 .. parts - 1 at once: part 0 on the calling thread, the others on
    the process's pool; returns when every part is done, raising the first part's error."""
    if parts <= 1:
        call(0)
        return
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            size = max(numba.config.NUMBA_NUM_THREADS - 1, 1)
            _POOL = ThreadPoolExecutor(size, thread_name_prefix="undertow-part")
        pool = _POOL
    futures = [pool.submit(call, t) for t in range(1, parts)]
    try:
        call(0)
    finally:
        wait(futures)
    for future in futures:
        future.result()


@contextmanager
def scatter_threads(n: int):
    """Mapping kernels called from this thread run in at most ``n`` parts inside the block (1:
    serial): numba's thread count, set per calling thread as ``numba.set_num_threads`` sets it."""
    before = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(before)


@contextmanager
def parallel_slot(n_samples: int, min_samples: int = PARALLEL_MIN_SAMPLES):
    """Yields how many parts (threads) a kernel over ``n_samples`` may use now: 1 when small
    (:func:`parallel_parts`; under ``min_samples`` for a kernel that sets its own threshold) or
    while another thread holds the process's parallel slot."""
    parts = parallel_parts(n_samples) if n_samples >= min_samples else 1
    if parts > 1 and _PARALLEL.acquire(blocking=False):
        try:
            yield parts
        finally:
            _PARALLEL.release()
    else:
        yield 1


def parallel_parts(n_samples: int) -> int:
    """Threads a kernel over ``n_samples`` uses: numba's thread count for the calling thread
    (``numba.set_num_threads``, ``NUMBA_NUM_THREADS``), 1 under :data:`PARALLEL_MIN_SAMPLES`."""
    if n_samples < PARALLEL_MIN_SAMPLES:
        return 1
    return int(numba.get_num_threads())
