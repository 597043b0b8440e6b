"""The choices a ROS bag's reader makes about its data, each stated: which topic is which
stream where the defaults name none (:func:`resolve_topics`), one time base for every row
(:func:`apply_time_base`), which way a depth pose's z points (:func:`depth_sign`), and the frame
of a DVL velocity stamped in the body frame (:func:`dvl_frame`). Used by
:mod:`undertow.io.rosbag`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from ..log import Dvl
from ..robot import Mounting
from .clock import TimeBase, choose_time_base
from .collect import Notes
from .read_options import LogOptions
from .rosbag_streams import Rows
from .topic_guess import propose_topics
from .topics import LIVE_WAVE_TOPIC, TopicMap

#: topics whose messages take no part in the time base: the DVL's raw JSON (unless it stands in
#: for a stream), the mounting, the sonar's confidence (matched to its range by stamp) and a
#: live session's wave decisions
UNTIMED = ("tf_static", "dvl_json", "sonar_confidence", "live_wave")


def resolve_topics(topics: TopicMap, available: dict, notes: Notes) -> tuple[dict, dict]:
    """(stream -> topic, stream -> guessed topic): the topic map's first candidates found, and
    for the streams whose default candidates are all absent, the topic :func:`propose_topics`
    scores best by type and name (stated in one line)."""
    mapped = topics.resolve(available)
    free = {t: m for t, m in available.items() if t not in mapped.values()}
    open_streams = tuple(
        s for s in ("dvl", "dead_reckoning", "imu", "pressure", "depth", "sonar", "gps")
        if s not in mapped and topics.is_default(s)
    )  # fmt: skip
    guessed = propose_topics(free, open_streams) if open_streams else {}
    if guessed:
        listing = ", ".join(f"{s}={c.topic} ({c.msgtype})" for s, c in guessed.items())
        notes.state(
            f"topics chosen by message type and name (no default topic name in the bag): "
            f"{listing}; `undertow check LOG --write-config FILE` writes them to a settings file"
        )
    mapped.update({s: c.topic for s, c in guessed.items()})
    if LIVE_WAVE_TOPIC in available:
        mapped["live_wave"] = LIVE_WAVE_TOPIC
    return mapped, {s: c.topic for s, c in guessed.items()}


def apply_time_base(rows: Rows, notes: Notes, used: dict, options: LogOptions) -> dict:
    """Put every row on one clock (:func:`~undertow.io.clock.choose_time_base`); the choice
    is stated in one line when the log mixes clocks or the user chose, and returned as a dict.
    The raw JSON topic (no stamps) takes part only where it stands in for a missing stream."""
    streams = {s for s in used.values() if s not in UNTIMED}
    if (rows.json_velocity and not len(rows.dvl)) or (
        rows.json_position and not rows.rows["dead_reckoning"]
    ):
        streams.add("dvl_json")
    names = {s: t for t, s in used.items()}
    base = choose_time_base(rows.clock, options.time, names, options.clock_tolerance_s, streams)
    rows.apply_times(base.times)
    rows.time_base = dataclasses.replace(base, times=np.zeros(0))
    if base.mixed or options.time != "auto":
        notes.state(base.line())
    return base.to_dict()


def depth_sign(rows: Rows, options: LogOptions, metadata: dict, notes: Notes) -> float:
    """+1 when the depth topic's value is depth (positive down), -1 when it is a height (a pose
    z up, REP-103's east-north-up). A float depth topic is positive down; a pose's z: the
    settings' ``depth_z``, else the sign of its correlation with the pressure when the log has
    both (depth grows with pressure), else up (REP-103)."""
    if not rows.rows["depth"]:
        return 1.0
    if rows.depth_kind == "float" and options.depth_z == "auto":
        metadata["depth_z"] = "down (a depth value)"
        return 1.0
    if options.depth_z != "auto":
        metadata["depth_z"] = f"{options.depth_z} (settings)"
        return 1.0 if options.depth_z == "down" else -1.0
    r = depth_pressure_correlation(rows)
    if r is not None and abs(r) >= 0.5:
        sign = 1.0 if r > 0 else -1.0
        metadata["depth_z"] = (
            f"{'down' if sign > 0 else 'up'} (correlation {r:+.2f} of the depth topic's z with "
            "the pressure)"
        )
        return sign
    metadata["depth_z"] = "up (REP-103 east-north-up; no pressure to tell)"
    notes.add("depth: a pose's z read as up (REP-103), depth = -z; set log: {depth_z: down} "
              "if it points down")  # fmt: skip
    return -1.0


def depth_pressure_correlation(rows: Rows) -> float | None:
    """Pearson correlation of the depth topic's value with the pressure interpolated at its
    times (None without both, or without variation)."""
    if not rows.rows["pressure"]:
        return None
    d, p = rows.array("depth", 2), rows.array("pressure", 2)
    d, p = d[np.isfinite(d).all(axis=1)], p[np.isfinite(p).all(axis=1)]
    if len(d) < 3 or len(p) < 3:
        return None
    p = p[np.argsort(p[:, 0], kind="stable")]
    inside = (d[:, 0] >= p[0, 0]) & (d[:, 0] <= p[-1, 0])
    if inside.sum() < 3:
        return None
    at = np.interp(d[inside, 0], p[:, 0], p[:, 1])
    z = d[inside, 1]
    if np.std(at) == 0 or np.std(z) == 0:
        return None
    return float(np.corrcoef(z, at)[0, 1])


def dvl_frame(dvl: Dvl | None, rows: Rows, topics: TopicMap, mounting: Mounting,
               metadata: dict, notes: Notes) -> Dvl | None:  # fmt: skip
    """A velocity stamped in the body (base) frame brought to the DVL frame, v_DVL = R^T v_B
    with R the DVL's mounting rotation (the lever arm's omega x r is not removed: a twist
    in the base frame is taken as the DVL's velocity rotated, as drivers that publish it do)."""
    frames = {f.lstrip("/") for f in rows.dvl_frames}
    base = topics.base_frame.lstrip("/")
    if dvl is None or frames != {base}:
        return dvl
    R = mounting.dvl.rotation_matrix()
    metadata["dvl_frame"] = f"{base} (body), rotated to the DVL frame by its mounting"
    notes.add(f"dvl: velocities stamped in the body frame {base}, rotated to the DVL frame")
    return replace(dvl, velocity=np.asarray(dvl.velocity) @ R)


def fixed_times(rows: Rows, base: TimeBase) -> np.ndarray:
    """The time of every message of ``rows.clock`` on the time base ``base`` chose for the
    whole log (no choice made again): the record time, or the header stamp where there is one
    and the record time minus the base's shift of its stream (else its offset, else 0) where
    there is none, as :func:`~undertow.io.clock.choose_time_base` puts them."""
    clock = rows.clock
    record = np.asarray(clock.record, dtype=np.float64)
    if base.base != "header":
        return record
    header = np.asarray(clock.header, dtype=np.float64)
    times = record.copy()
    have = np.isfinite(header)
    times[have] = header[have]
    if not have.all():
        kinds = np.asarray(clock.stream, dtype=object)
        for s in set(kinds[~have].tolist()):
            sel = (kinds == s) & ~have
            times[sel] = record[sel] - stream_offset(base, s)
    return times


def stream_offset(base: TimeBase, stream: str) -> float:
    """A stream's record time minus its time on ``base`` (s): 0 on the record time; on the
    stamps, the shift put on its unstamped messages, else its median offset, else 0."""
    if base.base != "header":
        return 0.0
    value = base.shift_s.get(stream, base.offsets_s.get(stream, math.nan))
    if not math.isfinite(value):
        finite = [v for v in base.offsets_s.values() if math.isfinite(v)]
        value = float(np.median(finite)) if finite else 0.0
    return value


def piece_keys(rows: Rows, base: TimeBase, times: np.ndarray, slack_s: float) -> np.ndarray:
    """The time that puts each message of ``rows.clock`` in a piece of a log read in pieces:
    its time on ``base`` when its record time is within ``slack_s`` of where its stream's
    offset puts it, else its record time minus that offset (a message stamped far off its
    stream stays in the piece it was recorded in, instead of falling between pieces)."""
    kinds = np.asarray(rows.clock.stream, dtype=object)
    record = np.asarray(rows.clock.record, dtype=np.float64)
    offset = np.zeros(len(record))
    for s in set(kinds.tolist()):
        offset[kinds == s] = stream_offset(base, s)
    expected = record - offset
    return np.where(np.abs(times - expected) <= slack_s, times, expected)


def piece_windows(base: TimeBase, streams: set[str], reader, piece_s: float,
                  slack_s: float) -> Iterator[tuple[float, float, int, int]]:  # fmt: skip
    """(a, b, start, stop) per piece of a bag read in pieces: the piece holds the messages
    whose key (:func:`piece_keys`) is in [a, b) s, read from the record times [start, stop) ns
    (the window widened by the streams' offsets on ``base`` and ``slack_s``). The pieces are
    ``piece_s`` long from the bag's first record time less the smallest offset; the first
    starts at -inf, the last (after which no message's key can fall) ends at +inf."""
    offsets = [stream_offset(base, s) for s in (*streams, "dvl_json")]
    lo, hi = min(offsets), max(offsets)
    first, end = reader.start_time * 1e-9, reader.end_time * 1e-9
    origin = first - lo
    k = 0
    while True:
        a = -math.inf if k == 0 else origin + k * piece_s
        b = origin + (k + 1) * piece_s
        last = b + lo - slack_s > end
        b = math.inf if last else b
        start = None if k == 0 else math.floor((a + lo - slack_s) * 1e9) - 1
        stop = None if last else math.ceil((b + hi + slack_s) * 1e9) + 1
        yield a, b, start, stop
        if last:
            return
        k += 1
