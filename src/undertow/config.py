"""One settings file for every stage: ``topics``, ``localizer`` and ``mapping`` sections.

Each section is the stage's own pydantic model (:class:`~undertow.io.topics.TopicMap`,
:class:`~undertow.estimation.localize.LocalizerConfig`,
:class:`~undertow.mapping.config.MappingConfig`); every field has a default, so an empty file (or
no file) runs, and a file sets only what differs::

    topics: {imu: [/mavros/imu/data]}
    localizer: {variant: proposed, dvl_velocity_std_m_s: [0.02, 0.02, 0.01]}
    mapping: {method: adaptive, resolution: 0.05}

The simulator's scenarios are separate files (see :mod:`undertow.sim.scenario`).
"""

from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import BaseModel, ConfigDict, Field

from ._validate import validate
from .errors import ConfigError
from .estimation.localize import LocalizerConfig
from .io.topics import TopicMap
from .mapping.config import MappingConfig


class Settings(BaseModel):
    """All stages' settings (defaults run with no file)."""

    model_config = ConfigDict(extra="forbid")

    topics: TopicMap = Field(default_factory=TopicMap)
    localizer: LocalizerConfig = Field(default_factory=LocalizerConfig)
    mapping: MappingConfig = Field(default_factory=MappingConfig)

    @classmethod
    def from_yaml(cls, path: str | Path | None) -> Settings:
        """Read a settings file; errors name the file and the field, in one line."""
        if path is None:
            return cls()
        try:
            data = yaml.safe_load(Path(path).read_text()) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise ConfigError(f"{path}: cannot read settings ({exc})") from exc
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: settings must be a mapping with topics/localizer/mapping")
        return validate(cls, data, f"{path}: ")

    def localizer_params(self) -> dict:
        """The localizer fields the file set explicitly (keyword arguments of Localizer)."""
        return self.localizer.model_dump(exclude_unset=True)
