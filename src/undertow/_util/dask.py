"""What the Dask runners (the study's seeds, the tiled map) share: the scheduler check before
any work, the optional import, and one line for a task's exception. Dask is imported only
inside the functions."""

from __future__ import annotations

import traceback
from pathlib import Path

from ..errors import ConfigError

NAMED_SCHEDULERS = ("local", "threads", "sync")
CONNECT_TIMEOUT_S = 3.0
INSTALL_HINT = "Dask is not installed: pip install 'undertow[dask]'"


def check_scheduler(
    scheduler: str | None, reach: bool = False, timeout_s: float = CONNECT_TIMEOUT_S
) -> str:
    """The scheduler mode for ``scheduler`` (None -> "local"), checked before any work.

    Raises :class:`ConfigError` for a name that is neither one of :data:`NAMED_SCHEDULERS` nor
    an address (``scheme://host:port`` or ``host:port``), for a missing Dask install (every mode
    but "sync" needs it) and, with ``reach``, for a ``tcp://`` address where nothing listens
    (a plain TCP connection within ``timeout_s``; whether it is a Dask scheduler is found out
    when connecting to it)."""
    mode = "local" if scheduler is None else scheduler
    if not isinstance(mode, str) or (mode not in NAMED_SCHEDULERS and ":" not in mode):
        raise ConfigError(
            f"unknown scheduler {scheduler!r}: use 'local', 'threads', 'sync' or an address "
            "tcp://host:port"
        )
    if mode != "sync":
        import_dask()
    if reach and mode not in NAMED_SCHEDULERS:
        _check_reachable(mode, timeout_s)
    return mode


def _check_reachable(address: str, timeout_s: float) -> None:
    import socket

    scheme, _, rest = address.rpartition("://")
    if scheme not in ("", "tcp"):
        return  # tls, ucx, inproc: left to Dask
    host, _, port = rest.rstrip("/").rpartition(":")
    try:
        with socket.create_connection((host.strip("[]") or "localhost", int(port)), timeout_s):
            pass
    except ValueError:
        raise ConfigError(f"scheduler address {address!r}: expected tcp://host:port") from None
    except OSError as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ConfigError(f"cannot reach the Dask scheduler at {address}: {reason}") from None


def import_dask():
    """The ``dask`` module, with ``distributed`` importable; ConfigError (install hint) if not."""
    try:
        import dask
        import distributed  # noqa: F401 - needed by every Dask scheduler mode here
    except ImportError:
        raise ConfigError(INSTALL_HINT) from None
    return dask


def describe_exception(exc: BaseException) -> str:
    """``"<Type>: <message> (at <file>:<line> in <func>)"`` on one line (last traceback frame)."""
    message = " ".join(str(exc).split())
    text = f"{type(exc).__name__}: {message}" if message else type(exc).__name__
    frames = traceback.extract_tb(exc.__traceback__)
    if frames:
        last = frames[-1]
        text += f" (at {Path(last.filename).name}:{last.lineno} in {last.name})"
    return text
