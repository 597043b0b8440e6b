"""A measurement as it travels from a source to the estimators: :class:`Record`, one measurement
of one :mod:`undertow.log` stream, and the functions that make Logs of them: the hand-off
between the live side (links, the recorder, the online estimators) and the offline one (the
MAVLink ``.tlog`` reader, every estimator that takes a Log).

A :class:`Record` names the stream it belongs to (``imu``, ``dvl``, ``dead_reckoning``,
``pressure``, ``sonar``) with that stream's fields in the Log's units and frames
(:data:`RECORD_FIELDS`), so that :func:`records_to_log` turns any sequence of records back into
a :class:`~undertow.log.Log`; :func:`concat_logs` joins consecutive chunks of such Logs into one.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import DataError
from .log import STREAM_NAMES, DeadReckoning, Dvl, Imu, Log, Mounting, Pressure, SonarRange

#: streams a record may name, and their fields (beyond ``t``) in :mod:`undertow.log` units
RECORD_FIELDS: dict[str, tuple[str, ...]] = {
    "imu": ("angular_velocity", "linear_acceleration", "orientation"),
    "dvl": (
        "velocity",
        "valid",
        "fom",
        "covariance",
        "altitude",
        "beam_range",
        "beam_valid",
        "beam_velocity",
    ),
    "dead_reckoning": ("position", "orientation", "std"),
    "pressure": ("pressure",),
    "sonar": ("range", "confidence"),
}


@dataclass(frozen=True)
class Record:
    """One measurement: ``stream`` (a :data:`RECORD_FIELDS` key), ``t`` (s; from a live link,
    the time its clock policy chose), ``data`` (that stream's fields), ``arrival`` (Unix s, when
    it reached this machine), ``sensor_time`` (the sensor's own time in s, NaN if none) and
    ``source`` (the link, or what else made it)."""

    stream: str
    t: float
    data: dict[str, Any]
    arrival: float = math.nan
    sensor_time: float = math.nan
    source: str = ""


def _stack(rows: list, shape: tuple, dtype=np.float64) -> np.ndarray:
    out = np.empty((len(rows), *shape), dtype=dtype)
    missing = np.nan if dtype == np.float64 else 0
    for i, value in enumerate(rows):
        out[i] = missing if value is None else value
    return out


def records_to_log(records: Iterable[Record], source: str = "", metadata=None) -> Log:
    """A :class:`~undertow.log.Log` of ``records`` (each stream sorted by time, stable)."""
    by_stream: dict[str, list[Record]] = {}
    for record in records:
        if record.stream not in RECORD_FIELDS:
            raise DataError(f"record stream '{record.stream}' is not one of {list(RECORD_FIELDS)}")
        by_stream.setdefault(record.stream, []).append(record)
    streams = {}
    for name, recs in by_stream.items():
        recs = sorted(recs, key=_time)
        t = np.array([r.t for r in recs], dtype=np.float64)
        if not np.isfinite(t).all():
            raise DataError(f"{name}.t: non-finite timestamps")
        # every array below is made here in its stream's dtype and shape, the times are finite
        # and sorted: the streams are built without the constructors' checks and copies
        streams[name] = _BUILDERS[name](t, [r.data for r in recs])
    return Log(**streams, source=source, metadata=dict(metadata or {}))


def _time(record: Record) -> float:
    return record.t


def _column(data: list[dict], key: str, shape: tuple, dtype=np.float64):
    rows = [d.get(key) for d in data]
    missing = sum(r is None for r in rows)
    if missing == len(rows):
        return None
    if not missing:  # one conversion of the whole column when every row is well formed
        try:
            out = np.array(rows, dtype=dtype)
        except (TypeError, ValueError):
            out = None
        if out is not None and out.shape == (len(rows), *shape):
            return out
    return _stack(rows, shape, dtype)


def _imu(t, data) -> Imu:
    return Imu.trusted(
        t=t,
        angular_velocity=_column(data, "angular_velocity", (3,)),
        linear_acceleration=_column(data, "linear_acceleration", (3,)),
        orientation=_column(data, "orientation", (4,)),
    )


def _dvl(t, data) -> Dvl:
    def col(key, shape=(), dtype=np.float64):
        return _column(data, key, shape, dtype)

    fields = Dvl.velocity_fields(
        t,
        col("velocity", (3,)),
        valid=col("valid", (), np.bool_),
        fom=col("fom"),
        covariance=col("covariance", (3, 3)),
        altitude=col("altitude"),
        beam_range=col("beam_range", (4,)),
        beam_valid=col("beam_valid", (4,), np.bool_),
        beam_velocity=col("beam_velocity", (4,)),
    )
    return Dvl.trusted(**fields)


def _dead_reckoning(t, data) -> DeadReckoning:
    return DeadReckoning.trusted(
        t=t,
        position=_column(data, "position", (3,)),
        orientation=_column(data, "orientation", (3,)),
        std=_column(data, "std", ()),
    )


def _pressure(t, data) -> Pressure:
    return Pressure.trusted(t=t, pressure=_column(data, "pressure", ()))


def _sonar(t, data) -> SonarRange:
    extra = {k: data[-1][k] for k in ("field_of_view", "min_range", "max_range") if k in data[-1]}
    return SonarRange.trusted(
        t=t, range=_column(data, "range", ()), confidence=_column(data, "confidence", ()), **extra
    )


_BUILDERS = {
    "imu": _imu,
    "dvl": _dvl,
    "dead_reckoning": _dead_reckoning,
    "pressure": _pressure,
    "sonar": _sonar,
}


def concat_logs(logs: list[Log], mounting: Mounting) -> Log:
    """One Log of consecutive chunks (each stream's rows in chunk order)."""
    streams = {}
    for name in STREAM_NAMES:
        parts = [getattr(log, name) for log in logs]
        parts = [p for p in parts if p is not None and len(p)]
        if not parts:
            continue
        if len(parts) == 1:
            streams[name] = parts[0]
            continue
        changes = {"t": np.concatenate([p.t for p in parts])}
        for field in parts[0].array_fields():
            values = [getattr(p, field) for p in parts]
            if all(v is None for v in values):
                continue
            like = next(v for v in values if v is not None)
            fill = False if like.dtype == np.bool_ else np.nan
            changes[field] = np.concatenate([
                v if v is not None else np.full((len(p), *like.shape[1:]), fill, like.dtype)
                for v, p in zip(values, parts, strict=True)
            ])  # fmt: skip
        streams[name] = dataclasses.replace(parts[0], **changes)
    return Log(**streams, mounting=mounting)
