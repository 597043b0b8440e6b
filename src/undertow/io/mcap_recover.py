"""Reading a crashed recording: the complete chunks of an MCAP file its writer never finished.

``undertow live`` records into ``<name>.partial-XXXXXXXX/<name>/<name>.mcap`` next to its
target and renames the bag into place at the end (:mod:`undertow.live.recorder`). After a
SIGKILL or a power cut the ``.partial`` folder stays, its ``.mcap`` holding every chunk flushed
so far but no summary nor footer, which rosbags refuses ("File end magic is invalid").
:func:`recover` reads such a file chunk by chunk and writes what it read as a new complete MCAP
file (the job of ``mcap recover``, the MCAP command line tool, which is Go and not part of
undertow); the original is only read, never changed.

**The walk.** An MCAP file (https://mcap.dev/spec) is the magic ``\\x89MCAP0\\r\\n``, a Header
record, then records of ``op`` (uint8), ``length`` (uint64) and ``length`` bytes of content.
rosbags writes the schemas, the channels and the messages into Chunk records (op 0x06: start
and end time, uncompressed size and CRC-32, compression, then the inner records), each followed
by one Message Index record (op 0x07) per channel. The walk keeps a chunk only when all of it
is there and sound: its length within the file, its data decompressed to the stated size
(and CRC-32 when one is stated: rosbags states none), its inner records filling it exactly,
every one a Schema (0x03), Channel (0x04) or Message (0x05) whose fields parse (UTF-8 strings,
a message of a known channel, at least 22 bytes); it stops at the first record that is not:
a truncated record (the crash's cut) or a damaged one (a length beyond the file, an unknown op
code, a malformed chunk). Records other than chunks (indexes, attachments, metadata) are
stepped over; a Data End or Footer record ends the data section. What follows the first bad
record is not read: after it, record boundaries are unknown. Damage inside a message's bytes
is not seen here (rosbags writes no CRC): the reader skips a message it cannot decode.

**The output** is a complete MCAP file of those chunks: the header, then each kept chunk (its
records as they were, uncompressed) with its message indexes, a Data End record, the summary
(schemas, channels, chunk indexes, statistics) and the footer. A lone ``.mcap``:
:func:`undertow.io.read_log` reads it as any other.

**Where it goes.** ``$UNDERTOW_CACHE_DIR/recovered/<name>-<hash of the original's path>/``
(default cache folder: ``$XDG_CACHE_HOME/undertow``, else ``~/.cache/undertow``; a temporary
folder when that cannot be written), with ``source.json`` naming the original, its size and
modification time: a second read of an unchanged original reuses the file, a changed one (a
recording still being written) is recovered again in its place.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import struct
import tempfile
from binascii import crc32
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..errors import ReaderError

MAGIC = b"\x89MCAP0\r\n"
#: the infix of the recorder's working folder: ``<name>.partial-XXXXXXXX``
PARTIAL = ".partial-"
CACHE_ENV = "UNDERTOW_CACHE_DIR"
_PARTIAL_NAME = re.compile(r"(?P<name>.+)\.partial-[A-Za-z0-9_]{8}")
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
_OP_CHUNK, _OP_MESSAGE_INDEX, _OP_CHUNK_INDEX, _OP_STATISTICS, _OP_DATA_END = (
    0x06, 0x07, 0x08, 0x0B, 0x0F)  # fmt: skip
_LAST_OP = 0x10  # the highest op code of the spec (Data End: 0x0F; 0x10 reserved)
_RECORD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQI")
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel, sequence, log time, publish time


class _Bad(Exception):
    """A record that does not parse (internal: the walk stops there)."""


@dataclass
class _Chunk:
    """A sound chunk: its uncompressed records and, per channel, (log time, offset) of its
    messages."""

    records: bytes
    crc: int
    index: dict[int, list[tuple[int, int]]] = field(default_factory=dict)


@dataclass
class Scan:
    """What :func:`scan` read: the header record's content, schemas and channels (content of
    their records by id, in order of appearance), the number of sound chunks, the bytes read
    (up to the end of the last sound record) and why the walk stopped."""

    header: bytes = b""
    schemas: dict[int, bytes] = field(default_factory=dict)
    channels: dict[int, bytes] = field(default_factory=dict)
    chunks: int = 0
    read: int = 0
    stop: str = ""
    complete: bool = False  # a Data End or Footer record was met


@dataclass(frozen=True)
class Recovered:
    """A recovered recording: ``source`` (the incomplete ``.mcap``, ``size`` bytes, of which
    ``read`` were read), ``path`` (the complete file written), its messages, chunks and time
    span (ns; 0 and 0 without messages), why reading stopped."""

    source: str
    path: str
    size: int
    read: int
    messages: int
    chunks: int
    start_ns: int
    end_ns: int
    stop: str

    def line(self) -> str:
        """One line: the recording was incomplete, what was recovered, where it went."""
        span = (self.end_ns - self.start_ns) * 1e-9
        left = self.size - self.read
        return (
            f"incomplete recording (no MCAP footer: its writer did not finish, e.g. a crash); "
            f"recovered {self.messages} messages in {self.chunks} chunks, {span:.1f} s of record "
            f"time ({self.start_ns * 1e-9:.3f} to {self.end_ns * 1e-9:.3f} s); {left} of "
            f"{self.size} bytes of {self.source} left unread ({self.stop}); the original is "
            f"unchanged, read from the copy {self.path}"
        )


# -- reading ------------------------------------------------------------------------------------
def is_complete(path: Path) -> bool:
    """True when the file ends with the MCAP magic (its writer finished it)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            if f.tell() < 2 * len(MAGIC):
                return False
            f.seek(-len(MAGIC), os.SEEK_END)
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return True  # not ours to judge: the ordinary reader says what is wrong


def scan(f, sink) -> Scan:
    """Walk the binary file object ``f`` record by record (module docstring), giving ``sink``
    (a :class:`McapOut`) the header and each sound chunk as it is read (one chunk in memory at
    a time); never raises for bad content, only OSError."""
    result = Scan()
    f.seek(0, os.SEEK_END)
    size = f.tell()
    f.seek(0)
    if f.read(len(MAGIC)) != MAGIC:
        result.stop = "not an MCAP file: no magic at its start"
        return result
    pos = len(MAGIC)
    first = True
    while True:
        head = f.read(_RECORD.size)
        if not head:
            result.stop = "the file ends after the last complete record"
            break
        if len(head) < _RECORD.size:
            result.stop = f"a record truncated at byte {pos}"
            break
        op, length = _RECORD.unpack(head)
        if op == 0 or op > _LAST_OP or (first and op != _OP_HEADER):
            result.stop = f"a damaged record at byte {pos} (op code {op:#04x})"
            break
        if length > size - pos - _RECORD.size:
            result.stop = f"a record truncated at byte {pos} (op {op:#04x}, {length} bytes)"
            break
        if op in (_OP_DATA_END, _OP_FOOTER):
            result.complete, result.stop = True, "the end of the data section"
            result.read = pos
            break
        content = f.read(length) if op in _KEPT else None
        if content is None:
            f.seek(length, os.SEEK_CUR)
        try:
            _take(result, op, content, first, sink)
        except _Bad as exc:
            result.stop = f"a damaged {_NAMES.get(op, 'record')} at byte {pos} ({exc})"
            break
        first = False
        pos += _RECORD.size + length
        result.read = pos
    return result


def _take(result: Scan, op: int, content: bytes | None, first: bool, sink) -> None:
    if op == _OP_HEADER:
        if not first:
            raise _Bad("a second header")
        _Fields(content).string()  # profile
        result.header = content
        sink.header(content)
    elif op == _OP_SCHEMA:
        schema_id = _schema(content)
        result.schemas.setdefault(schema_id, content)
    elif op == _OP_CHANNEL:
        channel_id = _channel(content, result.schemas)
        result.channels.setdefault(channel_id, content)
    elif op == _OP_MESSAGE:
        raise _Bad("a message outside a chunk (not written by rosbags)")
    elif op == _OP_CHUNK:
        sink.chunk(_chunk(content, result))
        result.chunks += 1


_KEPT = (_OP_HEADER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK)
_NAMES = {_OP_HEADER: "header", _OP_SCHEMA: "schema", _OP_CHANNEL: "channel",
          _OP_MESSAGE: "message", _OP_CHUNK: "chunk"}  # fmt: skip


class _Fields:
    """Little-endian fields read off a record's content; :class:`_Bad` past its end."""

    def __init__(self, data: bytes) -> None:
        self.data, self.pos = data, 0

    def take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > len(self.data):
            raise _Bad(f"a field runs past the record's end (byte {self.pos} + {n})")
        out = self.data[self.pos : self.pos + n]
        self.pos += n
        return out

    def unpack(self, fmt: str) -> tuple:
        return struct.unpack("<" + fmt, self.take(struct.calcsize("<" + fmt)))

    def string(self) -> str:
        raw = self.take(self.unpack("I")[0])
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError:
            raise _Bad("a string that is not UTF-8") from None

    def done(self) -> None:
        if self.pos != len(self.data):
            raise _Bad(f"{len(self.data) - self.pos} bytes after its last field")


def _schema(content: bytes) -> int:
    fields = _Fields(content)
    (schema_id,) = fields.unpack("H")
    if schema_id == 0:
        raise _Bad("schema id 0")
    fields.string(), fields.string(), fields.string()  # name, encoding, data (rosbags: text)
    fields.done()
    return schema_id


def _channel(content: bytes, schemas: dict[int, bytes]) -> int:
    fields = _Fields(content)
    channel_id, schema_id = fields.unpack("HH")
    if schema_id and schema_id not in schemas:
        raise _Bad(f"channel {channel_id} refers to schema {schema_id}, not defined before")
    fields.string(), fields.string()  # topic, message encoding
    metadata = _Fields(fields.take(fields.unpack("I")[0]))
    while metadata.pos < len(metadata.data):
        key, value = metadata.string(), metadata.string()
        if key == "offered_qos_profiles":
            _check_qos(value)
    fields.done()
    return channel_id


def _check_qos(text: str) -> None:
    """rosbags parses a channel's QoS profiles when it opens the file: a damaged one here."""
    from rosbags.rosbag2.metadata import parse_qos

    try:
        parse_qos(text)
    except Exception as exc:  # yaml and rosbags errors of many types
        raise _Bad(f"QoS profiles that do not parse ({type(exc).__name__})") from None


def _chunk(content: bytes, result: Scan) -> _Chunk:
    fields = _Fields(content)
    _, _, usize, crc = fields.unpack("QQQI")
    compression = fields.string()
    data = fields.take(fields.unpack("Q")[0])
    fields.done()
    records = _decompress(data, compression, usize)
    if crc and crc32(records) != crc:
        raise _Bad("CRC-32 mismatch")
    chunk = _Chunk(records, crc)
    schemas, channels = dict(result.schemas), dict(result.channels)
    inner, pos = _Fields(records), 0
    while pos < len(records):
        op, length = inner.unpack("BQ")
        body = inner.take(length)
        if op == _OP_SCHEMA:
            schemas.setdefault(_schema(body), body)
        elif op == _OP_CHANNEL:
            channels.setdefault(_channel(body, schemas), body)
        elif op == _OP_MESSAGE:
            if length < _MESSAGE_HEAD.size:
                raise _Bad(f"a message of {length} bytes")
            channel_id, _, log_time, _ = _MESSAGE_HEAD.unpack_from(body)
            if channel_id not in channels:
                raise _Bad(f"a message of channel {channel_id}, not defined before")
            chunk.index.setdefault(channel_id, []).append((log_time, pos))
        else:
            raise _Bad(f"a record of op {op:#04x} inside it")
        pos = inner.pos
    result.schemas, result.channels = schemas, channels  # only once all of it is sound
    return chunk


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    if compression == "":
        out = data
    else:
        from rosbags.rosbag2.storage_mcap import DECOMPRESSORS

        if compression not in DECOMPRESSORS:
            raise _Bad(f"unknown compression {compression!r}")
        try:
            out = DECOMPRESSORS[compression](data, size)
        except Exception as exc:  # lz4/zstd errors of their own types
            name = type(exc).__name__
            raise _Bad(f"{compression} data that does not decompress ({name})") from None
    if len(out) != size:
        raise _Bad(f"{len(out)} bytes of records where it states {size}")
    return out


# -- writing ------------------------------------------------------------------------------------
def _record(op: int, content: bytes) -> bytes:
    return _RECORD.pack(op, len(content)) + content


def _string(text: str) -> bytes:
    raw = text.encode("utf-8")
    return struct.pack("<I", len(raw)) + raw


class McapOut:
    """A complete MCAP file written to the binary file object ``out`` as :func:`scan` finds
    its parts: :meth:`header`, :meth:`chunk` for each sound chunk (uncompressed, with its
    message indexes), :meth:`finish` (Data End, summary, footer). ``messages``, ``chunks``,
    ``start_ns``, ``end_ns``: what it holds."""

    def __init__(self, out) -> None:
        self.out = out
        self.indexes: list[bytes] = []
        self.counts: dict[int, int] = {}
        self.messages = self.chunks = 0
        self.start_ns, self.end_ns = 2**64 - 1, 0

    def header(self, content: bytes) -> None:
        self.out.write(MAGIC + _record(_OP_HEADER, content))

    def chunk(self, chunk: _Chunk) -> None:
        out = self.out
        times = [t for entries in chunk.index.values() for t, _ in entries]
        first, last = (min(times), max(times)) if times else (0, 0)
        if times:
            self.start_ns, self.end_ns = min(self.start_ns, first), max(self.end_ns, last)
        size = len(chunk.records)
        chunk_start = out.tell()
        head = _CHUNK_HEAD.pack(first, last, size, chunk.crc)
        out.write(_record(_OP_CHUNK, head + _string("") + struct.pack("<Q", size) + chunk.records))
        chunk_end = out.tell()
        offsets = []
        for channel_id, entries in chunk.index.items():
            self.counts[channel_id] = self.counts.get(channel_id, 0) + len(entries)
            offsets.append(struct.pack("<HQ", channel_id, out.tell()))
            pairs = b"".join(struct.pack("<QQ", t, o) for t, o in sorted(entries))
            out.write(
                _record(_OP_MESSAGE_INDEX, struct.pack("<HI", channel_id, len(pairs)) + pairs)
            )
        offset_map = b"".join(offsets)
        length = chunk_end - chunk_start
        self.indexes.append(
            struct.pack("<QQQQI", first, last, chunk_start, length, len(offset_map))
            + offset_map + struct.pack("<Q", out.tell() - chunk_end) + _string("")
            + struct.pack("<QQ", size, size)
        )  # fmt: skip
        self.messages += len(times)
        self.chunks += 1

    def finish(self, schemas: dict[int, bytes], channels: dict[int, bytes]) -> None:
        out = self.out
        if not self.messages:
            self.start_ns = 0
        out.write(_record(_OP_DATA_END, struct.pack("<I", 0)))
        summary_start = out.tell()
        for content in schemas.values():
            out.write(_record(_OP_SCHEMA, content))
        for content in channels.values():
            out.write(_record(_OP_CHANNEL, content))
        for content in self.indexes:
            out.write(_record(_OP_CHUNK_INDEX, content))
        per_channel = b"".join(struct.pack("<HQ", c, self.counts.get(c, 0)) for c in channels)
        out.write(_record(_OP_STATISTICS, struct.pack(
            "<QHIIIIQQI", self.messages, len(schemas), len(channels), 0, 0, self.chunks,
            self.start_ns, self.end_ns, len(per_channel)) + per_channel))  # fmt: skip
        out.write(_record(_OP_FOOTER, struct.pack("<QQI", summary_start, 0, 0)) + MAGIC)


def rewrite(f, out) -> tuple[Scan, McapOut]:
    """:func:`scan` the incomplete MCAP file object ``f`` into a complete one written to
    ``out`` (both binary file objects); what the scan found and what was written."""
    sink = McapOut(out)
    result = scan(f, sink)
    if result.header:
        sink.finish(result.schemas, result.channels)
    return result, sink


# -- crashed recordings: paths, the cache ---------------------------------------------------------
def partial_folders(path: Path) -> list[Path]:
    """The recorder's ``.partial`` folders of the target ``path`` (newest first)."""
    try:
        siblings = list(path.parent.iterdir())
    except OSError:
        return []
    found = [
        p for p in siblings
        if (m := _PARTIAL_NAME.fullmatch(p.name)) and m["name"] == path.name and p.is_dir()
    ]  # fmt: skip
    return sorted(found, key=lambda p: p.stat().st_mtime, reverse=True)


def partial_bag(path) -> Path | None:
    """The bag inside a crashed recording's ``.partial`` folder when ``path`` is that folder or
    a target that does not exist but has one; None for any other path. Several ``.partial``
    folders of one target are one ReaderError line naming them."""
    path = Path(path)
    if _PARTIAL_NAME.fullmatch(path.name) and path.is_dir():
        holder = path
    elif not path.exists() and (holders := partial_folders(path)):
        if len(holders) > 1:
            names = ", ".join(str(h) for h in holders)
            raise ReaderError(
                f"{path}: no recording, but {len(holders)} crashed ones ({names}, newest "
                "first); give one of them"
            )
        holder = holders[0]
    else:
        return None
    name = _PARTIAL_NAME.fullmatch(holder.name)["name"]
    inside = holder / name
    if inside.exists():
        return inside
    raise ReaderError(f"{holder}: a crashed recording's folder without its bag ({name}); empty")


def incomplete_mcap(path) -> Path | None:
    """The ``.mcap`` file to recover when ``path`` is one without its end magic, or a folder
    without ``metadata.yaml`` holding one such file and no other storage file; else None."""
    path = Path(path)
    if path.is_dir():
        if (path / "metadata.yaml").exists():
            return None
        try:
            files = [p for p in path.iterdir() if p.suffix in (".mcap", ".db3") and p.is_file()]
        except OSError:
            return None
        if len(files) != 1:
            return None
        path = files[0]
    if path.suffix != ".mcap" or not path.is_file() or (path.parent / "metadata.yaml").exists():
        return None
    return None if is_complete(path) else path


def cache_root() -> Path:
    """``$UNDERTOW_CACHE_DIR``, else ``$XDG_CACHE_HOME/undertow``, else ``~/.cache/undertow``."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return Path(given)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "undertow"


def recover(source, cache: Path | None = None) -> Recovered:
    """Recover the incomplete MCAP file ``source`` into the cache (module docstring); reuse an
    earlier recovery of the same, unchanged file. A file with no complete chunk is one
    ReaderError line."""
    source = Path(source).resolve()
    try:
        stat = source.stat()
    except OSError as exc:
        raise ReaderError(f"{source}: cannot read ({exc.strerror or exc})") from None
    key = hashlib.sha256(str(source).encode()).hexdigest()[:16]
    stamp = {"source": str(source), "size": stat.st_size, "mtime_ns": stat.st_mtime_ns}
    folder = _cache_folder(cache or cache_root(), f"{source.stem}-{key}")
    done = _reuse(folder, stamp)
    if done is not None:
        return done
    target = folder / f"{source.stem}.mcap"
    try:
        with (
            open(source, "rb") as f,
            tempfile.NamedTemporaryFile(
                dir=folder, prefix=f".{source.stem}.", suffix=".tmp", delete=False
            ) as out,
        ):
            result, written = rewrite(f, out)
        if result.header and written.messages:
            os.replace(out.name, target)
        else:
            os.unlink(out.name)
    except OSError as exc:
        raise ReaderError(f"{source}: cannot recover into {folder} ({exc})") from None
    if not result.header or not written.messages:
        what = "no complete chunk of messages yet" if result.header else "no readable header"
        what = what if stat.st_size else "nothing written yet"
        raise ReaderError(
            f"{source}: incomplete recording with {what} ({stat.st_size} bytes; {result.stop});"
            " nothing to read"
        )
    recovered = Recovered(
        str(source), str(target), stat.st_size, result.read, written.messages, written.chunks,
        written.start_ns, written.end_ns, result.stop,
    )  # fmt: skip
    try:
        (folder / "source.json").write_text(json.dumps({**stamp, "recovered": asdict(recovered)}))
    except OSError:  # no reuse next time, nothing worse
        pass
    return recovered


def _cache_folder(root: Path, name: str) -> Path:
    try:
        folder = root / "recovered" / name
        folder.mkdir(parents=True, exist_ok=True)
        return folder
    except OSError:  # an unwritable cache: a temporary folder of its own
        return Path(tempfile.mkdtemp(prefix=f"undertow-recovered-{name}-"))


def _reuse(folder: Path, stamp: dict) -> Recovered | None:
    try:
        data = json.loads((folder / "source.json").read_text())
        recovered = Recovered(**data["recovered"])
        same = all(data.get(k) == v for k, v in stamp.items())
        return recovered if same and Path(recovered.path).is_file() else None
    except (OSError, ValueError, TypeError, KeyError):
        return None


__all__ = [
    "McapOut",
    "Recovered",
    "Scan",
    "cache_root",
    "incomplete_mcap",
    "is_complete",
    "partial_bag",
    "partial_folders",
    "recover",
    "rewrite",
    "scan",
]
