"""DVL messages of the field, read by the meaning of their fields: one table row per type.

Every ROS DVL message carries the same few quantities under different names: a velocity
(``geometry_msgs/Vector3``, m/s, in the DVL frame unless the header says otherwise), its
validity (a flag, a mode, or a covariance of -1), a 3x3 covariance ((m/s)^2, row-major), an
altitude (m), and per-beam values (radial velocity, range, validity; beam unit vectors where the
message has them). :data:`DVL_TYPES` says where each type keeps them; :func:`dvl_report` reads
one message into the arguments of :meth:`undertow.io.collect.DvlRows.append`. A new type with
the same meanings under other names is one more row of the table.

Conventions of the sources (their message files):

- Water Linked (``waterlinked_a50_ros_driver/DVL``, ``dvl_msgs/DVL``): ``velocity_valid``;
  ``fom``; beams with ids 0-3 (A50 geometry), ``distance``, ``valid``; ``dvl_msgs`` adds a 3x3
  ``covariance`` (a variable-length array: empty means unknown).
- UUV Simulator / COLA2 (``uuv_sensor_ros_plugins_msgs/DVL``, ``cola2_msgs/DVL``): "If the
  covariance is known, it should be filled. If it is unknown, it should be set to all zeros. If
  a measurement was invalid, its covariance should be set to -1"; beams ``range`` (< 0 invalid),
  ``velocity``, in order.
- ``marine_acoustic_msgs/Dvl`` and WHOI's ``ds_sensor_msgs/Dvl``: ``velocity_mode`` (0: not
  set), ``velocity_covar`` (-1: unknown), ``beam_unit_vec``, ``range``; the beam velocities
  (``beam_velocity``; ds's ``raw_velocity`` only when ``coordinate_mode`` is 0, beam
  coordinates), ``num_good_beams``; the sound speed the DVL converted with (``sound_speed``,
  ds's ``speed_sound``), which :mod:`undertow.io.sound_speed` takes as the DVL's setting.
- A body velocity as ``geometry_msgs/TwistWithCovarianceStamped`` (6x6 covariance, its
  top-left 3x3 the linear velocity's) or ``TwistStamped``: valid when finite.

A covariance that is all zeros or all -1 is unknown (NaN); the UUV convention's -1 also makes the
report invalid. A validity flag is kept as reported (as the velocity is, whatever the flag); a type
without one is valid when its velocity is finite (and, with a mode, the mode is set).
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass

import numpy as np

from .msgdefs import A50_DVL, COLA2_DVL, DS_DVL, MARINE_DVL, UUV_DVL, WL_DVL

TWIST_COV = "geometry_msgs/msg/TwistWithCovarianceStamped"
TWIST = "geometry_msgs/msg/TwistStamped"


@dataclass(frozen=True)
class DvlFields:
    """Where one DVL message type keeps each quantity (dotted attribute paths; None: absent).

    ``valid``: a bool field; ``mode``: a velocity mode whose 0 means "not set" (invalid);
    ``invalid_covariance``: a covariance of all -1 marks an invalid report (UUV convention);
    ``beams``: a sequence of beam messages with ``beam_velocity``/``beam_range``/``beam_valid``/
    ``beam_id`` fields (``beam_id`` None: beams in order); ``beam_units``/``ranges``/
    ``beam_velocities``/``ranges_valid``: per-beam arrays of a message without beam messages.
    ``beam_velocity_if``: (field, value) under which ``beam_velocities`` are beam-coordinate."""

    velocity: str = "velocity"
    valid: str | None = None
    mode: str | None = None
    covariance: str | None = None
    invalid_covariance: bool = False
    fom: str | None = None
    altitude: str | None = "altitude"
    beams: str | None = None
    beam_id: str | None = None
    beam_velocity: str = "velocity"
    beam_range: str = "distance"
    beam_valid: str | None = None
    beam_units: str | None = None
    ranges: str | None = None
    ranges_valid: str | None = None
    beam_velocities: str | None = None
    beam_velocity_if: tuple[str, int] | None = None
    good_beams: str | None = None
    #: the message's ``time`` field, kept to match the raw JSON topic's reports
    report_time: str | None = None
    #: the sound speed the DVL converted with (m/s; NaN or absent: not said)
    sound_speed: str | None = None


_WL = {"valid": "velocity_valid", "fom": "fom", "beams": "beams", "beam_id": "id",
       "beam_valid": "valid", "report_time": "time"}  # fmt: skip
_UUV = {"covariance": "velocity_covariance", "invalid_covariance": True, "beams": "beams",
        "beam_range": "range"}  # fmt: skip
_MARINE = {"mode": "velocity_mode", "covariance": "velocity_covar", "beam_units": "beam_unit_vec",
           "ranges": "range", "good_beams": "num_good_beams"}  # fmt: skip

#: message type -> where its fields are
DVL_TYPES: dict[str, DvlFields] = {
    A50_DVL: DvlFields(**_WL),
    WL_DVL: DvlFields(**_WL, covariance="covariance"),
    UUV_DVL: DvlFields(**_UUV),
    COLA2_DVL: DvlFields(**_UUV),
    MARINE_DVL: DvlFields(
        **_MARINE,
        ranges_valid="beam_ranges_valid",
        beam_velocities="beam_velocity",
        sound_speed="sound_speed",
    ),  # fmt: skip
    DS_DVL: DvlFields(
        **_MARINE,
        beam_velocities="raw_velocity",
        beam_velocity_if=("coordinate_mode", 0),
        sound_speed="speed_sound",
    ),  # fmt: skip
    TWIST_COV: DvlFields(
        velocity="twist.twist.linear", covariance="twist.covariance", altitude=None
    ),  # fmt: skip
    TWIST: DvlFields(velocity="twist.linear", altitude=None),
}


def _get(msg, path: str | None, default=None):
    if path is None:
        return default
    try:
        return operator.attrgetter(path)(msg)
    except AttributeError:  # a bag's own (older or newer) definition without this field
        return default


def _covariance(values) -> tuple[np.ndarray | None, bool]:
    """(3x3 covariance or None when unknown, whether it is the all -1 "invalid" marker) of a
    row-major 9-vector or 6x6 (top-left block)."""
    if values is None:
        return None, False
    c = np.asarray(values, dtype=np.float64).reshape(-1)
    if c.size == 36:
        c = c.reshape(6, 6)[:3, :3].reshape(-1)
    if c.size != 9:
        return None, False
    if np.all(c == -1):
        return None, True
    if np.all(c == 0):
        return None, False
    return c.reshape(3, 3), False


def dvl_report(msgtype: str, msg) -> dict:
    """The arguments of ``DvlRows.append`` (all but the time) of one message of a type in
    :data:`DVL_TYPES`; ``extra`` keys ``good_beams`` (when the message counts them) and ``key``
    (Water Linked: its report time and velocity, to match the raw JSON)."""
    f = DVL_TYPES[msgtype]
    v = _get(msg, f.velocity)
    velocity = (float(v.x), float(v.y), float(v.z))
    finite = all(math.isfinite(x) for x in velocity)
    cov, marked_invalid = _covariance(_get(msg, f.covariance))
    # a validity flag is kept as the sensor reported it (the velocity too, whatever the flag);
    # a message without one is valid when its velocity is finite
    valid = bool(_get(msg, f.valid, True)) if f.valid is not None else finite
    if f.mode is not None:
        valid = valid and int(_get(msg, f.mode, 0)) != 0
    if f.invalid_covariance and marked_invalid:
        valid = False
    report = {
        "velocity": velocity,
        "valid": valid,
        "fom": float(_get(msg, f.fom, math.nan)),
        "covariance": cov,
        "altitude": float(_get(msg, f.altitude, math.nan)),
    }
    report.update(_beams(f, msg))
    extra = {}
    if f.mode is not None:
        extra["mode_given"] = int(_get(msg, f.mode, 0)) != 0
    if f.good_beams is not None:
        extra["good_beams"] = int(_get(msg, f.good_beams, 0))
    if f.report_time is not None:
        extra["key"] = (_get(msg, f.report_time), *velocity)
    if f.sound_speed is not None:
        extra["sound_speed"] = float(_get(msg, f.sound_speed, math.nan))
    report["extra"] = extra
    return report


def _beams(f: DvlFields, msg) -> dict:
    """``beams`` (id, radial velocity, range, valid) and, for messages with beam unit vectors,
    ``beam_units`` (4, 3)."""
    if f.beams is not None:
        out = []
        for k, b in enumerate(_get(msg, f.beams, ()) or ()):
            bid = int(_get(b, f.beam_id, k)) if f.beam_id else k
            rng = float(_get(b, f.beam_range, math.nan))
            ok = bool(_get(b, f.beam_valid, True)) if f.beam_valid else rng >= 0
            out.append((bid, float(_get(b, f.beam_velocity, math.nan)), rng, ok))
        return {"beams": out}  # without ids: in order, with the DVL geometry of the log
    if f.beam_units is None:
        return {"beams": []}
    units = np.array([(u.x, u.y, u.z) for u in _get(msg, f.beam_units)], dtype=np.float64)
    rng = np.asarray(_get(msg, f.ranges), dtype=np.float64)
    ok = np.isfinite(rng) & (rng > 0)
    if f.ranges_valid is not None:
        ok &= bool(_get(msg, f.ranges_valid, True))
    vel = np.full(rng.shape, np.nan)
    raw = _get(msg, f.beam_velocities)
    beam_coordinates = f.beam_velocity_if is None or (
        _get(msg, f.beam_velocity_if[0]) == f.beam_velocity_if[1]
    )
    if raw is not None and beam_coordinates:
        vel = np.asarray(raw, dtype=np.float64)
    beams = list(zip(range(len(rng)), vel, rng, ok, strict=True))
    return {"beams": beams, "beam_units": units}
