"""Pydantic validation with the project's error style: one line naming where and what."""

from __future__ import annotations

from typing import TypeVar

from pydantic import BaseModel, ValidationError

from .errors import ConfigError

M = TypeVar("M", bound=BaseModel)


def validate(model: type[M], data, prefix: str) -> M:
    """``model.model_validate(data)``; the first error becomes ``ConfigError(prefix + "field.path:
    message")`` (e.g. prefix ``"run.yaml: field "`` gives ``run.yaml: field dvl.rate_hz: ...``)."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(p) for p in err["loc"]) or "(top level)"
        raise ConfigError(f"{prefix}{where}: {err['msg']}") from None
