"""Closing the live recording's MCAP chunk durably: what a crash keeps.

:func:`flush_chunk` closes rosbags' pending chunk (the chunk record and its message indexes go to
the file object), pushes it to the OS (``flush``: what a killed process keeps) and has the disk
take it (``fdatasync``, POSIX: "all data for the open file descriptor ... transferred to the
storage device", https://pubs.opengroup.org/onlinepubs/9799919799/functions/fdatasync.html):
what a power cut keeps, which without it is whatever the OS had written back (Linux: data dirty
for more than ``vm.dirty_expire_centisecs``, 30 s by default). The sync runs in a thread of its
own so that the live loop never waits on the disk; a flush that comes while the previous sync
still runs leaves its chunk to the next one.
"""

from __future__ import annotations

import os
import threading


def flush_chunk(storage, syncing: threading.Thread | None) -> threading.Thread | None:
    """Close the pending chunk of rosbags' MCAP ``storage`` (when it holds anything), write it
    and start its sync unless ``syncing`` (the previous flush's sync) still runs; the thread
    that syncs the file now (or ``syncing``)."""
    chunk = getattr(storage, "chunk", None)
    if chunk is None or not chunk.bio.tell() or not hasattr(storage, "close_chunk"):
        return syncing
    storage.close_chunk()
    storage.bio.flush()
    if syncing is not None and syncing.is_alive():
        return syncing
    thread = threading.Thread(target=_datasync, args=(storage.bio.fileno(),),
                              name="recording-sync", daemon=True)  # fmt: skip
    thread.start()
    return thread


def wait_synced(syncing: threading.Thread | None) -> None:
    """Wait for the sync ``syncing`` (before its file is closed)."""
    if syncing is not None:
        syncing.join()


def _datasync(fd: int) -> None:
    """The file's data to the disk (``fdatasync``; ``fsync`` where there is none)."""
    try:
        getattr(os, "fdatasync", os.fsync)(fd)
    except OSError:  # a file system that cannot (or a closed file): what the OS holds stays
        pass


__all__ = ["flush_chunk", "wait_synced"]
