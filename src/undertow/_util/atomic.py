"""Atomic outputs: write to a temporary sibling, then rename into place.

A crash or a user error half-way never leaves a half-written file or folder behind, and the
final permissions follow the user's umask (``tempfile`` alone would make them private).

The temporary sibling of ``NAME`` is a hidden folder ``.NAME.undertow-PID-HOST-XXXXXXXX``
(PID: the writing process, HOST: a tag of its host name). An exception or a signal the process
handles (SIGINT, SIGTERM) removes it on the way out; one left by a killed run (SIGKILL, power
loss) is removed by the next write into the same folder on the same host, once its process is
gone (:func:`remove_stale`). Nothing else is ever removed.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import signal
import socket
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import ConfigError

#: the host tag in temporary names: a process id means something only on its own host
_HOST = hashlib.sha1(socket.gethostname().encode()).hexdigest()[:6]
_TEMPORARY = re.compile(
    r"\.(?P<name>.+)\.undertow-(?P<pid>[0-9]+)-(?P<host>[0-9a-f]{6})-[a-z0-9_]{8}"
)


def temporary_prefix(name: str) -> str:
    """The prefix of this process's temporary siblings of ``name`` (for ``tempfile.mkdtemp``,
    which appends eight random characters)."""
    return f".{name}.undertow-{os.getpid()}-{_HOST}-"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):  # another user's, or not a pid here
        return True
    return True


def remove_stale(folder: str | Path) -> list[Path]:
    """Remove the temporary folders of our naming in ``folder`` whose process (on this host)
    is gone: what a killed run left behind. Returns those removed; anything that is not a
    folder of exactly that naming, of another host or of a live process is left alone."""
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        match = _TEMPORARY.fullmatch(entry.name)
        if match is None or match["host"] != _HOST or _alive(int(match["pid"])):
            continue
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(entry.path, ignore_errors=True)
            removed.append(Path(entry.path))
    return removed


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """SIGINT and SIGTERM wait until the end of the block (POSIX; elsewhere a no-op)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    stop = {signal.SIGINT, signal.SIGTERM}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, stop)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(
    path: str | Path, directory: bool = False, replaces_directory: bool = False
) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path``.

    With ``directory=True`` the temporary path is an (empty) directory and an existing
    directory at ``path`` is replaced as a whole. A file write never replaces a directory: an
    existing directory at ``path`` is an error, unless ``replaces_directory`` says the caller
    writes a folder itself (a ROS 2 bag) and has checked it may go. On an exception nothing at
    ``path`` changes.
    """
    path = Path(path)
    if path.is_dir() and not (directory or replaces_directory):
        raise ConfigError(f"{path}: is a directory; give a file name to write")
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(path.parent)
    holder = Path(tempfile.mkdtemp(prefix=temporary_prefix(path.name), dir=path.parent))
    tmp = holder / path.name
    if directory:
        tmp.mkdir()
    try:
        yield tmp
        mode = (0o777 if tmp.is_dir() else 0o666) & ~_umask()
        os.chmod(tmp, mode)
        with _signals_deferred():  # Ctrl-C / SIGTERM between the renames would lose both
            if path.is_dir() and not path.is_symlink():
                os.replace(path, holder / ".old")
            os.replace(tmp, path)
    finally:
        shutil.rmtree(holder, ignore_errors=True)


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through :func:`atomic_path`."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def check_output_folder(path: str | Path, overwrite: bool = False, inputs=()) -> Path:
    """Refuse an output folder that is a file, that holds files unless ``overwrite``, that is
    or contains one of the command's ``inputs`` (replacing it would delete them), or whose
    parent cannot be written.

    Called before long work so that a wrong ``--out`` fails at once, not after it."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{path}: output folder is an existing file")
    out = path.resolve()
    for given in inputs:
        if given is not None and (
            out == Path(given).resolve() or out in Path(given).resolve().parents
        ):
            raise ConfigError(f"{path}: output folder holds the input {given}; write elsewhere")
    if path.is_dir() and any(path.iterdir()) and not overwrite:
        raise ConfigError(f"{path}: output folder exists and is not empty (use --overwrite)")
    _probe(path)
    return path


def check_output_file(path: str | Path) -> Path:
    """Refuse an output file that is a folder or whose folder cannot be written; called before
    the work (reading a log) so that a wrong ``--out`` fails at once."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{path}: is a directory; give a file name to write")
    _probe(path)
    return path


def _probe(path: Path) -> None:
    """Create and remove a temporary folder where ``path`` will be written (its nearest
    existing ancestor: nothing is created yet); a ConfigError naming ``path`` if that fails."""
    ancestor = path.resolve().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    try:
        if not ancestor.is_dir():
            raise NotADirectoryError(f"{ancestor} is a file")
        os.rmdir(tempfile.mkdtemp(prefix=temporary_prefix(path.name), dir=ancestor))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot write here ({exc.strerror or exc})") from None


@contextmanager
def output_folder(path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """A result folder written all at once: yields an empty temporary folder that replaces
    ``path`` on success (an existing folder only with ``overwrite``)."""
    with atomic_path(check_output_folder(path, overwrite), directory=True) as tmp:
        yield tmp
