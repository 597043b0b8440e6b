"""Decoded ROS messages -> measurement rows -> :mod:`undertow.log` streams.

One small accumulator per stream; each knows the message types it accepts (:data:`ACCEPTED`;
DVL types are read by the meaning of their fields, :mod:`undertow.io.ros_dvl`; the multibeam a
``sensor_msgs/msg/PointCloud2`` of detections, :func:`cloud_points`). Every message's two times
(``header.stamp``, NaN when zero or absent, and the bag's record time) go to a
:class:`~undertow.io.clock.ClockTable`; a row holds its message's index there until
:meth:`Rows.apply_times` puts the chosen time base in (:mod:`undertow.io.clock`). Used by
:mod:`undertow.io.rosbag`.

Depth comes from a pose's z (``PoseWithCovarianceStamped``, ``PoseStamped``: its sign resolved
by the reader) or a ``std_msgs/Float64``/``Float32`` (positive down); position fixes from
``sensor_msgs/NavSatFix`` (status < 0 and non-finite fixes dropped and counted; projected to
local metres, :mod:`undertow.io.geo`) or a ``nav_msgs/Odometry`` in a local frame (east-north-up
as REP-103 says, made north-east-down about the first fix).

The sonar's confidence (``undertow_msgs/RangeConfidence``, :mod:`undertow.io.msgdefs`) is matched
to the range of the same header stamp (the n-th confidence of a stamp to the n-th range of it);
a range without one gets NaN (counted). A live session's wave decisions (``live_wave``: one JSON
object per ``std_msgs/String`` on :data:`~undertow.io.topics.LIVE_WAVE_TOPIC`) are kept as
written, in order.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np

from ..log import Depth, Dvl, GpsFix, GroundTruth, Imu, Multibeam, Pressure, SonarRange, WaveProbe
from ..rotations import quaternion_to_rpy, rpy_to_matrix
from .a50_json import (
    add_velocity_report,
    is_position_report,
    is_velocity_report,
    position_row,
    report_covariance,
)
from .clock import ClockTable
from .collect import MALFORMED, DvlRows, Notes, count_nan_rows, time_order
from .geo import local_ned
from .msgdefs import RANGE_CONFIDENCE, WL_DVLDR
from .ros_dvl import DVL_TYPES, dvl_report

TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE = "geometry_msgs/msg/PoseStamped"
FLOAT_TYPES = ("std_msgs/msg/Float64", "std_msgs/msg/Float32")
NAVSATFIX = "sensor_msgs/msg/NavSatFix"
ODOMETRY = "nav_msgs/msg/Odometry"
#: sensor_msgs/PointField datatype constants -> numpy type codes
POINT_FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
ACCEPTED = {
    "dvl": tuple(DVL_TYPES),
    "dead_reckoning": (POSE_COV, WL_DVLDR),
    "dvl_json": ("std_msgs/msg/String",),
    "imu": ("sensor_msgs/msg/Imu",),
    "pressure": ("sensor_msgs/msg/FluidPressure",),
    "depth": (POSE_COV, POSE, *FLOAT_TYPES),
    "sonar": ("sensor_msgs/msg/Range",),
    "sonar_confidence": (RANGE_CONFIDENCE,),
    "live_wave": ("std_msgs/msg/String",),
    "wave_probe": ("geometry_msgs/msg/PointStamped",),
    "ground_truth": (ODOMETRY,),
    "gps": (NAVSATFIX, ODOMETRY),
    "multibeam": (POINTCLOUD2,),
    "tf_static": (TF_MESSAGE,),
}
HPA_THRESHOLD = 20_000.0  # an absolute pressure below this (Pa) is a log in hPa/mbar


def ns_to_s(ns: int) -> float:
    """Integer nanoseconds to float seconds, as sec + nanosec * 1e-9 (like header stamps)."""
    return ns // 1_000_000_000 + (ns % 1_000_000_000) * 1e-9


def _stamp_ns(msg, record_ns: int) -> int:
    """A message's header stamp in ns (its record time when the stamp is zero)."""
    sec, nanosec = msg.header.stamp.sec, msg.header.stamp.nanosec
    return int(sec) * 1_000_000_000 + int(nanosec) if sec or nanosec else int(record_ns)


def _xyz(v) -> tuple[float, float, float]:
    return (v.x, v.y, v.z)


def _quat(q) -> tuple[float, float, float, float]:
    return (q.x, q.y, q.z, q.w)


def cloud_points(msg) -> tuple[np.ndarray, np.ndarray | None]:
    """(points (K, 3) float64, intensity (K,) or None) of a ``sensor_msgs/PointCloud2``.

    The cloud holds height x width points, row r at bytes [r row_step, r row_step + width
    point_step), each point's fields at their ``offset`` with their ``datatype`` (PointField
    constants INT8 = 1 .. FLOAT64 = 8, ``is_bigendian`` byte order); x, y, z are required,
    ``intensity`` optional, other fields are ignored. A count other than 1, an unknown datatype
    or a data array shorter than the layout says raises ValueError (a malformed message)."""
    fields = {f.name: f for f in msg.fields}
    if not all(name in fields for name in "xyz"):
        raise ValueError(f"PointCloud2 without x, y, z fields (has {', '.join(fields) or 'none'})")
    height, width, step = int(msg.height), int(msg.width), int(msg.point_step)
    names = [n for n in ("x", "y", "z", "intensity") if n in fields]
    order = ">" if msg.is_bigendian else "<"
    formats, offsets = [], []
    for name in names:
        f = fields[name]
        code = POINT_FIELD_TYPES.get(int(f.datatype))
        if code is None or int(f.count) not in (0, 1):
            raise ValueError(f"PointCloud2 field {name}: datatype {f.datatype}, count {f.count}")
        formats.append(order + code)
        offsets.append(int(f.offset))
        if int(f.offset) + np.dtype(code).itemsize > step:
            raise ValueError(f"PointCloud2 field {name} ends past point_step {step}")
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    data = np.asarray(msg.data, dtype=np.uint8)
    row_step = int(msg.row_step) if height > 1 else width * step
    if height * width and (row_step < width * step or data.size < (height - 1) * row_step
                           + width * step):  # fmt: skip
        raise ValueError(f"PointCloud2 data of {data.size} bytes, layout needs more")
    rows = [
        np.frombuffer(data[r * row_step : r * row_step + width * step].tobytes(), dtype=dtype)
        for r in range(height)
    ]
    cloud = np.concatenate(rows) if rows else np.zeros(0, dtype)
    points = np.stack([cloud[n].astype(np.float64) for n in "xyz"], axis=1).reshape(-1, 3)
    intensity = cloud["intensity"].astype(np.float64) if "intensity" in names else None
    return points, intensity


class Rows:
    """Plain row lists per stream, filled by :meth:`add` and turned into streams by builders.

    A row's time is its message's index in :attr:`clock` until :meth:`apply_times` replaces
    it with the time base's time (builders called without it take the rows' times as they
    are)."""

    def __init__(self, notes: Notes) -> None:
        self.notes = notes
        self.clock = ClockTable()
        #: the time of every message, by index (None until :meth:`apply_times`)
        self.times: np.ndarray | None = None
        self.dvl = DvlRows()
        self.dvl_mode_given: list[bool] = []
        self.dvl_sound_speed: list[float] = []  # what the DVL's messages say it converted with
        self.json_velocity: list[tuple[float, dict]] = []
        self.json_position: list[tuple] = []
        self.rows: dict[str, list] = {k: [] for k in ACCEPTED}
        self.sonar_limits: tuple | None = None
        #: the header stamp (ns) of each sonar row and the (stamp, confidence) of the
        #: confidence topic, in arrival order
        self.sonar_stamps: list[int] = []
        self.confidences: list[tuple[int, float]] = []
        #: a live session's wave decisions, as written
        self.live_wave: list[dict] = []
        self.probe_x: float | None = None
        #: (parent frame, child frame, translation, quaternion x y z w) of /tf_static
        self.transforms: list[tuple] = []
        #: (time, points (K, 3), intensity (K,) or None) per multibeam ping
        self.pings: list[tuple] = []
        #: the DVL messages carried their own beam unit vectors (marine_acoustic_msgs/Dvl)
        self.dvl_units_given = False
        #: header.frame_id of the DVL messages (a twist may be in the body frame)
        self.dvl_frames: set[str] = set()
        #: the depth topic's kind: "pose" (z, sign to resolve) or "float" (positive down)
        self.depth_kind: str | None = None
        #: the gps rows are (t, x, y, z, std) in a local frame (Odometry), not (t, lat, lon, alt,
        #: std) of NavSatFix
        self.gps_local = False
        # what the builders decide from all the rows, kept (None: not decided yet) so that a log
        # read in pieces decides once (:func:`undertow.io.rosbag.iter_rosbag_pieces`): the
        # pressure's scale (100 for hPa), the local GPS frame's origin, the depth's sign; the
        # chosen time base (:class:`~undertow.io.clock.TimeBase`)
        self.pressure_scale: float | None = None
        self.gps_local_origin: np.ndarray | None = None
        self.depth_sign: float | None = None
        self.time_base = None

    def stamp(self, stream: str, msg, record_ns: int) -> float:
        """Register the message's two times; the row's time placeholder (its index). A zero stamp
        recorded within a second of time zero is a clock that starts at zero (a simulation), not
        a stamp never filled; a message without a header has no stamp (NaN). (``ClockTable.add``
        inlined: called for every message.)"""
        record_s = record_ns // 1_000_000_000 + (record_ns % 1_000_000_000) * 1e-9
        header = getattr(msg, "header", None)
        if header is None:
            header_s = math.nan
        else:
            sec, nanosec = header.stamp.sec, header.stamp.nanosec
            if sec == 0 and nanosec == 0:
                header_s = 0.0 if abs(record_s) < 1.0 else math.nan
            else:
                header_s = sec + nanosec * 1e-9
        clock = self.clock
        clock.stream.append(stream)
        clock.header.append(header_s)
        clock.record.append(record_s)
        return float(len(clock.record) - 1)

    def add(self, stream: str, msgtype: str, msg, record_ns: int) -> None:
        if stream == "dvl_json":
            self._add_json(msg.data, record_ns)
        elif stream == "tf_static":
            for tf in msg.transforms:
                r = tf.transform
                self.transforms.append(
                    (
                        tf.header.frame_id,
                        tf.child_frame_id,
                        _xyz(r.translation),
                        _quat(r.rotation),
                    )
                )
        elif stream == "dvl":
            self._add_dvl(msgtype, msg, record_ns)
        elif stream == "multibeam":
            points, intensity = cloud_points(msg)
            self.pings.append((self.stamp(stream, msg, record_ns), points, intensity))
        elif stream == "dead_reckoning":
            self._add_dead_reckoning(msgtype, msg, record_ns)
        elif stream == "depth":
            self._add_depth(msgtype, msg, record_ns)
        elif stream == "gps":
            self._add_gps(msgtype, msg, record_ns)
        elif stream == "imu":
            has_q = msg.orientation_covariance[0] != -1
            has_a = msg.linear_acceleration_covariance[0] != -1
            row = (
                *_xyz(msg.angular_velocity),
                *_xyz(msg.linear_acceleration),
                *_quat(msg.orientation),
                has_a,
                has_q,
            )
            self.rows[stream].append((self.stamp(stream, msg, record_ns), *row))
        elif stream == "pressure":
            value = float(msg.fluid_pressure)
            self.rows[stream].append((self.stamp(stream, msg, record_ns), value))
        elif stream == "sonar":
            limits = (msg.field_of_view, msg.min_range, msg.max_range)
            value = float(msg.range)
            self.sonar_limits = self.sonar_limits or limits
            self.rows[stream].append((self.stamp(stream, msg, record_ns), value))
            self.sonar_stamps.append(_stamp_ns(msg, record_ns))
        elif stream == "sonar_confidence":
            self.confidences.append((_stamp_ns(msg, record_ns), float(msg.confidence)))
        elif stream == "live_wave":
            try:
                self.live_wave.append(dict(json.loads(msg.data)))
            except MALFORMED:
                self.notes.add("live_wave: malformed JSON messages skipped")
        elif stream == "wave_probe":
            x, z = float(msg.point.x), float(msg.point.z)
            self.probe_x = x if self.probe_x is None else self.probe_x
            self.rows[stream].append((self.stamp(stream, msg, record_ns), z))
        elif stream == "ground_truth":
            p, tw = msg.pose.pose, msg.twist.twist.linear
            row = (*_xyz(p.position), *_quat(p.orientation), *_xyz(tw))
            self.rows[stream].append((self.stamp(stream, msg, record_ns), *row))

    def _add_dvl(self, msgtype: str, msg, record_ns: int) -> None:
        report = dvl_report(msgtype, msg)
        extra = report.pop("extra")
        if "mode_given" in extra:
            self.dvl_mode_given.append(extra.pop("mode_given"))
        if "sound_speed" in extra:
            self.dvl_sound_speed.append(extra.pop("sound_speed"))
        if report.get("beam_units") is not None:
            self.dvl_units_given = True
        header = getattr(msg, "header", None)
        if header is not None:
            self.dvl_frames.add(str(header.frame_id))
        self.dvl.append(self.stamp("dvl", msg, record_ns), **report, **extra)

    def _add_dead_reckoning(self, msgtype: str, msg, record_ns: int) -> None:
        if msgtype == WL_DVLDR:  # position (m), pos_std (m), roll/pitch/yaw in degrees
            rpy = np.deg2rad([float(msg.roll), float(msg.pitch), float(msg.yaw)])
            row = (*_xyz(msg.position), float(msg.pos_std), *rpy)
            self.rows["dead_reckoning"].append((self.stamp("dead_reckoning", msg, record_ns), *row))
            return
        p = msg.pose.pose
        cov = float(msg.pose.covariance[0])
        std = math.sqrt(cov) if cov >= 0 else math.nan
        rpy = quaternion_to_rpy(np.array(_quat(p.orientation), dtype=np.float64))
        row = (*_xyz(p.position), std, *(float(a) for a in rpy))
        self.rows["dead_reckoning"].append((self.stamp("dead_reckoning", msg, record_ns), *row))

    def _add_depth(self, msgtype: str, msg, record_ns: int) -> None:
        if msgtype in FLOAT_TYPES:
            value, kind = float(msg.data), "float"
        else:
            pose = msg.pose.pose if msgtype == POSE_COV else msg.pose
            value, kind = float(pose.position.z), "pose"
        self.depth_kind = kind
        self.rows["depth"].append((self.stamp("depth", msg, record_ns), value))

    def _add_gps(self, msgtype: str, msg, record_ns: int) -> None:
        if msgtype == ODOMETRY:
            self.gps_local = True
            p = msg.pose.pose.position
            cov = float(msg.pose.covariance[0])
            std = math.sqrt(cov) if math.isfinite(cov) and cov > 0 else math.nan
            row = (float(p.x), float(p.y), float(p.z), std)
            if not all(math.isfinite(v) for v in row[:3]):
                self.notes.add("gps: odometry fixes with non-finite positions (dropped)")
                return
        else:
            lat, lon, alt = float(msg.latitude), float(msg.longitude), float(msg.altitude)
            if int(msg.status.status) < 0:
                self.notes.add("gps: fixes with status NO_FIX (< 0) (dropped)")
                return
            if not (math.isfinite(lat) and math.isfinite(lon) and abs(lat) <= 90
                    and abs(lon) <= 180):  # fmt: skip
                self.notes.add("gps: fixes with a non-finite or out-of-range latitude/longitude"
                               " (dropped)")  # fmt: skip
                return
            c = np.asarray(msg.position_covariance, dtype=np.float64)
            known = int(msg.position_covariance_type) > 0 and c.size == 9
            std = math.sqrt(max(c[0], 0) + max(c[4], 0)) if known else math.nan
            row = (lat, lon, alt if math.isfinite(alt) else 0.0, std)
        self.rows["gps"].append((self.stamp("gps", msg, record_ns), *row))

    def _add_json(self, text: str, record_ns: int) -> None:
        try:
            obj = json.loads(text.strip())
            if is_velocity_report(obj):
                add_velocity_report(DvlRows(), obj, 0.0)
                t = self.clock.add("dvl_json", math.nan, ns_to_s(record_ns))
                self.json_velocity.append((t, obj))
            elif is_position_report(obj):
                row = position_row(obj)  # its ts is the DVL's own clock: record time used
                t = self.clock.add("dvl_json", math.nan, ns_to_s(record_ns))
                self.json_position.append((t, *row[1:]))
        except MALFORMED:
            self.notes.add("dvl_json: malformed JSON messages skipped")

    def apply_times(self, times: np.ndarray) -> None:
        """Replace every row's time placeholder (its message index) by ``times[index]``: at
        once for the DVL, pings and JSON reports, as each table is built for the other streams
        (:meth:`array`)."""
        self.times = np.asarray(times, dtype=np.float64)
        at = self.times.take
        self.dvl.t = at(np.asarray(self.dvl.t, dtype=np.int64)).tolist()
        self.pings = [(float(at(int(p[0]))), *p[1:]) for p in self.pings]
        self.json_velocity = [(float(at(int(t))), obj) for t, obj in self.json_velocity]
        self.json_position = [(float(at(int(r[0]))), *r[1:]) for r in self.json_position]

    def array(self, stream: str, width: int) -> np.ndarray:
        """The rows of ``stream`` as a float array (N, width), column 0 the time (the time base's
        once :meth:`apply_times` ran)."""
        arr = np.array(self.rows[stream], dtype=np.float64).reshape(-1, width)
        if self.times is not None and len(arr):
            arr[:, 0] = self.times.take(arr[:, 0].astype(np.int64))
        return arr

    # -- builders ---------------------------------------------------------------------------

    def _table(self, stream: str, width: int, extra=None) -> np.ndarray | None:
        """The rows of ``stream`` with a finite time, time-ordered (None, noted, if none);
        ``extra``: one more column, a value per row in arrival order."""
        arr = self.array(stream, width)
        if extra is not None:
            arr = np.column_stack([arr, extra])
        arr = arr[time_order(arr[:, 0], stream, self.notes)]
        if not len(arr):
            self.notes.add(f"{stream}: no message with a finite time (stream dropped)")
            return None
        return arr

    def imu(self) -> Imu | None:
        if not self.rows["imu"]:
            return None
        a = self._table("imu", 13)
        if a is None:
            return None
        count_nan_rows(self.notes, "imu", a[:, 1:7])
        return Imu(
            t=a[:, 0],
            angular_velocity=a[:, 1:4],
            linear_acceleration=a[:, 4:7] if a[:, 11].all() else None,
            orientation=a[:, 7:11] if a[:, 12].all() else None,
        )

    def pressure(self) -> Pressure | None:
        if not self.rows["pressure"]:
            return None
        a = self._table("pressure", 2)
        if a is None:
            return None
        count_nan_rows(self.notes, "pressure", a[:, 1])
        p = a[:, 1]
        if self.pressure_scale is None:
            med = np.nanmedian(p) if np.isfinite(p).any() else math.nan
            self.pressure_scale = 100.0 if med < HPA_THRESHOLD else 1.0
            if self.pressure_scale != 1.0:
                self.notes.add(f"pressure: values look like hPa/mbar (median {med:.1f}), "
                               "converted to Pa (x100)", len(p))  # fmt: skip
        elif self.pressure_scale != 1.0:
            self.notes.add("pressure: values in hPa/mbar, converted to Pa (x100)", len(p))
        if self.pressure_scale != 1.0:
            p = p * 100.0
        return Pressure(t=a[:, 0], pressure=p)

    def sonar(self) -> SonarRange | None:
        if not self.rows["sonar"]:
            return None
        confidence = self._sonar_confidence()
        a = self._table("sonar", 2, confidence)
        if a is None:
            return None
        count_nan_rows(self.notes, "sonar", a[:, 1])
        fov, rmin, rmax = (float(x) for x in self.sonar_limits)
        return SonarRange(
            t=a[:, 0], range=a[:, 1], confidence=None if confidence is None else a[:, 2],
            field_of_view=fov, min_range=rmin, max_range=rmax,
        )  # fmt: skip

    def _sonar_confidence(self) -> np.ndarray | None:
        """Each sonar row's confidence (arrival order): the n-th confidence of its header stamp
        for the n-th range of it, NaN (counted) without one; None without a confidence topic."""
        if not self.confidences:
            return None
        by_stamp: dict[int, list[float]] = {}
        for key, value in reversed(self.confidences):  # popped from the end: first one first
            by_stamp.setdefault(key, []).append(value)
        out = np.full(len(self.sonar_stamps), np.nan)
        for i, key in enumerate(self.sonar_stamps):
            values = by_stamp.get(key)
            if values:
                out[i] = values.pop()
            else:
                self.notes.add("sonar_confidence: ranges without a confidence of their stamp (NaN)")
        return out

    def wave_probe(self) -> WaveProbe | None:
        if not self.rows["wave_probe"]:
            return None
        a = self._table("wave_probe", 2)
        if a is None:
            return None
        count_nan_rows(self.notes, "wave_probe", a[:, 1])
        return WaveProbe(t=a[:, 0], elevation=a[:, 1], x=float(self.probe_x))

    def ground_truth(self) -> GroundTruth | None:
        if not self.rows["ground_truth"]:
            return None
        a = self._table("ground_truth", 11)
        if a is None:
            return None
        count_nan_rows(self.notes, "ground_truth", a[:, 1:8])
        rpy = quaternion_to_rpy(a[:, 4:8])
        twist = a[:, 8:11]
        velocity = None
        if np.isfinite(twist).any():  # nav_msgs twist is in the child (body) frame
            velocity = np.einsum("nij,nj->ni", rpy_to_matrix(rpy), twist)
        return GroundTruth(t=a[:, 0], position=a[:, 1:4], orientation=rpy, velocity=velocity)

    def multibeam(self, min_range: float | None = None, max_range: float | None = None):
        """The pings as a :class:`~undertow.log.Multibeam` (None without pings): every ping
        padded with NaN to the most detections of any ping; intensity kept when every ping
        has it; limits as given (else the stream's defaults)."""
        if not self.pings:
            return None
        order = time_order(np.array([p[0] for p in self.pings]), "multibeam", self.notes)
        if not order.size:
            self.notes.add("multibeam: no message with a finite time (stream dropped)")
            return None
        pings = [self.pings[i] for i in order]
        beams = max(p[1].shape[0] for p in pings)
        points = np.full((len(pings), beams, 3), np.nan)
        has_i = all(p[2] is not None for p in pings)
        intensity = np.full((len(pings), beams), np.nan) if has_i else None
        for i, (_, pts, inten) in enumerate(pings):
            points[i, : pts.shape[0]] = pts
            if has_i:
                intensity[i, : inten.shape[0]] = inten
        limits = {k: float(v) for k, v in (("min_range", min_range), ("max_range", max_range))
                  if v is not None}  # fmt: skip
        return Multibeam(t=[p[0] for p in pings], points=points, intensity=intensity, **limits)

    def dead_reckoning_rows(self) -> np.ndarray:
        """(t, x, y, z, std, roll, pitch, yaw) rows of the dead-reckoning topic."""
        return self.array("dead_reckoning", 8)

    def depth(self, sign: float = 1.0) -> Depth | None:
        """The depth topic as depth positive down (``sign`` -1 for a pose z that points up)."""
        if not self.rows["depth"]:
            return None
        a = self._table("depth", 2)
        if a is None:
            return None
        count_nan_rows(self.notes, "depth", a[:, 1])
        self.depth_sign = sign
        return Depth(t=a[:, 0], depth=sign * a[:, 1])

    def gps(self, origin=None) -> GpsFix | None:
        """The fixes in north-east-down metres about ``origin`` (lat, lon, alt; default the
        first fix); Odometry fixes (east-north-up, REP-103) about the first one."""
        if not self.rows["gps"]:
            return None
        a = self._table("gps", 5)
        if a is None:
            return None
        if self.gps_local:
            if self.gps_local_origin is None:
                self.gps_local_origin = a[0, 1:4].copy()
            enu = a[:, 1:4] - self.gps_local_origin
            ned = np.column_stack([enu[:, 1], enu[:, 0], -enu[:, 2]])
            return GpsFix(t=a[:, 0], position=ned, horizontal_std=a[:, 4])
        origin = tuple(a[0, 1:4]) if origin is None else tuple(origin)
        ned = local_ned(a[:, 1], a[:, 2], a[:, 3], origin)
        return GpsFix(t=a[:, 0], position=ned, latitude=a[:, 1], longitude=a[:, 2],
                      altitude=a[:, 3], horizontal_std=a[:, 4], origin=origin)  # fmt: skip


def build_dvl(rows: Rows, notes: Notes, metadata: dict) -> Dvl | None:
    """The DVL stream of ``rows`` (its driver's messages, with what the raw JSON reports add,
    else the JSON reports alone), noting in ``metadata`` what came from the JSON."""
    if len(rows.dvl):
        if rows.dvl_mode_given and not any(rows.dvl_mode_given):
            # marine_acoustic_msgs with velocity_mode never set: judge by the beams instead
            good = np.array(rows.dvl.extra["good_beams"]) >= 3
            rows.dvl.valid = [
                bool(g) and np.isfinite(v).all()
                for g, v in zip(good, rows.dvl.velocity, strict=True)
            ]
            notes.add("dvl: velocity_mode never set; valid = at least 3 good beams", len(good))
        dvl, order = rows.dvl.build(notes)
        said = np.asarray(rows.dvl_sound_speed, float)
        said = said[np.isfinite(said) & (said > 0)]
        if said.size:  # the sound speed it converted with: its setting (undertow.io.sound_speed)
            metadata["dvl_sound_speed_m_s"] = float(np.median(said))
        return _merge_json(dvl, order, rows, metadata) if len(dvl) else None
    if rows.json_velocity:
        fallback = DvlRows()
        for t, obj in rows.json_velocity:
            add_velocity_report(fallback, obj, t)
        dvl, order = fallback.build(notes)
        if not len(dvl):
            return None
        tov = np.array(fallback.extra["time_of_validity"])[order]
        if np.isfinite(tov).any():
            metadata["dvl_time_of_validity_s"] = tov
        metadata["dvl_source"] = "dvl_json (time: bag record time)"
        return dvl
    return None


def _merge_json(dvl: Dvl, order: np.ndarray, rows: Rows, metadata: dict) -> Dvl:
    """Covariance and time_of_validity from raw JSON reports matching (time, vx, vy, vz)."""
    if not rows.json_velocity or "key" not in rows.dvl.extra:
        return dvl
    by_key = {(o.get("time"), o["vx"], o["vy"], o["vz"]): o for _, o in rows.json_velocity}
    keys = [rows.dvl.extra["key"][i] for i in order]
    cov = dvl.covariance.copy()
    tov = np.full(len(dvl), np.nan)
    for i, key in enumerate(keys):
        obj = by_key.get(key)
        if obj is None:
            continue
        obj_cov = report_covariance(obj)
        if obj_cov is not None and np.isnan(cov[i]).all():
            cov[i] = obj_cov
        if obj.get("time_of_validity") is not None:
            tov[i] = float(obj["time_of_validity"]) * 1e-6
    if np.isfinite(tov).any():
        metadata["dvl_time_of_validity_s"] = tov
    metadata["dvl_json_matched"] = int(sum(k in by_key for k in keys))
    return replace(dvl, covariance=cov)
