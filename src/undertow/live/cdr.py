"""CDR bytes of ROS 2 messages of fixed layout, packed in place instead of built and serialized
one by one (the live recorder's fast path, :mod:`undertow.live.recorder`).

A message of fixed layout (``sensor_msgs/Imu``, ``sensor_msgs/FluidPressure``,
``geometry_msgs/PoseWithCovarianceStamped``, the A50 driver's ``DVL``) keeps the bytes of a first
such message rosbags serializes as a :class:`CdrTemplate`: the stamp and the fields after the
header are packed into them (OMG CDR, little-endian, each primitive aligned to its size), and the
template is kept only when it reproduces rosbags' bytes of that message. :func:`string_cdr`
writes a ``std_msgs/String``. Stamps are (sec, nanosec) as rosbags' ``MessageBuilder`` computes
them (:func:`stamp`).
"""

from __future__ import annotations

import math
import re
import struct

STAMP = struct.Struct("<iI")


def stamp(t: float) -> tuple[int, int, int]:
    """(sec, nanosec, record time ns) of a header stamp, as MessageBuilder.header computes them."""
    sec = math.floor(t)
    nanosec = int(round((t - sec) * 1e9))
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return sec, nanosec, sec * 1_000_000_000 + nanosec


def aligned(codes: str) -> struct.Struct:
    """Little-endian struct of the CDR fields ``codes`` (struct codes; ``Ns`` bytes, aligned
    to 1) laid out from an offset aligned to 8: each primitive aligned to its size (OMG CDR)."""
    fmt, off = "<", 0
    for count, code in re.findall(r"(\d*)([a-zA-Z?])", codes):
        n = int(count or 1)
        items = [f"{n}s"] if code == "s" else [code] * n
        for item in items:
            size = struct.calcsize("<" + item)
            pad = -off % (1 if code == "s" else size)
            fmt += "x" * pad + item
            off += pad + size
    return struct.Struct(fmt)


class CdrTemplate:
    """The CDR bytes of a message of fixed layout after its ``std_msgs/Header`` (the ``tail``:
    by default ``n`` float64, as sensor_msgs/Imu and FluidPressure), written without building the
    message: the bytes of a first message serialized by rosbags, with the stamp (int32 sec,
    uint32 nanosec right after the 4-byte encapsulation header) and the tail replaced (OMG CDR:
    the frame id's length, bytes and padding stay those of the template; the tail starts
    aligned to 8). :meth:`make` keeps a template only when it reproduces rosbags' bytes of that
    message."""

    def __init__(self, serialized: bytes, tail: struct.Struct) -> None:
        self.tail = tail
        self.encapsulation = serialized[:4]
        self.middle = serialized[4 + STAMP.size : len(serialized) - tail.size]

    def pack(self, sec: int, nanosec: int, values) -> bytes:
        return b"".join((self.encapsulation, STAMP.pack(sec, nanosec), self.middle,
                         self.tail.pack(*values)))  # fmt: skip

    @classmethod
    def make(cls, serialized, t: float, values, tail=None) -> CdrTemplate | None:
        serialized = bytes(serialized)
        try:
            template = cls(serialized, tail or struct.Struct(f"<{len(values)}d"))
            sec, nanosec, _ = stamp(t)
            same = template.pack(sec, nanosec, values) == serialized
        except (struct.error, OverflowError):
            same = False
        return template if same else None


#: waterlinked_a50_ros_driver/msg/DVL after its header: time, velocity, fom, altitude, the
#: beams (a sequence of 4: id, velocity, distance, rssi, nsd, valid), velocity_valid, status,
#: form (a string of 7 characters)
DVL_TAIL = aligned("6d I" + " q4d?" * 4 + " ?q I8s")
DVL_FORM = b"json_v3\x00"


def string_cdr(encapsulation: bytes, text: str) -> bytes:
    """CDR bytes of a std_msgs/String: uint32 length (with the NUL), the UTF-8 bytes, NUL."""
    data = text.encode()
    return b"".join((encapsulation, struct.pack("<I", len(data) + 1), data, b"\x00"))
