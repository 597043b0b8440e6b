"""MAVLink messages (ArduSub on a BlueROV2) as undertow measurements, shared by the ``.tlog``
reader and the live MAVLink link.

Units are those of the MAVLink message definitions (common.xml / ardupilotmega.xml, as shipped
with pymavlink; the gyro scale is read from each message's ``fieldunits_by_name``):

- ``ATTITUDE``: roll, pitch, yaw (rad) and rollspeed, pitchspeed, yawspeed (rad/s), in the
  aeronautical frame (x forward, y right, z down, ZYX intrinsic = undertow's body FRD and its
  R = Rz(psi) Ry(theta) Rx(phi)). ArduPilot sends the AHRS body rates (gyro with the EKF's
  bias estimate removed) as the three speeds.
- ``SCALED_IMU``/``SCALED_IMU2``/``SCALED_IMU3``/``RAW_IMU``: gyro in mrad/s -> rad/s
  (omega = 1e-3 g), accelerations in mG -> m/s^2 (f = 1e-3 g0 a; the specific force, (0, 0, -g)
  at rest in FRD, as undertow's IMU).
- ``SCALED_PRESSURE``/``2``/``3``: press_abs (hPa) -> Pa (p = 100 press_abs); on a BlueROV2 the
  external Bar30 is ``SCALED_PRESSURE2`` (configurable).
- ``VISION_POSITION_DELTA`` (what the BlueOS DVL extension sends): over time_delta_usec dt (us),
  position_delta d (m, in the current body FRD frame) and angle_delta a (rad, rotation vector
  from the previous to the current body frame), confidence c (%). It becomes a DVL velocity
  v = d / (1e-6 dt) (body frame: the extension already rotated it into the vehicle frame, so the
  Log's DVL mount rotation is zero) valid when c >= ``min_confidence``, and dead reckoning
  integrated from the first message: R_k = R_{k-1} Exp(a_k), p_k = p_{k-1} + R_k d_k
  (position and attitude relative to the body frame at the start of the first message's
  interval, z down).
- ``DISTANCE_SENSOR``: current_distance, min/max_distance (cm) -> m; signal_quality (%,
  0 = unknown) -> confidence in 0..1 (NaN when unknown); only downward sensors (orientation 25,
  MAV_SENSOR_ROTATION_PITCH_270) and, when ``range_sensor_id`` is set, only that id.
  ``RANGEFINDER`` (ArduPilot, distance in m) is used when no DISTANCE_SENSOR was seen.

The timestamp of every record is chosen by the caller (the ``.tlog`` receive time, or the
arrival time live); ``time_boot_ms``/``time_usec`` are kept as ``sensor_time`` (s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..log import G0
from ..records import Record
from ..robot import Mounting, SensorMount
from ..rotations import matrix_to_rpy, rpy_to_quaternion_scalar
from .collect import MALFORMED

IMU_MESSAGES = ("SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3", "RAW_IMU")
PRESSURE_MESSAGES = ("SCALED_PRESSURE", "SCALED_PRESSURE2", "SCALED_PRESSURE3")
GYRO_SOURCES = ("attitude", *[m.lower() for m in IMU_MESSAGES])
MAV_SENSOR_ROTATION_PITCH_270 = 25
_RATE_UNITS = {"mrad/s": 1e-3, "rad/s": 1.0}
_ACCEL_UNITS = {"mG": 1e-3 * G0, "m/s/s": 1.0}


@dataclass(frozen=True)
class MavlinkConfig:
    """Which MAVLink messages feed which stream.

    ``gyro``: ``attitude`` (default: ATTITUDE rates and orientation, one IMU row per message;
    ArduSub streams it at the highest rate) or one of ``scaled_imu``, ``scaled_imu2``,
    ``scaled_imu3``, ``raw_imu`` (the gyro and accelerometer of that IMU, with the orientation of
    the latest ATTITUDE); ``pressure``: the SCALED_PRESSURE message of the external sensor
    (``SCALED_PRESSURE2`` for the Bar30 of a BlueROV2); ``range_sensor_id``: the
    DISTANCE_SENSOR id to use (None: any downward-looking sensor); ``min_confidence``: the
    VISION_POSITION_DELTA confidence (%) below which a DVL velocity is flagged invalid.
    """

    gyro: str = "attitude"
    pressure: str = "SCALED_PRESSURE2"
    range_sensor_id: int | None = None
    min_confidence: float = 1.0

    def __post_init__(self) -> None:
        if self.gyro not in GYRO_SOURCES:
            raise ConfigError(
                f"mavlink.gyro: '{self.gyro}' is not one of {', '.join(GYRO_SOURCES)}"
            )
        if self.pressure not in PRESSURE_MESSAGES:
            raise ConfigError(
                f"mavlink.pressure: '{self.pressure}' is not one of {', '.join(PRESSURE_MESSAGES)}"
            )
        if self.range_sensor_id is not None and not 0 <= int(self.range_sensor_id) <= 255:
            raise ConfigError("mavlink.range_sensor_id: expected an integer 0..255 or None")
        if not 0.0 <= float(self.min_confidence) <= 100.0:
            raise ConfigError("mavlink.min_confidence: expected a percentage 0..100")


def _finite(*values: float) -> bool:
    for v in values:  # (a loop, not all() over a generator: this runs for every message)
        if not (isinstance(v, int | float) and math.isfinite(v)):
            return False
    return True


def _rotation_vector_matrix(a: np.ndarray) -> np.ndarray:
    """Exp(a): Rodrigues' formula R = I + sin(th) K + (1 - cos(th)) K^2, th = |a|, K = [a/th]x."""
    th = float(np.linalg.norm(a))
    if th < 1e-12:
        return np.eye(3)
    k = a / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * (K @ K)


class MavlinkMapper:
    """Turns MAVLink messages into :class:`~undertow.records.Record` objects
    (stateful: the dead-reckoning integral, the latest attitude, the range sensor chosen).

    :meth:`records` takes a decoded pymavlink message and its time ``t`` (s) and returns the
    records it gives (possibly none); a message with unusable fields (non-finite, a zero
    time_delta_usec) gives none and is counted in :attr:`malformed`.
    """

    def __init__(self, config: MavlinkConfig | None = None, source: str = "mavlink") -> None:
        self.config = config or MavlinkConfig()
        self.source = source
        self.malformed = 0
        self.ignored_range_ids: set[int] = set()
        self.range_id: int | None = self.config.range_sensor_id
        self._attitude_q: tuple | None = None
        self._R = np.eye(3)
        self._p = np.zeros(3)
        self._seen_distance_sensor = False
        self._gyro_msg = None if self.config.gyro == "attitude" else self.config.gyro.upper()
        self._handlers = {
            "ATTITUDE": self._attitude,
            self.config.pressure: self._pressure,
            "VISION_POSITION_DELTA": self._vision_delta,
            "DISTANCE_SENSOR": self._distance_sensor,
            "RANGEFINDER": self._rangefinder,
        }
        if self._gyro_msg:
            self._handlers[self._gyro_msg] = self._imu

    @property
    def message_types(self) -> tuple[str, ...]:
        """The message names this mapper uses."""
        return tuple(self._handlers)

    @staticmethod
    def dvl_mount() -> SensorMount:
        """The DVL mount for VISION_POSITION_DELTA data: velocities are already in the body
        frame (zero rotation); the lever arm stays the BlueROV2 default's."""
        return SensorMount(Mounting().dvl.translation, (0.0, 0.0, 0.0))

    def records(self, msg, t: float, arrival: float = math.nan) -> list[Record]:
        handler = self._handlers.get(msg.get_type())
        if handler is None:
            return []
        try:
            out = handler(msg, t, arrival)
        except MALFORMED:  # a field of the wrong type or size, a unit not in the tables
            out = None
        if out is None:
            self.malformed += 1
            return []
        return out

    def _record(self, stream, t, data, arrival, sensor_time=math.nan) -> Record:
        return Record(stream, float(t), data, arrival, sensor_time, self.source)

    @staticmethod
    def _boot_s(msg) -> float:
        ms = getattr(msg, "time_boot_ms", None)
        return ms * 1e-3 if isinstance(ms, int) else math.nan

    def _attitude(self, msg, t, arrival):
        rpy = (msg.roll, msg.pitch, msg.yaw)
        rates = (msg.rollspeed, msg.pitchspeed, msg.yawspeed)
        if not _finite(*rpy, *rates):
            return None
        q = rpy_to_quaternion_scalar(*rpy)
        self._attitude_q = q
        if self._gyro_msg is not None:
            return []
        data = {"angular_velocity": rates, "orientation": q}
        return [self._record("imu", t, data, arrival, self._boot_s(msg))]

    def _imu(self, msg, t, arrival):
        units = msg.fieldunits_by_name
        w = _RATE_UNITS[units.get("xgyro", "mrad/s")]
        f = _ACCEL_UNITS[units.get("xacc", "mG")]
        gyro = (msg.xgyro * w, msg.ygyro * w, msg.zgyro * w)
        acc = (msg.xacc * f, msg.yacc * f, msg.zacc * f)
        if not _finite(*gyro, *acc):
            return None
        q = self._attitude_q if self._attitude_q is not None else (math.nan,) * 4
        data = {"angular_velocity": gyro, "linear_acceleration": acc, "orientation": q}
        usec = getattr(msg, "time_usec", None)
        sensor = usec * 1e-6 if isinstance(usec, int) else self._boot_s(msg)
        return [self._record("imu", t, data, arrival, sensor)]

    def _pressure(self, msg, t, arrival):
        p = msg.press_abs * 100.0
        if not _finite(p):
            return None
        return [self._record("pressure", t, {"pressure": p}, arrival, self._boot_s(msg))]

    def _vision_delta(self, msg, t, arrival):
        dt = msg.time_delta_usec * 1e-6
        d = np.array(msg.position_delta[:3], dtype=float)
        a = np.array(msg.angle_delta[:3], dtype=float)
        c = float(msg.confidence)
        if not (dt > 0 and np.isfinite(d).all() and np.isfinite(a).all() and _finite(c)):
            return None
        self._R = self._R @ _rotation_vector_matrix(a)
        self._p = self._p + self._R @ d
        v = d / dt
        sensor = msg.time_usec * 1e-6
        dvl = {"velocity": tuple(v), "valid": c >= self.config.min_confidence}
        dr = {
            "position": tuple(self._p),
            "orientation": tuple(matrix_to_rpy(self._R)),
            "std": math.nan,
        }
        return [
            self._record("dvl", t, dvl, arrival, sensor),
            self._record("dead_reckoning", t, dr, arrival, sensor),
        ]

    def _distance_sensor(self, msg, t, arrival):
        self._seen_distance_sensor = True
        if msg.orientation != MAV_SENSOR_ROTATION_PITCH_270:
            return []
        if self.range_id is None:
            self.range_id = int(msg.id)
        if msg.id != self.range_id:
            self.ignored_range_ids.add(int(msg.id))
            return []
        r = msg.current_distance / 100.0
        quality = getattr(msg, "signal_quality", 0)
        data = {
            "range": r,
            "confidence": quality / 100.0 if 0 < quality <= 100 else math.nan,
            "min_range": msg.min_distance / 100.0,
            "max_range": msg.max_distance / 100.0,
        }
        fov = getattr(msg, "horizontal_fov", 0.0)
        if _finite(fov) and fov > 0:
            data["field_of_view"] = float(fov)
        return [self._record("sonar", t, data, arrival, self._boot_s(msg))]

    def _rangefinder(self, msg, t, arrival):
        if self._seen_distance_sensor:
            return []
        if not _finite(msg.distance):
            return None
        data = {"range": float(msg.distance), "confidence": math.nan}
        return [self._record("sonar", t, data, arrival)]
