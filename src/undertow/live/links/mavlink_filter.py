"""A kernel socket filter for MAVLink over UDP: the datagrams that are one frame of a message no
stream uses never reach the process.

An autopilot streams dozens of message types (ArduSub's default streams: SYS_STATUS,
GPS_RAW_INT, RC_CHANNELS, SERVO_OUTPUT_RAW, SCALED_IMU2, ...), each a datagram that wakes the
link's thread, takes the GIL and is checked only to be counted. A classic BPF program attached
with ``SO_ATTACH_FILTER`` (Linux, socket(7); the instruction set of McCanne and Jacobson, "The
BSD Packet Filter", USENIX 1993, as in linux/filter.h) drops them in the kernel. For a UDP socket
the program sees the UDP header (8 bytes) then the payload. It keeps:

- a datagram that is exactly one MAVLink 2 frame (start 0xFD; length 12 + payload length, + 13
  when signed) or MAVLink 1 frame (0xFE; 8 + payload length) of a message id in ``keep``;
- anything else: shorter datagrams, other start bytes, several frames in one datagram, a length
  that does not match (what the link's parser counts as malformed).

So a dropped datagram is a well-framed message the link would only have counted: what is lost is
its count (``MavlinkLink.message_counts``) and a CRC check of it.
"""

from __future__ import annotations

import ctypes
import socket
import struct
import sys

SO_ATTACH_FILTER = 26  # asm-generic/socket.h (x86-64, arm64, arm)
_UDP = 8  # the UDP header before the payload
_ACCEPT, _DROP = 0xFFFFFFFF, 0

# linux/bpf_common.h
_LD_LEN = 0x00 | 0x00 | 0x80  # BPF_LD | BPF_W | BPF_LEN: A = packet length
_LDB = 0x00 | 0x10 | 0x20  # BPF_LD | BPF_B | BPF_ABS: A = byte [k]
_AND = 0x04 | 0x50  # BPF_ALU | BPF_AND | BPF_K
_ADD = 0x04 | 0x00  # BPF_ALU | BPF_ADD | BPF_K
_LSH = 0x04 | 0x60  # BPF_ALU | BPF_LSH | BPF_K
_OR_X = 0x04 | 0x40 | 0x08  # BPF_ALU | BPF_OR | BPF_X
_TAX = 0x07 | 0x00  # BPF_MISC | BPF_TAX: X = A
_JEQ = 0x05 | 0x10  # BPF_JMP | BPF_JEQ | BPF_K
_JEQ_X = 0x05 | 0x10 | 0x08  # BPF_JMP | BPF_JEQ | BPF_X
_JGE = 0x05 | 0x30  # BPF_JMP | BPF_JGE | BPF_K
_RET = 0x06  # BPF_RET | BPF_K
_INSN = struct.Struct("=HBBI")  # struct sock_filter: code, jt, jf, k


def program(keep_v2, keep_v1) -> list[tuple[int, int, int, int]]:
    """The filter (module docstring) as (code, jt, jf, k) instructions: ``keep_v2`` the message
    ids kept in MAVLink 2 frames, ``keep_v1`` those in MAVLink 1 frames (< 256)."""
    p = _UDP
    ids2, ids1 = sorted(set(keep_v2)), sorted(i for i in set(keep_v1) if 0 <= i < 256)
    asm: list[tuple] = [  # (code, k, jump-if-true label, jump-if-false label) / ("label", name)
        (_LD_LEN, 0, None, None),
        (_JGE, p + 10, None, "accept"),  # too short to hold a MAVLink 2 header: the parser's
        (_LDB, p + 0, None, None),
        (_JEQ, 0xFD, "v2", None),
        (_JEQ, 0xFE, "v1", "accept"),
        ("label", "v2"),
        (_LDB, p + 2, None, None),  # incompat_flags: bit 0, signed (13 more bytes)
        (_AND, 1, None, None),
        (_JEQ, 0, "unsigned", None),
        (_LDB, p + 1, None, None),
        (_ADD, p + 12 + 13, None, None),
        (_JEQ, 0xFFFFFFFF, "x2", "x2"),  # (an unconditional jump)
        ("label", "unsigned"),
        (_LDB, p + 1, None, None),
        (_ADD, p + 12, None, None),
        ("label", "x2"),
        (_TAX, 0, None, None),
        (_LD_LEN, 0, None, None),
        (_JEQ_X, 0, None, "accept"),  # not exactly one frame
        (_LDB, p + 9, None, None),  # msgid: 24 bits, little-endian, at payload bytes 7..9
        (_LSH, 8, None, None),
        (_TAX, 0, None, None),
        (_LDB, p + 8, None, None),
        (_OR_X, 0, None, None),
        (_LSH, 8, None, None),
        (_TAX, 0, None, None),
        (_LDB, p + 7, None, None),
        (_OR_X, 0, None, None),
        *((_JEQ, i, "accept", None) for i in ids2),
        (_RET, _DROP, None, None),
        ("label", "v1"),
        (_LDB, p + 1, None, None),
        (_ADD, p + 8, None, None),
        (_TAX, 0, None, None),
        (_LD_LEN, 0, None, None),
        (_JEQ_X, 0, None, "accept"),
        (_LDB, p + 5, None, None),  # msgid: payload byte 5
        *((_JEQ, i, "accept", None) for i in ids1),
        (_RET, _DROP, None, None),
        ("label", "accept"),
        (_RET, _ACCEPT, None, None),
    ]
    labels, n = {}, 0
    for item in asm:
        if item[0] == "label":
            labels[item[1]] = n
        else:
            n += 1
    out, pc = [], 0
    for item in asm:
        if item[0] == "label":
            continue
        code, k, jt, jf = item
        rel = [0 if j is None else labels[j] - (pc + 1) for j in (jt, jf)]
        if not all(0 <= r < 256 for r in rel):
            raise ValueError("mavlink filter: a jump out of reach (too many message ids)")
        out.append((code, rel[0], rel[1], k))
        pc += 1
    return out


def attach(sock: socket.socket, keep_v2, keep_v1) -> bool:
    """Attach :func:`program` to ``sock`` (a UDP socket); False where it cannot be (not Linux,
    a refused program): every datagram then reaches the process, as without a filter."""
    if sys.platform != "linux":
        return False
    try:
        insns = program(keep_v2, keep_v1)
    except ValueError:
        return False
    code = ctypes.create_string_buffer(b"".join(_INSN.pack(*i) for i in insns))
    fprog = struct.pack("@HL", len(insns), ctypes.addressof(code))  # struct sock_fprog
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER, fprog)
    except OSError:
        return False
    return True  # (the kernel copied the program: the buffer may go)
