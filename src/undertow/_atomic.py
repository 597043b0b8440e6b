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


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path: str | Path, directory: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path``.

    With ``directory=True`` the temporary path is an (empty) directory and an existing
    directory at ``path`` is replaced as a whole. On an exception nothing at ``path`` changes.
    """
    path = Path(path)
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
