"""Appending messages to an open rosbags MCAP bag at a live sensor's rate.

rosbags' ``Writer.write`` checks the connection against every registered one (a list search
comparing dataclasses) and its MCAP storage assembles each Message record through a temporary
buffer, about 5 us a message: at 100 Hz IMU played 50 times faster than real time, a tenth of
the live recording's time. :class:`MessageAppender` writes the same record (MCAP, "Message"
op 0x05: channel id uint16, sequence uint32, log time uint64, publish time uint64, data; after
the op code and the record length uint64, https://mcap.dev/spec#message-op0x05) into the storage's
pending chunk in one piece, with the bookkeeping rosbags' ``McapWriter.write`` does (the chunk's
and the file's time range, the chunk's message index, the channel's message count, the writer's
count and time range for ``metadata.yaml``), so the file is byte for byte what rosbags writes
(``tests/test_live_fast_paths.py``). It is used only when the writer's storage has the attributes
it relies on (rosbags' MCAP storage, uncompressed messages); otherwise :meth:`write` is the
writer's own.
"""

from __future__ import annotations

import struct

#: op code, record length, channel id, sequence, log time, publish time
_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_OP = 0x05
_FIXED = _HEAD.size - 9  # the record's bytes before the data (after op and length)
#: rosbags' McapWriter closes a chunk once it holds more than this many bytes
CHUNK_BYTES = 2**20


class MessageAppender:
    """``MessageAppender(writer).write(connection, ns, data)``: as ``writer.write`` (rosbags
    ``rosbag2.Writer``, open), faster (module docstring)."""

    def __init__(self, writer) -> None:
        self.writer = writer
        storage = getattr(writer, "storage", None)
        chunk = getattr(storage, "chunk", None)
        mode = getattr(getattr(writer, "compression_mode", None), "name", None)
        self.fast = (
            _has(chunk, "bio", "msgs", "message_start_time", "message_end_time")
            and _has(
                storage, "channel_stats", "message_start_time", "message_end_time", "close_chunk"
            )  # fmt: skip
            and _has(writer, "min_timestamp", "max_timestamp")
            and isinstance(getattr(writer, "counts", None), dict)
            and mode != "MESSAGE"
        )
        self.storage = storage

    def write(self, connection, ns: int, data) -> None:
        if not self.fast:
            self.writer.write(connection, ns, data)
            return
        storage = self.storage
        cid = connection.id
        if ns < storage.message_start_time:
            storage.message_start_time = ns
        if ns > storage.message_end_time:
            storage.message_end_time = ns
        storage.channel_stats[cid] += 1
        chunk = storage.chunk
        if ns < chunk.message_start_time:
            chunk.message_start_time = ns
        if ns > chunk.message_end_time:
            chunk.message_end_time = ns
        bio = chunk.bio
        chunk.msgs[cid].append((ns, bio.tell()))
        size = len(data) if type(data) is bytes else memoryview(data).nbytes
        bio.write(_HEAD.pack(_MESSAGE_OP, _FIXED + size, cid, 0, ns, ns))
        bio.write(data)
        if bio.tell() > CHUNK_BYTES:
            storage.close_chunk()
        writer = self.writer
        writer.counts[cid] += 1
        if ns < writer.min_timestamp:
            writer.min_timestamp = ns
        if ns > writer.max_timestamp:
            writer.max_timestamp = ns


def _has(obj, *names: str) -> bool:
    return obj is not None and all(hasattr(obj, name) for name in names)
