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
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

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
#: the lowest rate the autopilot link sends at: ArduPilot asks external navigation for 4 Hz or
#: more and EKF3 declares its position stale after 3 s without one; 5 Hz keeps a margin
MIN_AUTOPILOT_RATE_HZ = 5.0
AUTOPILOT_MODES = ("odometry", "vision-position", "velocity-delta")


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
    mavlink_pressure: Literal["SCALED_PRESSURE", "SCALED_PRESSURE2", "SCALED_PRESSURE3"] = Field(
        "SCALED_PRESSURE2", description="the MAVLink pressure message (Bar30: SCALED_PRESSURE2)"
    )
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
    # -- the estimate sent to the autopilot (docs/live.md, "Sending to the autopilot")
    autopilot: bool = Field(False, description="send the estimate to the autopilot (--mavlink)")
    autopilot_mode: Literal["odometry", "vision-position", "velocity-delta"] = "odometry"
    autopilot_rate_hz: float = Field(10.0, allow_inf_nan=False, description="messages per s")
    autopilot_covariance_inflation: float = Field(
        2.0, ge=1.0, allow_inf_nan=False,
        description="variance factor on what is sent (covariance intersection, weight 1/2)",
    )  # fmt: skip
    autopilot_max_position_std_m: float = Field(
        5.0, gt=0, allow_inf_nan=False,
        description="stop sending above this horizontal std (EKF3's GPS accuracy check: 5 m)",
    )  # fmt: skip
    autopilot_dvl_timeout_s: float = Field(
        1.0, gt=0, allow_inf_nan=False, description="stop after this long without a valid DVL"
    )
    autopilot_settle_s: float = Field(
        2.0, ge=0, allow_inf_nan=False, description="filter seconds before sending after a start"
    )
    autopilot_jump_m: float = Field(
        0.5, gt=0, allow_inf_nan=False, description="a step the velocity does not explain"
    )
    autopilot_yaw_offset_deg: float | None = Field(
        None, allow_inf_nan=False, description="autopilot heading minus undertow's (None: found)"
    )
    autopilot_origin: tuple[float, float] | tuple[float, float, float] | None = Field(
        None, description="EKF origin LAT,LON[,ALT] (deg, deg, m) sent once if none is set"
    )
    autopilot_set_params: bool = Field(False, description="set the parameters (PARAM_SET)")
    autopilot_component_id: int = Field(197, ge=1, le=255, description="our MAVLink compid")

    @field_validator("autopilot_rate_hz")
    @classmethod
    def _rate_floor(cls, rate: float) -> float:
        if not rate >= MIN_AUTOPILOT_RATE_HZ:
            raise ValueError(
                f"{rate:g} Hz is below {MIN_AUTOPILOT_RATE_HZ:g} Hz, the least "
                "EKF3's external navigation is fed at (ArduPilot: 4 Hz or more)"
            )
        return rate

    @field_validator("autopilot_origin", mode="before")
    @classmethod
    def _origin(cls, value):
        if isinstance(value, str):
            value = [v for v in value.replace(" ", "").split(",") if v]
        if value is None:
            return None
        try:
            values = [float(v) for v in value]
        except (TypeError, ValueError):
            raise ValueError("expected LAT,LON[,ALT] in degrees and metres") from None
        if len(values) not in (2, 3) or not all(abs(v) < float("inf") for v in values):
            raise ValueError("expected LAT,LON[,ALT] in degrees and metres")
        if not (-90 <= values[0] <= 90 and -180 <= values[1] <= 180):
            raise ValueError(f"latitude {values[0]} / longitude {values[1]} out of range")
        return tuple(values)

    @model_validator(mode="after")
    def _autopilot_needs_mavlink(self):
        if self.autopilot and not self.mavlink:
            raise ValueError("autopilot: sending to the autopilot needs its link (--mavlink)")
        return self


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
