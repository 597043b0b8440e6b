"""Atomic outputs: write to a temporary sibling, then rename into place.

A crash or a user error half-way never leaves a half-written file or folder behind, and the
final permissions follow the user's umask (``tempfile`` alone would make them private).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import ConfigError


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
    holder = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    tmp = holder / path.name
    if directory:
        tmp.mkdir()
    try:
        yield tmp
        mode = (0o777 if tmp.is_dir() else 0o666) & ~_umask()
        os.chmod(tmp, mode)
        if path.is_dir() and not path.is_symlink():
            os.replace(path, holder / ".old")
        os.replace(tmp, path)
    finally:
        shutil.rmtree(holder, ignore_errors=True)


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
    ancestor = out.parent
    while not ancestor.exists():  # nothing is created yet: probe the nearest existing folder
        ancestor = ancestor.parent
    try:
        if not ancestor.is_dir():
            raise NotADirectoryError(f"{ancestor} is a file")
        os.rmdir(tempfile.mkdtemp(prefix=f".{path.name}.", dir=ancestor))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot write here ({exc.strerror or exc})") from None
    return path


@contextmanager
def output_folder(path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """A result folder written all at once: yields an empty temporary folder that replaces
    ``path`` on success (an existing folder only with ``overwrite``)."""
    with atomic_path(check_output_folder(path, overwrite), directory=True) as tmp:
        yield tmp
