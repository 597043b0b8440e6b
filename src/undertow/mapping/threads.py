"""How many numba threads a mapping kernel may use: one parallel kernel at a time per process.

A scatter (:mod:`.grid`) or a sample expansion (:mod:`.samples`) of enough samples runs on
numba's threads. Only one such kernel runs at a time per process: a second caller (a Dask
thread, the live pipeline) runs the serial kernel instead of nesting numba's thread pool (its
workqueue layer aborts then).
"""

from __future__ import annotations

import threading
from contextlib import contextmanager

import numba

PARALLEL_MIN_SAMPLES = 2048  # below this a kernel stays on the calling thread
_PARALLEL = threading.Lock()  # the process's one parallel slot (module docstring)


@contextmanager
def scatter_threads(n: int):
    """Mapping kernels on this thread use at most ``n`` numba threads inside the block (1: serial;
    the setting is per calling thread, as ``numba.set_num_threads``)."""
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
