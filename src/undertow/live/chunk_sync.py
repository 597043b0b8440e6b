"""Closing the live recording's MCAP chunk durably: what a crash keeps.

:meth:`ChunkSync.flush` closes rosbags' pending chunk (the chunk record and its message indexes
go to the file object) and pushes it to the OS (``flush``: what a killed process keeps); a
thread of its own then has the disk take it (``fdatasync``, POSIX: "all data for the open file
descriptor ... transferred to the storage device",
https://pubs.opengroup.org/onlinepubs/9799919799/functions/fdatasync.html): what a power cut
keeps, which without it is whatever the OS had written back (Linux: data dirty for more than
``vm.dirty_expire_centisecs``, 30 s by default). The live loop never waits on the disk, and the
thread syncs at most once per ``every_s`` (1 s) of wall time: every flush before a sync is in
it, so a chunk reaches the disk within about ``every_s`` of its flush plus the sync's own time
(one sync per flush at real time, where the recorder flushes once per second; fewer when a log
is replayed faster, so the disk's work per wall second stays the same).
"""

from __future__ import annotations

import os
import threading


class ChunkSync:
    """``flush(storage)`` after each chunk, ``wait()`` before the file closes (module
    docstring). Not thread-safe by itself: the recorder calls both under its lock."""

    def __init__(self, every_s: float = 1.0) -> None:
        self.every_s = float(every_s)
        self._pending = False  # flushed, not yet synced
        self._wake = threading.Event()
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None
        self._fd: int | None = None

    def flush(self, storage) -> None:
        """Close the pending chunk of rosbags' MCAP ``storage`` (when it holds anything), write
        it to the file and have it synced."""
        chunk = getattr(storage, "chunk", None)
        if chunk is None or not chunk.bio.tell() or not hasattr(storage, "close_chunk"):
            return
        storage.close_chunk()
        storage.bio.flush()
        if self._thread is None:
            self._fd = storage.bio.fileno()
            self._thread = threading.Thread(target=self._run, name="recording-sync", daemon=True)
            self._thread.start()
        self._pending = True  # (after the write: a sync that sees it covers the chunk)
        self._wake.set()

    def wait(self) -> None:
        """Sync what was flushed and is not yet synced, then end the thread (before the file
        closes: the thread uses its descriptor)."""
        self._closing.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join()

    def _run(self) -> None:
        while True:
            if not self._closing.is_set():
                self._wake.wait()
            self._wake.clear()
            if self._pending:
                self._pending = False
                _datasync(self._fd)
                self._closing.wait(self.every_s)  # at most one sync per every_s, until closing
            elif self._closing.is_set():
                return


def _datasync(fd: int) -> None:
    """The file's data to the disk (``fdatasync``; ``fsync`` where there is none)."""
    try:
        getattr(os, "fdatasync", os.fsync)(fd)
    except OSError:  # a file system that cannot: what the OS holds is all there is
        pass


__all__ = ["ChunkSync"]
