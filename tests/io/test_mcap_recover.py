"""A crashed recording: an MCAP file cut anywhere, or damaged, reads back every complete chunk
before the cut (or the damage) bit for bit, through a recovered copy, never changing the
original and never raising anything but one line.

The oracle is rosbags' own index of the complete file: its chunk index records (offset and
length of each chunk, the span of its messages) and its messages. The recording writes every
message at a distinct, increasing time, so that the chunks partition the timeline: the
messages of the chunks that end before a cut are those up to the last such chunk's end time.
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import tempfile
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir
from rosbags.highlevel import AnyReader
from rosbags.rosbag2.storage_mcap import McapReader

from undertow.errors import ReaderError, UndertowError
from undertow.io import detect_format, read_log
from undertow.io.mcap_recover import (
    CACHE_ENV,
    is_complete,
    partial_bag,
    recover,
    rewrite,
)
from undertow.io.msgdefs import dvl_typestore
from undertow.io.rosbag import bag_topics
from undertow.live.recorder import Recorder
from undertow.records import Record
from undertow.robot import Mounting

set_hypothesis_home_dir(Path(tempfile.gettempdir()) / "undertow-hypothesis")
FUZZ = hsettings(
    max_examples=150,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
#: the one line of every recovery (tests that check it catch it themselves)
pytestmark = pytest.mark.filterwarnings("ignore:.*incomplete recording:UserWarning")
MOUNTING = Mounting().updated({"dvl": {"translation": [0.1, -0.05, 0.2]}})
T0 = 1_700_000_000.0


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    """Recovered copies go to this test's folder, not the user's cache."""
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))


def _write(rec: Recorder, n: int, start: int = 0) -> None:
    """n steps of 10 ms: IMU each, pressure and DVL every 10th, a pose every 25th; every
    message at its own time (the DVL's two messages share one)."""
    rng = np.random.default_rng(start)
    for i in range(start, start + n):
        t = T0 + i * 0.01
        rec.write_record(Record("imu", t, {"angular_velocity": tuple(rng.normal(0, 0.1, 3))}))
        if i % 10 == 0:
            rec.write_record(Record("pressure", t + 0.002, {"pressure": 1.2e5 + i}))
            rec.write_record(Record("dvl", t + 0.004, {"velocity": tuple(rng.normal(0, 0.3, 3))}))
        if i % 25 == 0:
            rec.write_pose(t + 0.006, np.r_[rng.normal(size=6), np.zeros(12)], np.eye(18))


@pytest.fixture(scope="module")
def complete(tmp_path_factory) -> Path:
    """A closed recording of 8 s in chunks of about 0.3 s: its .mcap."""
    folder = tmp_path_factory.mktemp("complete")
    with Recorder(folder / "rec", MOUNTING, flush_every_s=0.3) as rec:
        rec.declare(["imu", "pressure", "dvl"])
        _write(rec, 800)
    return folder / "rec" / "rec.mcap"


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    with AnyReader([path], default_typestore=dvl_typestore()) as reader:
        return sorted((c.topic, ns, bytes(raw)) for c, ns, raw in reader.messages())


@pytest.fixture(scope="module")
def oracle(complete):
    """(chunk ends (byte offsets), their end times, every message) of the complete file."""
    reader = McapReader(complete)
    reader.open()
    try:
        ends = [c.chunk_start_offset + c.chunk_length for c in reader.chunks]
        times = [c.message_end_time for c in reader.chunks]
    finally:
        reader.close()
    assert len(ends) > 20 and ends == sorted(ends)
    return ends, times, _messages(complete)


def _expected(oracle, good: int) -> list:
    """The messages of the chunks whose record ends at or before byte ``good``."""
    ends, times, messages = oracle
    done = [t for end, t in zip(ends, times, strict=True) if end <= good]
    return [m for m in messages if done and m[1] <= done[-1]]


def _recovered(data: bytes, folder: Path) -> tuple[list, object]:
    folder.mkdir(exist_ok=True)
    out = folder / "out.mcap"
    with open(out, "wb") as f:
        result, written = rewrite(io.BytesIO(data), f)
    return (_messages(out) if written.messages else []), result


def test_every_cut_reads_back_every_complete_chunk_before_it(complete, oracle, tmp_path):
    data = complete.read_bytes()
    ends = oracle[0]
    cuts = {0, 7, 8, 20, len(data) - 1, *np.linspace(0, len(data), 120).astype(int).tolist()}
    cuts |= {e + d for e in ends for d in (-1, 0, 1)}
    for cut in sorted(c for c in cuts if 0 <= c < len(data)):
        got, result = _recovered(data[:cut], tmp_path / "cuts")
        assert got == _expected(oracle, cut), cut
        assert result.read <= cut


def test_read_log_at_chunk_boundaries_and_between(complete, oracle, tmp_path):
    full = read_log(complete)
    data = complete.read_bytes()
    ends = oracle[0]
    for cut in (ends[0] - 1, ends[0], (ends[3] + ends[4]) // 2, ends[-1] - 5):
        path = tmp_path / f"cut{cut}" / "rec.mcap"
        path.parent.mkdir()
        path.write_bytes(data[:cut])
        n_imu = sum(m[0] == "/imu/data" for m in _expected(oracle, cut))
        if n_imu == 0:
            with pytest.raises(ReaderError, match="no complete chunk") as err:
                read_log(path)
            assert "\n" not in str(err.value)
            continue
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            log = read_log(path)
        assert len(log.imu) == n_imu
        assert np.array_equal(log.imu.angular_velocity, full.imu.angular_velocity[:n_imu])
        assert log.mounting.to_dict() == MOUNTING.to_dict()  # from /tf_static, no sidecar
        line = next(str(w.message) for w in caught if "incomplete recording" in str(w.message))
        assert f"of {cut} bytes of {path.resolve()} left unread" in line
        assert log.metadata["recovered"]["messages"] == len(_expected(oracle, cut))
        assert log.source == str(path)


def test_a_complete_file_is_read_as_it_is(complete):
    assert is_complete(complete)
    log = read_log(complete)
    assert "recovered" not in log.metadata


def _damaged(data, raw: bytes) -> tuple[bytes, int]:
    """``raw`` cut at a random point and damaged at random places after a random one (flipped
    bits, zeroed or random runs); the damaged bytes and the first byte changed (the cut if
    none is). Points are drawn as fractions of the file, so that they spread over it."""
    cut = int(data.draw(st.floats(0, 1)) * len(raw))
    out = bytearray(raw[:cut])
    first = cut
    start = int(data.draw(st.floats(0, 1)) * cut)
    for _ in range(data.draw(st.integers(0, 6)) if cut > start else 0):
        i = start + int(data.draw(st.floats(0, 1, exclude_max=True)) * (cut - start))
        kind = data.draw(st.sampled_from(["flip", "zero", "random"]))
        n = 1 if kind == "flip" else data.draw(st.integers(1, 16))
        before = bytes(out[i : i + n])
        if kind == "flip":
            out[i] ^= 1 << data.draw(st.integers(0, 7))
        elif kind == "zero":
            out[i : i + n] = bytes(len(before))
        else:
            out[i : i + n] = data.draw(st.binary(min_size=len(before), max_size=len(before)))
        if bytes(out[i : i + n]) != before:
            first = min(first, i)
    return bytes(out), first


@FUZZ
@given(data=st.data())
def test_fuzz_truncated_and_damaged_recordings(complete, oracle, tmp_path, data):
    damaged, first = _damaged(data, complete.read_bytes())
    expected = _expected(oracle, first)
    event(f"intact chunks: {sum(e <= first for e in oracle[0]) // 10 * 10}+")
    if expected:  # the chunks before the first damaged byte: all there, bit for bit
        got, _ = _recovered(damaged, tmp_path / "fuzz")
        missing = Counter(expected) - Counter(got)
        assert not missing, f"{sum(missing.values())} messages of intact chunks not recovered"
    path = tmp_path / "fuzz" / "rec.mcap"
    path.parent.mkdir(exist_ok=True)
    path.write_bytes(damaged)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            read_log(path)
            event("read: a log")
        except UndertowError as exc:
            assert str(exc) and "\n" not in str(exc), repr(str(exc))
            event(f"read: {type(exc).__name__}")
    leaked = [str(w.message) for w in caught if not issubclass(w.category, UserWarning)]
    assert not leaked, leaked
    assert path.read_bytes() == damaged


# -- a crashed Recorder: the paths that name it, the original untouched, the cache ----------------
def _crash(folder: Path, name: str = "rec", n: int = 300, overwrite: bool = False) -> Recorder:
    rec = Recorder(folder / name, MOUNTING, overwrite=overwrite)
    rec.declare(["imu", "pressure", "dvl"])
    _write(rec, n)
    return rec  # never closed: what SIGKILL leaves


def _digest(folder: Path) -> dict:
    return {
        str(p): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_every_path_of_a_crashed_recording_reads_it_and_changes_nothing(tmp_path):
    rec = _crash(tmp_path / "dive")
    (holder,) = (tmp_path / "dive").iterdir()
    before = _digest(tmp_path / "dive")
    paths = [tmp_path / "dive" / "rec", holder, holder / "rec", holder / "rec" / "rec.mcap"]
    logs = []
    for path in paths:
        assert detect_format(path) == "ros2"
        assert bag_topics(path)["/imu/data"][1] == len(read_log(path).imu)
        logs.append(read_log(path))
    n = len(logs[0].imu)
    assert 0 < n < 300 and all(len(log.imu) == n for log in logs)
    # the flushed part: everything up to at most one second (flush_every_s) before the last
    assert logs[0].imu.t[-1] >= T0 + 299 * 0.01 - rec.flush_every_s - 0.011
    assert _digest(tmp_path / "dive") == before
    (copy,) = (tmp_path / "cache" / "recovered").iterdir()  # one copy for every path
    assert {p.name for p in copy.iterdir()} == {"rec.mcap", "source.json"}
    rec.abort()


def test_the_copy_is_reused_until_the_recording_grows(tmp_path):
    rec = _crash(tmp_path)
    mcap = next(tmp_path.glob("rec.partial-*/rec/rec.mcap"))
    first = recover(mcap)
    again = recover(mcap)
    assert again == first
    assert Path(first.path).stat().st_mtime_ns == os.stat(again.path).st_mtime_ns
    _write(rec, 300, start=300)  # still recording: more chunks flushed
    grown = recover(mcap)
    assert grown.path == first.path and grown.messages > first.messages
    assert len(read_log(tmp_path / "rec").imu) > 300
    rec.abort()


def test_crashed_recordings_of_one_target_and_empty_ones(tmp_path):
    first = _crash(tmp_path)
    second = _crash(tmp_path)
    with pytest.raises(ReaderError, match="2 crashed ones") as err:
        read_log(tmp_path / "rec")
    assert "\n" not in str(err.value)
    for holder in tmp_path.glob("rec.partial-*"):  # each one on its own
        assert len(read_log(holder).imu) > 0
    first.abort(), second.abort()
    empty = Recorder(tmp_path / "empty")  # nothing flushed yet: the header only
    with pytest.raises(ReaderError, match="nothing written yet"):  # the header is buffered
        read_log(tmp_path / "empty")
    empty.abort()
    assert partial_bag(tmp_path / "missing") is None
    with pytest.raises(ReaderError, match="no such file"):
        read_log(tmp_path / "missing")


def test_a_finished_recording_is_read_without_recovery(tmp_path):
    with Recorder(tmp_path / "done", MOUNTING) as rec:
        _write(rec, 100)
    crashed = _crash(tmp_path, "done", overwrite=True)  # a second session's crash
    log = read_log(tmp_path / "done")  # the target exists: it, not the .partial
    assert "recovered" not in log.metadata and len(log.imu) == 100
    assert log.metadata["mounting_source"] == "undertow.yaml"
    crashed.abort()


def test_the_line_states_what_was_recovered(tmp_path):
    rec = _crash(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_log(tmp_path / "rec")
    rec.abort()
    lines = [str(w.message) for w in caught if "incomplete recording" in str(w.message)]
    assert len(lines) == 1 and lines[0] in log.metadata["warnings"]
    info = log.metadata["recovered"]
    span = (info["end_ns"] - info["start_ns"]) * 1e-9
    assert math.isclose(span, log.time_span[1] - log.time_span[0], abs_tol=0.05)
    assert f"recovered {info['messages']} messages in {info['chunks']} chunks" in lines[0]
    assert f"{span:.1f} s of record time" in lines[0] and info["path"] in lines[0]
