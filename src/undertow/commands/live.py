"""`undertow live` as a library function: the settings of a live session, from a settings file
and the command's options, checked before any link opens. The session that runs on them is
:class:`~undertow.live.pipeline.LiveSession`::

    from undertow.commands.live import live_settings
    from undertow.live.pipeline import LiveSession

    settings = live_settings("robot.yaml", dvl="tcp://192.168.194.95", wave="auto")
    session = LiveSession(settings, "dive1").start()
    result = session.run()          # until stopped: session.request_stop() from another thread
"""

from __future__ import annotations

from pathlib import Path

from ..errors import UndertowError
from ..live.pipeline import check_live_settings
from ..settings import Settings
from .common import as_settings


def live_settings(settings: Settings | str | Path | None = None, *, variant: str | None = None,
                  **live) -> Settings:  # fmt: skip
    """``settings`` (a :class:`~undertow.settings.Settings`, a settings YAML path or None:
    defaults) with the ``live`` fields given (:class:`~undertow.settings.LiveSettings` fields;
    None: not given) on top of its ``live`` section and ``variant`` on its localizer's. A value
    out of range is one line naming the field; no sensor link given is an error
    (:func:`~undertow.live.pipeline.check_live_settings`)."""
    settings = as_settings(settings)
    data = settings.model_dump(exclude_unset=True)
    data["live"] = {**data.get("live", {}), **{k: v for k, v in live.items() if v is not None}}
    if variant is not None:
        data["localizer"] = {**data.get("localizer", {}), "variant": variant}
    try:
        settings = Settings.model_validate(data)
    except ValueError as exc:  # pydantic: one line naming the field
        first = str(exc).splitlines()
        raise UndertowError(f"live options: {' '.join(first[1:3]).strip()}") from None
    check_live_settings(settings)
    return settings
