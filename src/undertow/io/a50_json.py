"""Reader of the Water Linked DVL A50 TCP JSON protocol (one JSON object per line).

Supported reports (Water Linked DVL protocol documentation, JSON protocol over TCP port 16171):

- velocity reports: json_v1 (no ``type`` field) and json_v2/v3 (``type: "velocity"``, with a
  3x3 ``covariance`` in (m/s)^2 and ``time_of_validity``/``time_of_transmission`` in Unix
  microseconds); become a :class:`~undertow.log.Dvl` stream;
- ``position_local`` dead-reckoning reports (``ts`` Unix s, ``x y z`` m, ``std`` m,
  ``roll pitch yaw`` in DEGREES, converted to radians); become a
  :class:`~undertow.log.DeadReckoning` stream.

Time: ``time_of_validity`` when every velocity report has it; otherwise (json_v1 has no
absolute time) the cumulative sum of the ``time`` field (ms since the previous report) in
seconds, starting at 0 -- ``Log.metadata['time_base']`` says which. Exact duplicate lines (the
real v1 log repeats lines) are dropped and malformed lines skipped (anything that does not decode
to a report with numeric fields: broken or absurdly nested JSON, numbers too large for a float,
non-finite beam ids), each kind with one counted warning naming its first line; a stream whose
every time is non-finite is dropped with a warning; a file with nothing usable is one
:class:`~undertow.errors.ReaderError` line.
The module also formats velocity reports (json_v3) for the bag writer.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import ReaderError
from ..log import DeadReckoning, Dvl, Log
from .collect import (
    MALFORMED,
    DvlRows,
    Notes,
    beam_columns,
    check_regular,
    count_nan_rows,
    report_altitude,
    time_order,
)

JSON_SUFFIXES = (".txt", ".json", ".jsonl", ".log")


def is_velocity_report(obj: dict) -> bool:
    return obj.get("type", "velocity") == "velocity" and "vx" in obj


def is_position_report(obj: dict) -> bool:
    return obj.get("type") == "position_local"


def report_covariance(obj: dict):
    """A report's ``covariance`` field as a 3 x 3 array; None when absent or not 3 x 3."""
    cov = obj.get("covariance")
    if cov is None:
        return None
    arr = np.asarray(cov, dtype=np.float64)
    return arr if arr.shape == (3, 3) else None


#: largest ``time`` field (ms since the previous report) taken as sent: a day
MAX_REPORT_INTERVAL_MS = 86_400_000.0


def add_velocity_report(rows: DvlRows, obj: dict, t: float) -> None:
    """Append one velocity report (raises one of ``_collect.MALFORMED`` when malformed; a
    ``time`` field that is not a number of ms in [0, a day] is malformed: summed into the json_v1
    time base, one absurd value would push every later report out of the log)."""
    time_ms = _report_time_ms(obj)
    tov = obj.get("time_of_validity")
    rows.append(
        t,
        (float(obj["vx"]), float(obj["vy"]), float(obj["vz"])),
        bool(obj.get("velocity_valid", True)),
        fom=float(obj.get("fom", math.nan)),
        covariance=report_covariance(obj),
        altitude=float(obj.get("altitude", math.nan)),
        beams=_beams(obj),
        raw_altitude=float(obj.get("altitude", math.nan)),
        time_of_validity=math.nan if tov is None else float(tov) * 1e-6,
        time_ms=time_ms,
    )


def velocity_fields(obj: dict) -> tuple[dict, float]:
    """(the fields of a ``dvl`` record, time of validity s or NaN) of one velocity report: what
    :func:`add_velocity_report` appends, as plain values (the same checks and quirks)."""
    _report_time_ms(obj)
    tov = obj.get("time_of_validity")
    velocity = (float(obj["vx"]), float(obj["vy"]), float(obj["vz"]))
    cov = report_covariance(obj)
    rng, ok, vel = beam_columns(_beams(obj))
    fields = {
        "velocity": velocity,
        "valid": bool(obj.get("velocity_valid", True)),
        "fom": float(obj.get("fom", math.nan)),
        "covariance": np.full((3, 3), np.nan) if cov is None else cov,
        "altitude": report_altitude(float(obj.get("altitude", math.nan))),
        "beam_range": tuple(rng),
        "beam_valid": tuple(ok),
        "beam_velocity": tuple(vel),
    }
    return fields, math.nan if tov is None else float(tov) * 1e-6


def _report_time_ms(obj: dict) -> float:
    time_ms = float(obj.get("time", math.nan))
    if "time" in obj and not 0.0 <= time_ms <= MAX_REPORT_INTERVAL_MS:
        raise ValueError(f"time field {time_ms} is not a report interval in ms")
    return time_ms


def _beams(obj: dict) -> list[tuple]:
    return [
        (b["id"], float(b["velocity"]), float(b["distance"]), bool(b.get("beam_valid", True)))
        for b in obj.get("transducers", [])
    ]


def position_row(obj: dict) -> tuple:
    """(ts, x, y, z, std, roll, pitch, yaw) in s, m, rad from a ``position_local`` report."""
    deg = [float(obj[k]) for k in ("roll", "pitch", "yaw")]
    return (
        float(obj["ts"]),
        float(obj["x"]),
        float(obj["y"]),
        float(obj["z"]),
        float(obj.get("std", math.nan)),
        *np.deg2rad(deg),
    )


def position_fields(obj: dict) -> tuple[dict, float]:
    """(the fields of a ``dead_reckoning`` record, the report's ``ts`` s) of one
    ``position_local`` report: :func:`position_row` as a record's fields."""
    ts, x, y, z, std, roll, pitch, yaw = position_row(obj)
    return {"position": (x, y, z), "orientation": (roll, pitch, yaw), "std": std}, ts


def dead_reckoning_from_rows(rows: list[tuple], notes: Notes) -> DeadReckoning | None:
    """A time-ordered DeadReckoning stream from :func:`position_row` tuples (None, with a note,
    when no row has a finite time)."""
    arr = np.array(rows, dtype=np.float64).reshape(-1, 8)
    order = time_order(arr[:, 0], "dead_reckoning", notes)
    if order.size == 0:
        notes.add("dead_reckoning: no report with a finite time (stream dropped)")
        return None
    arr = arr[order]
    count_nan_rows(notes, "dead_reckoning", arr[:, [1, 2, 3, 5, 6, 7]])  # std is optional
    return DeadReckoning(t=arr[:, 0], position=arr[:, 1:4], orientation=arr[:, 5:8], std=arr[:, 4])


def _read_lines(path: Path) -> list[str]:
    if not path.exists():
        raise ReaderError(f"{path}: no such file")
    check_regular(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise ReaderError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    except MemoryError:
        raise ReaderError(f"{path}: too large to read into memory") from None
    if not text.strip():
        raise ReaderError(f"{path}: empty file (no JSON reports)")
    return text.splitlines()


def read_a50_json(path) -> Log:
    """Read a Water Linked TCP JSON log (json_v1/v2/v3) into a Log."""
    with np.errstate(all="ignore"):  # overflow to inf is counted as NaN/non-finite, not warned
        return _read_a50_json(Path(path))


def _read_a50_json(path: Path) -> Log:
    lines = _read_lines(path)
    notes = Notes(str(path))
    seen: set[str] = set()
    velocity: list[tuple[int, dict]] = []
    positions: list[tuple] = []
    bad_lines: list[int] = []
    duplicates = 0
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if not text:
            continue
        if text in seen:
            duplicates += 1
            continue
        seen.add(text)
        try:
            obj = json.loads(text)
            if is_position_report(obj):
                positions.append(position_row(obj))
            elif is_velocity_report(obj):
                add_velocity_report(DvlRows(), obj, 0.0)  # validates the report
                velocity.append((number, obj))
            elif not isinstance(obj, dict) or "type" not in obj:
                raise ValueError("not a DVL report")
        except MALFORMED:
            bad_lines.append(number)
    notes.add("exact duplicate lines dropped", duplicates)
    if bad_lines:
        shown = ", ".join(map(str, bad_lines[:5])) + (" ..." if len(bad_lines) > 5 else "")
        notes.add("malformed lines skipped", len(bad_lines), f"line {shown}")
    if not velocity and not positions:
        raise ReaderError(f"{path}: no readable Water Linked JSON report (line {bad_lines[0]})")
    metadata: dict = {"format": "waterlinked_tcp_json"}
    dvl = _dvl_from_reports(velocity, notes, metadata) if velocity else None
    dead_reckoning = dead_reckoning_from_rows(positions, notes) if positions else None
    if dvl is None and dead_reckoning is None:
        raise ReaderError(f"{path}: no report with a finite time (every stream dropped)")
    metadata["warnings"] = notes.finish()
    return Log(dvl=dvl, dead_reckoning=dead_reckoning, source=str(path), metadata=metadata)


def _dvl_from_reports(reports: list[tuple[int, dict]], notes: Notes, metadata: dict) -> Dvl | None:
    formats = sorted({str(obj.get("format", "json_v1")) for _, obj in reports})
    metadata["json_formats"] = formats
    tov = [obj.get("time_of_validity") for _, obj in reports]
    if all(v is not None for v in tov):
        t = np.array(tov, dtype=np.float64) * 1e-6
        metadata["time_base"] = "time_of_validity (Unix s)"
    else:
        ms = np.array([float(obj.get("time", math.nan)) for _, obj in reports])
        ms = np.where(np.isfinite(ms), ms, 0.0)
        t = (np.cumsum(ms) - ms[0]) * 1e-3
        metadata["time_base"] = (
            "cumulative sum of the 'time' field (ms since previous report), seconds from 0; "
            "no absolute time in this log"
        )
    rows = DvlRows()
    for (_, obj), ti in zip(reports, t, strict=True):
        add_velocity_report(rows, obj, float(ti))
    count_nan_rows(notes, "dvl altitude", np.array(rows.extra["raw_altitude"]))
    dvl, _ = rows.build(notes)
    return dvl if len(dvl) else None


class VelocityReport(NamedTuple):
    """One json_v3 velocity report's values as the A50 sends them (plain Python values): the
    protocol's invalid markers in place (NaN altitude -> -1, an invalid beam's distance -> -1);
    ``beams`` four (id, velocity, distance, valid); ``covariance`` 3 rows of 3; times: ``time_ms``
    since the previous report, ``tov_us`` the time of validity in Unix us."""

    time_ms: float
    velocity: tuple[float, float, float]
    fom: float
    covariance: list
    altitude: float
    beams: tuple
    valid: bool
    tov_us: int


def velocity_report(dvl: Dvl, i: int, time_ms: float, time_of_validity_s: float) -> VelocityReport:
    """Row ``i`` of ``dvl`` as a :class:`VelocityReport`."""
    altitude = float(dvl.altitude[i])
    ok = dvl.beam_valid[i].tolist()
    ids, vel, dist = dvl.beam_id[i].tolist(), dvl.beam_velocity[i], dvl.beam_range[i]
    return report_values(
        time_ms, dvl.velocity[i].tolist(), float(dvl.fom[i]), dvl.covariance[i].tolist(),
        altitude, [(int(ids[k]), float(vel[k]), float(dist[k]), bool(ok[k])) for k in range(4)],
        bool(dvl.valid[i]), time_of_validity_s,
    )  # fmt: skip


def report_values(time_ms, velocity, fom, covariance, altitude, beams, valid,
                  time_of_validity_s) -> VelocityReport:  # fmt: skip
    """A :class:`VelocityReport` of plain values: ``beams`` (id, velocity, distance, valid) with
    the distance as measured (-1 written for an invalid beam), ``altitude`` NaN when unknown."""
    return VelocityReport(
        float(time_ms),
        tuple(velocity),
        fom,
        covariance,
        altitude if math.isfinite(altitude) else -1.0,
        tuple((bid, bvel, dist if ok else -1.0, ok) for bid, bvel, dist, ok in beams),
        valid,
        int(round(time_of_validity_s * 1e6)),
    )


def report_line(r: VelocityReport) -> str:
    """The json_v3 line of a :class:`VelocityReport` (NaN values written as ``NaN``)."""
    vx, vy, vz = r.velocity
    report = {
        "time": r.time_ms,
        "vx": vx,
        "vy": vy,
        "vz": vz,
        "fom": r.fom,
        "covariance": r.covariance,
        "altitude": r.altitude,
        "transducers": [
            {
                "id": bid,
                "velocity": bvel,
                "distance": dist,
                "rssi": math.nan,
                "nsd": math.nan,
                "beam_valid": ok,
            }
            for bid, bvel, dist, ok in r.beams
        ],
        "velocity_valid": r.valid,
        "status": 0,
        "format": "json_v3",
        "type": "velocity",
        "time_of_validity": r.tov_us,
        "time_of_transmission": r.tov_us,
    }
    return json.dumps(report)


def velocity_report_line(dvl: Dvl, i: int, time_ms: float, time_of_validity_s: float) -> str:
    """Row ``i`` of ``dvl`` as a json_v3 velocity report line (as the A50 sends it).

    NaN altitude is written as -1 and the distance of an invalid beam as -1 (the protocol's
    invalid markers); other NaN values are written as ``NaN``.
    """
    return report_line(velocity_report(dvl, i, time_ms, time_of_validity_s))
