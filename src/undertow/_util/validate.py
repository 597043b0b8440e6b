"""Pydantic validation with the project's error style: one line naming where and what."""

from __future__ import annotations

from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, ValidationError

from ..errors import ConfigError

M = TypeVar("M", bound=BaseModel)

# names a settings, calibration or profile file may still use from before the rename to one
# name per quantity and one spelling per unit (_m_s, _rad_s, _rad); refused with the new name
RENAMED = {
    "dead_reckoning_drift_rad_per_s": "dr_bias_drift_rad_s",
    "imu_gyro_bias_rad_per_s": "gyro_bias_rad_s",
    "initial_gyro_bias_rad_s": "gyro_bias_rad_s",
    "dvl_std_mps": "dvl_std_m_s",
    "dvl_extra_std_mps": "dvl_extra_std_m_s",
}


def validate(model: type[M], data, prefix: str) -> M:
    """``model.model_validate(data)``; the first error becomes ``ConfigError(prefix + "field.path:
    message")`` (e.g. prefix ``"run.yaml: field "`` gives ``run.yaml: field dvl.rate_hz: ...``).
    A key renamed since an earlier release (:data:`RENAMED`) is refused naming its new name."""
    refuse_renamed(data, prefix, ())
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(_key(p) for p in err["loc"]) or "(top level)"
        raise ConfigError(f"{prefix}{where}: {err['msg']}") from None


def _key(part) -> str:
    """A key of an error's location as text on one line: quoted (repr) when it is empty or holds
    whitespace or control characters, as a user's stray key may (found by hypothesis)."""
    text = str(part)
    return (
        text if text and text.isprintable() and not any(c.isspace() for c in text) else repr(text)
    )


def refuse_renamed(data, prefix: str, where: tuple = ()) -> None:
    """ConfigError naming the new name of the first key of ``data`` (nested) in :data:`RENAMED`."""
    if isinstance(data, dict):
        for key, value in data.items():
            if isinstance(key, str) and key in RENAMED:
                path = ".".join((*where, _key(key)))
                raise ConfigError(f"{prefix}{path}: renamed, use {RENAMED[key]!r}")
            refuse_renamed(value, prefix, (*where, _key(key)))
    elif isinstance(data, list):
        for i, value in enumerate(data):
            refuse_renamed(value, prefix, (*where, str(i)))


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
