"""What every job shares: reading a log with the user's topic names and mounting."""

from __future__ import annotations

from pathlib import Path

from ..io import read_log
from ..io.clock import check_policy
from ..io.read_options import LogOptions
from ..io.topics import TopicMap
from ..log import Log
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
