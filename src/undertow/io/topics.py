"""Which ROS topic holds which measurement stream: :class:`TopicMap`.

Each field is a list of candidate topic names; the first one present in a bag wins, so common
alternatives of BlueROV2 logs (``/BlueROV/pressure2_fluid``, ``/vectornav/IMU``,
``/ping_sonar/data``) work without a file. The DVL topic is decoded by message type
(``waterlinked_a50_ros_driver/msg/DVL`` or ``marine_acoustic_msgs/msg/Dvl``), never by name.
"""

from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import BaseModel, ConfigDict, field_validator

from .._validate import validate
from ..errors import ConfigError

STREAM_FIELDS = (
    "dvl",
    "dead_reckoning",
    "dvl_json",
    "imu",
    "pressure",
    "sonar",
    "wave_probe",
    "ground_truth",
)


class TopicMap(BaseModel):
    """Candidate topic names per stream (first found wins); a single string is accepted."""

    model_config = ConfigDict(extra="forbid")

    dvl: list[str] = ["/dvl/data"]
    dead_reckoning: list[str] = ["/dvl/local_position"]
    dvl_json: list[str] = ["/dvl/json_data"]
    imu: list[str] = ["/imu/data", "/vectornav/IMU", "/mavros/imu/data", "/BlueROV/imu"]
    pressure: list[str] = ["/fluid_pressure", "/BlueROV/pressure2_fluid", "/pressure"]
    sonar: list[str] = ["/ping_sonar/range", "/ping_sonar/data", "/sonar/range"]
    wave_probe: list[str] = ["/wave_probe"]
    ground_truth: list[str] = ["/ground_truth/odom", "/ground_truth"]

    @field_validator(*STREAM_FIELDS, mode="before")
    @classmethod
    def _one_or_many(cls, value):
        return [value] if isinstance(value, str) else value

    def first(self, stream: str) -> str:
        """The preferred (first) topic name of ``stream`` (used by the writer)."""
        return getattr(self, stream)[0]

    def resolve(self, available) -> dict[str, str]:
        """Map each stream to the first of its candidates found in ``available`` topic names."""
        available = set(available)
        found = {}
        for stream in STREAM_FIELDS:
            for topic in getattr(self, stream):
                if topic in available:
                    found[stream] = topic
                    break
        return found

    @classmethod
    def from_yaml(cls, path) -> TopicMap:
        """Load from a YAML mapping ``stream: topic`` or ``stream: [topic, ...]``."""
        path = Path(path)
        try:
            data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
        except OSError as exc:
            raise ConfigError(f"{path}: cannot read topic map: {exc.strerror or exc}") from exc
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: invalid YAML: {str(exc).splitlines()[0]}") from exc
        if isinstance(data, dict) and isinstance(data.get("topics"), dict):
            data = data["topics"]
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: topic map must be a mapping of stream name to topic(s)")
        return validate(cls, data, f"{path}: topic map field ")
