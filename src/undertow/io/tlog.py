"""Reader of MAVLink telemetry logs (``.tlog``, as QGroundControl and BlueOS record them).

A ``.tlog`` is a sequence of records [8-byte big-endian uint64: receive time in microseconds
since the Unix epoch][one MAVLink v1 or v2 message] (the format pymavlink's ``mavlogfile``
reads and writes). Each message is decoded and CRC-checked by pymavlink's generated
``ardupilotmega`` dialect (a superset of common.xml) and mapped to measurements by
:class:`~undertow.io.mavlink.MavlinkMapper` (the same mapping as the live MAVLink link; units
and frames are documented there).

Time: every record is stamped with the tlog's receive time (Unix s), the only clock all messages
share (``time_boot_ms`` is the autopilot's, ``time_usec`` of VISION_POSITION_DELTA the companion
computer's); ``Log.metadata['tlog']['clock_offsets_s']`` keeps, per message type, the median of
receive time minus the message's own time (s) and its spread, so a user can see how the clocks
relate.

Damage: a record whose timestamp is implausible (before 2000 or after 2100), whose MAVLink
frame is truncated or whose CRC fails is skipped, and the reader resynchronizes on the next byte
that can start a record; each damaged region is counted once (one warning with the count and
the first byte offset), the good messages are kept. A message whose receive time is more than
an hour away from both its neighbours' (a damaged timestamp with a valid frame) is dropped and
counted; receive times going backwards are sorted, with a warning. A file with no decodable
record is one :class:`~undertow.errors.ReaderError` line.
"""

from __future__ import annotations

import dataclasses
import math
import struct
from collections import Counter, defaultdict
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from ..errors import ReaderError
from ..log import Log
from ..records import records_to_log
from ..robot import Mounting
from .collect import MALFORMED, Notes, read_regular_bytes
from .mavlink import MavlinkConfig, MavlinkMapper

TLOG_SUFFIXES = (".tlog",)
_MIN_T, _MAX_T = 946_684_800.0, 4_102_444_800.0  # 2000-01-01 and 2100-01-01, Unix s
#: a receive time further than this from both its neighbours' is a damaged timestamp
OUTLIER_S = 3600.0


def _mavlink():
    from pymavlink.dialects.v20 import ardupilotmega

    return ardupilotmega


def _frame_length(data, i: int, mav) -> int | None:
    """Length of the MAVLink frame starting at ``data[i]`` (None if not a frame start or its
    header is cut off): v1 6 + len + 2, v2 10 + len + 2 (+ 13 when signed)."""
    if i + 3 > len(data):
        return None
    magic, payload = data[i], data[i + 1]
    if magic == mav.PROTOCOL_MARKER_V1:
        return mav.HEADER_LEN_V1 + payload + 2
    if magic == mav.PROTOCOL_MARKER_V2:
        signed = data[i + 2] & mav.MAVLINK_IFLAG_SIGNED
        return mav.HEADER_LEN_V2 + payload + 2 + (mav.MAVLINK_SIGNATURE_BLOCK_LEN if signed else 0)
    return None


class TlogScanner:
    """Walks the records of a ``.tlog`` byte string; :meth:`messages` yields (receive time s,
    message name, pymavlink message) for every record whose frame is intact. Messages named in
    ``wanted`` are decoded in full; the others only have their CRC checked (the message is then
    None), which is several times faster. Damage is counted in :attr:`damaged` (regions
    skipped), :attr:`first_damage` (byte offset), :attr:`unknown` (well-framed messages of ids
    the dialect does not know) and :attr:`truncated` (a cut-off last record)."""

    def __init__(self, data: bytes, wanted: Iterable[str] | None = None) -> None:
        self.data = data
        self.mav_module = mav = _mavlink()
        self.mav = mav.MAVLink(None)
        self.mav.robust_parsing = True
        self.wanted_ids = None
        if wanted is not None:
            names = set(wanted)
            self.wanted_ids = {i for i, c in mav.mavlink_map.items() if c.msgname in names}
        self.damaged = 0
        self.first_damage: int | None = None
        self.unknown = 0
        self.truncated = False
        self._next = {mav.PROTOCOL_MARKER_V1: -1, mav.PROTOCOL_MARKER_V2: -1}

    @staticmethod
    def _plausible(t: float) -> bool:
        return _MIN_T <= t <= _MAX_T

    def _try(self, i: int):
        """(t, name or None for an unknown id, message or None, end offset) of a good record at
        i, or None; 'truncated' when a plausible record runs past the end of the data."""
        data, mav = self.data, self.mav_module
        if i + 8 >= len(data):
            return None
        t = struct.unpack_from(">Q", data, i)[0] * 1e-6
        if not self._plausible(t):
            return None
        length = _frame_length(data, i + 8, mav)
        if length is None:
            return None
        end = i + 8 + length
        if end > len(data):
            return "truncated"
        frame = data[i + 8 : end]
        if self.wanted_ids is not None:
            msg_id = frame[5] if frame[0] == mav.PROTOCOL_MARKER_V1 else _v2_id(frame)
            if msg_id not in self.wanted_ids:
                return self._crc_only(t, frame, msg_id, end)
        try:
            msg = self.mav.decode(bytearray(frame))
        except (mav.MAVError, struct.error, ValueError, TypeError, IndexError):
            return None
        if isinstance(msg, mav.MAVLink_unknown) or msg.get_msgId() < 0:
            return t, None, None, end
        return t, msg.get_type(), msg, end

    def _crc_only(self, t: float, frame: bytes, msg_id: int, end: int):
        """The CRC check of pymavlink's decode (x25 over the frame after the magic byte, plus the
        message's crc_extra), without unpacking the payload."""
        mav = self.mav_module
        cls = mav.mavlink_map.get(msg_id)
        if cls is None:
            return t, None, None, end
        signed = frame[0] == mav.PROTOCOL_MARKER_V2 and frame[2] & mav.MAVLINK_IFLAG_SIGNED
        tail = 2 + (mav.MAVLINK_SIGNATURE_BLOCK_LEN if signed else 0)
        if len(frame) < tail + 3:
            return None
        sent = frame[-tail] | (frame[-tail + 1] << 8)
        if mav.x25crc(frame[1:-tail] + bytes([cls.crc_extra])).crc != sent:
            return None
        return t, cls.msgname, None, end

    def _looks_like_record(self, i: int) -> bool:
        if i >= len(self.data):
            return True
        found = self._try(i)
        return found is not None and found != "truncated"

    def messages(self) -> Iterator[tuple[float, str, object]]:
        n, i = len(self.data), 0
        in_damage = False
        while i < n:
            found = self._try(i)
            if found == "truncated":
                self.truncated = True
                break
            if found is not None and (found[1] is not None or self._looks_like_record(found[3])):
                t, name, msg, end = found
                in_damage = False
                i = end
                if name is None:
                    self.unknown += 1
                    continue
                yield t, name, msg
                continue
            if not in_damage:
                self.damaged += 1
                self.first_damage = i if self.first_damage is None else self.first_damage
                in_damage = True
            i = self._next_candidate(i + 1)

    def _next_candidate(self, i: int) -> int:
        """The next offset whose 9th byte is a MAVLink start marker (or the end); the positions
        of the next markers are cached, so a long damaged region is scanned once."""
        data, n = self.data, len(self.data)
        best = n
        for marker, pos in self._next.items():
            if pos < i + 8:
                pos = data.find(bytes([marker]), i + 8)
                self._next[marker] = pos = n + 8 if pos < 0 else pos
            best = min(best, pos - 8)
        return best


def _v2_id(frame: bytes) -> int:
    """The 24-bit message id of a MAVLink 2 frame (header bytes 7-9, little endian)."""
    return frame[7] | (frame[8] << 8) | (frame[9] << 16) if len(frame) >= 10 else -1


def _read_bytes(path: Path) -> bytes:
    data = read_regular_bytes(path)
    if not data:
        raise ReaderError(f"{path}: empty file (no MAVLink records)")
    return data


def looks_like_tlog(head: bytes) -> bool:
    """True when ``head`` (the first bytes of a file) starts with a plausible tlog record."""
    scanner = TlogScanner(head)
    found = scanner._try(0)
    return found is not None and found != "truncated"


def read_tlog(path, config: MavlinkConfig | None = None) -> Log:
    """Read a MAVLink ``.tlog`` into a Log (streams as :class:`MavlinkMapper` maps them)."""
    path = Path(path)
    with np.errstate(all="ignore"):
        return _read_tlog(path, _read_bytes(path), config or MavlinkConfig())


def _read_tlog(path: Path, data: bytes, config: MavlinkConfig) -> Log:
    mapper = MavlinkMapper(config, source=str(path))
    scanner = TlogScanner(data, wanted={*mapper.message_types, "PARAM_VALUE"})
    types, times, kept = Counter(), [], []
    ground = ground_pressure_param(config.pressure)
    params: dict[str, float] = {}
    for t, name, msg in scanner.messages():
        types[name] += 1
        if name == "PARAM_VALUE" and msg is not None:
            _keep_param(msg, ground, params)
        elif msg is not None:
            kept.append((len(times), t, msg))
        times.append(t)
    outliers = _time_outliers(np.array(times))
    records = []
    offsets: dict[str, list[float]] = defaultdict(list)
    for index, t, msg in kept:
        if outliers[index]:
            continue
        name = msg.get_type()
        for record in mapper.records(msg, t, arrival=t):
            records.append(record)
            if math.isfinite(record.sensor_time) and len(offsets[name]) < 100_000:
                offsets[name].append(t - record.sensor_time)
    notes = _notes(path, scanner, mapper, config, np.array(times), outliers)
    if not types:
        raise ReaderError(f"{path}: not a MAVLink telemetry log (no decodable tlog record)")
    if not records:
        seen = ", ".join(f"{k} x{v}" for k, v in types.most_common(6))
        raise ReaderError(
            f"{path}: no usable measurement (need ATTITUDE/SCALED_IMU*, {config.pressure}, "
            f"VISION_POSITION_DELTA or DISTANCE_SENSOR; the log has {seen})"
        )
    metadata = {
        "format": "mavlink_tlog",
        "time_base": "tlog receive time (Unix s)",
        "tlog": {
            "messages": dict(types.most_common()),
            "gyro_source": config.gyro,
            "pressure_message": config.pressure,
            "range_sensor_id": mapper.range_id,
            "clock_offsets_s": _offset_summary(offsets),
        },
    }
    if ground in params:
        metadata["surface_pressure_pa"] = params[ground]
        metadata["surface_pressure_source"] = f"{ground} parameter of the telemetry log"
    log = records_to_log(records, source=str(path), metadata=metadata)
    metadata["warnings"] = notes.finish()
    imu = log.imu
    if imu is not None and imu.orientation is not None and np.isnan(imu.orientation).all():
        log = log.replace(imu=dataclasses.replace(imu, orientation=None))
    return log.replace(mounting=Mounting(dvl=MavlinkMapper.dvl_mount()), metadata=metadata)


def ground_pressure_param(pressure_message: str) -> str:
    """The ArduPilot parameter holding the ground (surface) pressure, Pa, of the barometer a
    SCALED_PRESSURE message reports: SCALED_PRESSURE -> BARO1_GND_PRESS, SCALED_PRESSURE2 ->
    BARO2_GND_PRESS (MAVLink's common.xml: SCALED_PRESSURE2 holds the "readings for 2nd
    barometer"; AP_Baro numbers its parameters from 1 and calibrates ``_GND_PRESS`` at boot)."""
    suffix = pressure_message.removeprefix("SCALED_PRESSURE") or "1"
    return f"BARO{suffix}_GND_PRESS"


def _keep_param(msg, wanted: str, params: dict) -> None:
    """The first finite positive value of the parameter ``wanted`` from a PARAM_VALUE."""
    try:
        name = str(msg.param_id).split("\x00")[0].strip()
        value = float(msg.param_value)
    except (*MALFORMED, UnicodeError):
        return
    if name == wanted and wanted not in params and math.isfinite(value) and 0 < value < 1e7:
        params[wanted] = value


def _notes(path, scanner: TlogScanner, mapper: MavlinkMapper, config, times, outliers) -> Notes:
    """The counted warnings of a read: damage, dropped times, skipped messages."""
    notes = Notes(str(path))
    if scanner.damaged:
        notes.add(
            "damaged records skipped (bad bytes, bad timestamp or CRC)",
            scanner.damaged,
            f"byte {scanner.first_damage}",
        )
    notes.add("truncated last record dropped", int(scanner.truncated))
    notes.add(
        "messages with a receive time an hour off their neighbours' dropped", int(outliers.sum())
    )
    good_times = times[~outliers]
    notes.add(
        "messages with receive time going backwards (sorted by time)",
        int(np.sum(np.diff(good_times) < 0)),
    )
    notes.add("messages of unknown MAVLink ids skipped", scanner.unknown)
    notes.add("messages with unusable fields skipped", mapper.malformed)
    if mapper.ignored_range_ids and config.range_sensor_id is None:  # chosen, not asked for
        ids = ", ".join(map(str, sorted(mapper.ignored_range_ids)))
        notes.add(f"DISTANCE_SENSOR ids other than {mapper.range_id} ignored", 1, f"ids {ids}")
    return notes


def _time_outliers(t: np.ndarray) -> np.ndarray:
    """Rows whose time is more than OUTLIER_S from both neighbours (an end row: from its only
    neighbour, when that one agrees with its own other neighbour)."""
    bad = np.zeros(t.size, bool)
    if t.size < 3:
        return bad
    gap = np.abs(np.diff(t)) > OUTLIER_S
    bad[1:-1] = gap[:-1] & gap[1:]
    bad[0] = gap[0] and not gap[1]
    bad[-1] = gap[-1] and not gap[-2]
    return bad


def _offset_summary(offsets: dict[str, list[float]]) -> dict:
    out = {}
    for name, values in offsets.items():
        v = np.asarray(values)
        v = v[np.isfinite(v)]
        if v.size:
            q = np.percentile(v, [5, 50, 95])
            out[name] = {"median": float(q[1]), "p5_p95_spread": float(q[2] - q[0])}
    return out
