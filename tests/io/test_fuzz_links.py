"""Property-based tests (hypothesis) of the parsers that read from the network or a .tlog file:
the .tlog reader, the A50 line handling of the TCP link, Ping frame decoding and the MAVLink
mapping. No input may raise anything but a one-line ``UndertowError`` (possibly after
warnings), leak a numpy warning, or grow a buffer without bound; where the undamaged part of
the input is known, it is kept. Bounded to a few seconds per test (``max_examples``; set
``UNDERTOW_FUZZ_EXAMPLES`` for a long campaign)."""

from __future__ import annotations

import json
import math
import os
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from test_fuzz_readers import JUNK_LINE, WEIRD, _v1_reports, _v3_reports, mutated_report, outcome

from undertow.io import read_log
from undertow.io.mavlink import MavlinkConfig, MavlinkMapper
from undertow.io.ping import decode_ping_frames, distance_data
from undertow.live.links.a50_tcp import MAX_LINE_BYTES, A50LineDecoder, LineBuffer
from undertow.live.links.base import ClockPolicy, LinkCounters
from undertow.records import RECORD_FIELDS, records_to_log

#: opens sockets on 127.0.0.1 (servers it starts)
pytestmark = pytest.mark.network

set_hypothesis_home_dir(Path(tempfile.gettempdir()) / "undertow-hypothesis")
#: examples per property: 40 in the suite (a few seconds); UNDERTOW_FUZZ_EXAMPLES=N for a long run
FAST = hsettings(
    max_examples=int(os.environ.get("UNDERTOW_FUZZ_EXAMPLES", "40")),
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
EPOCH = 1_700_000_000.0


def _tlog_bytes() -> tuple[bytes, int]:
    """A small tlog of every mapped message type (60 records) and its record count."""
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    out = []
    for k in range(10):
        t = k * 0.1
        msgs = [
            mavlink2.MAVLink_attitude_message(k * 100, 0.1, -0.2, 1.0 + k * 0.01, 0.01, 0.02, 0.03),
            mavlink2.MAVLink_scaled_imu2_message(k * 100, 1, 2, -1000, 10, -20, 30, 0, 0, 0, 2000),
            mavlink2.MAVLink_scaled_pressure2_message(k * 100, 1100.0 + k, 0.0, 1500),
            mavlink2.MAVLink_vision_position_delta_message(
                int(t * 1e6), 100_000, [0.0, 0.0, 0.01], [0.05, 0.0, 0.0], 90.0
            ),
            mavlink2.MAVLink_distance_sensor_message(k * 100, 30, 5000, 150 + k, 1, 0, 25, 0),
            mavlink2.MAVLink_heartbeat_message(12, 3, 0, 0, 0, 3),
        ]
        out += [
            struct.pack(">Q", int((EPOCH + t + j * 1e-3) * 1e6)) + m.pack(mav)
            for j, m in enumerate(msgs)
        ]
    return b"".join(out), len(out)


TLOG, TLOG_RECORDS = _tlog_bytes()


def _rows(raw: bytes, tmp_path) -> int:
    path = tmp_path / "intact.tlog"
    path.write_bytes(raw)
    return sum(len(s) for s in read_log(path).streams().values())


@FAST
@given(data=st.data())
def test_tlog_bytes(tmp_path, data):
    raw = bytearray(TLOG)
    kind = data.draw(st.sampled_from(["flip", "truncate", "fill", "insert", "random"]))
    hits = data.draw(st.integers(1, 6))
    if kind == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw)))]
    elif kind == "random":
        raw = bytearray(data.draw(st.binary(max_size=2000)))
    for _ in range(hits if kind in ("flip", "fill", "insert") else 0):
        i = data.draw(st.integers(0, len(raw) - 1))
        if kind == "flip":
            raw[i] ^= 1 << data.draw(st.integers(0, 7))
        elif kind == "fill":
            raw[i : i + 8] = bytes(len(raw[i : i + 8]))
        else:
            raw[i:i] = data.draw(st.binary(min_size=1, max_size=40))
    path = tmp_path / "fuzz.tlog"
    path.write_bytes(bytes(raw))
    log = outcome(read_log, path)
    if kind in ("flip", "fill", "insert"):  # each hit costs at most the records it touches
        assert log is not None
        kept = sum(len(s) for s in log.streams().values())
        # a hit touches at most two records, each at most two rows (VISION_POSITION_DELTA)
        assert kept >= _rows(TLOG, tmp_path) - 4 * hits


@FAST
@given(
    values=st.lists(
        st.one_of(st.floats(width=32), st.integers(-(2**31), 2**31 - 1)), min_size=12, max_size=12
    ),
    gyro=st.sampled_from(["attitude", "scaled_imu2"]),
)
def test_mavlink_mapping_of_any_field_values(values, gyro):
    """Messages built with arbitrary field values (NaN, inf, huge) map to finite records or to
    none (counted); the integrals of the dead reckoning never become non-finite."""
    f = [float(v) for v in values]
    i = [int(v) if isinstance(v, int) else 7 for v in values]
    msgs = [
        mavlink2.MAVLink_attitude_message(1, *f[:6]),
        mavlink2.MAVLink_scaled_imu2_message(1, *[x % 30000 for x in i[:9]]),
        mavlink2.MAVLink_scaled_pressure2_message(1, f[6], f[7], 0),
        mavlink2.MAVLink_vision_position_delta_message(abs(i[0]), abs(i[1]), f[0:3], f[3:6], f[8]),
        mavlink2.MAVLink_distance_sensor_message(
            1,
            abs(i[2]) % 65536,
            abs(i[3]) % 65536,
            abs(i[4]) % 65536,
            0,
            abs(i[5]) % 256,
            25,
            0,
            signal_quality=abs(i[6]) % 256,
        ),
        mavlink2.MAVLink_rangefinder_message(f[9], f[10]),
    ]
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    mapper = MavlinkMapper(MavlinkConfig(gyro=gyro))
    records = []
    for msg in msgs:  # through the wire format, as a link or a tlog receives them
        decoded = mav.decode(bytearray(msg.pack(mav)))
        records += mapper.records(decoded, EPOCH)
    for r in records:
        assert r.stream in RECORD_FIELDS
        for key in ("angular_velocity", "pressure", "velocity", "position"):
            if key in r.data:
                assert np.all(np.isfinite(r.data[key])), r
    assert np.all(np.isfinite(mapper._p)) and np.all(np.isfinite(mapper._R))
    if records:
        outcome(records_to_log, records)


def _decoder():
    counters = LinkCounters()
    return A50LineDecoder(counters, ClockPolicy(counters, max_offset_s=math.inf)), counters


@FAST
@given(data=st.data(), v3=st.booleans())
def test_a50_link_lines_keep_the_good_reports(data, v3):
    good = _v3_reports() if v3 else _v1_reports()
    damaged = {}
    for _ in range(data.draw(st.integers(1, 4))):
        k = data.draw(st.integers(0, len(good) - 1))
        damaged[k] = data.draw(st.one_of(mutated_report(json.loads(good[k])), JUNK_LINE))
    lines = [damaged.get(k, line) for k, line in enumerate(good)]
    decoder, counters = _decoder()
    records = []
    for k, line in enumerate(lines):
        records += decoder.decode(line.encode("utf-8", errors="surrogatepass"), 1000.0 + k)
    intact = [ln for k, ln in enumerate(good) if k not in damaged]
    velocity = [ln for ln in intact if json.loads(ln).get("type", "velocity") == "velocity"]
    assert sum(r.stream == "dvl" for r in records) >= len(velocity)
    assert counters.received >= counters.malformed + counters.duplicate
    if records:
        outcome(records_to_log, records)


@FAST
@given(
    chunks=st.lists(st.binary(max_size=3000), max_size=20),
    long_line=st.integers(0, 3 * MAX_LINE_BYTES),
)
def test_a50_link_byte_stream_is_bounded(chunks, long_line):
    """Any byte stream, including a line longer than MAX_LINE_BYTES, keeps the pending buffer
    bounded, and the decoder never raises."""
    counters = LinkCounters()
    buffer = LineBuffer(counters)
    decoder = A50LineDecoder(counters, ClockPolicy(counters))
    stream = [*chunks, b"x" * long_line, b"\n", *chunks]
    for chunk in stream:
        for line in buffer.feed(chunk):
            assert len(line) <= MAX_LINE_BYTES
            decoder.decode(line, 1000.0)
        assert len(buffer.pending) <= MAX_LINE_BYTES
    if long_line > MAX_LINE_BYTES:
        assert counters.malformed >= 1


def _ping_frames(pings) -> bytes:
    from brping import definitions, pingmessage

    out = b""
    for distance, confidence, number in pings:
        msg = pingmessage.PingMessage(definitions.PING1D_DISTANCE)
        msg.distance, msg.confidence, msg.ping_number = distance, confidence, number
        msg.pack_msg_data()
        out += bytes(msg.msg_data)
    return out


PINGS = st.lists(
    st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 2**16 - 1), st.integers(0, 2**32 - 1)),
    min_size=1,
    max_size=5,
)


@FAST
@given(pings=PINGS, data=st.data())
def test_ping_frames(pings, data):
    raw = _ping_frames(pings)
    decoded, rejected = decode_ping_frames(raw)
    assert [(d["distance"], d["confidence"], d["ping_number"]) for d in decoded] == pings
    assert rejected == 0
    for d in decoded:
        fields = distance_data(d["distance"], d["confidence"])
        assert fields["range"] == d["distance"] / 1000.0
        assert math.isnan(fields["confidence"]) or 0.0 <= fields["confidence"] <= 1.0
    damaged = bytearray(raw)
    for _ in range(data.draw(st.integers(1, 4))):
        k = data.draw(st.integers(0, len(damaged) - 1))
        damaged[k] ^= 1 << data.draw(st.integers(0, 7))
    decode_ping_frames(bytes(damaged))  # never raises
    decode_ping_frames(data.draw(st.binary(max_size=500)))


@FAST
@given(distance=WEIRD, confidence=WEIRD)
def test_ping_distance_fields(distance, confidence):
    try:
        fields = distance_data(distance, confidence)
    except ValueError:
        return
    assert isinstance(fields["range"], float)


@pytest.mark.parametrize("n", [0, 1, 7])
def test_tlog_of_only_unknown_or_heartbeat_messages_is_one_line(tmp_path, n):
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = mavlink2.MAVLink_heartbeat_message(12, 3, 0, 0, 0, 3)
    path = tmp_path / "hb.tlog"
    path.write_bytes(
        b"".join(struct.pack(">Q", int(EPOCH * 1e6) + k) + msg.pack(mav) for k in range(n))
        or b"\x00"
    )
    assert outcome(read_log, path) is None


@FAST
@given(data=st.data())
def test_mavlink_link_on_damaged_bytes(data):
    """Damaged MAVLink bytes through pymavlink's stream parser (as the live link receives them)
    and the link's handler: nothing raises, every record is of a known stream."""
    from undertow.live.links.mavlink_udp import MavlinkLink

    raw, k = bytearray(), 0
    while k < len(TLOG):  # the frames of the tlog, without their timestamps
        length = _frame_len(TLOG, k + 8)
        raw += TLOG[k + 8 : k + 8 + length]
        k += 8 + length
    for _ in range(data.draw(st.integers(0, 6))):
        i = data.draw(st.integers(0, len(raw) - 1))
        raw[i] ^= 1 << data.draw(st.integers(0, 7))
    raw[data.draw(st.integers(0, len(raw))) : 0] = data.draw(st.binary(max_size=64))
    records = []
    link = MavlinkLink("udpin:127.0.0.1:9", records.append)
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    for msg in mav.parse_buffer(bytes(raw)) or []:
        link.handle(msg, EPOCH)
    assert all(r.stream in RECORD_FIELDS for r in records)
    assert link.counters.delivered == len(records)


def _frame_len(data: bytes, i: int) -> int:
    if data[i] == 0xFE:
        return 6 + data[i + 1] + 2
    return 10 + data[i + 1] + 2 + (13 if data[i + 2] & 1 else 0)


def _tlog_frames() -> list[bytes]:
    frames, k = [], 0
    while k < len(TLOG):
        length = _frame_len(TLOG, k + 8)
        frames.append(TLOG[k + 8 : k + 8 + length])
        k += 8 + length
    return frames


def test_single_mavlink_frames_named_or_decoded_without_pymavlinks_parser():
    """Intact frames of messages no stream reads are named; mapped ones of scalar fields are
    decoded to pymavlink's message (fields, header); a message with arrays, a bad CRC, a frame
    after buffered bytes and a signed frame go to pymavlink's parser."""
    from undertow.live.links.mavlink_udp import _SingleFrames

    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    used = MavlinkMapper().message_types
    frames = _SingleFrames(mav, used)
    got = [frames.check(f) for f in _tlog_frames()[:6]]
    names = [g if g is None else (g[0], g[1] is not None) for g in got]
    # VISION_POSITION_DELTA and DISTANCE_SENSOR have array fields: pymavlink's parser
    assert names == [("ATTITUDE", True), ("SCALED_IMU2", False), ("SCALED_PRESSURE2", True),
                     None, None, ("HEARTBEAT", False)]  # fmt: skip
    for k in (0, 2):
        ref = mavlink2.MAVLink(None).parse_buffer(_tlog_frames()[k])[0]
        assert got[k][1].to_dict() == ref.to_dict()
        assert vars(got[k][1].get_header()) == vars(ref.get_header())
        assert got[k][1].get_msgbuf() == ref.get_msgbuf()
    imu = bytearray(_tlog_frames()[1])
    imu[-1] ^= 0x01
    assert frames.check(bytes(imu)) is None
    signed = bytearray(_tlog_frames()[1])
    signed[2] |= 0x01
    assert frames.check(bytes(signed)) is None
    mav.parse_buffer(_tlog_frames()[0][:5])  # half a frame waits in the parser's buffer
    assert frames.check(_tlog_frames()[1]) is None


@FAST
@given(data=st.data())
def test_single_mavlink_frames_are_what_pymavlink_decodes(data):
    """Any damage to a frame: the link names (counts without decoding) or decodes a datagram
    itself only when pymavlink's parser decodes exactly one message of that name from it, with
    the same fields and header; a named one is a message no stream uses."""
    from undertow.live.links.mavlink_udp import _SingleFrames

    frame = bytearray(data.draw(st.sampled_from(_tlog_frames())))
    for _ in range(data.draw(st.integers(0, 3))):
        i = data.draw(st.integers(0, len(frame) - 1))
        frame[i] ^= 1 << data.draw(st.integers(0, 7))
    cut = data.draw(st.integers(0, len(frame)))
    frame = frame[:cut] + data.draw(st.binary(max_size=4)) + frame[cut:]
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    used = MavlinkMapper().message_types
    got = _SingleFrames(mav, used).check(bytes(frame))
    decoded = mav.parse_buffer(bytes(frame)) or []
    if got is not None:
        name, msg = got
        assert [m.get_type() for m in decoded] == [name]
        if msg is None:
            assert name not in used
        else:
            assert msg.to_dict() == decoded[0].to_dict()
            assert vars(msg.get_header()) == vars(decoded[0].get_header())
