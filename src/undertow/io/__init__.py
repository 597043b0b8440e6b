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

from dataclasses import dataclass
from pathlib import Path

from ..errors import ConfigError, ReaderError
from ..log import Log
from .a50_json import JSON_SUFFIXES, read_a50_json
from .collect import check_regular
from .dataflash import DATAFLASH_SUFFIXES, read_dataflash
from .dataflash_records import looks_like_dataflash
from .info import LogSummary, StreamSummary, summarize
from .mcap_recover import partial_bag
from .ply import read_ply, write_ply
from .read_options import LogOptions
from .rosbag import DECIDE_S, bag_index, iter_rosbag_pieces, read_rosbag
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
                    options: LogOptions | None = None, decide_s: float = DECIDE_S,
                    streams: tuple[str, ...] | None = None):  # fmt: skip
    """:func:`read_log` in pieces of ``piece_s`` seconds of log time, each a Log with the
    whole read's choices (:func:`~undertow.io.rosbag.iter_rosbag_pieces`, decided from the
    first ``decide_s`` seconds; ``streams``: only these streams in the pieces) for a ROS bag;
    any other format (small files) is read whole and given as one piece."""
    if detect_format(path) in ("ros1", "ros2"):
        yield from iter_rosbag_pieces(path, piece_s, topics, options, decide_s, streams=streams)
    else:
        yield read_log(path, topics, mavlink, options)


#: a ROS bag whose index spans more than this (s of record time) is read in pieces by
#: `localize` and `map` (:func:`piece_choice`): the whole read of `localize --smooth` peaks at
#: 0.85 GB at 1.1 hours of the simulated field survey and 1.45 GB at 2 (0.65 GB an hour; the
#: pieces 0.8-1.0 GB at any length; docs/benchmarks.md), so a log of up to two hours is read
#: whole, under 1.5 GB, and gives the outputs it always did bit for bit
PIECES_ABOVE_S = 7200.0
#: or whose index holds more messages than this (two hours of that survey: 0.9 million an
#: hour, the IMU and ground truth at 100 Hz): a log of faster sensors is as large sooner
PIECES_ABOVE_MESSAGES = 1_800_000
#: seconds of log per piece (a piece of that survey decodes to about 70 MB)
PIECE_S = 600.0


@dataclass(frozen=True)
class PieceChoice:
    """Whether a log is read in pieces of ``piece_s`` seconds (:func:`iter_log_pieces`) or
    whole, as ``policy`` says ("auto": from the bag's index; "asked": ``--in-pieces`` or
    ``--whole``), with the index's record-time span (s) and message count (None: not a ROS
    bag, always read whole) and, when the size asked for pieces but the command cannot take
    them, why (``whole_because``)."""

    pieces: bool
    policy: str
    piece_s: float = PIECE_S
    span_s: float | None = None
    messages: int | None = None
    whole_because: str | None = None

    @property
    def long(self) -> bool:
        """The index says the log is too long to read whole (:data:`PIECES_ABOVE_S`)."""
        return self.span_s is not None and (
            self.span_s > PIECES_ABOVE_S or (self.messages or 0) > PIECES_ABOVE_MESSAGES
        )

    def blocked(self, reason: str) -> PieceChoice:
        """The whole read after all, because of ``reason`` (what needs the whole log)."""
        return PieceChoice(False, self.policy, self.piece_s, self.span_s, self.messages, reason)

    def line(self, source) -> str | None:
        """The one line stating the choice (None for a log read whole as it always was)."""
        size = "not a ROS bag"
        if self.span_s is not None:
            size = f"its index spans {self.span_s / 3600:.2f} h, {self.messages} messages"
        limit = f"{PIECES_ABOVE_S / 3600:g} h or {PIECES_ABOVE_MESSAGES} messages"
        if self.pieces and self.policy == "auto":
            return (f"{source}: read in {self.piece_s:g} s pieces ({size}: more than {limit} "
                    "is read in pieces, in bounded memory); --whole reads it at once")  # fmt: skip
        if self.pieces:
            return f"{source}: read in {self.piece_s:g} s pieces as asked (--in-pieces; {size})"
        if self.whole_because is not None:
            return f"{source}: read whole ({size}), as {self.whole_because} needs the whole log"
        if self.policy == "asked" and self.long:
            return f"{source}: read whole as asked (--whole; {size}, more than {limit})"
        return None

    def to_dict(self) -> dict:
        """What an output's metadata records (``read_in_pieces``) of a log read in pieces."""
        return {"piece_s": self.piece_s, "policy": self.policy, "span_s": self.span_s,
                "messages": self.messages}  # fmt: skip


def piece_choice(path, in_pieces: bool | None = None, piece_s: float = PIECE_S) -> PieceChoice:
    """Whether `localize` and `map` read the log at ``path`` in pieces: ``in_pieces`` True or
    False as asked, None (auto) for a ROS bag whose index (no message decoded) spans more than
    :data:`PIECES_ABOVE_S` or holds more than :data:`PIECES_ABOVE_MESSAGES` messages; any other
    format (small files) is read whole."""
    if not piece_s > 0:
        raise ConfigError(f"piece_s (--piece-s): a piece is > 0 s long, not {piece_s}")
    if detect_format(path) not in ("ros1", "ros2"):
        return PieceChoice(False, "auto" if in_pieces is None else "asked", piece_s)
    topics, span_s = bag_index(path)
    messages = sum(count for _, count in topics.values())
    choice = PieceChoice(bool(in_pieces), "asked", piece_s, round(span_s, 3), messages)
    if in_pieces is None:
        return PieceChoice(choice.long, "auto", piece_s, choice.span_s, messages)
    return choice


__all__ = [
    "LogOptions",
    "LogSummary",
    "PieceChoice",
    "StreamSummary",
    "TopicMap",
    "detect_format",
    "iter_log_pieces",
    "piece_choice",
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
