"""Readers and writers of log formats, all returning or taking a :class:`~undertow.log.Log`.

:func:`read_log` guesses the format from the path: a ``.bag`` file is ROS 1; a directory with
``metadata.yaml`` or a ``.mcap``/``.db3`` file is ROS 2; ``.txt/.json/.jsonl`` is Water
Linked TCP JSON, and so is ``.log`` unless it is an ArduPilot dataflash log (binary, or text
whose lines start ``FMT,``); ``.tlog`` (or any other file whose first bytes are a timestamped
MAVLink record) is a MAVLink telemetry log; ``.BIN`` (or any other file starting with a binary
dataflash FMT record, 0xA3 0x95 0x80) is an ArduPilot dataflash log; named pipes, devices and
sockets are refused before opening. A crashed ``undertow live`` recording (its ``.partial-*``
folder, or the intended target when only that folder exists) is ROS 2: read up to its last
complete chunk (:mod:`undertow.io.rosbag`).
:func:`write_log` writes a ROS 2 mcap bag; TUM trajectories and PLY clouds have their own small
modules.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import ReaderError
from ..log import Log
from .a50_json import JSON_SUFFIXES, read_a50_json
from .collect import check_regular
from .dataflash import DATAFLASH_SUFFIXES, read_dataflash
from .dataflash_records import looks_like_dataflash
from .info import LogSummary, StreamSummary, summarize
from .mcap_recover import partial_bag
from .ply import read_ply, write_ply
from .read_options import LogOptions
from .rosbag import DECIDE_S, iter_rosbag_pieces, read_rosbag
from .rosbag_write import write_log
from .tlog import TLOG_SUFFIXES, looks_like_tlog, read_tlog
from .topics import TopicMap
from .tum import read_tum, write_tum
from .units import resolve_units

ROS2_SUFFIXES = (".mcap", ".db3")


def detect_format(path) -> str:
    """'ros1', 'ros2', 'a50_json', 'tlog' or 'dataflash' for ``path``; ReaderError naming the
    file otherwise."""
    path = Path(path)
    suffix = path.suffix.lower()
    if partial_bag(path) is not None:  # a crashed recording (undertow live's .partial folder)
        return "ros2"
    check_regular(path, directory_ok=True)  # a named pipe must not block, a device be read
    if path.is_dir():
        if (path / "metadata.yaml").exists() or any(
            p.suffix in ROS2_SUFFIXES for p in path.iterdir()
        ):
            return "ros2"
        raise ReaderError(f"{path}: directory is not a ROS 2 bag (no metadata.yaml, .mcap or .db3)")
    if not path.exists():
        raise ReaderError(f"{path}: no such file or directory")
    if suffix == ".bag":
        return "ros1"
    if suffix in ROS2_SUFFIXES:
        return "ros2"
    if suffix in DATAFLASH_SUFFIXES:
        return "dataflash"
    if suffix in JSON_SUFFIXES:
        dataflash = suffix == ".log" and looks_like_dataflash(_head(path, 8192))
        return "dataflash" if dataflash else "a50_json"
    if suffix in TLOG_SUFFIXES or looks_like_tlog(_head(path, 300)):
        return "tlog"
    if looks_like_dataflash(_head(path, 3)) == "binary":
        return "dataflash"
    raise ReaderError(
        f"{path}: unknown log format '{suffix or path.name}' (expected .bag, a ROS 2 bag "
        f"directory, .mcap, .db3, .tlog, .BIN, or {', '.join(JSON_SUFFIXES)})"
    )


def _head(path: Path, size: int) -> bytes:
    """The first ``size`` bytes of the file (b'' when it cannot be read), to sniff its format."""
    try:
        with open(path, "rb") as f:
            return f.read(size)
    except OSError:
        return b""


def read_log(path, topics: TopicMap | None = None, mavlink=None,
             options: LogOptions | None = None) -> Log:  # fmt: skip
    """Read any supported log into a Log (format guessed from the path). ``mavlink``: a
    :class:`~undertow.io.mavlink.MavlinkConfig` for ``.tlog`` files (default: ATTITUDE gyro,
    SCALED_PRESSURE2 pressure). ``options``: the time base, units and references where the log
    cannot say them (:class:`~undertow.io.read_options.LogOptions`, default: detected); the
    gyro's unit, the surface pressure and the water are resolved and stated
    (:func:`~undertow.io.units.resolve_units`)."""
    options = options or LogOptions()
    fmt = detect_format(path)
    if fmt == "a50_json":
        log = read_a50_json(path)
    elif fmt == "tlog":
        log = read_tlog(path, mavlink)
    elif fmt == "dataflash":
        log = read_dataflash(path, options.gps_origin)
    else:
        log = read_rosbag(path, topics, options)
    return resolve_units(log, options)


def iter_log_pieces(path, piece_s: float, topics: TopicMap | None = None, mavlink=None,
                    options: LogOptions | None = None, decide_s: float = DECIDE_S):  # fmt: skip
    """:func:`read_log` in pieces of ``piece_s`` seconds of log time, each a Log with the
    whole read's choices (:func:`~undertow.io.rosbag.iter_rosbag_pieces`, decided from the
    first ``decide_s`` seconds) for a ROS bag; any other format (small files) is read whole
    and given as one piece."""
    if detect_format(path) in ("ros1", "ros2"):
        yield from iter_rosbag_pieces(path, piece_s, topics, options, decide_s)
    else:
        yield read_log(path, topics, mavlink, options)


__all__ = [
    "LogOptions",
    "LogSummary",
    "StreamSummary",
    "TopicMap",
    "detect_format",
    "iter_log_pieces",
    "read_a50_json",
    "read_dataflash",
    "read_log",
    "read_ply",
    "read_rosbag",
    "read_tlog",
    "read_tum",
    "summarize",
    "write_log",
    "write_ply",
    "write_tum",
]
