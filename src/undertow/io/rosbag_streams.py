"""Decoded ROS messages -> measurement rows -> :mod:`undertow.log` streams.

One small accumulator per stream; each knows the message types it accepts (DVL by type:
``waterlinked_a50_ros_driver/msg/DVL`` or ``marine_acoustic_msgs/msg/Dvl``; the multibeam a
``sensor_msgs/msg/PointCloud2`` of detections, :func:`cloud_points`). Times are
``header.stamp`` in float seconds (the bag's record time when a message has no header or a
zero stamp). Used by :mod:`undertow.io.rosbag`.
"""

from __future__ import annotations

import json
import math

import numpy as np

from ..log import GroundTruth, Imu, Multibeam, Pressure, SonarRange, WaveProbe
from ..rotations import quaternion_to_rpy, rpy_to_matrix
from ._collect import MALFORMED, DvlRows, Notes, count_nan_rows, time_order
from .a50_json import add_velocity_report, is_position_report, is_velocity_report, position_row
from .msgdefs import A50_DVL, MARINE_DVL

TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
#: sensor_msgs/PointField datatype constants -> numpy type codes
POINT_FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
ACCEPTED = {
    "dvl": (A50_DVL, MARINE_DVL),
    "dead_reckoning": ("geometry_msgs/msg/PoseWithCovarianceStamped",),
    "dvl_json": ("std_msgs/msg/String",),
    "imu": ("sensor_msgs/msg/Imu",),
    "pressure": ("sensor_msgs/msg/FluidPressure",),
    "sonar": ("sensor_msgs/msg/Range",),
    "wave_probe": ("geometry_msgs/msg/PointStamped",),
    "ground_truth": ("nav_msgs/msg/Odometry",),
    "multibeam": (POINTCLOUD2,),
    "tf_static": (TF_MESSAGE,),
}
HPA_THRESHOLD = 20_000.0  # an absolute pressure below this (Pa) is a log in hPa/mbar


def ns_to_s(ns: int) -> float:
    """Integer nanoseconds to float seconds, as sec + nanosec * 1e-9 (like header stamps)."""
    return ns // 1_000_000_000 + (ns % 1_000_000_000) * 1e-9


def stamp(msg, record_ns: int, notes: Notes) -> float:
    """header.stamp in seconds; the record time (with a note) when the stamp is zero."""
    st = msg.header.stamp
    if st.sec == 0 and st.nanosec == 0 and record_ns != 0:  # a stamp the driver never filled
        notes.add("messages with a zero header.stamp (bag record time used)")
        return ns_to_s(record_ns)
    return st.sec + st.nanosec * 1e-9


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
    """Plain row lists per stream, filled by :meth:`add` and turned into streams by builders."""

    def __init__(self, notes: Notes) -> None:
        self.notes = notes
        self.dvl = DvlRows()
        self.dvl_mode_given: list[bool] = []
        self.json_velocity: list[tuple[float, dict]] = []
        self.json_position: list[tuple] = []
        self.rows: dict[str, list] = {k: [] for k in ACCEPTED}
        self.sonar_limits: tuple | None = None
        self.probe_x: float | None = None
        #: (parent frame, child frame, translation, quaternion x y z w) of /tf_static
        self.transforms: list[tuple] = []
        #: (time, points (K, 3), intensity (K,) or None) per multibeam ping
        self.pings: list[tuple] = []
        #: the DVL messages carried their own beam unit vectors (marine_acoustic_msgs/Dvl)
        self.dvl_units_given = False

    def add(self, stream: str, msgtype: str, msg, record_ns: int) -> None:
        notes = self.notes
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
        elif msgtype == A50_DVL:
            beams = [(b.id, b.velocity, b.distance, b.valid) for b in msg.beams]
            self.dvl.append(
                stamp(msg, record_ns, notes),
                _xyz(msg.velocity),
                msg.velocity_valid,
                fom=msg.fom,
                altitude=msg.altitude,
                beams=beams,
                key=(msg.time, *_xyz(msg.velocity)),
            )
        elif msgtype == MARINE_DVL:
            self._add_marine(msg, record_ns)
        elif stream == "multibeam":
            points, intensity = cloud_points(msg)
            self.pings.append((stamp(msg, record_ns, notes), points, intensity))
        elif stream == "dead_reckoning":
            p = msg.pose.pose
            cov = msg.pose.covariance[0]
            std = math.sqrt(cov) if cov >= 0 else math.nan
            self.rows[stream].append(
                (stamp(msg, record_ns, notes), *_xyz(p.position), std, *_quat(p.orientation))
            )
        elif stream == "imu":
            has_q = msg.orientation_covariance[0] != -1
            has_a = msg.linear_acceleration_covariance[0] != -1
            self.rows[stream].append(
                (
                    stamp(msg, record_ns, notes),
                    *_xyz(msg.angular_velocity),
                    *_xyz(msg.linear_acceleration),
                    *_quat(msg.orientation),
                    has_a,
                    has_q,
                )
            )
        elif stream == "pressure":
            self.rows[stream].append((stamp(msg, record_ns, notes), msg.fluid_pressure))
        elif stream == "sonar":
            self.sonar_limits = self.sonar_limits or (
                msg.field_of_view,
                msg.min_range,
                msg.max_range,
            )
            self.rows[stream].append((stamp(msg, record_ns, notes), msg.range))
        elif stream == "wave_probe":
            self.probe_x = msg.point.x if self.probe_x is None else self.probe_x
            self.rows[stream].append((stamp(msg, record_ns, notes), msg.point.z))
        elif stream == "ground_truth":
            p, tw = msg.pose.pose, msg.twist.twist.linear
            self.rows[stream].append(
                (stamp(msg, record_ns, notes), *_xyz(p.position), *_quat(p.orientation), *_xyz(tw))
            )

    def _add_marine(self, msg, record_ns: int) -> None:
        units = np.array([_xyz(u) for u in msg.beam_unit_vec])
        rng = np.asarray(msg.range, dtype=np.float64)
        ok = msg.beam_ranges_valid & np.isfinite(rng) & (rng > 0)
        vel = np.asarray(msg.beam_velocity, dtype=np.float64)
        cov = np.asarray(msg.velocity_covar, dtype=np.float64).reshape(3, 3)
        if np.all(cov == -1):
            cov = None
        v = _xyz(msg.velocity)
        self.dvl_mode_given.append(msg.velocity_mode != 0)
        self.dvl_units_given = True
        valid = msg.velocity_mode != 0 and all(math.isfinite(x) for x in v)
        self.dvl.append(
            stamp(msg, record_ns, self.notes),
            v,
            valid,
            covariance=cov,
            altitude=msg.altitude,
            beams=list(zip(range(4), vel, rng, ok, strict=True)),
            beam_units=units,
            good_beams=int(msg.num_good_beams),
        )

    def _add_json(self, text: str, record_ns: int) -> None:
        try:
            obj = json.loads(text.strip())
            if is_velocity_report(obj):
                add_velocity_report(DvlRows(), obj, 0.0)
                self.json_velocity.append((ns_to_s(record_ns), obj))
            elif is_position_report(obj):
                self.json_position.append(position_row(obj))
        except MALFORMED:
            self.notes.add("dvl_json: malformed JSON messages skipped")

    # -- builders ---------------------------------------------------------------------------

    def _table(self, stream: str, width: int) -> np.ndarray | None:
        """The rows of ``stream`` with a finite time, time-ordered (None, noted, if none)."""
        arr = np.array(self.rows[stream], dtype=np.float64).reshape(-1, width)
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
        med = np.nanmedian(p) if np.isfinite(p).any() else math.nan
        if med < HPA_THRESHOLD:
            self.notes.add(
                f"pressure: values look like hPa/mbar (median {med:.1f}), converted to Pa (x100)",
                len(p),
            )
            p = p * 100.0
        return Pressure(t=a[:, 0], pressure=p)

    def sonar(self) -> SonarRange | None:
        if not self.rows["sonar"]:
            return None
        a = self._table("sonar", 2)
        if a is None:
            return None
        count_nan_rows(self.notes, "sonar", a[:, 1])
        fov, rmin, rmax = (float(x) for x in self.sonar_limits)
        return SonarRange(
            t=a[:, 0], range=a[:, 1], field_of_view=fov, min_range=rmin, max_range=rmax
        )

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
        """(t, x, y, z, std, roll, pitch, yaw) rows from the pose topic."""
        a = np.array(self.rows["dead_reckoning"], dtype=np.float64).reshape(-1, 9)
        return np.column_stack([a[:, :5], quaternion_to_rpy(a[:, 5:9]).reshape(-1, 3)])
