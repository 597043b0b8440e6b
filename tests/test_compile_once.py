"""The test suite's own plumbing: under pytest-xdist a numba kernel that two workers need at the
same moment is compiled by one of them (tests/conftest.py), the other loading it from numba's
cache."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

KERNEL = """
import numpy as np
from numba import njit


@njit(cache=True)
def kernel(x):
    out = np.empty_like(x)
    for i in range(x.size):
        out[i] = np.sin(x[i]) * np.cos(2.0 * x[i]) + np.sqrt(abs(x[i]))
    return out
"""

WORKER = """
import os, sys, time
from pathlib import Path

import numpy as np
from numba.core import event

folder = Path(sys.argv[2])
sys.path[:0] = [sys.argv[1], str(folder)]
import conftest
import kernel

conftest.compile_each_kernel_once(folder / "locks")  # as every xdist worker does
conftest.compile_each_kernel_once(folder / "locks")  # a second call changes nothing

compiles = []


class Count(event.Listener):
    def on_start(self, ev):
        compiles.append(ev.data["dispatcher"].py_func.__name__)

    def on_end(self, ev):
        pass


event.register("numba:compile", Count())
ready = folder / "ready"  # both imported, then both call the kernel
(ready / str(os.getpid())).touch()
deadline = time.time() + 60.0
while len(list(ready.iterdir())) < 2 and time.time() < deadline:
    time.sleep(0.005)
value = float(kernel.kernel(np.linspace(-1.0, 1.0, 11)).sum())
print(compiles.count("kernel"), value)
"""


def test_two_workers_needing_one_kernel_at_once_compile_it_once(tmp_path):
    """Two processes sharing a lock folder and an empty numba cache call the same cached
    kernel at the same moment: one compiles it, the other waits and loads it (without the lock
    both compile); both get the kernel's values, as numpy computes them."""
    (tmp_path / "kernel.py").write_text(KERNEL)
    (tmp_path / "worker.py").write_text(textwrap.dedent(WORKER))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    tests = str(Path(__file__).resolve().parent)
    (tmp_path / "ready").mkdir()
    procs = [
        subprocess.Popen(
            [sys.executable, str(tmp_path / "worker.py"), tests, str(tmp_path)],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    out = [p.communicate(timeout=120)[0].split() for p in procs]
    assert [p.returncode for p in procs] == [0, 0]
    assert sorted(int(o[0]) for o in out) == [0, 1], out
    x = np.linspace(-1.0, 1.0, 11)
    expected = float(np.sum(np.sin(x) * np.cos(2.0 * x) + np.sqrt(np.abs(x))))
    assert [float(o[1]) for o in out] == pytest.approx([expected, expected], rel=1e-12)
