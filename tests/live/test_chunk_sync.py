"""Flushing the live recording's chunk: written to the file before it is synced, synced in the
background (at most once per ``every_s``, every flush before a sync in it), what is pending
synced before the file closes; a failing sync is harmless."""

from __future__ import annotations

import io
import os
import threading

import pytest

from undertow.live.chunk_sync import ChunkSync
from undertow.live.recorder import Recorder
from undertow.records import Record


class _Chunk:
    def __init__(self) -> None:
        self.bio = io.BytesIO()


class _Storage:
    """rosbags' McapWriter as ChunkSync sees it: a pending chunk and the file object."""

    def __init__(self, path) -> None:
        self.bio = open(path, "wb")  # (closed by the test)
        self.chunk = _Chunk()
        self.closed_chunks = 0

    def close_chunk(self) -> None:
        self.bio.write(self.chunk.bio.getvalue())
        self.chunk = _Chunk()
        self.closed_chunks += 1

    def add(self, data: bytes) -> None:
        self.chunk.bio.write(data)


@pytest.fixture
def syncs(monkeypatch):
    """The calls of os.fdatasync: (fd, the file's size on the OS's side at the call); a sync
    waits while the gate is closed."""
    calls, gate = [], threading.Event()
    gate.set()

    def fake(fd):
        calls.append((fd, os.fstat(fd).st_size))
        assert gate.wait(30)

    monkeypatch.setattr(os, "fdatasync", fake, raising=False)
    return calls, gate


@pytest.mark.parametrize("every_s", [0.0, 1000.0])
def test_every_flushed_chunk_is_synced_by_the_end(tmp_path, syncs, every_s):
    calls, gate = syncs
    storage = _Storage(tmp_path / "f")
    sync = ChunkSync(every_s)
    sync.flush(storage)
    assert storage.closed_chunks == 0 and sync._thread is None  # nothing pending: nothing done
    gate.clear()  # a slow disk: the first sync waits
    storage.add(b"x" * 100)
    sync.flush(storage)
    _until(lambda: len(calls) == 1)  # the first sync has begun (and waits at the gate)
    for size in (50, 7):
        storage.add(b"x" * size)
        sync.flush(storage)  # never waits for the disk
    assert storage.closed_chunks == 3 and os.stat(tmp_path / "f").st_size == 157
    gate.set()
    sync.wait()
    # one sync at the first flush, one for the two that came while it ran (and its pause)
    assert calls == [(storage.bio.fileno(), 100), (storage.bio.fileno(), 157)]
    storage.bio.close()


def _until(condition) -> None:
    for _ in range(3000):
        if condition():
            return
        threading.Event().wait(0.01)
    pytest.fail("the sync thread did not start")


def test_a_failing_sync_is_harmless(tmp_path, monkeypatch):
    errors = []
    monkeypatch.setattr(threading, "excepthook", errors.append)

    def fail(fd):
        raise OSError(22, "Invalid argument")

    monkeypatch.setattr(os, "fdatasync", fail, raising=False)
    storage = _Storage(tmp_path / "f")
    storage.add(b"x")
    sync = ChunkSync()
    sync.flush(storage)
    sync.wait()
    storage.bio.close()
    assert errors == []


def test_the_recorder_syncs_its_chunks_and_waits_before_closing(tmp_path, syncs):
    calls, gate = syncs
    rec = Recorder(tmp_path / "rec", flush_every_s=0.5)
    gate.clear()
    for i in range(5):  # a flush at each record from the second on
        rec.write_record(Record("pressure", 1.0 + i, {"pressure": 1e5}))
    closing = threading.Thread(target=rec.close)
    closing.start()
    closing.join(0.5)
    assert closing.is_alive()  # close waits for the sync
    gate.set()
    closing.join(30)
    assert not closing.is_alive() and (tmp_path / "rec").is_dir() and calls
