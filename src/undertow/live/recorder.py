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
- ``/undertow/wave_condition`` (:data:`~undertow.io.topics.LIVE_WAVE_TOPIC`): ``std_msgs/String``,
  one JSON object per wave condition the filter was given (``--wave auto``): ``t`` (the update's
  time), ``from_t`` (the rows it applies to: those at or after it; null: every row, the filter
  had not started) and ``condition`` ("calm" or [a m, f Hz], floats as they were; JSON keeps
  a float's digits exactly). The reader keeps them (``metadata["live_wave"]``) and the
  offline filter replays them (:mod:`undertow.estimation.wave_schedule`);
- ``/undertow/status``: ``std_msgs/String``, one JSON object (rates, counters, filter health);
- ``/undertow/late/<stream>``: records that arrived after the reorder horizon (not given to the
  filter), with their stream's message type (``/undertow/late/dvl_json`` for the DVL's line).

The messages of each record, their CDR templates, and what a replay reads back of each record
(:meth:`Recorder.write_record` returns it) are :mod:`undertow.live.record_encoder`'s; the
messages are appended to the MCAP chunk by :mod:`undertow.live.mcap_append` (the file rosbags'
writer makes, byte for byte).

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
from ..io.rosbag import SIDECAR
from ..io.rosbag_streams import TF_MESSAGE
from ..io.rosbag_write import TF_STATIC_QOS, MessageBuilder, tf_static_message
from ..io.topics import LIVE_WAVE_TOPIC, TopicMap
from ..records import RECORD_FIELDS, Record
from ..robot import Mounting
from ..rotations import rpy_to_quaternion
from .chunk_sync import ChunkSync
from .mcap_append import MessageAppender
from .record_encoder import POSE_TYPE, STREAM_TYPES, STRING_TYPE, RecordEncoder

#: topics of the estimates (the raw streams use TopicMap's first names)
POSE_TOPIC = "/undertow/pose"
WAVE_TOPIC = "/undertow/wave"
STATUS_TOPIC = "/undertow/status"
LATE_PREFIX = "/undertow/late/"
#: builtin_interfaces/Time holds seconds in an int32 and the mcap record time is unsigned
MAX_TIME_S = 2.0**31 - 1.0
_WAVE_TYPE = "geometry_msgs/msg/Vector3Stamped"


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
        #: the records' messages (and what a replay reads back of each)
        self.encoder = RecordEncoder(self._b, self.topics)
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
        self._last_flush: float | None = None
        self._sync = ChunkSync()  # each flushed chunk to the disk, in the background

    def declare(self, streams, wave: bool = False) -> None:
        """Add the topics of ``streams`` (raw stream names) and of the estimates (pose, status;
        the wave and the wave conditions with ``wave``) now, before their first message:
        rosbags' ``add_connection`` takes milliseconds (the topic's QoS through a YAML dump), a
        stall the first record of each stream would otherwise wait for. A declared topic without
        messages is an empty topic of the bag (the readers skip it)."""
        with self._lock:
            self._check_open()
            for stream in streams:
                if stream not in STREAM_TYPES:
                    raise DataError(f"record stream '{stream}' is not one of {list(STREAM_TYPES)}")
                for name, msgtype in STREAM_TYPES[stream]:
                    self._connection(self.topics.first(name), msgtype)
            self._connection(POSE_TOPIC, POSE_TYPE)
            self._connection(STATUS_TOPIC, STRING_TYPE)
            if wave:
                self._connection(WAVE_TOPIC, _WAVE_TYPE)
                self._connection(LIVE_WAVE_TOPIC, STRING_TYPE)

    # -- raw records --------------------------------------------------------------------------
    def write_record(self, record: Record) -> Record:
        """Write ``record`` on its stream's standard topic; return it as ``read_log`` reads it."""
        with self._lock:
            self._check_open()
            t = self._check_time(record)
            data, messages = self.encoder.messages(t, record, "")
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
            _, messages = self.encoder.messages(t, record, LATE_PREFIX)
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
            msgtype = POSE_TYPE

            def build():
                h, ns = b.header(t, "world")
                return ns, b.T[msgtype](header=h, pose=b.pose_cov(x[0:3], x[3:6], cov))

            # the message's fields after the header: position, quaternion (as pose_cov makes
            # it), covariance: 43 float64
            values = (*x[0:3].tolist(), *rpy_to_quaternion(x[3:6]).tolist(), *cov.tolist())
            message = self.encoder.templated((topic,), msgtype, t, values, build)
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

    def write_wave_condition(self, t: float, from_t: float | None, condition) -> None:
        """A wave condition the filter was given on ``/undertow/wave_condition`` (module
        docstring): at the update time ``t``, for the rows at or after ``from_t`` (None: all)."""
        if condition != "calm":
            condition = [float(condition[0]), float(condition[1])]
        entry = {"t": float(t), "from_t": None if from_t is None else float(from_t),
                 "condition": condition}  # fmt: skip
        self.write_status(t, entry, LIVE_WAVE_TOPIC)

    def write_status(self, t: float, status: dict, topic: str = STATUS_TOPIC) -> None:
        """``status`` as one JSON object (``std_msgs/String``) on ``/undertow/status`` (or
        ``topic``); NaN and infinities become null (strict JSON)."""
        text = json.dumps(json_safe(status), default=str, allow_nan=False)
        with self._lock:
            self._check_open()
            t = self._time(t, "status")
            _, ns = self._b.header(t, "")
            msg = self._b.T[STRING_TYPE](data=text)
            self._write_all([(topic, ns, STRING_TYPE, msg)])

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


__all__ = ["Recorder", "POSE_TOPIC", "WAVE_TOPIC", "STATUS_TOPIC", "LATE_PREFIX"]
