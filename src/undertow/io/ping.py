"""The Blue Robotics Ping protocol of a Ping1D echosounder (Blue Robotics ping-protocol), as
``bluerobotics-ping`` (``brping``) speaks it: frames ``B`` ``R``, payload length (u16), message id
(u16), source and destination device ids (u8), payload, and a u16 checksum = the sum of every
preceding byte mod 2^16.

The ``distance`` message (id 1212; ``distance_simple``, 1211, without the ping number) carries
``distance`` (uint32, mm) and ``confidence`` (uint16, %): :func:`distance_data` reads them as a
``sonar`` record's range r = 1e-3 distance (m) and confidence in 0..1 (NaN above 100 %), and
:func:`distance_fields` writes a range and confidence as them. :func:`decode_ping_frames`
finds the distance messages in received bytes. Used by the live Ping1D link
(:mod:`undertow.live.links.ping1d`) and the virtual robot's Ping1D (:mod:`undertow.sim.robot`).
``brping`` is imported at first use (:func:`load_brping`).
"""

from __future__ import annotations

import contextlib
import io
import math

PING1D_DISTANCE = 1212
PING1D_DISTANCE_SIMPLE = 1211


def load_brping():
    """brping and its ``definitions`` and ``pingmessage`` modules (imported at first use)."""
    import brping
    from brping import definitions, pingmessage

    return brping, definitions, pingmessage


def distance_data(distance_mm, confidence_pct) -> dict:
    """The ``sonar`` record fields of a Ping1D distance: range (m) and confidence (0..1)."""
    ok = type(distance_mm) is int and type(confidence_pct) is int
    if not (ok and 0 <= distance_mm < 2**32 and 0 <= confidence_pct < 2**16):
        raise ValueError("Ping1D distance (uint32 mm) and confidence (uint16 %) out of range")
    confidence = confidence_pct / 100.0 if 0 <= confidence_pct <= 100 else math.nan
    return {"range": distance_mm / 1000.0, "confidence": confidence}


def decode_ping_frames(data: bytes, parser=None) -> tuple[list[dict], int]:
    """The distance messages (dicts with distance, confidence, ping_number) in ``data`` decoded
    with brping's ``PingParser`` (checksum verified), and the number of frames rejected (bad
    checksum or unknown id). Other valid messages are ignored."""
    _, definitions, pingmessage = load_brping()
    parser = parser or pingmessage.PingParser()
    out, errors = [], parser.errors
    rejected = 0
    with contextlib.redirect_stdout(io.StringIO()):  # brping prints on unknown messages
        for byte in data:
            if parser.parse_byte(byte) != pingmessage.PingParser.NEW_MESSAGE:
                continue
            msg = parser.rx_msg
            if not hasattr(msg, "payload_field_names"):
                rejected += 1
                continue
            if msg.message_id in (PING1D_DISTANCE, PING1D_DISTANCE_SIMPLE):
                fields = {n: getattr(msg, n, None) for n in msg.payload_field_names}
                if isinstance(fields.get("distance"), int):
                    out.append(fields)
                else:
                    rejected += 1
    del definitions
    return out, rejected + parser.errors - errors


def distance_fields(r: float, c: float) -> tuple[int, int]:
    """(distance mm, confidence %) of a range r (m) and confidence c (0..1) (module
    docstring)."""
    if not math.isfinite(r) or r < 0:
        return 0, 0
    pct = int(round(100.0 * c)) if math.isfinite(c) and 0.0 <= c <= 1.0 else 255
    return int(min(round(1000.0 * r), 2**32 - 1)), pct
