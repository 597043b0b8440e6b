"""Reader of ArduPilot dataflash logs (``.BIN``, and text ``.log``), what every ArduSub vehicle
writes onboard.

Records (framed by :mod:`undertow.io.dataflash_records`, laid out by pymavlink's ``DFReader``
formats) map to streams as ArduPilot logs them (``AP_Logger/LogStructure.h``,
``AP_InertialSensor``, ``AP_Baro``, ``AP_NavEKF3``, ``AP_VisualOdom_Logging.cpp``); every time is
``TimeUS`` (microseconds since the autopilot booted) in seconds:

- ``imu``: ``IMU`` of the lowest instance (GyrX/Y/Z rad/s and AccX/Y/Z m/s^2, body FRD, the
  board orientation applied; the filtered samples at the logging rate). ``GYR`` (raw,
  unfiltered samples at the sensor rate, logged on request) is used only when the log has no
  ``IMU`` (gyro only, timed by its ``SampleUS``). ``orientation``: ``ATT`` (Roll, Pitch, Yaw in
  degrees: the AHRS attitude, NED from body, R = Rz(Yaw) Ry(Pitch) Rx(Roll)) as quaternions
  interpolated to the IMU times by
  :func:`~undertow.io.dataflash_streams.interpolate_orientation`.
- ``pressure``: ``BARO`` Press (Pa) of ArduSub's depth sensor: the instance ``BARO_PRIMARY``
  names (ArduSub makes its first water-type barometer primary at boot, ``ArduSub/system.cpp``);
  without that parameter the instance whose Alt follows Press as water does
  (Alt = (p_gnd - p) / (9800 SG), ``AP_Baro::update``), else the lowest.
  ``metadata['surface_pressure_pa']``: that barometer's ground pressure parameter
  ``BARO{n}_GND_PRESS`` (n = instance + 1), calibrated at boot.
- ``sonar``: ``RFND`` Dist (m) of the lowest downward rangefinder (Orient 25, pitch 270); a
  status other than Good (4) makes the range NaN; limits from ``RNGFND{n}_MIN_CM/MAX_CM``.
- ``dvl``: ``VISO`` (VISION_POSITION_DELTA as the EKF received it: dt s, position change m in
  the body frame, the sensor orientation already applied): v = PosD / dt, valid when conf >=
  :data:`~undertow.io.dataflash_streams.MIN_CONFIDENCE` %. Without VISO, ``VISV`` (a velocity
  in NED, m/s; ``AP_VisualOdom_Logging.cpp``) rotated into the body by the ATT attitude,
  v^B = R^T v^NED (valid unless the EKF ignored it); the metadata says which. The DVL mount
  rotation is zero (the autopilot rotated it) and its lever arm is ``VISO_POS_X/Y/Z`` when the
  log has them.
- ``dead_reckoning``: ``VISP`` (PX, PY, PZ m north-east-down, Roll/Pitch/Yaw deg, PErr m as
  the standard deviation).
- ``gps``: ``GPS`` of the lowest instance, fixes with Status >= 3 (3D) only (no-fix and
  non-finite fixes dropped and counted), projected to north-east-down metres about the first
  good fix or a given origin (``GpsFix.origin``, :func:`undertow.io.geo.local_ned`); ``GPA``
  HAcc (m) as the horizontal standard deviation.
- ``autopilot``: ``XKF1`` of EKF core 0 (``NKF1``, EKF2, in logs without it): PN/PE/PD m,
  Roll/Pitch/Yaw deg, VN/VE/VD m/s.

Units: each field's unit is read from the log's ``FMTU``/``UNIT``/``MULT`` records where present;
a field declared in another unit is converted when the conversion is known (deg <-> rad,
deg/s <-> rad/s) and its records refused otherwise, each with one warning line.

Damage (untrusted input): damaged regions, a truncated last record, records whose fields do not
decode and times an hour away from both neighbours are skipped and counted, one warning per
kind, the good records kept; a file with nothing usable is one ReaderError line.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from ..errors import ReaderError
from ..log import Log
from ..robot import Mounting
from .collect import MALFORMED, Notes, read_regular_bytes
from .dataflash_records import (
    BinaryScanner,
    Columns,
    TextScanner,
    looks_like_dataflash,
    text_field,
)
from .dataflash_streams import StreamBuilder

DATAFLASH_SUFFIXES = (".bin",)
#: a record time further than this from both its neighbours' is a damaged time (s)
OUTLIER_S = 3600.0

#: the columns read per message and the unit each must have (ArduPilot's UNIT labels; None:
#: an id or flag). Columns marked "?" may be absent (older or newer layouts).
FIELDS: dict[str, tuple[tuple[str, str | None], ...]] = {
    "IMU": (("TimeUS", "s"), ("I?", None), *((f"Gyr{a}", "rad/s") for a in "XYZ"),
            *((f"Acc{a}", "m/s/s") for a in "XYZ")),
    "GYR": (("TimeUS", "s"), ("I?", None), ("SampleUS?", "s"),
            *((f"Gyr{a}", "rad/s") for a in "XYZ")),
    "ATT": (("TimeUS", "s"), ("Roll", "deg"), ("Pitch", "deg"), ("Yaw", "deg")),
    "BARO": (("TimeUS", "s"), ("I?", None), ("Press", "Pa"), ("Alt?", "m")),
    "RFND": (("TimeUS", "s"), ("Instance?", None), ("Dist", "m"), ("Stat?", None),
             ("Orient?", None), ("Qual?", None)),
    "VISO": (("TimeUS", "s"), ("dt", "s"), *((f"PosD{a}", "m") for a in "XYZ"), ("conf", None)),
    "VISP": (("TimeUS", "s"), *((f"P{a}", "m") for a in "XYZ"), ("Roll", "deg"),
             ("Pitch", "deg"), ("Yaw", "deg"), ("PErr?", "m"), ("Rst?", None)),
    "VISV": (("TimeUS", "s"), *((f"V{a}", "m/s") for a in "XYZ"), ("VErr?", "m/s"),
             ("Ign?", None)),
    "GPS": (("TimeUS", "s"), ("I?", None), ("Status", None), ("Lat", "deg"), ("Lng", "deg"),
            ("Alt", "m")),
    "GPA": (("TimeUS", "s"), ("I?", None), ("HAcc", "m")),
    "XKF1": (("TimeUS", "s"), ("C?", None), ("Roll", "deg"), ("Pitch", "deg"), ("Yaw", "deg"),
             *((f"V{a}", "m/s") for a in "NED"), *((f"P{a}", "m") for a in "NED")),
}  # fmt: skip
FIELDS["NKF1"] = FIELDS["XKF1"]
_TEXT_MESSAGES = ("PARM", "MSG", "VER")
#: the same quantity under another label: factor to the expected unit
_CONVERSIONS = {
    ("deg/s", "rad/s"): math.pi / 180.0,
    ("rad", "deg"): 180.0 / math.pi,
    ("deg", "rad"): math.pi / 180.0,
    ("degheading", "deg"): 1.0,
    ("deglatitude", "deg"): 1.0,
    ("deglongitude", "deg"): 1.0,
}
#: fields whose declared multiplier ArduPilot does not apply when writing: VISO.dt is declared
#: in 1e-6 s but written in s (AP_VisualOdom_Backend: time_delta_usec / 1e6)
_WRITTEN_UNSCALED = {("VISO", "dt")}
#: times are microseconds since boot by ArduPilot's definition of these columns, whatever a
#: (possibly damaged) declaration says
_MICROSECONDS = ("TimeUS", "SampleUS")


def read_dataflash(path, gps_origin=None) -> Log:
    """Read an ArduPilot dataflash log (binary or text) into a Log (see the module docstring);
    ``gps_origin`` (lat deg, lon deg, alt m): the origin of the GPS fixes' local frame (default
    the first 3D fix)."""
    path = Path(path)
    data = read_regular_bytes(path)
    if not data:
        raise ReaderError(f"{path}: empty file (no dataflash records)")
    kind = looks_like_dataflash(data[:8192]) or "binary"
    with np.errstate(all="ignore"):
        return _Reader(path, data, kind, gps_origin).read()


class _Reader:
    def __init__(self, path: Path, data: bytes, kind: str, gps_origin=None) -> None:
        self.path, self.kind, self.gps_origin = path, kind, gps_origin
        wanted = (*FIELDS, *_TEXT_MESSAGES)
        if kind == "binary":
            self.scanner = BinaryScanner(data, wanted)
        else:
            self.scanner = TextScanner(data.decode("utf-8", errors="replace"), wanted)
        self.scan = self.scanner.scan
        self.notes = Notes(str(path))
        self.rows: dict[str, list] = {name: [] for name in FIELDS}
        self.params: dict[str, float] = {}
        self.param_changes: dict[str, list] = {}
        self.texts: list[str] = []
        self.version: dict[str, str] = {}
        self.info: dict = {"kind": kind}

    # -- reading -----------------------------------------------------------------------------

    def read(self) -> Log:
        self._collect()
        if not self.scan.counts.get("FMT"):
            raise ReaderError(f"{self.path}: not an ArduPilot dataflash log (no FMT record)")
        tables = {name: self._table(name) for name in FIELDS}
        streams = self._streams(tables)
        if not streams:
            seen = ", ".join(f"{k} x{v}" for k, v in self.scan.counts.most_common(8))
            raise ReaderError(
                f"{self.path}: no usable measurement (need IMU/GYR, BARO, ATT, RFND, VISO/VISP/"
                f"VISV, GPS or XKF1 records; the log has {seen or 'none'})"
            )
        self._damage_notes()
        metadata = self._metadata()
        metadata["warnings"] = self.notes.finish()
        return Log(**streams, mounting=self._mounting(), source=str(self.path),
                   metadata=metadata)  # fmt: skip

    def _collect(self) -> None:
        text, cache = self.kind == "text", {}
        for fmt, elements in self.scanner.records():
            name = fmt.name
            if name in self.rows:
                entry = cache.get(id(fmt))
                if entry is None or entry[0] is not fmt:
                    entry = cache[id(fmt)] = (fmt, self._columns(fmt, text))
                if entry[1] is None:
                    continue
                try:
                    self.rows[name].append(entry[1](elements))
                except MALFORMED:
                    self.scan.bad_records += 1
            else:
                self._text_record(fmt, elements)

    def _columns(self, fmt, text: bool) -> Columns | None:
        """The extractor of ``fmt``'s columns of :data:`FIELDS`; None (noted) when it lacks one
        that is not optional."""
        names = [c.rstrip("?") for c, _ in FIELDS[fmt.name]]
        missing = [c for c, _ in FIELDS[fmt.name] if not c.endswith("?") and c not in fmt.colhash]
        if missing:
            self.notes.add(f"{fmt.name} records without {', '.join(missing)} skipped", 1)
            return None
        return Columns(fmt, tuple(names), text)

    def _text_record(self, fmt, elements) -> None:
        try:
            if fmt.name == "PARM":
                name = text_field(fmt, elements, "Name")
                value = float(elements[fmt.colhash["Value"]])
                self.params.setdefault(name, value)  # the value in effect when the log began
                if name.endswith("_GND_PRESS"):
                    t = float(elements[fmt.colhash["TimeUS"]]) * 1e-6
                    self.param_changes.setdefault(name, []).append([t, value])
            elif fmt.name == "MSG":
                self.texts.append(text_field(fmt, elements, "Message"))
            elif fmt.name == "VER":
                for key in ("FWS", "BU"):
                    if key in fmt.colhash:
                        self.version[key] = text_field(fmt, elements, key)
        except MALFORMED:
            self.scan.bad_records += 1

    def _table(self, name: str) -> np.ndarray | None:
        """The rows of ``name`` (n, columns) in :data:`FIELDS` units, time outliers dropped;
        None when there are none or a unit is refused."""
        rows = self.rows[name]
        if not rows:
            return None
        table = np.array(rows, dtype=np.float64)
        for j, (column, expected) in enumerate(FIELDS[name]):
            factor = self._unit_factor(name, column.rstrip("?"), expected)
            if factor is None:
                return None
            if factor != 1.0:
                table[:, j] *= factor
        outliers = _isolated_times(table[:, 0])
        self.notes.add(f"{name}: records with a time an hour off their neighbours' dropped",
                       int(outliers.sum()))  # fmt: skip
        return table[~outliers] if not outliers.all() else None

    def _unit_factor(self, name: str, column: str, expected: str | None) -> float | None:
        """Factor taking ``name.column`` as written to ``expected`` (the log's declaration when
        it has one, else ArduPilot's); None (with a warning) when the declared unit is another
        quantity."""
        if column in _MICROSECONDS:
            return 1e-6
        declared = self.scan.unit(name, column)
        if declared is None or expected is None:
            return 1.0
        label, mult = declared
        if (name, column) in _WRITTEN_UNSCALED:
            mult = 1.0
        if label in ("", "UNKNOWN", expected):
            return mult
        conversion = _CONVERSIONS.get((label, expected))
        if conversion is None:
            self.notes.add(f"{name}.{column}: unit '{label}' in the log, expected {expected}: "
                           f"{name} records not used", 1)  # fmt: skip
            return None
        if conversion != 1.0:
            self.notes.add(f"{name}.{column}: unit '{label}' in the log, converted to "
                           f"{expected}", 1)  # fmt: skip
        return mult * conversion

    # -- streams -------------------------------------------------------------------------------

    def _streams(self, tables: dict) -> dict:
        self.builder = StreamBuilder(self.notes, self.params, self.gps_origin)
        return self.builder.build(tables)

    # -- metadata ------------------------------------------------------------------------------

    def _damage_notes(self) -> None:
        scan, notes, text = self.scan, self.notes, self.kind == "text"
        where = f"{'line' if text else 'byte'} {scan.first_damage}"
        what = "lines of no known format skipped" if text else "damaged regions skipped"
        notes.add(what, scan.damaged, where)
        notes.add("truncated last record dropped", int(scan.truncated))
        notes.add("FMT records with unknown format characters or lengths skipped",
                  scan.bad_formats)  # fmt: skip
        notes.add("records with fields that do not decode skipped", scan.bad_records)

    def _metadata(self) -> dict:
        info = {**self.info, **self.builder.info}
        info["messages"] = dict(self.scan.counts.most_common())
        info["units"] = (
            "checked against the log's FMTU/UNIT/MULT records"
            if self.scan.unit_ids
            else "as ArduPilot's LogStructure.h declares them (the log has no FMTU records)"
        )
        info["trailing_bytes"] = self.scan.trailing_bytes
        kept = ("BARO", "VISO_", "EK3_SRC", "RNGFND1_", "AHRS_EKF_TYPE", "AHRS_ORIENTATION")
        info["parameters"] = {k: self.params[k] for k in sorted(self.params) if k.startswith(kept)}
        changed = {k: v for k, v in self.param_changes.items() if len(v) > 1}
        if changed:  # (e.g. the ground pressure recalibrated on disarming)
            info["parameter_changes"] = changed
        metadata = {"format": "dataflash", "time_base": "TimeUS (microseconds since boot) in s"}
        firmware = self.version.get("FWS") or _firmware(self.texts)
        if firmware:
            metadata["firmware"] = firmware
            metadata["vehicle"] = firmware.split()[0]
        if self.builder.surface is not None:
            metadata["surface_pressure_pa"] = float(self.builder.surface[0])
            metadata["surface_pressure_source"] = self.builder.surface[1]
        metadata["dataflash"] = info
        if self.builder.gps_origin_used is not None:
            metadata["gps_origin"] = list(self.builder.gps_origin_used)
        return metadata

    def _mounting(self) -> Mounting:
        """The BlueROV2 defaults, the DVL's rotation zero (the autopilot applied VISO_ORIENT),
        the lever arms of the log's VISO_POS_*, RNGFND1_POS_* and INS_POS1_* parameters."""
        changes: dict = {"dvl": {"rotation": (0.0, 0.0, 0.0)}}
        for sensor, prefix in (("dvl", "VISO_POS_"), ("sonar", "RNGFND1_POS_"),
                               ("imu", "INS_POS1_")):  # fmt: skip
            xyz = [self.params.get(prefix + axis, math.nan) for axis in "XYZ"]
            if all(math.isfinite(v) for v in xyz):
                changes.setdefault(sensor, {})["translation"] = tuple(xyz)
        return Mounting().updated(changes)


def _isolated_times(t: np.ndarray) -> np.ndarray:
    """Rows (in file order) whose time is more than OUTLIER_S from both neighbours' (an end
    row: from its only neighbour, when that one agrees with its own other neighbour)."""
    bad = np.zeros(t.size, bool)
    if t.size < 3:
        return bad
    gap = ~(np.abs(np.diff(t)) <= OUTLIER_S)
    bad[1:-1] = gap[:-1] & gap[1:]
    bad[0] = gap[0] and not gap[1]
    bad[-1] = gap[-1] and not gap[-2]
    return bad | ~np.isfinite(t)


def _firmware(texts: list[str]) -> str | None:
    """The firmware line of the log's MSG records (e.g. 'ArduSub V4.1.0 (89639005)')."""
    for text in texts:
        if re.match(r"^(Ardu\w+|APM:\w+)\s+V?\d", text):
            return text.strip()
    return None
