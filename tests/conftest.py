"""Shared fixtures: where the real DVL recordings live, and simulated runs computed once.

The recordings are in the project's shared folder (``../shared/data/real`` next to the
checkout). Set UNDERTOW_REAL_DATA to point elsewhere. Tests that read them carry the marker
``realdata``; without the folder they fail (``UNDERTOW_SKIP_REAL_DATA=1`` skips them). Tests
that open sockets on 127.0.0.1 carry ``network``.

Simulated runs are deterministic per (scenario, seed), so several test files share one
simulation per session: ``simulation(name, seed)`` gives the :class:`SimulationResult` (its
arrays read-only: a test that needs to change one copies it), ``simulated_run(name, seed)`` the
run folder ``undertow simulate NAME --seed SEED`` writes (tests must not write into it; copy it
with :func:`shutil.copytree` to change it).

Tests marked ``slow`` (heavy fixtures, clusters, long logs, end-to-end command chains) are left
out by ``make test-fast`` (``pytest -m "not slow"``); ``make test`` runs everything.
"""

import contextlib
import dataclasses
import fcntl
import os
from pathlib import Path

import numpy as np
import pytest


def _find_real_data() -> Path:
    env = os.environ.get("UNDERTOW_REAL_DATA")
    if env:
        return Path(env)
    here = Path(__file__).resolve().parent
    for parent in here.parents:
        candidate = parent / "shared" / "data" / "real"
        if candidate.is_dir():
            return candidate
    return Path("/work/shared/data/real")


REAL_DATA = _find_real_data()


def compile_each_kernel_once(folder: Path) -> None:
    """Processes that share ``folder`` compile a numba kernel they need at the same moment once:
    the first compiles it, the others wait and load it from numba's cache
    (``Dispatcher.compile`` looks there first). On a clean clone the xdist workers otherwise
    compile the filter's loop and the InEKF's side by side, about 40 s of CPU the second time.
    One lock file per cached function, taken inside numba's compiler lock (one compiling thread
    per process) and in call order (caller before callee; kernels do not recurse), so no two
    processes wait on each other. Installed once per process (a second call does nothing: two
    locks on one file from one process would wait on each other)."""
    from numba.core.caching import NullCache
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.dispatcher import Dispatcher

    if getattr(Dispatcher.compile, "compiles_once", False):
        return
    folder.mkdir(parents=True, exist_ok=True)
    original, held = Dispatcher.compile, set()

    def compile_once(self, sig):
        name = f"{self.py_func.__module__}.{self.py_func.__qualname__}"
        if isinstance(self._cache, NullCache) or name in held:
            return original(self, sig)
        with global_compiler_lock, open(folder / name, "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            held.add(name)
            try:
                return original(self, sig)
            finally:
                held.discard(name)
                fcntl.flock(lock, fcntl.LOCK_UN)

    compile_once.compiles_once = True
    Dispatcher.compile = compile_once


def pytest_configure(config):
    """In a pytest-xdist worker, :func:`compile_each_kernel_once` among the run's workers (their
    temporary folders' common parent, which pytest prunes)."""
    if hasattr(config, "workerinput") and config.option.basetemp:
        compile_each_kernel_once(Path(config.option.basetemp).parent / "numba-compile-locks")


def pytest_runtest_setup(item):
    """A test marked ``realdata`` fails loudly when the shared recordings are missing (CI always
    has them: a silent skip would hide that the real-data tests did not run);
    ``UNDERTOW_SKIP_REAL_DATA=1`` skips them instead, on a machine without the folder."""
    if item.get_closest_marker("realdata") is None or REAL_DATA.is_dir():
        return
    if os.environ.get("UNDERTOW_SKIP_REAL_DATA"):
        pytest.skip(f"real recordings not found at {REAL_DATA} (UNDERTOW_SKIP_REAL_DATA is set)")
    pytest.fail(
        f"real recordings not found at {REAL_DATA}: set UNDERTOW_REAL_DATA to their folder, or "
        "UNDERTOW_SKIP_REAL_DATA=1 to skip the tests marked realdata",
        pytrace=False,
    )


def multibeam_fan(rng, pings: int, beams: int, seed: int, var_high) -> tuple:
    """Multibeam fans (120 deg across track, small roll/pitch from ``rng``) 1.75 m over a wavy
    floor, one pose variance per ping drawn in [0, var_high): rays (origin, direction, range,
    variance), as the mapping benchmark's."""
    a = np.radians(np.linspace(-60, 60, beams))
    o, v, r, var = [], [], [], []
    for k in range(pings):
        roll, pitch = rng.normal(0, 0.03, 2)
        d = np.stack([np.full(beams, np.sin(pitch)), np.sin(a + roll), np.cos(a + roll)], 1)
        d /= np.linalg.norm(d, axis=1)[:, None]
        origin = np.array([0.9 * k + 7.0 * seed + 0.37, -1.1 + seed, 5.0])
        depth = 6.75 + 0.2 * np.sin(3.0 * d[:, 1] / d[:, 2])
        o.append(np.repeat(origin[None], beams, 0))
        v.append(d)
        r.append((depth - origin[2]) / d[:, 2])
        var.append(np.repeat(rng.uniform(0, var_high, (1, 3)), beams, 0))
    return tuple(np.concatenate(x) for x in (o, v, r, var))


def numeric_jacobian(fun, n: int, h: float = 1e-6) -> np.ndarray:
    """d fun / d e at e = 0 by central differences, one column per coordinate of e (n)."""
    cols = []
    for j in range(n):
        e = np.zeros(n)
        e[j] = h
        cols.append((fun(e) - fun(-e)) / (2 * h))
    return np.stack(cols, axis=1)


def same_map(a, b) -> bool:
    """Two mappers hold the same map bit for bit: the same chunks in the same order and the same
    cells, alpha and beta."""
    n = a.grid.n_chunks
    keys = np.array_equal(a.grid.chunk_mass(np.arange(n))[0],
                          b.grid.chunk_mass(np.arange(b.grid.n_chunks))[0])  # fmt: skip
    ca, cb = a.grid.cells(), b.grid.cells()
    return keys and all(np.array_equal(x, y) for x, y in zip(ca, cb, strict=True))


@contextlib.contextmanager
def numba_threads(threads: int):
    """numba's thread count set to ``threads`` inside the block."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        yield
    finally:
        numba.set_num_threads(before)


def one_error_line(result):
    """The single ``error:`` line of a CLI result that exited with status 1 (a user error), with
    no traceback; fails otherwise."""
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 1, result.output
    assert len(lines) == 1 and lines[0].startswith("error:"), result.output
    assert "Traceback" not in result.output
    return lines[0]


def _freeze(obj) -> None:
    """Make every numpy array held by ``obj`` (a dataclass, at any depth) read-only."""
    if isinstance(obj, np.ndarray):
        obj.flags.writeable = False
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            _freeze(getattr(obj, f.name))


@pytest.fixture(scope="session")
def simulation():
    """``simulation(name, seed=0)``: the built-in scenario ``name`` simulated with ``seed``, once
    per session; its arrays are read-only."""
    from undertow.sim import load_scenario, simulate

    cache = {}

    def get(name: str, seed: int = 0):
        if (name, seed) not in cache:
            result = simulate(load_scenario(name), seed=seed)
            _freeze(result)
            cache[name, seed] = result
        return cache[name, seed]

    return get


@pytest.fixture(scope="session")
def simulated_run(tmp_path_factory, simulation):
    """``simulated_run(name, seed=0)``: the folder ``undertow simulate name --seed seed`` writes
    (log/, ground_truth.tum, ground_truth.ply, scenario.yaml), once per session. Read only."""
    from undertow.sim import write_simulation

    root = tmp_path_factory.mktemp("simulated_runs")
    cache = {}

    def get(name: str, seed: int = 0) -> Path:
        if (name, seed) not in cache:
            cache[name, seed] = write_simulation(simulation(name, seed), root / f"{name}_{seed}")
        return cache[name, seed]

    return get
