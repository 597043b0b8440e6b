"""Which ROS topic holds which stream, which tf frame is which sensor: :class:`TopicMap`.

Each stream field is a list of candidate topic names; the first one present in a bag wins, so
common alternatives of BlueROV2 logs (``/BlueROV/pressure2_fluid``, ``/vectornav/IMU``,
``/ping_sonar/data``) work without a file. The DVL topic is decoded by message type
(``waterlinked_a50_ros_driver/msg/DVL`` or ``marine_acoustic_msgs/msg/Dvl``), never by name.
The multibeam is a ``sensor_msgs/msg/PointCloud2`` of detections in the sensor frame (the
common output of MBES ROS drivers), on ``/mbes/points`` or ``/multibeam/points``.
A candidate list the user changed (not the default) that matches no topic of a bag is reported
by the reader (one warning line); absent defaults stay silent (a DVL-only log is legal).

Sensor mounting as ROS sees it: ``tf_static`` (``tf2_msgs/msg/TFMessage``) holds one transform
per sensor from ``base_frame`` to the sensor's frame; ``frames`` names those frames (candidates,
first used by the writer, all recognized by the reader). Only direct children of ``base_frame``
are read (no chains of transforms).
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, field_validator

from .._util.validate import read_yaml, validate
from ..errors import ConfigError

STREAM_FIELDS = (
    "dvl",
    "dead_reckoning",
    "dvl_json",
    "imu",
    "pressure",
    "depth",
    "sonar",
    "sonar_confidence",
    "wave_probe",
    "ground_truth",
    "gps",
    "multibeam",
)


#: a live session's wave decisions (``undertow live --wave auto``: std_msgs/String, one JSON
#: object per decision; :mod:`undertow.live.recorder`), read into ``metadata["live_wave"]``
LIVE_WAVE_TOPIC = "/undertow/wave_condition"

SENSOR_NAMES = ("imu", "dvl", "sonar", "barometer")  # as in robot.Mounting; always in /tf_static
#: every sensor with a tf frame: the multibeam's transform is written when the log has one
ALL_SENSOR_NAMES = (*SENSOR_NAMES, "multibeam")


def _as_list(value):
    return [value] if isinstance(value, str) else value


class SensorFrames(BaseModel):
    """tf frame ids of the sensors (children of the base frame), candidates per sensor."""

    model_config = ConfigDict(extra="forbid")

    imu: list[str] = ["imu_link"]
    dvl: list[str] = ["dvl_link"]
    sonar: list[str] = ["sonar_link"]
    barometer: list[str] = ["pressure_link"]
    multibeam: list[str] = ["mbes_link"]

    @field_validator(*ALL_SENSOR_NAMES, mode="before")
    @classmethod
    def _one_or_many(cls, value):
        return _as_list(value)

    def sensor_of(self, frame_id: str) -> str | None:
        """The sensor whose frame is ``frame_id`` (a leading '/' of ROS 1 ignored), or None."""
        frame_id = frame_id.lstrip("/")
        for sensor in ALL_SENSOR_NAMES:
            if frame_id in (f.lstrip("/") for f in getattr(self, sensor)):
                return sensor
        return None


class TopicMap(BaseModel):
    """Candidate topic names per stream (first found wins); a single string is accepted.
    ``tf_static``, ``base_frame`` and ``frames``: where the sensor mounting is in a bag."""

    model_config = ConfigDict(extra="forbid")

    dvl: list[str] = ["/dvl/data"]
    dead_reckoning: list[str] = ["/dvl/local_position"]
    dvl_json: list[str] = ["/dvl/json_data"]
    imu: list[str] = ["/imu/data", "/vectornav/IMU", "/mavros/imu/data", "/BlueROV/imu"]
    pressure: list[str] = ["/fluid_pressure", "/BlueROV/pressure2_fluid", "/pressure"]
    depth: list[str] = ["/depth"]
    sonar: list[str] = ["/ping_sonar/range", "/ping_sonar/data", "/sonar/range"]
    #: the sonar's confidence beside its range (undertow_msgs/RangeConfidence, io.msgdefs)
    sonar_confidence: list[str] = ["/ping_sonar/confidence"]
    wave_probe: list[str] = ["/wave_probe"]
    ground_truth: list[str] = ["/ground_truth/odom", "/ground_truth"]
    gps: list[str] = ["/gps/fix", "/fix", "/mavros/global_position/raw/fix"]
    multibeam: list[str] = ["/mbes/points", "/multibeam/points"]
    tf_static: list[str] = ["/tf_static"]
    base_frame: str = "base_link"
    frames: SensorFrames = SensorFrames()

    @field_validator(*STREAM_FIELDS, "tf_static", mode="before")
    @classmethod
    def _one_or_many(cls, value):
        return _as_list(value)

    def is_default(self, stream: str) -> bool:
        """The stream's candidate list is the default one (the user did not name topics)."""
        return getattr(self, stream) == type(self).model_fields[stream].default

    def first(self, stream: str) -> str:
        """The preferred (first) topic name of ``stream`` (used by the writer)."""
        return getattr(self, stream)[0]

    def resolve(self, available) -> dict[str, str]:
        """Map each stream (and ``tf_static``) to the first of its candidates found in
        ``available`` topic names."""
        available = set(available)
        found = {}
        for stream in (*STREAM_FIELDS, "tf_static"):
            for topic in getattr(self, stream):
                if topic in available:
                    found[stream] = topic
                    break
        return found

    def unmatched_user_topics(self, available) -> dict[str, list[str]]:
        """Streams whose candidate list differs from the default (the user named them), is not
        empty (which turns the stream off) and of which no topic is in ``available``:
        ``{stream: candidates}``."""
        available = set(available)
        return {
            stream: getattr(self, stream)
            for stream in (*STREAM_FIELDS, "tf_static")
            if getattr(self, stream)  # an empty list turns the stream off on purpose
            and getattr(self, stream) != type(self).model_fields[stream].default
            and not available.intersection(getattr(self, stream))
        }

    @classmethod
    def from_yaml(cls, path) -> TopicMap:
        """Load from a YAML mapping ``stream: topic`` or ``stream: [topic, ...]``."""
        path = Path(path)
        data = read_yaml(path, "topic map") or {}
        if isinstance(data, dict) and isinstance(data.get("topics"), dict):
            data = data["topics"]
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: topic map must be a mapping of stream name to topic(s)")
        return validate(cls, data, f"{path}: topic map field ")
