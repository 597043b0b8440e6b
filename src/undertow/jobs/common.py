"""What every job shares: reading a log with the user's topic names and mounting."""

from __future__ import annotations

from pathlib import Path

from ..io import read_log
from ..io.topics import TopicMap
from ..log import Log
from ..settings import Settings


def load_log(path: str | Path, topics: str | Path | None = None,
             settings: Settings | None = None) -> Log:  # fmt: skip
    """Read a log. Topic names: the ``topics`` file when given, else the settings file's
    ``topics`` section, else the defaults; the settings' mounting overrides are applied."""
    topic_map = TopicMap.from_yaml(topics) if topics else settings.topics if settings else None
    log = read_log(path, topics=topic_map)
    return settings.apply_mounting(log) if settings else log
