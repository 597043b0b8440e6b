"""``undertow info``: a per-stream summary of a :class:`~undertow.log.Log`.

:func:`summarize` counts, per stream, messages, median rate, time span, invalid rows (the
stream's own ``invalid_count``) and missing values (NaN entries in the stream's measurement:
for the DVL, NaN altitude plus invalid beams; for the multibeam, beams without a detection;
elsewhere non-finite main values).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .._util.plain import json_safe
from ..log import Log


@dataclass(frozen=True)
class StreamSummary:
    """Counts and timing of one stream (times in the log's seconds)."""

    name: str
    messages: int
    rate_hz: float
    start_s: float
    end_s: float
    duration_s: float
    invalid: int
    missing_values: int
    missing_detail: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class LogSummary:
    """What a log holds: one :class:`StreamSummary` per stream plus overall span and notes."""

    source: str
    streams: list[StreamSummary]
    start_s: float
    end_s: float
    duration_s: float
    warnings: list[str]

    def to_dict(self) -> dict:
        """JSON-serializable dict (NaN becomes None)."""
        return json_safe(asdict(self))


def _missing(name: str, stream) -> dict[str, int]:
    if name == "dvl":
        return {
            "altitude": int(np.sum(np.isnan(stream.altitude))),
            "invalid_beams": int(np.sum(~stream.beam_valid)),
            "velocity": int(np.sum(np.isnan(stream.velocity).any(axis=1))),
        }
    if name == "multibeam":
        return {"beams_without_detection": int(np.sum(~stream.valid))}
    main = {
        "imu": "angular_velocity",
        "dead_reckoning": "position",
        "pressure": "pressure",
        "sonar": "range",
        "wave_probe": "elevation",
        "ground_truth": "position",
        "depth": "depth",
        "gps": "position",
        "autopilot": "position",
    }[name]
    values = np.asarray(getattr(stream, main), dtype=np.float64).reshape(len(stream), -1)
    return {main: int(np.sum(~np.isfinite(values).all(axis=1))) if values.size else 0}


def summarize(log: Log) -> LogSummary:
    """Per-stream counts, rates and spans of ``log``."""
    with np.errstate(all="ignore"):  # extreme values give inf/NaN figures, not numpy warnings
        return _summarize(log)


def _summarize(log: Log) -> LogSummary:
    streams = []
    for name, s in log.streams().items():
        n = len(s)
        start = float(s.t[0]) if n else float("nan")
        end = float(s.t[-1]) if n else float("nan")
        detail = _missing(name, s)
        streams.append(
            StreamSummary(
                name=name,
                messages=n,
                rate_hz=s.rate_hz,
                start_s=start,
                end_s=end,
                duration_s=end - start,
                invalid=s.invalid_count(),
                missing_values=sum(detail.values()),
                missing_detail=detail,
            )
        )
    start, end = log.time_span
    return LogSummary(
        source=log.source,
        streams=streams,
        start_s=start,
        end_s=end,
        duration_s=end - start,
        warnings=list(log.metadata.get("warnings", [])),
    )
