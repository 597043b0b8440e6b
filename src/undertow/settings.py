"""One settings file for every stage: ``topics``, ``log``, ``mounting``, ``localizer``,
``mapping``, ``trajectory``, ``live``.

Each section is the stage's own pydantic model (:class:`~undertow.io.topics.TopicMap`,
:class:`~undertow.estimation.config.LocalizerConfig`,
:class:`~undertow.mapping.config.MappingConfig`); every field has a default, so an empty file (or
no file) runs, and a file sets only what differs::

    topics: {imu: [/mavros/imu/data]}
    log: {time: record, imu_units: deg/s, surface_pressure_pa: 85300, water: fresh}
    mounting: {imu: {rotation: [3.141592653589793, 0, 0]}}   # IMU in ROS FLU, body is FRD
    localizer: {variant: proposed, dvl_velocity_std_m_s: [0.02, 0.02, 0.01]}
    mapping: {method: adaptive, resolution: 0.05}
    trajectory: {position_std_m: [0.05, 0.05, 0.02], frame: auto}   # a TUM file to map from
    live: {dvl: tcp://192.168.194.95:16171, mavlink: "udpin:0.0.0.0:14550"}

The simulator's scenarios are separate files (see :mod:`undertow.sim.scenario`).
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from ._util.validate import read_yaml, validate
from .errors import ConfigError
from .estimation.config import LocalizerConfig
from .io.read_options import LogOptions
from .io.topics import TopicMap
from .io.trajectory_input import TrajectoryOptions
from .log import Log
from .mapping.config import MappingConfig

#: fixed pose-variance bounds (m^2, min then max per axis) of the adaptive kernel when mapping
#: live, where no session is known in advance: no stretch at zero variance, the longest length
#: scale from a 1 m horizontal and 0.1 m vertical position standard deviation on
LIVE_VARIANCE_BOUNDS = ((0.0, 0.0, 0.0), (1.0, 1.0, 0.01))


class LiveSettings(BaseModel):
    """``undertow live``: the sensor links (any subset) and the pipeline's options."""

    model_config = ConfigDict(extra="forbid")

    dvl: str | None = Field(None, description="A50 TCP address, tcp://HOST[:PORT] (16171)")
    sonar: str | None = Field(None, description="Ping1D: udp://HOST:PORT or a serial device")
    mavlink: str | None = Field(None, description="pymavlink address, e.g. udpin:0.0.0.0:14550")
    wave: str | None = Field(None, description="auto, a condition name, or none (the log's)")
    time_scale: float = Field(
        1.0, gt=0, allow_inf_nan=False,
        description="sensor time per wall second (serve --rate R plays R times real time)",
    )  # fmt: skip
    reorder_s: float = Field(
        0.25, ge=0, allow_inf_nan=False, description="reorder buffer, sensor seconds"
    )
    commit_every_s: float = Field(
        0.5, ge=0, allow_inf_nan=False,
        description="sensor seconds between releases from the buffer to the filter and map",
    )  # fmt: skip
    max_clock_offset_s: float = Field(
        1.0, gt=0, allow_inf_nan=False,
        description="a sensor clock within this of arrival is trusted (wall s; x time_scale)",
    )  # fmt: skip
    ping_rate_hz: float = Field(10.0, gt=0, le=100, description="Ping1D request rate, Hz")
    map: bool = Field(True, description="map the sonar and DVL ranges online")
    record_pose_hz: float | None = Field(
        10.0, gt=0, description="poses recorded per sensor second (None: every filter state)"
    )
    wave_update_s: float = Field(10.0, gt=0, allow_inf_nan=False, description="s between updates")
    wave_window_s: float = Field(60.0, gt=0, allow_inf_nan=False, description="estimate window, s")
    reset_dead_reckoning: bool = False
    calibrate_gyro: bool = False
    view: bool = Field(False, description="serve the Foxglove live view")
    view_host: str = "127.0.0.1"
    view_port: int = Field(8765, ge=0, le=65535)
    idle_stop_s: float | None = Field(
        None, gt=0, description="stop once no record came for this long (wall s), after data"
    )
    duration_s: float | None = Field(None, gt=0, description="stop after this long (wall s)")


class Settings(BaseModel):
    """All stages' settings (defaults run with no file)."""

    model_config = ConfigDict(extra="forbid")

    topics: TopicMap = Field(default_factory=TopicMap)
    #: how logs are read where the data cannot say: time base, gyro unit, surface pressure, water
    log: LogOptions = Field(default_factory=LogOptions)
    #: sensor mounting overrides applied to every log read (e.g. an IMU logged in ROS's FLU
    #: convention: ``imu: {rotation: [3.141592653589793, 0, 0]}``); see Mounting.updated
    mounting: dict = Field(default_factory=dict)
    localizer: LocalizerConfig = Field(default_factory=LocalizerConfig)
    mapping: MappingConfig = Field(default_factory=MappingConfig)
    #: how a trajectory made elsewhere (TUM) is read for mapping: its pose std, its frame
    trajectory: TrajectoryOptions = Field(default_factory=TrajectoryOptions)
    live: LiveSettings = Field(default_factory=LiveSettings)

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
