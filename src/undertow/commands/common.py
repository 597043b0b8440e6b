"""What every command shares: reading a log with the user's topic names and mounting, finding
the ``.npz`` a command reads in a file or folder, and gathering the warnings a command returns.

Kept light (no mapping or estimation import): every command imports it, and the CLI imports a
command only when it runs."""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import ReaderError
from ..io import iter_log_pieces, read_log
from ..io.clock import check_policy
from ..io.read_options import LogOptions
from ..io.topics import TopicMap
from ..log import Log
from ..occupancy import not_an_npz
from ..settings import Settings


def load_log(path: str | Path, topics: str | Path | None = None,
             settings: Settings | None = None, time: str | None = None) -> Log:  # fmt: skip
    """Read a log. Topic names: the ``topics`` file when given, else the settings file's
    ``topics`` section, else the defaults; the settings' ``log`` section says how to read it
    (``time``, e.g. ``--time record``, overrides its time base); the settings' mounting
    overrides are applied."""
    topic_map = TopicMap.from_yaml(topics) if topics else settings.topics if settings else None
    options = settings.log if settings else LogOptions()
    if time is not None:
        options = options.model_copy(update={"time": check_policy(time)})
    log = read_log(path, topics=topic_map, options=options)
    return settings.apply_mounting(log) if settings else log


def load_log_pieces(
    path: str | Path,
    piece_s: float,
    topics: str | Path | None,
    settings: Settings,
    streams: tuple[str, ...] | None = None,
) -> Iterator[Log]:
    """:func:`load_log` in pieces of ``piece_s`` seconds (:func:`~undertow.io.iter_log_pieces`;
    ``streams``: only these streams), each piece with the settings' mounting applied."""
    topic_map = TopicMap.from_yaml(topics) if topics else settings.topics
    pieces = iter_log_pieces(path, piece_s, topic_map, options=settings.log, streams=streams)
    return (settings.apply_mounting(piece) for piece in pieces)


def as_settings(settings: Settings | str | Path | None) -> Settings:
    """``settings`` as is, or the settings file at that path (None: the defaults)."""
    return settings if isinstance(settings, Settings) else Settings.from_yaml(settings)


@contextmanager
def collect_warnings(into: list[str]) -> Iterator[None]:
    """Append the text of every warning raised inside to ``into`` instead of showing it (each
    distinct warning once per call, as a fresh process would show it)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.filterwarnings("default", category=UserWarning)
        try:
            yield
        finally:
            into.extend(str(w.message) for w in caught)


def npz_file(path: str | Path, name: str, expected: str, prefix: str = "") -> Path:
    """``path``, or ``path/name`` for a folder; a wrong kind of file (a .tum, .ply, .yaml) is
    one line saying what it looks like and what was ``expected``."""
    path = Path(path)
    path = path / name if path.is_dir() else path
    problem = not_an_npz(path, expected)
    if problem:
        raise ReaderError(prefix + problem)
    return path
