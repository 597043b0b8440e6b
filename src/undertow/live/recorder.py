"""The live recording: a ROS 2 bag directory (mcap storage) written as records arrive.

Raw records (:class:`~undertow.records.Record`) go on the standard topics of
:class:`~undertow.io.topics.TopicMap` (first names) with the message types of
:func:`~undertow.io.rosbag_write.write_log` (message builders shared with it), so
:func:`undertow.io.read_log` and ``undertow localize``/``map`` replay a recording, and ROS 2
tools and Foxglove open it. The DVL is written in the ``driver`` flavor
(``waterlinked_a50_ros_driver/msg/DVL`` on ``/dvl/data`` plus the json_v3 report line on
``/dvl/json_data``): it is the flavor that carries every DVL field of a record at full precision
(``fom`` and float64 beam velocities; the covariance through the JSON line, which the reader
matches by (time, vx, vy, vz)); ``marine_acoustic_msgs/Dvl`` has no figure of merit and float32
beam velocities.

The estimates, on topics of their own (the readers ignore them):

- ``/undertow/pose``: ``geometry_msgs/PoseWithCovarianceStamped`` in ``world`` (undertow's
  north-east-down world frame) from the 18-state (x, P) of :mod:`undertow.estimation.model`:
  position eta[0:3] = x[0:3], orientation the quaternion of (phi, theta, psi) = x[3:6], and the
  6x6 covariance P[0:6, 0:6] row-major over (x, y, z, phi, theta, psi). The message defines the
  last three as rotations about the X, Y, Z axes; Euler-angle perturbations equal those to first
  order only near zero roll, pitch and yaw (elsewhere they differ by the Euler-rate transform), so
  the block is the filter's Euler-angle covariance as is, not rotated;
- ``/undertow/wave``: ``geometry_msgs/Vector3Stamped`` in ``world``: vector.x = amplitude a (m),
  vector.y = frequency f (Hz), vector.z = 0;
- ``/undertow/status``: ``std_msgs/String``, one JSON object (rates, counters, filter health);
- ``/undertow/late/<stream>``: records that arrived after the reorder horizon (not given to the
  filter), with their stream's message type (``/undertow/late/dvl_json`` for the DVL's line).

The messages of fixed layout (``sensor_msgs/Imu``, ``sensor_msgs/FluidPressure``, the pose and
dead reckoning, the A50 driver's ``DVL``) are not built and serialized one by one: their CDR
bytes are a template of the first such message rosbags serializes, with the stamp and the fields
after the header packed in place (:mod:`undertow.live.cdr`; kept only when it reproduces
rosbags' bytes of that message: the same bytes, a fifth of the time); the DVL's JSON line goes
into its ``std_msgs/String`` the same way. The messages are appended to the MCAP chunk by
:mod:`undertow.live.mcap_append` (the file rosbags' writer makes, byte for byte).

Header stamps are the record time t (s) as ``sec = floor(t)``, ``nanosec = round((t - sec) 1e9)``;
the bag's record time is the same instant in ns.

**What a replay reads back.** :meth:`Recorder.write_record` returns the record exactly as
``read_log(recording)`` will give it (the promise the live pipeline relies on: the filter is fed
what a replay sees): t = sec + nanosec 1e-9 as the reader computes it; values quantized by the
message field types and the reader's conventions:

- sonar: ``sensor_msgs/Range`` is float32 (range, field of view, min/max range); the limits of
  the session's first sonar record are written on every message (the reader keeps the first);
  the Ping's confidence has no field in the message and is not returned (no estimator uses it);
- DVL: an altitude that is not a finite number >= 0 reads back NaN; an invalid beam's range NaN;
  missing fields read back as NaN (fom, covariance, beam values) / False (beam_valid); the
  covariance reads back NaN when a velocity component is NaN (the JSON match fails);
- dead reckoning: the attitude passes through a quaternion (roll, pitch, yaw recomputed from
  it), the std through its square (std = sqrt(std^2)), NaN when missing;
- IMU: which optional parts (acceleration, orientation) the stream has is fixed by the session's
  first IMU record (the reader keeps a part only when every message has it): a later record
  missing such a part gets NaN there, a part the first record lacked is not recorded;
- pressure is written in Pa as given; note that the reader converts a whole pressure stream whose
  median is below 20 000 Pa from hPa (x100): live links deliver Pa (about 1e5 underwater).

Same-time records of one stream come back in write order.

**Atomicity.** The bag is written in ``<name>.partial-XXXXXXXX/<name>`` next to the target and
renamed into place by :meth:`Recorder.close` (after ``metadata.yaml`` and the sidecar
``undertow.yaml`` with the mounting, as ``write_log`` writes); :meth:`Recorder.abort` removes it;
nothing half-written ever appears at the target. After a crash the ``.partial`` folder stays
(:mod:`undertow._util.atomic` does not clean it up): its ``.mcap`` holds every chunk flushed
(:meth:`Recorder.flush`, at the first record ``flush_every_s`` = 1 s of record time or more after
the last: written and synced to the disk) but no footer; ``read_log`` reads it up to its last
complete chunk (:mod:`undertow.io.mcap_recover`; the mounting from ``/tf_static``).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import threading
from pathlib import Path

import numpy as np
import yaml
from rosbags.rosbag2 import StoragePlugin, Writer

from .._util.plain import json_safe, to_plain
from ..errors import ConfigError, DataError
from ..io.a50_json import MAX_REPORT_INTERVAL_MS, report_line, report_values
from ..io.msgdefs import A50_DVL
from ..io.rosbag import SIDECAR
from ..io.rosbag_streams import TF_MESSAGE
from ..io.rosbag_write import (
    TF_STATIC_QOS,
    MessageBuilder,
    dead_reckoning_message,
    driver_message,
    imu_message,
    pressure_message,
    sonar_message,
    tf_static_message,
)
from ..io.topics import SENSOR_NAMES, TopicMap
from ..log import SonarRange
from ..records import RECORD_FIELDS, Record
from ..robot import Mounting
from ..rotations import quaternion_to_rpy_one, rpy_to_quaternion, rpy_to_quaternion_scalar
from .cdr import DVL_FORM, DVL_TAIL, CdrTemplate, stamp, string_cdr
from .chunk_sync import ChunkSync
from .mcap_append import MessageAppender

#: topics of the estimates (the raw streams use TopicMap's first names)
POSE_TOPIC = "/undertow/pose"
WAVE_TOPIC = "/undertow/wave"
STATUS_TOPIC = "/undertow/status"
LATE_PREFIX = "/undertow/late/"
#: builtin_interfaces/Time holds seconds in an int32 and the mcap record time is unsigned
MAX_TIME_S = 2.0**31 - 1.0
#: the message type of each raw stream's topic(s) (the DVL: its driver message and JSON line)
_IMU_TYPE = "sensor_msgs/msg/Imu"
_PRESSURE_TYPE = "sensor_msgs/msg/FluidPressure"
_RANGE_TYPE = "sensor_msgs/msg/Range"
_POSE_TYPE = "geometry_msgs/msg/PoseWithCovarianceStamped"  # dead reckoning and the estimate
_WAVE_TYPE = "geometry_msgs/msg/Vector3Stamped"
_STRING_TYPE = "std_msgs/msg/String"  # the DVL's JSON line and the status
_STREAM_TYPES: dict[str, tuple[tuple[str, str], ...]] = {
    "imu": (("imu", _IMU_TYPE),),
    "pressure": (("pressure", _PRESSURE_TYPE),),
    "sonar": (("sonar", _RANGE_TYPE),),
    "dead_reckoning": (("dead_reckoning", _POSE_TYPE),),
    "dvl": (("dvl", A50_DVL), ("dvl_json", _STRING_TYPE)),
}
_SONAR_DEFAULTS = {
    "field_of_view": SonarRange.field_of_view,
    "min_range": SonarRange.min_range,
    "max_range": SonarRange.max_range,
}


def _floats(value, n: int) -> tuple[float, ...]:
    if value is None:
        return (math.nan,) * n
    if type(value) is tuple and len(value) == n:  # (what the links deliver)
        try:
            return tuple(map(float, value))
        except (TypeError, ValueError):  # not numbers: the general path says so
            pass
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size != n:
        raise ValueError(f"expected {n} values, got {arr.size}")
    return tuple(float(v) for v in arr)


def _float(value) -> float:
    return math.nan if value is None else float(value)


_ZEROS9 = (0.0,) * 9
_NO_ESTIMATE9 = (-1.0,) + (0.0,) * 8  # sensor_msgs/Imu: covariance[0] = -1, no estimate


def _f32(value: float) -> float:
    with np.errstate(over="ignore"):
        return float(np.float32(value))


class Recorder:
    """A ROS 2 bag (mcap) recording written record by record (see the module docstring).

    ``path``: the bag directory to create (refused if it exists, unless ``overwrite``);
    ``mounting``: the session's :class:`~undertow.robot.Mounting` (``/tf_static`` and the sidecar);
    ``metadata``: plain values for the sidecar; ``topics``: the topic names (default TopicMap).
    """

    def __init__(
        self,
        path,
        mounting: Mounting | None = None,
        metadata: dict | None = None,
        *,
        topics: TopicMap | None = None,
        overwrite: bool = False,
        flush_every_s: float = 1.0,
    ) -> None:
        self.path = Path(path)
        if self.path.exists() and not (overwrite and self.path.is_dir()):
            raise ConfigError(f"{self.path}: recording already exists (choose another --out)")
        self.mounting = mounting or Mounting()
        self.metadata = dict(metadata or {})
        self.topics = topics or TopicMap()
        self.flush_every_s = float(flush_every_s)
        self.counts: dict[str, int] = {}
        self._b = MessageBuilder()
        self._frame = {s: getattr(self.topics.frames, s)[0] for s in SENSOR_NAMES}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._holder = Path(
            tempfile.mkdtemp(prefix=f"{self.path.name}.partial-", dir=self.path.parent)
        )
        self._bag = self._holder / self.path.name
        self._writer = Writer(self._bag, version=9, storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except Exception as exc:  # rosbags' WriterError or an OSError: nothing may stay behind
            shutil.rmtree(self._holder, ignore_errors=True)
            raise ConfigError(f"{self.path}: cannot start the recording ({exc})") from None
        self._append = MessageAppender(self._writer).write
        self._conns: dict[str, object] = {}
        self._mounting_written = False
        self._lock = threading.Lock()
        self._state = "open"
        self._imu_parts: tuple[bool, bool] | None = None  # (acceleration, orientation)
        self._sonar_limits: tuple[float, float, float] | None = None
        self._dvl_last_t: float | None = None
        self._dvl_keys: set[tuple] = set()
        self._last_flush: float | None = None
        self._sync = ChunkSync()  # each flushed chunk to the disk, in the background
        self._templates: dict[tuple, CdrTemplate | None] = {}
        self._string_template: bytes | bool | None = None  # std_msgs/String's encapsulation
        self._by_stream = {stream: getattr(self, f"_{stream}") for stream in RECORD_FIELDS}

    def declare(self, streams, wave: bool = False) -> None:
        """Add the topics of ``streams`` (raw stream names) and of the estimates (pose, status;
        the wave with ``wave``) now, before their first message: rosbags' ``add_connection``
        takes milliseconds (the topic's QoS through a YAML dump), a stall the first record of
        each stream would otherwise wait for. A declared topic without messages is an empty
        topic of the bag (the readers skip it)."""
        with self._lock:
            self._check_open()
            for stream in streams:
                if stream not in _STREAM_TYPES:
                    raise DataError(f"record stream '{stream}' is not one of {list(_STREAM_TYPES)}")
                for name, msgtype in _STREAM_TYPES[stream]:
                    self._connection(self.topics.first(name), msgtype)
            self._connection(POSE_TOPIC, _POSE_TYPE)
            self._connection(STATUS_TOPIC, _STRING_TYPE)
            if wave:
                self._connection(WAVE_TOPIC, _WAVE_TYPE)

    # -- raw records --------------------------------------------------------------------------
    def write_record(self, record: Record) -> Record:
        """Write ``record`` on its stream's standard topic; return it as ``read_log`` reads it."""
        with self._lock:
            self._check_open()
            t = self._check_time(record)
            data, messages = self._messages(t, record, "")
            self._write_all(messages)
            t_read = self._t_read(messages[0][1])
            return Record(
                record.stream, t_read, data, record.arrival, record.sensor_time, record.source
            )

    def write_late(self, record: Record) -> None:
        """Write a record that came after the reorder horizon on ``/undertow/late/<stream>``."""
        with self._lock:
            self._check_open()
            t = self._check_time(record)
            _, messages = self._messages(t, record, LATE_PREFIX)
            self._write_all(messages)

    # -- estimates ----------------------------------------------------------------------------
    def write_pose(self, t: float, x, P, topic: str = POSE_TOPIC) -> None:
        """(x, P) of the 18-state filter on ``/undertow/pose`` (module docstring), or another
        pose in that layout on ``topic`` (the autopilot's, :mod:`undertow.live.autopilot`)."""
        x = np.asarray(x, dtype=np.float64).reshape(-1)
        P = np.asarray(P, dtype=np.float64)
        if x.size < 6 or P.shape[0] < 6 or P.ndim != 2:
            raise DataError("write_pose: x needs 6+ states and P a square matrix")
        b = self._b
        with self._lock:
            self._check_open()
            t = self._time(t, "pose")
            cov = np.ascontiguousarray(P[:6, :6]).reshape(36)
            msgtype = _POSE_TYPE

            def build():
                h, ns = b.header(t, "world")
                return ns, b.T[msgtype](header=h, pose=b.pose_cov(x[0:3], x[3:6], cov))

            # the message's fields after the header: position, quaternion (as pose_cov makes
            # it), covariance: 43 float64
            values = (*x[0:3].tolist(), *rpy_to_quaternion(x[3:6]).tolist(), *cov.tolist())
            message = self._templated((topic,), msgtype, t, values, build)
            self._write_all([(topic, *message)])

    def write_wave(self, t: float, amplitude_m: float, frequency_hz: float) -> None:
        """The wave estimate on ``/undertow/wave``: vector (a m, f Hz, 0)."""
        b = self._b
        with self._lock:
            self._check_open()
            t = self._time(t, "wave")
            h, ns = b.header(t, "world")
            msgtype = _WAVE_TYPE
            msg = b.T[msgtype](header=h, vector=b.vec((amplitude_m, frequency_hz, 0.0)))
            self._write_all([(WAVE_TOPIC, ns, msgtype, msg)])

    def write_status(self, t: float, status: dict, topic: str = STATUS_TOPIC) -> None:
        """``status`` as one JSON object (``std_msgs/String``) on ``/undertow/status`` (or
        ``topic``); NaN and infinities become null (strict JSON)."""
        text = json.dumps(json_safe(status), default=str, allow_nan=False)
        with self._lock:
            self._check_open()
            t = self._time(t, "status")
            _, ns = self._b.header(t, "")
            msg = self._b.T[_STRING_TYPE](data=text)
            self._write_all([(topic, ns, _STRING_TYPE, msg)])

    # -- finishing ----------------------------------------------------------------------------
    def flush(self) -> None:
        """Close the pending mcap chunk, write it and sync it to the disk in the background
        (what a crash or a power cut keeps; :class:`~undertow.live.chunk_sync.ChunkSync`)."""
        self._sync.flush(getattr(self._writer, "storage", None))

    def close(self) -> Path:
        """Finish the bag (metadata.yaml, sidecar undertow.yaml) and rename it into place."""
        with self._lock:
            if self._state == "closed":
                return self.path
            self._check_open()
            self._sync.wait()
            self._writer.close()
            sidecar = {
                "source": "undertow live",
                "flavor": "driver",
                "mounting": to_plain(drop_unknown=True, value=self.mounting.to_dict()),
                "metadata": to_plain(drop_unknown=True, value=self.metadata) or {},
            }
            text = yaml.safe_dump(sidecar, sort_keys=False)
            (self._bag / SIDECAR).write_text(text, encoding="utf-8")
            if self.path.is_dir():  # overwrite: the old recording goes with the holder
                os.replace(self.path, self._holder / ".old")
            os.replace(self._bag, self.path)
            shutil.rmtree(self._holder, ignore_errors=True)
            self._state = "closed"
            return self.path

    def abort(self) -> None:
        """Drop the recording: nothing is left at the target nor next to it."""
        with self._lock:
            if self._state != "open":
                return
            self._state = "aborted"
            self._sync.wait()
            try:
                self._writer.close()
            except Exception:  # a half-open writer: the folder goes anyway
                pass
            shutil.rmtree(self._holder, ignore_errors=True)

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # -- internals ----------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._state != "open":
            raise DataError(f"{self.path}: recording is {self._state}; nothing more is written")

    def _time(self, t, what: str) -> float:
        t = float(t)
        if not (0.0 <= t < MAX_TIME_S):
            raise DataError(f"{what}: time {t} s is not in [0, 2^31) s (a ROS 2 stamp)")
        return t

    def _check_time(self, record: Record) -> float:
        if record.stream not in RECORD_FIELDS:
            raise DataError(f"record stream '{record.stream}' is not one of {list(RECORD_FIELDS)}")
        return self._time(record.t, f"{record.stream} record")

    @staticmethod
    def _t_read(ns: int) -> float:
        """The time the reader computes from a header stamp (sec, nanosec) = divmod(ns, 1e9):
        sec + nanosec 1e-9 (the record time in ns is the stamp's)."""
        sec, nanosec = divmod(ns, 1_000_000_000)
        return sec + nanosec * 1e-9

    def _connection(self, topic: str, msgtype: str):
        conn = self._conns.get(topic)
        if conn is None:
            qos = (TF_STATIC_QOS,) if msgtype == TF_MESSAGE else ()
            conn = self._writer.add_connection(
                topic, msgtype, typestore=self._b.store, offered_qos_profiles=qos
            )
            self._conns[topic] = conn
        return conn

    def _write_all(self, messages) -> None:
        if not self._mounting_written:  # the mounting first, at the first message's time
            self._mounting_written = True
            topic = self.topics.tf_static[0]
            ns, msg = tf_static_message(self._b, self.topics, self.mounting, messages[0][1] * 1e-9)
            messages = [(topic, ns, TF_MESSAGE, msg), *messages]
        store, counts, conns = self._b.store, self.counts, self._conns
        for topic, ns, msgtype, msg in messages:
            data = msg if type(msg) is bytes else store.serialize_cdr(msg, msgtype)
            conn = conns.get(topic) or self._connection(topic, msgtype)
            self._append(conn, ns, data)
            counts[topic] = counts.get(topic, 0) + 1
        t = messages[-1][1] * 1e-9
        if self._last_flush is None:
            self._last_flush = t
        elif t - self._last_flush >= self.flush_every_s:
            self.flush()
            self._last_flush = t

    def _messages(self, t: float, record: Record, late: str):
        try:
            return self._by_stream[record.stream](t, record, late)
        except (TypeError, ValueError) as exc:  # a field that is not numbers of its shape
            raise DataError(f"{record.stream} record: malformed field ({exc})") from None

    def _topic(self, stream: str, late: str) -> str:
        return late + stream if late else self.topics.first(stream)

    # -- one method per stream: (data as read back, [(topic, ns, msgtype, message)]) ----------
    def _imu(self, t: float, record: Record, late: str):
        d = record.data
        parts = (d.get("linear_acceleration") is not None, d.get("orientation") is not None)
        if late:
            has_a, has_q = parts
        else:
            if self._imu_parts is None:
                self._imu_parts = parts
            has_a, has_q = self._imu_parts
        w = _floats(d.get("angular_velocity"), 3)
        acc = _floats(d.get("linear_acceleration"), 3) if has_a else (0.0,) * 3
        q = _floats(d.get("orientation"), 4) if has_q else (0.0,) * 4
        data = {"angular_velocity": w}
        if has_a:
            data["linear_acceleration"] = acc
        if has_q:
            data["orientation"] = q
        topic = self._topic("imu", late)
        values = q + (_ZEROS9 if has_q else _NO_ESTIMATE9) + w + _ZEROS9 + acc + (
            _ZEROS9 if has_a else _NO_ESTIMATE9)  # fmt: skip

        def build():
            return imu_message(self._b, t, self._frame["imu"], w, acc, q, has_a, has_q)

        message = self._templated((topic, has_a, has_q), _IMU_TYPE, t, values, build)
        return data, [(topic, *message)]

    def _pressure(self, t: float, record: Record, late: str):
        p = _float(record.data.get("pressure"))
        topic, msgtype = self._topic("pressure", late), _PRESSURE_TYPE

        def build():
            return pressure_message(self._b, t, self._frame["barometer"], p)

        return {"pressure": p}, [(topic, *self._templated((topic,), msgtype, t, (p, 0.0), build))]

    def _templated(self, key: tuple, msgtype: str, t: float, values: tuple, build, tail=None):
        """(ns, msgtype, CDR bytes) of a message of fixed layout: packed on the key's template
        (:class:`CdrTemplate`), made from the first such message rosbags serializes."""
        template = self._templates.get(key)
        if template is not None:
            sec, nanosec, ns = stamp(t)
            return ns, msgtype, template.pack(sec, nanosec, values)
        ns, msg = build()
        if key in self._templates:  # no template reproduces this type's bytes: rosbags
            return ns, msgtype, msg
        serialized = bytes(self._b.store.serialize_cdr(msg, msgtype))
        self._templates[key] = CdrTemplate.make(serialized, t, values, tail)
        return ns, msgtype, serialized

    def _sonar(self, t: float, record: Record, late: str):
        d = record.data
        limits = None if late else self._sonar_limits
        if limits is None:
            limits = tuple(_f32(d.get(k, v)) for k, v in _SONAR_DEFAULTS.items())
            if not late:
                self._sonar_limits = limits
        rng = _f32(_float(d.get("range")))
        ns, msg = sonar_message(self._b, t, self._frame["sonar"], limits, rng)
        data = {"range": rng, **dict(zip(_SONAR_DEFAULTS, limits, strict=True))}
        return data, [(self._topic("sonar", late), ns, _RANGE_TYPE, msg)]

    def _dead_reckoning(self, t: float, record: Record, late: str):
        d = record.data
        position = _floats(d.get("position"), 3)
        rpy = _floats(d.get("orientation"), 3)
        std = np.float64(_float(d.get("std")))
        var = float(std**2)  # (numpy's power: not always the bits of std * std)
        # the message's fields after the header as dead_reckoning_message makes them: position,
        # the quaternion of the attitude, the covariance with std^2 at 0, 7 and 14 (43 float64)
        try:
            q = rpy_to_quaternion_scalar(*rpy)  # numpy's bits (tests/test_rotations.py)
        except ValueError:  # an infinite angle: math.cos refuses it, numpy gives NaN
            q = tuple(rpy_to_quaternion(np.array(rpy)).tolist())
        cov = [0.0] * 36
        cov[0] = cov[7] = cov[14] = var
        topic = self._topic("dead_reckoning", late)

        def build():
            return dead_reckoning_message(self._b, t, position, np.array(rpy), std)

        message = self._templated((topic,), _POSE_TYPE, t, (*position, *q, *cov), build)
        data = {
            "position": position,
            "orientation": quaternion_to_rpy_one(q),  # the reader's: from this quaternion
            "std": math.sqrt(var) if var >= 0 else math.nan,
        }
        return data, [(topic, *message)]

    def _dvl(self, t: float, record: Record, late: str):
        fields = _dvl_fields(record.data)
        v, valid, fom, cov, altitude, rng, ok, bvel = fields
        time_ms = self._dvl_interval_ms(t, late, v)
        tov = record.sensor_time if math.isfinite(record.sensor_time) else t
        beams = [(k, bvel[k], rng[k], ok[k]) for k in range(4)]
        report = report_values(time_ms, v, fom, cov, altitude, beams, valid, tov)
        topic, json_topic = self._topic("dvl", late), self._topic("dvl_json", late)
        values = (report.time_ms, *v, fom, report.altitude, 4,
                  *(x for bid, bv, dist, b_ok in report.beams
                    for x in (bid, bv, dist, math.nan, math.nan, b_ok)),
                  valid, 0, len(DVL_FORM), DVL_FORM)  # fmt: skip

        def build():
            return driver_message(self._b, t, self._frame["dvl"], report)

        ns, _, msg = self._templated((topic,), A50_DVL, t, values, build, DVL_TAIL)
        line = report_line(report)
        string = self._string_template
        if string is None:  # the first line: rosbags' bytes, kept as the template if equal
            ours = string_cdr(b"\x00\x01\x00\x00", line)
            ref = bytes(self._b.store.serialize_cdr(self._b.T[_STRING_TYPE](data=line),
                                                    _STRING_TYPE))  # fmt: skip
            self._string_template = string = ours[:4] if ours == ref else False
        text = string_cdr(string, line) if string else self._b.T[_STRING_TYPE](data=line)
        messages = [(topic, ns, A50_DVL, msg), (json_topic, ns, _STRING_TYPE, text)]
        return _dvl_read_back(fields), messages

    def _dvl_interval_ms(self, t: float, late: str, v: tuple) -> float:
        """The driver's ``time`` field (ms since the previous report, in [0, a day]), made
        unique with its velocity among the session's reports: the reader matches a report's
        JSON line (its covariance) by (time, vx, vy, vz)."""
        if late:
            return 0.0
        last, self._dvl_last_t = self._dvl_last_t, t
        time_ms = 0.0 if last is None else min(max((t - last) * 1e3, 0.0), MAX_REPORT_INTERVAL_MS)
        step_to = math.inf  # the reader keeps `time` in [0, MAX]: at the top, search downwards
        while (time_ms, *v) in self._dvl_keys:
            if time_ms >= MAX_REPORT_INTERVAL_MS:
                step_to = 0.0
            time_ms = float(np.nextafter(time_ms, step_to))
        self._dvl_keys.add((time_ms, *v))
        return time_ms


def _dvl_fields(d: dict) -> tuple:
    """(velocity, valid, fom, covariance (3 lists of 3), altitude, beam_range, beam_valid,
    beam_velocity) of a DVL record's fields as plain values, missing ones as
    ``Dvl.from_velocity`` fills them (valid True, NaN values, beams not valid)."""
    valid, beam_valid = d.get("valid"), d.get("beam_valid")
    cov = d.get("covariance")
    return (
        _floats(d.get("velocity"), 3),
        True if valid is None else _bool(valid),
        _float(d.get("fom")),
        [[math.nan] * 3] * 3 if cov is None else np.asarray(cov, np.float64).reshape(3, 3).tolist(),
        _float(d.get("altitude")),
        _floats(d.get("beam_range"), 4),
        (False,) * 4 if beam_valid is None else tuple(_bool(k) for k in _items(beam_valid, 4)),
        _floats(d.get("beam_velocity"), 4),
    )


def _bool(value) -> bool:
    return value if type(value) is bool else bool(np.asarray(value, np.bool_).reshape(()))


def _items(value, n: int) -> list:
    items = list(value) if isinstance(value, (tuple, list)) else np.asarray(value).reshape(-1)
    if len(items) != n:
        raise ValueError(f"expected {n} values, got {len(items)}")
    return items


def _dvl_read_back(fields: tuple) -> dict:
    """The DVL fields as the bag reader gives them back (module docstring)."""
    v, valid, fom, cov, alt, rng, ok, bvel = fields
    nan_v = any(math.isnan(x) for x in v)  # NaN != NaN: no JSON match, no covariance
    return {
        "velocity": v,
        "valid": valid,
        "fom": fom,
        "covariance": np.full((3, 3), np.nan) if nan_v else np.array(cov, dtype=np.float64),
        "altitude": alt if math.isfinite(alt) and alt >= 0 else math.nan,
        "beam_range": tuple(r if k else math.nan for r, k in zip(rng, ok, strict=True)),
        "beam_valid": ok,
        "beam_velocity": bvel,
    }


__all__ = ["Recorder", "POSE_TOPIC", "WAVE_TOPIC", "STATUS_TOPIC", "LATE_PREFIX"]
