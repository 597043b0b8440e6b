"""Writer of a :class:`~undertow.log.Log` as a ROS 2 bag (mcap storage, ROS 2 Humble types).

``flavor="driver"`` writes the DVL as ``waterlinked_a50_ros_driver/msg/DVL`` (NaN altitude as
-1, invalid beam distance as -1, as the driver does) plus the raw json_v3 line on the DVL JSON
topic; ``flavor="standard"`` writes ``marine_acoustic_msgs/msg/Dvl`` (unknown covariance -1,
``velocity_mode`` 0 for an invalid velocity, invalid beam range NaN; no fom). Other streams use
standard types: Imu, FluidPressure, Range (the sonar's confidence, when the log has it, beside it
as ``undertow_msgs/RangeConfidence`` of the same stamp, :mod:`undertow.io.msgdefs`),
PoseWithCovarianceStamped (dead reckoning, std^2 on
the position diagonal), PointStamped (wave probe: x = probe x, z = elevation up), Odometry
(ground truth, twist in the body frame as ROS requires), PointCloud2 (multibeam: one organized
cloud of B points per ping, x y z float64 in the sensor frame, NaN for a beam without a
detection, plus intensity when the stream has it; see :func:`multibeam_message`). The sensor
mounting is in the bag
itself as ``/tf_static`` (see :func:`tf_static_message`), so a bare copy of the ``.mcap`` keeps it
and ROS tools and Foxglove see the sensor frames; it is also, with source and plain metadata, in a
sidecar ``undertow.yaml``. The bag is written in a temp dir next to the target, then renamed
(nothing half-written is left at ``path``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np
import yaml
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer

from .._util.atomic import atomic_path
from .._util.plain import to_plain
from ..errors import UndertowError
from ..log import Log
from ..rotations import rpy_to_quaternion, world_to_body
from .a50_json import VelocityReport, velocity_report, velocity_report_line
from .msgdefs import A50_BEAM, A50_DVL, MARINE_DVL, RANGE_CONFIDENCE, dvl_typestore
from .rosbag import SIDECAR
from .rosbag_streams import POINTCLOUD2, TF_MESSAGE
from .topics import ALL_SENSOR_NAMES, SENSOR_NAMES, TopicMap

_ZERO = QosTime(0, 0)  # rmw default (infinite) deadline, lifespan, lease
_NO_ESTIMATE = np.array([-1.0] + [0.0] * 8)  # sensor_msgs/Imu: covariance[0] = -1, no estimate
#: /tf_static as tf2's static broadcaster offers it: latched (transient local), depth 1, reliable
TF_STATIC_QOS = Qos(
    QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
    _ZERO, _ZERO, QosLiveliness.AUTOMATIC, _ZERO, False,
)  # fmt: skip


class MessageBuilder:
    """Message constructors bound to the typestore (shared by :func:`write_log` and the live
    recorder, :mod:`undertow.live.recorder`)."""

    def __init__(self) -> None:
        self.store = dvl_typestore()
        self.T = self.store.types

    def header(self, t: float, frame: str):
        sec = math.floor(t)
        ns = int(round((t - sec) * 1e9))
        if ns >= 1_000_000_000:
            sec, ns = sec + 1, ns - 1_000_000_000
        time = self.T["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=ns)
        return self.T["std_msgs/msg/Header"](stamp=time, frame_id=frame), sec * 1_000_000_000 + ns

    def vec(self, v):
        return self.T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def point(self, v):
        return self.T["geometry_msgs/msg/Point"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quat(self, q):
        return self.T["geometry_msgs/msg/Quaternion"](
            x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])
        )

    def transform(self, t: float, parent: str, child: str, translation, rpy):
        h, _ = self.header(t, parent)
        tf = self.T["geometry_msgs/msg/Transform"](
            translation=self.vec(translation), rotation=self.quat(rpy_to_quaternion(rpy))
        )
        return self.T["geometry_msgs/msg/TransformStamped"](
            header=h, child_frame_id=child, transform=tf
        )

    def pose_cov(self, position, rpy, cov):
        pose = self.T["geometry_msgs/msg/Pose"](
            position=self.point(position), orientation=self.quat(rpy_to_quaternion(rpy))
        )
        return self.T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov)


def _decimate(t: np.ndarray, rate_hz: float | None) -> np.ndarray:
    if rate_hz is None or t.size < 2:
        return np.arange(t.size)
    _, first = np.unique(np.floor((t - t[0]) * rate_hz), return_index=True)
    return first


def write_log(
    log: Log,
    path,
    flavor: Literal["driver", "standard"] = "driver",
    topics: TopicMap | None = None,
    *,
    overwrite: bool = False,
    ground_truth_rate_hz: float | None = 100.0,
) -> Path:
    """Write ``log`` as a ROS 2 mcap bag directory at ``path``; returns the path."""
    if flavor not in ("driver", "standard"):
        raise UndertowError(f"write_log: unknown flavor {flavor!r} (use 'driver' or 'standard')")
    path = Path(path)
    if path.exists() and not overwrite:
        raise UndertowError(f"{path}: already exists (pass overwrite=True to replace it)")
    topics = topics or TopicMap()
    b = MessageBuilder()
    records = list(_messages(log, flavor, b, ground_truth_rate_hz, topics))
    records.append(tf_static_record(log, b, topics))
    records.sort(key=lambda r: r[1])
    with atomic_path(path, replaces_directory=True) as bag:
        with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = {}
            for stream, msgtype in sorted({(r[0], r[2]) for r in records}):
                qos = (TF_STATIC_QOS,) if stream == "tf_static" else ()
                conns[stream] = writer.add_connection(
                    topics.first(stream), msgtype, typestore=b.store, offered_qos_profiles=qos
                )
            for stream, ns, msgtype, msg in records:
                writer.write(conns[stream], ns, b.store.serialize_cdr(msg, msgtype))
        sidecar = {
            "source": log.source,
            "flavor": flavor,
            "mounting": to_plain(drop_unknown=True, value=log.mounting.to_dict()),
            "metadata": to_plain(drop_unknown=True, value=log.metadata) or {},
        }
        if log.multibeam is not None:
            mb = log.multibeam
            sidecar["multibeam"] = {"min_range": mb.min_range, "max_range": mb.max_range}
        (bag / SIDECAR).write_text(yaml.safe_dump(sidecar, sort_keys=False), encoding="utf-8")
    return path


def tf_static_record(log: Log, b: MessageBuilder, topics: TopicMap):
    """The mounting as one ``/tf_static`` message at the log's start (:func:`tf_static_message`)."""
    start = log.time_span[0]
    t = start if math.isfinite(start) else 0.0
    sensors = ALL_SENSOR_NAMES if log.multibeam is not None else SENSOR_NAMES
    ns, msg = tf_static_message(b, topics, log.mounting, t, sensors)
    return "tf_static", ns, TF_MESSAGE, msg


def tf_static_message(
    b: MessageBuilder, topics: TopicMap, mounting, t: float, sensors=SENSOR_NAMES
):
    """(record time ns, ``tf2_msgs/msg/TFMessage``): the mounting at time ``t``.

    One ``geometry_msgs/TransformStamped`` per sensor of ``sensors`` (imu, dvl, sonar,
    barometer; and multibeam, ``mbes_link``, when the log has one): parent
    ``topics.base_frame`` (``base_link``), child the sensor's frame (``topics.frames``:
    ``imu_link``, ``dvl_link``, ``sonar_link``, ``pressure_link``, the frame_id of that sensor's
    messages), translation = lever arm (m), rotation = quaternion of the mounting's roll, pitch,
    yaw, i.e. R_sensor^body (a vector in the sensor frame to the body frame), as tf defines a
    parent-to-child transform. The body frame keeps undertow's convention, forward-right-down
    (x forward, y right, z down), not ROS REP-103's forward-left-up; sensor frames are the
    sensors' own (A50: x forward, y right, z down).
    """
    mounts = mounting.to_dict()
    transforms = [
        b.transform(
            t,
            topics.base_frame,
            getattr(topics.frames, sensor)[0],
            mounts[sensor]["translation"],
            np.asarray(mounts[sensor]["rotation"], dtype=np.float64),
        )
        for sensor in sensors
    ]
    _, ns = b.header(t, topics.base_frame)
    return ns, b.T[TF_MESSAGE](transforms=transforms)


def _messages(log: Log, flavor: str, b: MessageBuilder, gt_rate: float | None, topics: TopicMap):
    """(stream, record time ns, msgtype, message) for every message of ``log``, stream by
    stream (DVL, IMU, pressure, sonar, wave probe, dead reckoning, ground truth)."""
    frame = {sensor: getattr(topics.frames, sensor)[0] for sensor in ALL_SENSOR_NAMES}
    if log.dvl is not None:
        yield from (_dvl_driver if flavor == "driver" else _dvl_standard)(log, b, frame["dvl"])
    if log.imu is not None:
        yield from _imu_messages(log.imu, b, frame["imu"])
    if log.pressure is not None:
        yield from _pressure_messages(log.pressure, b, frame["barometer"])
    if log.sonar is not None:
        yield from _sonar_messages(log.sonar, b, frame["sonar"])
    if log.wave_probe is not None:
        yield from _wave_probe_messages(log.wave_probe, b)
    if log.dead_reckoning is not None:
        yield from _dead_reckoning_messages(log.dead_reckoning, b)
    if log.ground_truth is not None:
        yield from _ground_truth_messages(log.ground_truth, b, gt_rate)
    if log.multibeam is not None:
        yield from _multibeam_messages(log.multibeam, b, frame["multibeam"])


def _multibeam_messages(s, b: MessageBuilder, frame: str):
    """``sensor_msgs/PointCloud2``, one per ping (:func:`multibeam_message`)."""
    for i in range(len(s)):
        intensity = None if s.intensity is None else s.intensity[i]
        ns, msg = multibeam_message(b, s.t[i], frame, s.points[i], intensity)
        yield "multibeam", ns, POINTCLOUD2, msg


def multibeam_message(b: MessageBuilder, t, frame: str, points, intensity=None):
    """(record time ns, ``sensor_msgs/PointCloud2``) of one ping: an organized cloud (height 1,
    width B, one point per beam in beam order) with fields x, y, z (and intensity) as FLOAT64
    (PointField datatype 8) at offsets 0, 8, 16 (24), little-endian; a beam without a
    detection is a NaN point and makes the cloud not dense (``is_dense`` False)."""
    columns = [np.asarray(points, np.float64).reshape(-1, 3)]
    names = ["x", "y", "z"]
    if intensity is not None:
        columns.append(np.asarray(intensity, np.float64).reshape(-1, 1))
        names.append("intensity")
    table = np.ascontiguousarray(np.hstack(columns), dtype="<f8")
    field_t = b.T["sensor_msgs/msg/PointField"]
    fields = [field_t(name=n, offset=8 * k, datatype=8, count=1) for k, n in enumerate(names)]
    h, ns = b.header(t, frame)
    step = 8 * len(names)
    return ns, b.T[POINTCLOUD2](
        header=h,
        height=1,
        width=int(table.shape[0]),
        fields=fields,
        is_bigendian=False,
        point_step=step,
        row_step=step * int(table.shape[0]),
        data=table.view(np.uint8).reshape(-1),
        is_dense=bool(np.isfinite(table).all()),
    )


def _imu_messages(s, b: MessageBuilder, frame: str):
    """``sensor_msgs/Imu``; a missing orientation or acceleration is zeros with covariance
    element 0 set to -1 ("no estimate", as the sensor_msgs/Imu message definition asks)."""
    n = len(s)
    acc = s.linear_acceleration if s.linear_acceleration is not None else np.zeros((n, 3))
    q = s.orientation if s.orientation is not None else np.zeros((n, 4))
    has_q, has_a = s.orientation is not None, s.linear_acceleration is not None
    for i in range(n):
        ns, msg = imu_message(b, s.t[i], frame, s.angular_velocity[i], acc[i], q[i], has_a, has_q)
        yield "imu", ns, "sensor_msgs/msg/Imu", msg


def imu_message(b: MessageBuilder, t, frame, angular_velocity, acc, q, has_acc, has_q):
    """(record time ns, ``sensor_msgs/Imu``) of one row; covariance element 0 of a part is -1
    when the row has no such estimate (``has_acc``/``has_q`` False)."""
    h, ns = b.header(t, frame)
    msg = b.T["sensor_msgs/msg/Imu"](
        header=h,
        orientation=b.quat(q),
        orientation_covariance=np.zeros(9) if has_q else _NO_ESTIMATE.copy(),
        angular_velocity=b.vec(angular_velocity),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=b.vec(acc),
        linear_acceleration_covariance=np.zeros(9) if has_acc else _NO_ESTIMATE.copy(),
    )
    return ns, msg


def _pressure_messages(s, b: MessageBuilder, frame: str):
    """``sensor_msgs/FluidPressure`` (Pa, variance 0: not reported)."""
    for i in range(len(s)):
        ns, msg = pressure_message(b, s.t[i], frame, s.pressure[i])
        yield "pressure", ns, "sensor_msgs/msg/FluidPressure", msg


def pressure_message(b: MessageBuilder, t, frame: str, pressure):
    """(record time ns, ``sensor_msgs/FluidPressure``) of one row (Pa, variance 0)."""
    h, ns = b.header(t, frame)
    return ns, b.T["sensor_msgs/msg/FluidPressure"](
        header=h, fluid_pressure=float(pressure), variance=0.0
    )


def _sonar_messages(s, b: MessageBuilder, frame: str):
    """``sensor_msgs/Range`` (radiation type 0: ultrasound), and the confidence beside each
    range when the stream has one."""
    limits = (s.field_of_view, s.min_range, s.max_range)
    for i in range(len(s)):
        ns, msg = sonar_message(b, s.t[i], frame, limits, s.range[i])
        yield "sonar", ns, "sensor_msgs/msg/Range", msg
        if s.confidence is not None:
            _, msg = confidence_message(b, s.t[i], frame, s.confidence[i])
            yield "sonar_confidence", ns, RANGE_CONFIDENCE, msg


def confidence_message(b: MessageBuilder, t, frame: str, confidence):
    """(record time ns, ``undertow_msgs/RangeConfidence``): the confidence (0..1, NaN unknown,
    float64) of the range of the same stamp."""
    h, ns = b.header(t, frame)
    return ns, b.T[RANGE_CONFIDENCE](header=h, confidence=float(confidence))


def sonar_message(b: MessageBuilder, t, frame: str, limits, rng):
    """(record time ns, ``sensor_msgs/Range``) of one row; ``limits`` = (field of view rad,
    min range m, max range m); radiation type 0 (ultrasound). Range fields are float32."""
    h, ns = b.header(t, frame)
    fov, rmin, rmax = limits
    return ns, b.T["sensor_msgs/msg/Range"](
        header=h,
        radiation_type=0,
        field_of_view=float(fov),
        min_range=float(rmin),
        max_range=float(rmax),
        range=float(rng),
    )


def _wave_probe_messages(s, b: MessageBuilder):
    """``geometry_msgs/PointStamped`` in ``world``: x = probe x, z = elevation (up)."""
    point_t = b.T["geometry_msgs/msg/PointStamped"]
    for i in range(len(s)):
        h, ns = b.header(s.t[i], "world")
        msg = point_t(header=h, point=b.point((s.x, 0.0, s.elevation[i])))
        yield "wave_probe", ns, "geometry_msgs/msg/PointStamped", msg


def _dead_reckoning_messages(s, b: MessageBuilder):
    """``geometry_msgs/PoseWithCovarianceStamped`` in ``dvl_odom`` (see
    :func:`dead_reckoning_message`)."""
    std = s.std if s.std is not None else np.full(len(s), np.nan)
    for i in range(len(s)):
        ns, msg = dead_reckoning_message(b, s.t[i], s.position[i], s.orientation[i], std[i])
        yield "dead_reckoning", ns, "geometry_msgs/msg/PoseWithCovarianceStamped", msg


def dead_reckoning_message(b: MessageBuilder, t, position, rpy, std):
    """(record time ns, ``geometry_msgs/PoseWithCovarianceStamped``) of one dead-reckoning row
    in ``dvl_odom``: std^2 on the position diagonal (row-major 6x6: elements 0, 7, 14), NaN
    when unknown; orientation the quaternion of (roll, pitch, yaw)."""
    h, ns = b.header(t, "dvl_odom")
    cov = np.zeros(36)
    cov[[0, 7, 14]] = std**2
    pose_t = b.T["geometry_msgs/msg/PoseWithCovarianceStamped"]
    return ns, pose_t(header=h, pose=b.pose_cov(position, rpy, cov))


def _ground_truth_messages(s, b: MessageBuilder, gt_rate: float | None):
    """``nav_msgs/Odometry`` in ``world``, decimated to ``gt_rate``; the twist is the body-frame
    velocity v_b = R^T v_w (R body to world), as nav_msgs/Odometry puts the twist in the
    child frame."""
    T = b.T
    vel = s.velocity if s.velocity is not None else np.full((len(s), 3), np.nan)
    body_vel = world_to_body(s.orientation, vel)
    twist_t = T["geometry_msgs/msg/TwistWithCovariance"]
    for i in _decimate(s.t, gt_rate):
        h, ns = b.header(s.t[i], "world")
        twist = twist_t(
            twist=T["geometry_msgs/msg/Twist"](linear=b.vec(body_vel[i]), angular=b.vec((0, 0, 0))),
            covariance=np.zeros(36),
        )
        msg = T["nav_msgs/msg/Odometry"](
            header=h,
            child_frame_id="base_link",
            pose=b.pose_cov(s.position[i], s.orientation[i], np.zeros(36)),
            twist=twist,
        )
        yield "ground_truth", ns, "nav_msgs/msg/Odometry", msg


def _dvl_driver(log: Log, b: MessageBuilder, frame: str):
    d = log.dvl
    time_ms = np.concatenate([[0.0], np.diff(d.t) * 1e3])
    tov = np.asarray(log.metadata.get("dvl_time_of_validity_s", d.t), dtype=np.float64)
    tov = np.where(np.isfinite(tov), tov, d.t) if tov.shape == d.t.shape else d.t
    string_t = b.T["std_msgs/msg/String"]
    for i in range(len(d)):
        ns, msg = dvl_driver_message(b, d, i, frame, time_ms[i])
        yield "dvl", ns, A50_DVL, msg
        line = velocity_report_line(d, i, time_ms[i], tov[i])
        yield "dvl_json", ns, "std_msgs/msg/String", string_t(data=line)


def dvl_driver_message(b: MessageBuilder, d, i: int, frame: str, time_ms: float):
    """(record time ns, ``waterlinked_a50_ros_driver/msg/DVL``) of row ``i`` of the Dvl ``d``:
    NaN altitude as -1 and an invalid beam's distance as -1, as the driver sends them."""
    return driver_message(b, float(d.t[i]), frame, velocity_report(d, i, time_ms, d.t[i]))


def driver_message(b: MessageBuilder, t: float, frame: str, r: VelocityReport):
    """(record time ns, ``waterlinked_a50_ros_driver/msg/DVL``) stamped ``t`` of a velocity
    report's values (rssi and nsd NaN: the report's own are not kept)."""
    beam_t = b.T[A50_BEAM]
    h, ns = b.header(t, frame)
    beams = [beam_t(id=bid, velocity=bvel, distance=dist, rssi=math.nan, nsd=math.nan, valid=ok)
             for bid, bvel, dist, ok in r.beams]  # fmt: skip
    msg = b.T[A50_DVL](
        header=h,
        time=r.time_ms,
        velocity=b.vec(r.velocity),
        fom=r.fom,
        altitude=r.altitude,
        beams=beams,
        velocity_valid=r.valid,
        status=0,
        form="json_v3",
    )
    return ns, msg


def _dvl_standard(log: Log, b: MessageBuilder, frame: str):
    d = log.dvl
    dvl_t = b.T[MARINE_DVL]
    # the sound speed the DVL converted with, when the log says (a simulated DVL's setting)
    sound_speed = np.float32(log.metadata.get("dvl_sound_speed_m_s", np.nan))
    minus = np.full(4, -1.0, np.float32)
    for i in range(len(d)):
        h, ns = b.header(d.t[i], frame)
        v = d.velocity[i]
        cov = np.where(np.isnan(d.covariance[i]), -1.0, d.covariance[i]).reshape(9)
        rng = np.where(d.beam_valid[i], d.beam_range[i], np.nan)
        yield (
            "dvl",
            ns,
            MARINE_DVL,
            dvl_t(
                header=h,
                velocity_mode=1 if d.valid[i] else 0,
                dvl_type=0,
                velocity=b.vec(v),
                velocity_covar=cov,
                altitude=float(d.altitude[i]),
                course_gnd=math.atan2(v[1], v[0]),
                speed_gnd=math.hypot(v[0], v[1]),
                num_good_beams=int(d.beam_valid[i].sum()),
                sound_speed=sound_speed,
                beam_ranges_valid=bool(d.beam_valid[i].any()),
                beam_velocities_valid=True,
                beam_unit_vec=[b.vec(u) for u in d.beam_unit[i]],
                range=rng.astype(np.float64),
                range_covar=minus,
                beam_quality=np.full(4, np.nan, np.float32),
                beam_velocity=d.beam_velocity[i].astype(np.float32),
                beam_velocity_covar=minus,
            ),
        )
