"""The kernel filter of MAVLink datagrams: what a real socket with the program attached lets
through, against a Python statement of the rule (module docstring of
undertow.live.links.mavlink_filter), on real pymavlink frames (MAVLink 1 and 2, signed), their
mutations and random bytes; and a live link with it delivering the same records."""

from __future__ import annotations

import socket
import sys
import time

import pytest
from hypothesis import given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from pymavlink.dialects.v10 import ardupilotmega as mavlink1
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from undertow.live.links import Backoff
from undertow.live.links.mavlink_filter import attach, program
from undertow.live.links.mavlink_udp import MavlinkLink

pytestmark = [
    pytest.mark.network,
    pytest.mark.skipif(sys.platform != "linux", reason="a Linux socket filter"),
]

KEEP = {mavlink2.MAVLINK_MSG_ID_ATTITUDE, mavlink2.MAVLINK_MSG_ID_HEARTBEAT,
        mavlink2.MAVLINK_MSG_ID_VISION_POSITION_DELTA}  # fmt: skip


def _kept_by_rule(data: bytes) -> bool:
    """The filter's rule, stated in Python: dropped only when the datagram is exactly one
    MAVLink 2 frame (0xFD, 12 + payload length bytes, + 13 signed) or MAVLink 1 frame (0xFE,
    8 + payload length) of an id not kept."""
    if len(data) < 10:
        return True
    if data[0] == 0xFD:
        single = len(data) == 12 + data[1] + (13 if data[2] & 1 else 0)
        return not single or (data[7] | data[8] << 8 | data[9] << 16) in KEEP
    if data[0] == 0xFE:
        return len(data) != 8 + data[1] or data[5] in KEEP
    return True


def _frames() -> list[bytes]:
    m2 = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    m1 = mavlink1.MAVLink(None, srcSystem=1, srcComponent=1)
    signed = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    signed.signing.secret_key = bytes(range(32))
    signed.signing.sign_outgoing = True
    out = []
    for mav in (m2, m1, signed):
        out += [
            mav.attitude_encode(1, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03).pack(mav),
            mav.scaled_imu2_encode(1, 1, 2, 3, 4, 5, 6, 7, 8, 9).pack(mav),
            mav.heartbeat_encode(12, 3, 0, 0, 4, 3).pack(mav),
            mav.sys_status_encode(*[0] * 13).pack(mav),
        ]
    out.append(m2.vision_position_delta_encode(1, 2, [0.1] * 3, [0.2] * 3, 90.0).pack(m2))
    return out


class _Receiver:
    def __init__(self) -> None:
        self.rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.rx.bind(("127.0.0.1", 0))
        self.rx.settimeout(0.05)
        assert attach(self.rx, KEEP, {i for i in KEEP if i < 256})
        self.tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def passes(self, data: bytes) -> bool:
        """Whether ``data`` sent now arrives (a marker datagram after it bounds the wait)."""
        self.tx.sendto(data, self.rx.getsockname())
        self.tx.sendto(b"marker", self.rx.getsockname())
        got = []
        while True:
            try:
                got.append(self.rx.recv(70_000))
            except TimeoutError:
                break
            if got[-1] == b"marker":
                break
        assert got and got[-1] == b"marker"
        return got[:-1] == [data]

    def close(self) -> None:
        self.rx.close()
        self.tx.close()


@pytest.fixture(scope="module")
def receiver():
    r = _Receiver()
    yield r
    r.close()


def test_real_frames_and_their_neighbours(receiver):
    frames = _frames()
    cases = [*frames, frames[1] + frames[0], frames[0] + frames[1], frames[1][:-1],
             frames[1] + b"\x00", b"", b"\xfd", b"hello, autopilot"]  # fmt: skip
    dropped = 0
    for data in cases:
        kept = receiver.passes(data)
        assert kept == _kept_by_rule(data), data
        dropped += not kept
    assert dropped >= 6  # SCALED_IMU2 and SYS_STATUS in MAVLink 1, 2 and signed 2


@hsettings(max_examples=150, deadline=None)
@given(st.sampled_from(_frames()), st.integers(0, 40), st.integers(0, 255), st.binary(max_size=8))
def test_mutated_frames_follow_the_rule(receiver, frame, pos, value, tail):
    data = bytearray(frame)
    if pos < len(data):
        data[pos] = value
    data = bytes(data) + (tail if value % 3 == 0 else b"")
    assert receiver.passes(data) == _kept_by_rule(data)


def test_program_jumps_stay_inside():
    insns = program(range(0, 700, 7), range(0, 256, 4))
    for i, (code, jt, jf, _) in enumerate(insns):
        if code & 0x07 == 0x05:  # BPF_JMP: both targets are instructions of the program
            assert i + 1 + max(jt, jf) < len(insns)
    assert insns[-1][0] & 0x07 == 0x06  # it ends with a return
    with pytest.raises(ValueError, match="out of reach"):
        program(range(400), ())


def test_live_link_with_the_filter_delivers_the_same_records():
    """Same stream of ATTITUDE, SCALED_IMU2 (not used: the gyro comes from ATTITUDE) and
    HEARTBEAT to a link with the filter and one without: the same records; the filtered one
    never saw SCALED_IMU2."""
    m2 = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    out = {}
    for kernel_filter in (True, False):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        s.close()
        records = []
        fast = Backoff(0.02, 2.0, 0.1)
        link = MavlinkLink(f"udpin:127.0.0.1:{port}", records.append, deferred=True,
                           kernel_filter=kernel_filter, backoff=fast)  # fmt: skip
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        with link:
            deadline = time.monotonic() + 10
            while link.counters.connects == 0:
                assert time.monotonic() < deadline
                time.sleep(0.005)
            for k in range(60):
                att = m2.attitude_encode(10 * k, 0.1, 0.2, 0.3, 0.01 * k, 0.02, 0.03)
                imu = m2.scaled_imu2_encode(10 * k, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10)
                for msg in (
                    (att, imu) if k % 10 else (att, imu, m2.heartbeat_encode(12, 3, 0, 0, 4, 3))
                ):
                    tx.sendto(msg.pack(m2), ("127.0.0.1", port))
                time.sleep(0.001)
            while link.message_counts.get("ATTITUDE", 0) < 60:
                assert time.monotonic() < deadline, link.message_counts
                link.pump()
                time.sleep(0.005)
        tx.close()
        out[kernel_filter] = ([r.data for r in records], dict(link.message_counts), link.info)
    assert out[True][0] == out[False][0] and len(out[True][0]) == 60
    assert "SCALED_IMU2" not in out[True][1] and out[False][1]["SCALED_IMU2"] == 60
    assert out[True][1]["HEARTBEAT"] == out[False][1]["HEARTBEAT"] == 6
    assert out[True][2]["kernel_filter"] is True and "kernel_filter" not in out[False][2]
