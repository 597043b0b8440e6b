"""Records -> the messages of the live recording, and each record as a replay reads it back.

:class:`RecordEncoder` turns a :class:`~undertow.records.Record` into its stream's messages on
the standard topics (:mod:`undertow.live.recorder` writes them): the message types and builders
of :func:`~undertow.io.rosbag_write.write_log`, the DVL in the ``driver`` flavor (see the
recorder), the sonar's range as ``sensor_msgs/Range`` with its confidence beside it as
``undertow_msgs/RangeConfidence`` of the same stamp (:mod:`undertow.io.msgdefs`: the reader
matches them by stamp).

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
  the confidence (float64, NaN when the record has none) goes beside it as
  ``undertow_msgs/RangeConfidence`` of the same stamp and reads back as given;
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
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import DataError
from ..io.a50_json import MAX_REPORT_INTERVAL_MS, report_line, report_values
from ..io.msgdefs import A50_DVL, RANGE_CONFIDENCE
from ..io.rosbag_write import (
    MessageBuilder,
    confidence_message,
    dead_reckoning_message,
    driver_message,
    imu_message,
    pressure_message,
    sonar_message,
)
from ..io.topics import SENSOR_NAMES, TopicMap
from ..log import SonarRange
from ..records import RECORD_FIELDS, Record
from ..rotations import quaternion_to_rpy_one, rpy_to_quaternion, rpy_to_quaternion_scalar
from .cdr import DVL_FORM, DVL_TAIL, CdrTemplate, stamp, string_cdr

#: the message type of each raw stream's topic(s) (the DVL: its driver message and JSON line)
IMU_TYPE = "sensor_msgs/msg/Imu"
PRESSURE_TYPE = "sensor_msgs/msg/FluidPressure"
RANGE_TYPE = "sensor_msgs/msg/Range"
POSE_TYPE = "geometry_msgs/msg/PoseWithCovarianceStamped"  # dead reckoning and the estimate
STRING_TYPE = "std_msgs/msg/String"  # the DVL's JSON line and the status
STREAM_TYPES: dict[str, tuple[tuple[str, str], ...]] = {
    "imu": (("imu", IMU_TYPE),),
    "pressure": (("pressure", PRESSURE_TYPE),),
    "sonar": (("sonar", RANGE_TYPE), ("sonar_confidence", RANGE_CONFIDENCE)),
    "dead_reckoning": (("dead_reckoning", POSE_TYPE),),
    "dvl": (("dvl", A50_DVL), ("dvl_json", STRING_TYPE)),
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


class RecordEncoder:
    """A session's records as messages (module docstring). ``builder``: the recorder's
    :class:`~undertow.io.rosbag_write.MessageBuilder`; ``topics``: its topic names. Keeps what
    the session's first records fix (the IMU's parts, the sonar's limits), the DVL reports'
    keys and the CDR templates."""

    def __init__(self, builder: MessageBuilder, topics: TopicMap) -> None:
        self.b = builder
        self.topics = topics
        self._frame = {s: getattr(topics.frames, s)[0] for s in SENSOR_NAMES}
        self._imu_parts: tuple[bool, bool] | None = None  # (acceleration, orientation)
        self._sonar_limits: tuple[float, float, float] | None = None
        self._dvl_last_t: float | None = None
        self._dvl_keys: set[tuple] = set()
        self._templates: dict[tuple, CdrTemplate | None] = {}
        self._string_template: bytes | bool | None = None  # std_msgs/String's encapsulation
        self._by_stream = {stream: getattr(self, f"_{stream}") for stream in RECORD_FIELDS}

    def messages(self, t: float, record: Record, late: str):
        """(the record's data as read back, [(topic, record time ns, msgtype, message or CDR
        bytes)]) of ``record`` at time ``t``; ``late``: the late topics' prefix, or ""."""
        try:
            return self._by_stream[record.stream](t, record, late)
        except (TypeError, ValueError) as exc:  # a field that is not numbers of its shape
            raise DataError(f"{record.stream} record: malformed field ({exc})") from None

    def templated(self, key: tuple, msgtype: str, t: float, values: tuple, build, tail=None):
        """(ns, msgtype, CDR bytes) of a message of fixed layout: packed on the key's template
        (:class:`CdrTemplate`), made from the first such message rosbags serializes."""
        template = self._templates.get(key)
        if template is not None:
            sec, nanosec, ns = stamp(t)
            return ns, msgtype, template.pack(sec, nanosec, values)
        ns, msg = build()
        if key in self._templates:  # no template reproduces this type's bytes: rosbags
            return ns, msgtype, msg
        serialized = bytes(self.b.store.serialize_cdr(msg, msgtype))
        self._templates[key] = CdrTemplate.make(serialized, t, values, tail)
        return ns, msgtype, serialized

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
            return imu_message(self.b, t, self._frame["imu"], w, acc, q, has_a, has_q)

        message = self.templated((topic, has_a, has_q), IMU_TYPE, t, values, build)
        return data, [(topic, *message)]

    def _pressure(self, t: float, record: Record, late: str):
        p = _float(record.data.get("pressure"))
        topic, msgtype = self._topic("pressure", late), PRESSURE_TYPE

        def build():
            return pressure_message(self.b, t, self._frame["barometer"], p)

        return {"pressure": p}, [(topic, *self.templated((topic,), msgtype, t, (p, 0.0), build))]

    def _sonar(self, t: float, record: Record, late: str):
        d = record.data
        limits = None if late else self._sonar_limits
        if limits is None:
            limits = tuple(_f32(d.get(k, v)) for k, v in _SONAR_DEFAULTS.items())
            if not late:
                self._sonar_limits = limits
        rng = _f32(_float(d.get("range")))
        confidence = _float(d.get("confidence"))
        frame = self._frame["sonar"]
        ns, msg = sonar_message(self.b, t, frame, limits, rng)
        _, conf = confidence_message(self.b, t, frame, confidence)
        data = {"range": rng, "confidence": confidence,
                **dict(zip(_SONAR_DEFAULTS, limits, strict=True))}  # fmt: skip
        return data, [
            (self._topic("sonar", late), ns, RANGE_TYPE, msg),
            (self._topic("sonar_confidence", late), ns, RANGE_CONFIDENCE, conf),
        ]

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
            return dead_reckoning_message(self.b, t, position, np.array(rpy), std)

        message = self.templated((topic,), POSE_TYPE, t, (*position, *q, *cov), build)
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
            return driver_message(self.b, t, self._frame["dvl"], report)

        ns, _, msg = self.templated((topic,), A50_DVL, t, values, build, DVL_TAIL)
        line = report_line(report)
        string = self._string_template
        if string is None:  # the first line: rosbags' bytes, kept as the template if equal
            ours = string_cdr(b"\x00\x01\x00\x00", line)
            ref = bytes(self.b.store.serialize_cdr(self.b.T[STRING_TYPE](data=line),
                                                    STRING_TYPE))  # fmt: skip
            self._string_template = string = ours[:4] if ours == ref else False
        text = string_cdr(string, line) if string else self.b.T[STRING_TYPE](data=line)
        messages = [(topic, ns, A50_DVL, msg), (json_topic, ns, STRING_TYPE, text)]
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


__all__ = ["RecordEncoder", "STREAM_TYPES", "POSE_TYPE", "STRING_TYPE"]
