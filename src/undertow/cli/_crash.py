"""What the command line does with a bug and with a request to stop.

A bug (any exception that is not a user error) becomes one line naming a crash report file
(traceback, versions, command line) and exit status :data:`EXIT_BUG`; SIGTERM is turned into
:class:`~undertow.errors.Terminated` while a command runs, so temporary output is removed on the
way out as for Ctrl-C. Exit statuses follow sysexits.h and the shell's 128 + signal number.
"""

from __future__ import annotations

import os
import platform
import signal
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

from ..errors import Terminated

EXIT_USER = 1  # a user error: bad file, bad option value, missing data
EXIT_USAGE = 2  # the command line itself: unknown option, missing argument (click)
EXIT_BUG = 70  # EX_SOFTWARE (sysexits.h): an internal error, a bug in undertow
EXIT_INTERRUPTED = 128 + signal.SIGINT  # 130, Ctrl-C
EXIT_TERMINATED = 128 + signal.SIGTERM  # 143, SIGTERM (kill, systemd, a batch scheduler)

_PACKAGES = ("undertow", "numpy", "scipy", "numba", "rosbags", "typer", "pydantic")


def crash_folder() -> Path:
    """Where crash reports go: ``$XDG_STATE_HOME/undertow`` (default
    ``~/.local/state/undertow``)."""
    state = os.environ.get("XDG_STATE_HOME") or os.path.join(os.path.expanduser("~"), ".local",
                                                             "state")  # fmt: skip
    return Path(state) / "undertow"


def _versions() -> str:
    lines = [f"python {platform.python_version()} ({sys.executable})", platform.platform()]
    for name in _PACKAGES:
        try:
            lines.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            continue
    return "\n".join(lines)


def write_crash_report(exc: BaseException) -> Path | None:
    """Write the traceback of ``exc``, the versions and the command line to a new file in
    :func:`crash_folder` (else the temporary folder); its path, or None when neither can be
    written."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    text = (
        f"undertow crash report, {time.strftime('%Y-%m-%d %H:%M:%S %z')}\n\n"
        f"command line: {' '.join(sys.argv)}\nworking folder: {os.getcwd()}\n\n"
        f"{_versions()}\n\n"
        + "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    )
    for folder in (crash_folder(), Path(tempfile.gettempdir())):
        path = folder / f"undertow-crash-{stamp}-{os.getpid()}.txt"
        try:
            folder.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
        except OSError:
            continue
        return path
    return None


def bug_line(exc: BaseException) -> str:
    """The one line a bug prints: what happened, and where the report is."""
    report = write_crash_report(exc)
    where = f"crash report: {report}" if report else "no crash report could be written"
    detail = f"{type(exc).__name__}: {exc}".strip().splitlines()[0][:200]
    return f"internal error, a bug in undertow ({detail}); {where} - please report it with it"


def _terminate(signum, frame) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second SIGTERM must not cut the cleanup
    raise Terminated()


@contextmanager
def sigterm_as_exception() -> Iterator[None]:
    """While inside, SIGTERM raises :class:`~undertow.errors.Terminated` in the main thread
    (the previous handler is restored afterwards; nothing changes outside the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
