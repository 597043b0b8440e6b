"""What a served message says, decoded by the same functions the live links use: the
:class:`~undertow.records.Record` a link receiving it intact would deliver (values in the
Log's units), stamped with the message's playback time ``t`` (log time) instead of an arrival
time, so a manifest turns back into a Log (:func:`served_log`) to compare with the original."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable

from ...io.a50_json import is_position_report, position_fields, velocity_fields
from ...io.mavlink import MavlinkConfig, MavlinkMapper
from ...io.ping import decode_ping_frames, distance_data
from ...records import Record, records_to_log
from .player import Served


def _a50(entry: Served) -> list[Record]:
    obj = json.loads(entry.payload)
    if is_position_report(obj):
        data, _ = position_fields(obj)
        return [Record("dead_reckoning", entry.t, data, entry.wall, entry.sensor_time, "a50")]
    fields, _ = velocity_fields(obj)
    return [Record("dvl", entry.t, fields, entry.wall, entry.sensor_time, "a50")]


def _ping(entry: Served) -> list[Record]:
    if entry.index < 0:
        return []
    messages, _ = decode_ping_frames(entry.payload)
    data = distance_data(messages[0]["distance"], messages[0]["confidence"])
    return [Record("sonar", entry.t, data, entry.wall, math.nan, "ping1d")]


def served_records(
    entries: Iterable[Served], mavlink: MavlinkConfig | None = None, faulty: bool = False
) -> list[Record]:
    """The records of ``entries`` (delivered ones only unless ``faulty``; a duplicate, or a
    Ping reply repeating the previous reply's ping, once), in order; MAVLink decoded by
    pymavlink and mapped with ``mavlink`` (default config)."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    mav = mavlink2.MAVLink(None)
    mapper = MavlinkMapper(mavlink or MavlinkConfig(), source="mavlink")
    out: list[Record] = []
    last_ping = math.nan
    for e in entries:
        if e.fault == "duplicate" or not (faulty or e.delivered):
            continue
        if e.protocol == "a50":
            out += _a50(e)
        elif e.protocol == "ping1d" and e.t != last_ping:  # a ping polled twice: once
            last_ping = e.t
            out += _ping(e)
        elif e.protocol == "mavlink":
            for r in mapper.records(mav.decode(bytearray(e.payload)), e.t, e.wall):
                out.append(Record(r.stream, r.t, r.data, r.arrival, e.sensor_time, r.source))
    return out


def served_log(
    entries: Iterable[Served], mavlink: MavlinkConfig | None = None, faulty: bool = False
):
    """:func:`served_records` as a Log (each stream sorted by playback time)."""
    return records_to_log(served_records(entries, mavlink, faulty), source="served")
