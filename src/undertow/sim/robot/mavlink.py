"""A virtual autopilot: the log's IMU, pressure (and optionally sonar) sent as MAVLink with
pymavlink, the inverse of :class:`undertow.io.mavlink.MavlinkMapper`.

Messages (units of the MAVLink common message set, common.xml), system 1 component 1 (an
ArduSub autopilot), MAVLink 2, to any pymavlink connection string (default
``udpout:127.0.0.1:14550``, where BlueOS's router sends the telemetry):

- ``ATTITUDE`` per IMU row: roll, pitch, yaw (rad) and rollspeed, pitchspeed, yawspeed (rad/s,
  the row's angular velocity; float32 on the wire). The attitude is the IMU's orientation when
  the log has it, else the ground truth's (a simulated log: the autopilot's AHRS), else the
  message is not sent.
- ``SCALED_IMU2`` per IMU row with a linear acceleration: gyro mrad/s = round(1000 omega),
  acceleration mG = round(1000 f / g0) (int16, clipped).
- ``SCALED_PRESSURE2`` per pressure row: press_abs hPa = p / 100 (float32), temperature
  15 degC.
- ``DISTANCE_SENSOR`` per sonar row when asked: current/min/max distance cm (uint16),
  orientation 25 (MAV_SENSOR_ROTATION_PITCH_270, downward), id 1, signal_quality % (0 =
  unknown).
- ``HEARTBEAT`` once per second of log time (MAV_TYPE_SUBMARINE, MAV_AUTOPILOT_ARDUPILOTMEGA).

``time_boot_ms`` = 1000 (tau - t0) (+ a clock-jump fault): the autopilot booted when the log
starts (:class:`~undertow.sim.robot.player.PlayClock`).
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from ...errors import ConfigError
from ...log import G0, Log
from ...rotations import quaternion_to_rpy
from .player import Faults, Manifest, PlayClock, Served, flip_one_byte

DEFAULT_ADDRESS = "udpout:127.0.0.1:14550"
MAV_TYPE_SUBMARINE = 12
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_STATE_ACTIVE = 4
MAV_DISTANCE_SENSOR_ULTRASOUND = 1
MAV_SENSOR_ROTATION_PITCH_270 = 25
#: MAVLink v2 header length (bytes before the payload)
HEADER_V2 = 10


def _int16(values) -> list[int]:
    return [int(min(max(round(v), -32768), 32767)) for v in values]


def _attitude_rpy(log: Log) -> np.ndarray | None:
    """Roll, pitch, yaw (rad) at the IMU rows: the IMU's orientation, else the ground truth's."""
    imu = log.imu
    if imu.orientation is not None and np.isfinite(imu.orientation).all():
        return quaternion_to_rpy(imu.orientation)
    gt = log.ground_truth
    if gt is not None and len(gt) > 1:
        _, rpy, _ = gt.interpolate(np.clip(imu.t, gt.t[0], gt.t[-1]))
        return rpy
    return None


def corrupt_packet(packet: bytes, rng: np.random.Generator) -> bytes:
    """``packet`` with one payload or CRC byte changed (the CRC-16/MCRF4XX check then fails;
    the length field is untouched, so the next packet parses)."""
    return flip_one_byte(packet, HEADER_V2, rng)


class MavlinkSender:
    """The MAVLink sink of the player (module docstring)."""

    protocol = "mavlink"

    def __init__(
        self,
        log: Log,
        manifest: Manifest,
        faults: Faults,
        rng: np.random.Generator,
        address: str = DEFAULT_ADDRESS,
        distance_sensor: bool = False,
        heartbeat_hz: float = 1.0,
    ) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink2

        self.m = mavlink2
        self.log, self.manifest = log, manifest
        self.clock: PlayClock | None = None  # set by the player
        self.faults, self.rng = faults, rng
        self.address = str(address)
        self.distance_sensor = bool(distance_sensor)
        self.heartbeat_hz = float(heartbeat_hz)
        self.mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        #: one packer and socket for the player and the virtual autopilot (its replies)
        self.lock = threading.Lock()
        imu = log.imu
        self.rpy = _attitude_rpy(log) if imu is not None and len(imu) else None
        self.conn = None

    def schedule(self, log: Log) -> dict[str, np.ndarray]:
        out = {}
        if log.imu is not None and len(log.imu):
            if self.rpy is not None:
                out["attitude"] = log.imu.t
            if log.imu.linear_acceleration is not None:
                out["scaled_imu2"] = log.imu.t
        if log.pressure is not None and len(log.pressure):
            out["pressure"] = log.pressure.t
        if self.distance_sensor and log.sonar is not None and len(log.sonar):
            out["sonar"] = log.sonar.t
        if out and self.heartbeat_hz > 0:
            t0, t1 = log.time_span
            out["heartbeat"] = np.arange(t0, t1 + 1e-9, 1.0 / self.heartbeat_hz)
        return out

    def ready(self) -> bool:
        return True  # datagrams: nobody to wait for

    def open(self) -> MavlinkSender:
        from pymavlink import mavutil

        try:
            self.conn = mavutil.mavlink_connection(
                self.address, source_system=1, source_component=1
            )
        except Exception as exc:  # pymavlink raises bare Exceptions for bad addresses
            raise ConfigError(f"--mavlink '{self.address}': {exc}") from None
        return self

    def close(self) -> None:
        if self.conn is not None:
            try:
                self.conn.close()
            except OSError:
                pass

    def message(self, key: str, index: int, at: float):
        """(message name, undertow stream, pymavlink message, time_boot_ms or None)."""
        stream = {"attitude": "imu", "scaled_imu2": "imu"}.get(key, key)
        boot = self.clock.boot_ms(at, self.faults.jump(stream, at - self.clock.t0))
        m, log = self.m, self.log
        if key == "attitude":
            rates = [float(v) for v in log.imu.angular_velocity[index]]
            return (
                "ATTITUDE",
                stream,
                m.MAVLink_attitude_message(boot, *self.rpy[index], *rates),
                boot,
            )
        if key == "scaled_imu2":
            imu = log.imu
            gyro = _int16(1e3 * imu.angular_velocity[index])
            acc = _int16(1e3 / G0 * imu.linear_acceleration[index])
            msg = m.MAVLink_scaled_imu2_message(boot, *acc, *gyro, 0, 0, 0, 1500)
            return "SCALED_IMU2", stream, msg, boot
        if key == "pressure":
            hpa = float(log.pressure.pressure[index]) / 100.0
            return (
                "SCALED_PRESSURE2",
                stream,
                m.MAVLink_scaled_pressure2_message(boot, hpa, 0.0, 1500),
                boot,
            )
        if key == "sonar":
            return "DISTANCE_SENSOR", stream, self._distance(index, boot), boot
        msg = m.MAVLink_heartbeat_message(
            MAV_TYPE_SUBMARINE, MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, MAV_STATE_ACTIVE, 3
        )
        return "HEARTBEAT", "", msg, None

    def _distance(self, index: int, boot: int):
        s = self.log.sonar
        r = float(s.range[index])
        c = math.nan if s.confidence is None else float(s.confidence[index])
        cm = int(min(max(round(100 * r), 0), 65535)) if math.isfinite(r) else 65535
        quality = int(round(100 * c)) if math.isfinite(c) and 0 < c <= 1 else 0
        return self.m.MAVLink_distance_sensor_message(
            boot,
            int(round(100 * s.min_range)),
            int(min(round(100 * s.max_range), 65535)),
            cm,
            MAV_DISTANCE_SENSOR_ULTRASOUND,
            1,
            MAV_SENSOR_ROTATION_PITCH_270,
            255,
            horizontal_fov=float(s.field_of_view),
            signal_quality=quality,
        )

    def emit(self, key: str, index: int, at: float) -> None:
        name, stream, msg, boot = self.message(key, index, at)
        with self.lock:
            packet = bytes(msg.pack(self.mav))
            self.mav.seq = (self.mav.seq + 1) % 256
            fault, out = "", packet
            if self.faults.corrupt and self.rng.random() < self.faults.corrupt:
                fault, out = "corrupt", corrupt_packet(packet, self.rng)
            self.conn.write(out)
        sensor = math.nan if boot is None else boot * 1e-3
        self.manifest.add(
            Served(
                "mavlink",
                name,
                stream,
                index if stream else -1,
                at,
                at,
                sensor,
                time.time(),
                fault,
                -1,
                packet,
            )
        )

    def send(self, msg, at: float) -> None:
        """Send one more message (the virtual autopilot's replies) on the same link and
        sequence, listed in the manifest with no stream; never corrupted."""
        with self.lock:
            packet = bytes(msg.pack(self.mav))
            self.mav.seq = (self.mav.seq + 1) % 256
            self.conn.write(packet)
        self.manifest.add(
            Served("mavlink", msg.get_type(), "", -1, at, at, math.nan, time.time(), "", -1, packet)
        )
