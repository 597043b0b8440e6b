"""One settings file for every stage: ``topics``, ``mounting``, ``localizer``, ``mapping``.

Each section is the stage's own pydantic model (:class:`~undertow.io.topics.TopicMap`,
:class:`~undertow.estimation.config.LocalizerConfig`,
:class:`~undertow.mapping.config.MappingConfig`); every field has a default, so an empty file (or
no file) runs, and a file sets only what differs::

    topics: {imu: [/mavros/imu/data]}
    mounting: {imu: {rotation: [3.141592653589793, 0, 0]}}   # IMU in ROS FLU, body is FRD
    localizer: {variant: proposed, dvl_velocity_std_m_s: [0.02, 0.02, 0.01]}
    mapping: {method: adaptive, resolution: 0.05}

The simulator's scenarios are separate files (see :mod:`undertow.sim.scenario`).
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from ._util.validate import read_yaml, validate
from .errors import ConfigError
from .estimation.config import LocalizerConfig
from .io.topics import TopicMap
from .log import Log
from .mapping.config import MappingConfig


class Settings(BaseModel):
    """All stages' settings (defaults run with no file)."""

    model_config = ConfigDict(extra="forbid")

    topics: TopicMap = Field(default_factory=TopicMap)
    #: sensor mounting overrides applied to every log read (e.g. an IMU logged in ROS's FLU
    #: convention: ``imu: {rotation: [3.141592653589793, 0, 0]}``); see Mounting.updated
    mounting: dict = Field(default_factory=dict)
    localizer: LocalizerConfig = Field(default_factory=LocalizerConfig)
    mapping: MappingConfig = Field(default_factory=MappingConfig)

    @classmethod
    def from_yaml(cls, path: str | Path | None) -> Settings:
        """Read a settings file; errors name the file and the field, in one line."""
        if path is None:
            return cls()
        data = read_yaml(path, "settings file") or {}
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: settings must be a mapping with topics/localizer/mapping")
        settings = validate(cls, data, f"{path}: ")
        try:
            Log().mounting.updated(settings.mounting)  # check it now, not at first use
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from None
        return settings

    def apply_mounting(self, log: Log) -> Log:
        """``log`` with this file's mounting overrides (unchanged when there are none)."""
        if not self.mounting:
            return log
        return log.replace(mounting=log.mounting.updated(self.mounting))

    def localizer_params(self) -> dict:
        """The localizer fields the file set explicitly (keyword arguments of Localizer)."""
        return self.localizer.model_dump(exclude_unset=True)
