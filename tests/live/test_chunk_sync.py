"""Flushing the live recording's chunk: written to the file before its sync, the sync in the
background, one at a time, waited for before the file closes; a failing sync is harmless."""

from __future__ import annotations

import io
import os
import threading

import pytest

from undertow.live.chunk_sync import flush_chunk, wait_synced
from undertow.live.recorder import Recorder
from undertow.records import Record


class _Chunk:
    def __init__(self) -> None:
        self.bio = io.BytesIO()


class _Storage:
    """rosbags' McapWriter as flush_chunk sees it: a pending chunk and the file object."""

    def __init__(self, path) -> None:
        self.bio = open(path, "wb")  # (closed by the test)
        self.chunk = _Chunk()
        self.closed_chunks = 0

    def close_chunk(self) -> None:
        self.bio.write(self.chunk.bio.getvalue())
        self.chunk = _Chunk()
        self.closed_chunks += 1


@pytest.fixture
def syncs(monkeypatch):
    """The calls of os.fdatasync: (fd, the file's size on the OS's side at the call)."""
    calls, gate = [], threading.Event()
    gate.set()

    def fake(fd):
        calls.append((fd, os.fstat(fd).st_size))
        assert gate.wait(30)

    monkeypatch.setattr(os, "fdatasync", fake, raising=False)
    return calls, gate


def test_a_chunk_is_written_then_synced_in_the_background(tmp_path, syncs):
    calls, gate = syncs
    storage = _Storage(tmp_path / "f")
    assert flush_chunk(storage, None) is None and storage.closed_chunks == 0  # nothing pending
    storage.chunk.bio.write(b"x" * 100)
    gate.clear()  # the disk is slow: the first sync waits
    first = flush_chunk(storage, None)
    storage.chunk.bio.write(b"y" * 50)
    again = flush_chunk(storage, first)  # while the first sync runs: no second one
    assert again is first and storage.closed_chunks == 2
    assert os.stat(tmp_path / "f").st_size == 150  # both chunks written all the same
    gate.set()
    wait_synced(first)
    assert [fd for fd, _ in calls] == [storage.bio.fileno()]
    assert calls[0][1] >= 100  # the chunk was in the file before its sync
    storage.chunk.bio.write(b"z")
    later = flush_chunk(storage, first)  # the first has ended: a new sync
    wait_synced(later)
    assert later is not first and len(calls) == 2 and calls[1][1] == 151
    storage.bio.close()


def test_a_failing_sync_is_harmless(tmp_path, monkeypatch):
    errors = []
    monkeypatch.setattr(threading, "excepthook", errors.append)

    def fail(fd):
        raise OSError(22, "Invalid argument")

    monkeypatch.setattr(os, "fdatasync", fail, raising=False)
    storage = _Storage(tmp_path / "f")
    storage.chunk.bio.write(b"x")
    wait_synced(flush_chunk(storage, None))
    storage.bio.close()
    assert errors == []


def test_the_recorder_syncs_its_chunks_and_waits_before_closing(tmp_path, syncs):
    calls, gate = syncs
    rec = Recorder(tmp_path / "rec", flush_every_s=0.5)
    gate.clear()
    for i in range(5):  # a flush at each record from the second on: one sync runs
        rec.write_record(Record("pressure", 1.0 + i, {"pressure": 1e5}))
    closing = threading.Thread(target=rec.close)
    closing.start()
    closing.join(0.5)
    assert closing.is_alive()  # close waits for the sync
    gate.set()
    closing.join(30)
    assert not closing.is_alive() and (tmp_path / "rec").is_dir() and len(calls) == 1
