"""Pydantic validation with the project's error style: one line naming where and what."""

from __future__ import annotations

from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, ValidationError

from ..errors import ConfigError

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


def read_yaml(path, what: str):
    """Parse a user's YAML file; any failure is one ``ConfigError`` line naming the file and
    ``what`` it should be: missing or unreadable, binary (not UTF-8 text), or malformed YAML (the
    parser's first problem with its line and column)."""
    import yaml

    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: not a {what} (binary content: byte {exc.object[exc.start]:#04x} at "
            f"offset {exc.start} is not UTF-8 text)"
        ) from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"{path}: invalid YAML in {what}{where}: {problem}") from None
