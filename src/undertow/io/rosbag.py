"""Reader of ROS bags (ROS 1 ``.bag``; ROS 2 sqlite3 and mcap) into a :class:`~undertow.log.Log`.

Topics come from a :class:`~undertow.io.topics.TopicMap` (first candidate found wins); the DVL
topic is decoded by message type. The raw A50 JSON topic (``/dvl/json_data``) fills what the
driver message lacks (covariance; ``time_of_validity`` kept in
``metadata['dvl_time_of_validity_s']``) and stands in for a missing DVL or dead-reckoning topic
(times: bag record time, i.e. receive time). The sensor mounting comes from, in this order: a
sidecar ``undertow.yaml`` next to the bag (written by :func:`undertow.io.rosbag_write.write_log`,
it also restores metadata), the bag's ``/tf_static`` (transforms from the topic map's base frame
to its sensor frames, body forward-right-down; see :mod:`undertow.io.topics`), else the BlueROV2
defaults; ``metadata['mounting_source']`` says which. A user-given topic that is not in the bag
gives one warning line. A directory without ``metadata.yaml`` holding a single ``.mcap``/``.db3``
is read as that file. DVL messages without beam vectors (the A50 driver's) get the A50 geometry,
or the one recorded in the sidecar's ``metadata.dvl_geometry`` (``robot.DvlGeometry.to_dict``:
a Nortek or Teledyne head, say). The multibeam (``sensor_msgs/PointCloud2`` detections) takes
its range limits from the sidecar's ``multibeam`` entry when there is one. rosbags errors
become one-line :class:`~undertow.errors.ReaderError`.

Everything in and beside a bag is untrusted: a message that cannot be decoded or holds malformed
fields is skipped and counted (one warning per topic); a sidecar that is not a mapping, or whose
mounting or numeric metadata (``water_density_kg_m3``, ``surface_pressure_pa``) is malformed, is
ignored in that part with one warning; named pipes, devices and sockets are refused before
opening.

A crashed recording (``undertow live`` killed, a power cut) is read up to its last complete
chunk: the ``.partial-*`` folder the recorder left, the bag folder or ``.mcap`` inside it, the
intended target when only its ``.partial-*`` sibling exists, or any lone ``.mcap`` without its
end magic (not one of a bag folder with ``metadata.yaml``: such a file was complete once) is
recovered into a new file by :func:`undertow.io.mcap_recover.recover` (the original is not
changed) and read from there, with one line saying so, how much was recovered and where the
copy is (``metadata['recovered']`` holds the same). The sidecar ``undertow.yaml`` the recorder
writes at the end is then missing: the mounting comes from the bag's ``/tf_static``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml
from rosbags.highlevel import AnyReader

from ..errors import ConfigError, ReaderError, UndertowError
from ..log import Dvl, Log
from ..robot import DvlGeometry, Mounting
from ..rotations import quaternion_to_rpy
from .a50_json import dead_reckoning_from_rows
from .clock import TimeBase
from .collect import MALFORMED, Notes, check_regular
from .mcap_recover import Recovered, incomplete_mcap, partial_bag, recover
from .msgdefs import dvl_typestore
from .read_options import LogOptions
from .rosbag_choices import (
    apply_time_base,
    depth_sign,
    dvl_frame,
    fixed_times,
    piece_keys,
    piece_windows,
    resolve_topics,
)
from .rosbag_guard import close_bag, empty_bad_files
from .rosbag_streams import ACCEPTED, Rows, build_dvl
from .topics import TopicMap
from .units import DEG, resolve_units

SIDECAR = "undertow.yaml"
STORAGE_SUFFIXES = (".mcap", ".db3")
#: sidecar metadata the estimation uses as numbers: kept only when a finite positive number
NUMERIC_METADATA = ("water_density_kg_m3", "surface_pressure_pa")

# what rosbags' own exceptions without a message mean for a damaged file
_BARE = {
    "AssertionError": "a record header or length field is malformed",
    "MemoryError": "a record claims a length too large to allocate (corrupt length field)",
    "IndexError": "a record ends before its declared length",
    "KeyError": "a record refers to a connection or type that is not defined",
    "RecursionError": "a message definition refers to itself",
}


def _one_line(exc: BaseException) -> str:
    name = type(exc).__name__
    text = str(exc).strip().splitlines()
    if name in _BARE and (not text or name in ("MemoryError", "KeyError", "IndexError")):
        return _BARE[name]
    return f"{name}: {text[0][:200]}" if text else name


def _bag_paths(path: Path) -> list[Path]:
    check_regular(path, directory_ok=True)
    if path.suffix == ".bag":
        return [path]
    if path.is_dir():
        if (path / "metadata.yaml").exists():
            for inner in path.iterdir():  # rosbags opens the metadata and the storage files
                if inner.name == "metadata.yaml" or inner.suffix in STORAGE_SUFFIXES:
                    check_regular(inner)
            return [path]
        files = sorted(p for p in path.iterdir() if p.suffix in STORAGE_SUFFIXES)
        if len(files) == 1:  # a bag directory whose metadata.yaml was not copied
            return files
        if not files:
            raise ReaderError(
                f"{path}: directory is not a ROS 2 bag (no metadata.yaml, .mcap or .db3 file)"
            )
        names = ", ".join(p.name for p in files)
        raise ReaderError(
            f"{path}: no metadata.yaml and {len(files)} storage files ({names}); give one file"
        )
    if (path.parent / "metadata.yaml").exists():
        return [path.parent]
    return [path]


def _warn_unmatched(topics: TopicMap, available: dict, path: Path, log: Log) -> list[str]:
    """One warning line per user-given stream of which no topic is in the bag, saying whether
    the stream was read from a fallback (the DVL and its dead reckoning from the raw JSON
    topic) or not at all."""
    listing = sorted(map(str, available))
    shown = ", ".join(listing[:8]) + (f", ... ({len(listing)} in all)" if len(listing) > 8 else "")
    lines = []
    for stream, candidates in topics.unmatched_user_topics(available).items():
        fallback = log.metadata.get(f"{stream}_source") if getattr(log, stream, None) else None
        outcome = f"read from {fallback} instead" if fallback else "stream not read"
        lines.append(
            f"{path}: {stream}: no topic of the topic map ({', '.join(candidates)}) is in the bag;"
            f" {outcome} (topics in the bag: {shown or 'none'})"
        )
    for line in lines:
        warnings.warn(line, stacklevel=3)
    return lines


def read_rosbag(path, topics: TopicMap | None = None, options: LogOptions | None = None) -> Log:
    """Read a ROS 1 or ROS 2 bag into a Log (see the module docstring); ``options``: the time
    base, a pose-depth's sign and the GPS origin (:class:`~undertow.io.read_options.LogOptions`,
    default: detected)."""
    path = Path(path)
    recovered = recover_crashed(path)
    if recovered is None and not path.exists():
        raise ReaderError(f"{path}: no such file or directory")
    if recovered is None and path.is_file() and path.stat().st_size == 0:
        raise ReaderError(f"{path}: empty file")
    with np.errstate(all="ignore"):  # overflow to inf is counted as non-finite, not warned
        return _read_rosbag(path, topics or TopicMap(), options or LogOptions(), recovered)


#: seconds at the start of a log read in pieces from which its choices are made (time base,
#: units, surface pressure, depth sign, mounting): the whole log when it is shorter, so that a
#: log of up to an hour is read with exactly the whole read's choices and evidence (the surface
#: pressure, say, is the median of the readings near the log's lowest pressure)
DECIDE_S = 3600.0
#: a message more than this (s) off where its stream's clock offset puts it is put in a piece
#: by its record time (:func:`~undertow.io.rosbag_choices.piece_keys`)
PIECE_SLACK_S = 2.0
#: metadata a piece has of its own (not the head's)
PIECE_METADATA = ("warnings", "dvl_time_of_validity_s", "dvl_json_matched")
#: what a head's rows decide that the pieces' rows keep (the first message's constants)
PIECE_DECIDED = ("pressure_scale", "gps_local_origin", "sonar_limits", "probe_x")


@dataclass(frozen=True)
class Head:
    """The choices a log read in pieces makes once, from its first ``DECIDE_S`` seconds: that
    part read as a whole log (``log``: its metadata and mounting go to every piece) and what
    its rows decided."""

    log: Log
    time_base: TimeBase
    #: the attributes of :class:`~undertow.io.rosbag_streams.Rows` its rows decided
    decided: dict
    depth_sign: float | None
    gps_origin: tuple | None
    warned: set = field(default_factory=set)


def iter_rosbag_pieces(path, piece_s: float, topics: TopicMap | None = None,
                       options: LogOptions | None = None, decide_s: float = DECIDE_S,
                       slack_s: float = PIECE_SLACK_S,
                       streams: tuple[str, ...] | None = None) -> Iterator[Log]:  # fmt: skip
    """The bag at ``path`` as Logs of consecutive ``piece_s``-second windows of its time base,
    with its units resolved (:func:`~undertow.io.units.resolve_units`), each holding only its
    window (memory: a piece, not the log).

    Every choice the whole read (:func:`read_rosbag`) makes from the data is made once, from
    the first ``decide_s`` seconds read as a log (all of it when it is shorter: then the
    choices are the whole read's): topics, time base (its shifts and offsets), gyro unit,
    surface pressure and water, hPa, a depth pose's sign, GPS origin, mounting, sonar and wave
    probe constants; every piece carries that part's metadata (``warnings`` and the DVL's
    ``time_of_validity`` are the piece's own). A message is in the piece of its time on that
    base (:func:`~undertow.io.rosbag_choices.piece_keys`); the bag is read by record time, a
    window ``slack_s`` wider than the pieces' (plus the streams' clock offsets) on each side.
    The pieces' streams concatenated are those of :func:`~undertow.io.read_log` as long as each
    stream's times are in record order (no message sorted across a piece's edge) and the
    decisions of the first ``decide_s`` seconds are those of the whole log. ``streams``: the
    pieces hold only these streams (their topics alone decoded; the choices as without it)."""
    if not (piece_s > 0 and decide_s > 0 and slack_s >= 0):
        raise ConfigError(f"pieces: piece_s {piece_s} and decide_s {decide_s} must be > 0, "
                          f"slack_s {slack_s} >= 0")  # fmt: skip
    path = Path(path)
    recovered = recover_crashed(path)
    if recovered is None and not path.exists():
        raise ReaderError(f"{path}: no such file or directory")
    topics, options = topics or TopicMap(), options or LogOptions()
    notes = Notes(str(path))
    reader = _open(path, recovered, notes)
    try:
        available, used, guessed, conns = _select(reader, topics, notes)
        rows = Rows(notes)
        with np.errstate(all="ignore"):
            _read_messages(reader, conns, used, rows, notes, path,
                           stop=reader.start_time + int(decide_s * 1e9))  # fmt: skip
            selected = (available, used, guessed)
            log = resolve_units(_finish(rows, notes, path, selected, topics, options, recovered),
                                options)  # fmt: skip
        gps = None if log.gps is None or rows.gps_local else log.gps.origin
        kept = {name: getattr(rows, name) for name in PIECE_DECIDED}
        head = Head(log, rows.time_base, kept, rows.depth_sign, gps)
        del log, rows  # the head's rows: only what they decided is kept
        windows = piece_windows(head.time_base, set(used.values()), reader, piece_s, slack_s)
        if streams is not None:
            conns = [c for c in conns if used[str(c.topic)] in streams]
        for a, b, start, stop in windows:
            with np.errstate(all="ignore"):
                piece = _piece(reader, conns, used, path, topics, head, (a, b, start, stop),
                               slack_s)  # fmt: skip
            if piece is not None:
                yield piece
    finally:
        reader.close()


def _piece(reader, conns, used, path: Path, topics: TopicMap, head: Head, window: tuple,
           slack_s: float) -> Log | None:  # fmt: skip
    """The piece of the messages whose time is in [a, b) (``window``: a, b and the record
    times start, stop (ns) to read), None when it has none."""
    a, b, start, stop = window
    notes = Notes(str(path))
    rows = Rows(notes)
    for name, value in head.decided.items():
        setattr(rows, name, value)
    _read_messages(reader, conns, used, rows, notes, path, start=start, stop=stop)
    base = head.time_base
    times = fixed_times(rows, base)
    keys = piece_keys(rows, base, times, slack_s)
    rows.apply_times(np.where((keys >= a) & (keys < b), times, np.nan))
    log = _assemble(rows, notes, path, used, topics, LogOptions(), path, head)
    if not log.streams():
        return None
    for kind in list(notes.counts):  # the messages of other pieces, left out
        if kind.endswith(("with a non-finite time dropped", "(stream dropped)")):
            del notes.counts[kind]
    log.metadata["warnings"] = notes.lines()
    for kind, line in zip([*notes.statements, *notes.counts], notes.lines(), strict=True):
        if kind not in head.warned:  # each kind of note once for the whole log
            head.warned.add(kind)
            warnings.warn(line, stacklevel=4)
    imu_units = head.log.metadata.get("imu_units") or {}
    if log.imu is not None and imu_units.get("converted"):
        log = log.replace(imu=replace(log.imu, angular_velocity=log.imu.angular_velocity * DEG))
    return log


def recover_crashed(path) -> Recovered | None:
    """The recovered copy of the crashed recording ``path`` names (module docstring), None
    when it names none."""
    path = Path(path)
    inside = partial_bag(path)
    mcap = incomplete_mcap(inside or path)
    return recover(mcap) if mcap is not None else None


def _storage(path: Path, recovered: Recovered | None) -> list[Path]:
    """What rosbags opens: the recovered copy, the bag inside a ``.partial`` folder (its
    writer finished it but did not rename it), else the bag itself."""
    if recovered is not None:
        return [Path(recovered.path)]
    return _bag_paths(partial_bag(path) or path)


def bag_topics(path) -> dict[str, tuple[str, int]]:
    """``{topic: (message type, message count)}`` of a ROS 1/2 bag, from its index (no
    message is read); one ReaderError line for a file that is not a readable bag."""
    return bag_index(path)[0]


def bag_index(path) -> tuple[dict[str, tuple[str, int]], float]:
    """(:func:`bag_topics`, the span of its record times in s) from the bag's index, no
    message decoded; one ReaderError line for a file that is not a readable bag."""
    path = Path(path)
    try:
        reader = AnyReader(_storage(path, recover_crashed(path)), default_typestore=dvl_typestore())
        reader.open()
        empty_bad_files(reader)
    except ReaderError:
        raise
    except Exception as exc:  # rosbags raises many types for corrupt input
        raise ReaderError(f"{path}: cannot open bag ({_one_line(exc)})") from exc
    try:
        topics: dict[str, tuple[str, int]] = {}
        for c in reader.connections:
            msgtype, count = topics.get(str(c.topic), (str(c.msgtype), 0))
            topics[str(c.topic)] = (msgtype, count + int(c.msgcount))
        span = max(int(reader.end_time) - int(reader.start_time), 0) if topics else 0
        return topics, span / 1e9
    finally:
        close_bag(reader)


def _read_rosbag(path: Path, topics: TopicMap, options: LogOptions,
                 recovered: Recovered | None) -> Log:  # fmt: skip
    notes = Notes(str(path))
    rows = Rows(notes)
    reader = _open(path, recovered, notes)
    try:
        available, used, guessed, conns = _select(reader, topics, notes)
        _read_messages(reader, conns, used, rows, notes, path)
    finally:
        if (failed := close_bag(reader)) is not None:
            notes.add("closing the bag failed (what was read is kept)", 1, _one_line(failed))
    return _finish(rows, notes, path, (available, used, guessed), topics, options, recovered)


def _open(path: Path, recovered: Recovered | None, notes: Notes):
    """The opened AnyReader of the bag (one ReaderError line when it cannot be opened)."""
    paths = _storage(path, recovered)
    if recovered is not None:
        notes.state(recovered.line())
    try:
        reader = AnyReader(paths, default_typestore=dvl_typestore())
        reader.open()
    except Exception as exc:  # rosbags raises many types for corrupt input
        raise ReaderError(f"{path}: cannot open bag ({_one_line(exc)})") from exc
    if empty_bad_files(reader):
        notes.add("metadata.yaml: 'files' is not a list (ignored)")
    return reader


def _select(reader, topics: TopicMap, notes: Notes) -> tuple[dict, dict, dict, list]:
    """(topic -> type in the bag, topic -> stream read, guessed topics, connections read)."""
    available = {str(c.topic): str(c.msgtype) for c in reader.connections}
    mapped, guessed = resolve_topics(topics, available, notes)
    used = {}
    for stream, topic in mapped.items():
        if available[topic] in ACCEPTED[stream]:
            used[topic] = stream
        else:
            notes.add(
                f"topic {topic} has unsupported type {available[topic]} for {stream} (skipped)"
            )
    conns = [c for c in reader.connections if str(c.topic) in used]
    return available, used, guessed, conns


def _finish(rows: Rows, notes: Notes, path: Path, selected: tuple, topics: TopicMap,
            options: LogOptions, recovered: Recovered | None) -> Log:  # fmt: skip
    """The Log of the rows read (``selected``: what :func:`_select` gave)."""
    available, used, guessed = selected
    beside = Path(recovered.source) if recovered else partial_bag(path) or path  # the sidecar's
    log = _assemble(rows, notes, path, used, topics, options, beside)
    if recovered is not None:
        log.metadata["recovered"] = asdict(recovered)
    if guessed:
        log.metadata["topics_guessed"] = guessed
    unmatched = _warn_unmatched(topics, available, path, log)
    if not log.streams():
        listing = ", ".join(f"{t} ({m})" for t, m in sorted(available.items())) or "none"
        if any(notes.counts):
            listing += "; " + "; ".join(notes.lines()[:2])
        raise ReaderError(f"{path}: no known measurement stream; topics in the bag: {listing}")
    log.metadata["warnings"] = unmatched + notes.finish()
    return log


def _read_messages(reader, conns, used, rows: Rows, notes: Notes, path: Path,
                   start: int | None = None, stop: int | None = None) -> None:  # fmt: skip
    """Decode the messages of ``conns`` recorded in [start, stop) ns (all by default) into
    ``rows``."""
    if not conns:  # rosbags reads every topic when given no connection
        return
    messages = reader.messages(connections=conns, start=start, stop=stop)
    index = 0
    while True:
        try:
            conn, record_ns, raw = next(messages)
        except StopIteration:
            return
        except Exception as exc:  # rosbags raises many types for corrupt input
            raise ReaderError(
                f"{path}: corrupt or truncated bag after {index} messages of the read topics "
                f"({_one_line(exc)})"
            ) from None
        index += 1
        topic = str(conn.topic)
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception:  # a corrupt message: count it, keep the rest
            notes.add(f"{topic}: messages that could not be decoded (skipped)", detail=f"#{index}")
            continue
        try:
            rows.add(used[topic], conn.msgtype, msg, record_ns)
        except MALFORMED as exc:  # decoded but with unusable fields: count it, keep the rest
            notes.add(
                f"{topic}: messages with malformed fields (skipped)",
                detail=f"#{index}: {type(exc).__name__}: {str(exc)[:80]}",
            )


def _assemble(rows: Rows, notes: Notes, path: Path, used: dict, topics: TopicMap,
              options: LogOptions, beside: Path, head: Head | None = None) -> Log:  # fmt: skip
    """The Log of ``rows``: the choices made from them, or (``head``, a piece of a log read in
    pieces) those the head made, with its metadata."""
    metadata: dict = {"format": "rosbag", "topics": {s: t for t, s in used.items()}}
    if head is None:
        metadata["time_base"] = apply_time_base(rows, notes, used, options)
        if rows.live_wave:  # a live session's wave decisions (estimation.wave_schedule replays)
            metadata["live_wave"] = rows.live_wave
        mounting, source_meta = _mounting(rows, notes, used, topics, beside, metadata)
    else:
        metadata = {k: v for k, v in head.log.metadata.items() if k not in PIECE_METADATA}
        mounting, source_meta = head.log.mounting, head.log.metadata.get("recorded") or {}
    dvl = build_dvl(rows, notes, metadata)
    dead_reckoning = None
    if rows.rows["dead_reckoning"]:
        dead_reckoning = dead_reckoning_from_rows(list(rows.dead_reckoning_rows()), notes)
    elif rows.json_position:
        dead_reckoning = dead_reckoning_from_rows(rows.json_position, notes)
        metadata["dead_reckoning_source"] = "dvl_json position_local reports"
    dvl = _dvl_geometry(dvl, rows, metadata, notes)
    dvl = dvl_frame(dvl, rows, topics, mounting, metadata, notes)
    if head is None:
        depth = rows.depth(depth_sign(rows, options, metadata, notes))
        gps = rows.gps(options.gps_origin)
    else:
        depth, gps = rows.depth(head.depth_sign or 1.0), rows.gps(head.gps_origin)
    if gps is not None and head is None:
        metadata["gps_origin"] = (
            [float(v) for v in gps.origin] if not rows.gps_local else ("first odometry fix")
        )
    limits = (source_meta or {}).get("multibeam")
    limits = limits if isinstance(limits, dict) else {}
    return Log(
        imu=rows.imu(),
        dvl=dvl,
        dead_reckoning=dead_reckoning,
        pressure=rows.pressure(),
        sonar=rows.sonar(),
        wave_probe=rows.wave_probe(),
        ground_truth=rows.ground_truth(),
        multibeam=rows.multibeam(_limit(limits, "min_range"), _limit(limits, "max_range")),
        mounting=mounting,
        source=str(path),
        metadata=metadata,
        depth=depth,
        gps=gps,
    )


def _mounting(rows: Rows, notes: Notes, used: dict, topics: TopicMap, beside: Path,
              metadata: dict) -> tuple[Mounting, dict]:  # fmt: skip
    """(the mounting: the sidecar's, else /tf_static's, else the defaults; the sidecar's other
    fields), its source and the sidecar's metadata put in ``metadata``."""
    mounting, source_meta = _sidecar(beside, notes)
    if mounting is not None:
        metadata["mounting_source"] = SIDECAR
    elif (mounting := _tf_mounting(rows.transforms, topics, notes)) is not None:
        metadata["mounting_source"] = _used_topic(used, "tf_static")
    else:
        mounting = Mounting()
        metadata["mounting_source"] = "default (BlueROV2)"
    if source_meta:
        # the writer's metadata (e.g. a simulated run's wave condition and water density) comes
        # back at the top level, as it was; the reader's own keys win
        recorded = dict(source_meta)
        for key, value in (recorded.pop("metadata", None) or {}).items():
            metadata.setdefault(key, value)
        metadata["recorded"] = recorded
    return mounting, source_meta


def _limit(limits: dict, key: str) -> float | None:
    """A finite non-negative number from the sidecar's multibeam limits, else None."""
    value = limits.get(key)
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    return float(value) if ok and math.isfinite(value) and value >= 0 else None


def _dvl_geometry(dvl: Dvl | None, rows: Rows, metadata: dict, notes: Notes) -> Dvl | None:
    """The beam vectors of ``metadata['dvl_geometry']`` for DVL messages that carry none."""
    data = metadata.get("dvl_geometry")
    if dvl is None or rows.dvl_units_given or not isinstance(data, dict):
        return dvl
    try:
        return dvl.with_geometry(DvlGeometry.from_dict(data))
    except UndertowError as exc:
        notes.add(f"{SIDECAR}: dvl_geometry unusable, A50 beams kept ({_one_line(exc)})")
        return dvl


def _used_topic(used: dict, stream: str) -> str:
    """The topic read for ``stream`` (``used`` maps topic -> stream)."""
    return next(t for t, s in used.items() if s == stream)


def _tf_mounting(transforms: list, topics: TopicMap, notes: Notes) -> Mounting | None:
    """Mounting from /tf_static transforms base_frame -> sensor frame (None if there is none).

    A transform's translation is the sensor's lever arm in the base (body) frame and its rotation
    the sensor frame's orientation in it, i.e. R_sensor^body, as ``SensorMount.rotation`` (roll,
    pitch, yaw). The body frame is forward-right-down, as everywhere in undertow (a REP-103
    forward-left-up base_link from another tool needs the settings' ``mounting`` overrides).
    Sensors without a transform keep their default; the last transform of a frame wins.
    """
    base = topics.base_frame.lstrip("/")
    changes: dict = {}
    for parent, child, translation, quaternion in transforms:
        sensor = topics.frames.sensor_of(child)
        if sensor is None:
            continue
        if parent.lstrip("/") != base:
            notes.add(
                f"tf_static: sensor frames whose parent is not {base} (ignored; tf chains are"
                " not followed)",
                detail=f"{parent} -> {child}",
            )
            continue
        q = np.asarray(quaternion, dtype=np.float64)
        if not (np.isfinite(q).all() and np.isfinite(translation).all()) or not np.any(q):
            notes.add(
                "tf_static: sensor transforms with a non-finite or zero rotation (ignored)",
                detail=f"{parent} -> {child}",
            )
            continue
        rpy = quaternion_to_rpy(q)
        changes[sensor] = {"translation": translation, "rotation": tuple(float(a) for a in rpy)}
    return Mounting().updated(changes) if changes else None


def _sidecar(path: Path, notes: Notes) -> tuple[Mounting | None, dict]:
    """(mounting or None if the sidecar has none, the sidecar's other fields)."""
    file = path / SIDECAR if path.is_dir() else path.parent / SIDECAR
    if not file.exists():
        return None, {}
    try:
        check_regular(file)
        data = yaml.safe_load(file.read_text(encoding="utf-8"))
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise TypeError(f"a mapping is expected, found a {type(data).__name__}")
        mounting = Mounting.from_dict(data["mounting"]) if "mounting" in data else None
        if mounting is not None and not np.isfinite(_mount_values(mounting)).all():
            raise ValueError("mounting has non-finite values")
    except (OSError, yaml.YAMLError, UnicodeDecodeError, UndertowError, *MALFORMED) as exc:
        notes.add(f"{SIDECAR} unreadable, its mounting and metadata ignored ({_one_line(exc)})")
        return None, {}
    rest = {str(k): v for k, v in data.items() if k != "mounting"}
    if not isinstance(rest.get("metadata", {}), dict):
        notes.add(f"{SIDECAR}: metadata is not a mapping (ignored)")
        rest.pop("metadata")
    _check_numeric(rest.get("metadata") or {}, notes)
    return mounting, rest


def _mount_values(mounting: Mounting) -> list[float]:
    return [v for m in mounting.to_dict().values() for part in m.values() for v in part]


def _check_numeric(metadata: dict, notes: Notes) -> None:
    """Drop (with a note) sidecar metadata the estimation reads as a number that is not a
    finite positive number (e.g. ``water_density_kg_m3: sea``)."""
    for key in NUMERIC_METADATA:
        if key not in metadata:
            continue
        value = metadata[key]
        try:
            ok = isinstance(value, int | float) and not isinstance(value, bool)
            ok = ok and math.isfinite(float(value)) and value > 0
        except OverflowError:
            ok = False
        if not ok:
            notes.add(f"{SIDECAR}: {key} is not a positive number (ignored)", 1, repr(value)[:40])
            del metadata[key]


__all__ = ["bag_topics", "iter_rosbag_pieces", "read_rosbag", "SIDECAR"]
