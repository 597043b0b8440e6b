"""The one-line notice of a numba compilation: told once, for undertow's kernels only, and not
when the kernels come from numba's cache."""

import os
import subprocess
import sys
from pathlib import Path

import numba
import pytest
from numba.core import event

from undertow.cli._compile_notice import NOTICE, CompileNotice, install

UNDERTOW = Path(sys.executable).with_name("undertow")


def _kernel(module: str):
    """A new jitted function (no cache: every call in a new process compiles) of ``module``."""

    def twice(x):
        return 2 * x

    twice.__module__ = module
    return numba.njit(twice)


def test_the_first_compilation_of_an_undertow_kernel_is_told_once():
    said = []
    listener = install(said.append)
    try:
        assert isinstance(listener, CompileNotice)
        _kernel("not_undertow.kernels")(1.0)
        assert said == []  # another package's kernel
        _kernel("undertow.probe")(1.0)
        assert said == [NOTICE]
        _kernel("undertow.probe")(2)  # another kernel of undertow, and another signature
        assert said == [NOTICE]
    finally:
        event.unregister("numba:compile", listener)


def _simulate(out: Path, cache: Path, terminal: bool) -> tuple[int, str]:
    """`undertow simulate calm` with the numba cache ``cache``: (exit status, stderr), stderr a
    pseudo-terminal when ``terminal``, else a pipe."""
    env = {k: v for k, v in os.environ.items() if k not in ("FORCE_TERMINAL", "TTY_COMPATIBLE")}
    env["NUMBA_CACHE_DIR"] = str(cache)
    args = [str(UNDERTOW), "simulate", "calm", "--out", str(out), "-q"]
    if not terminal:
        done = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
        return done.returncode, done.stderr
    master, slave = os.openpty()  # (the few lines of -q fit the terminal's buffer)
    try:
        done = subprocess.run(args, env=env, stdout=subprocess.DEVNULL, stderr=slave, timeout=120)
    finally:
        os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # EIO: the other end is closed and everything was read
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(master)
    return done.returncode, b"".join(chunks).decode(errors="replace")


@pytest.mark.slow  # three subprocesses: about 9 s
@pytest.mark.skipif(not UNDERTOW.exists() or not hasattr(os, "openpty"), reason="script, POSIX")
def test_the_command_tells_a_user_of_a_compilation_and_not_of_a_cache_load(tmp_path):
    """With an empty numba cache (NUMBA_CACHE_DIR) `undertow simulate` compiles and says so once
    on a terminal's stderr; run again, it loads the kernels from that cache and says nothing;
    into a pipe (a script, a log, JSON read by a program) it says nothing either."""
    notice = f"note: {NOTICE}"
    first = _simulate(tmp_path / "a", tmp_path / "cache", terminal=True)
    again = _simulate(tmp_path / "b", tmp_path / "cache", terminal=True)
    piped = _simulate(tmp_path / "c", tmp_path / "other-cache", terminal=False)
    assert [first[0], again[0], piped[0]] == [0, 0, 0], (first, again, piped)
    assert " ".join(first[1].split()).count(notice) == 1, first[1]
    assert "compiling" not in again[1] and "compiling" not in piped[1], (again, piped)
