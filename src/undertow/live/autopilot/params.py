"""The autopilot parameters that decide whether EKF3 uses undertow: read at connect
(PARAM_REQUEST_READ), compared with what the chosen mode needs, printed as exactly what to set,
and set on request (``--set-params``: PARAM_SET, each checked by the PARAM_VALUE the autopilot
answers with; never by default).

The values and why (ArduPilot's parameter documentation in its source: AP_AHRS.cpp,
AP_NavEKF3.cpp, AP_NavEKF_Source.cpp, AP_VisualOdom.cpp, AP_GPS.cpp; "reboot" where it says
``@RebootRequired: True``):

==================  =====  ======  ==========================================================
parameter           value  reboot  why
==================  =====  ======  ==========================================================
AHRS_EKF_TYPE       3              EKF3 is the navigation filter the vehicle flies on
EK3_ENABLE          1      yes     EKF3 runs
VISO_TYPE           1      yes     the MAVLink visual-odometry backend takes the messages
GPS1_TYPE           0      yes     no GPS under water (GPS_TYPE before ArduPilot 4.6)
EK3_SRC1_POSXY      6              horizontal position from external navigation
EK3_SRC1_VELXY      6              horizontal velocity from external navigation
EK3_SRC1_POSZ       1              depth from the barometer (undertow's is the same sensor's)
EK3_SRC1_VELZ       0              no vertical velocity source (the default, GPS, is absent)
EK3_SRC1_YAW        1              yaw from the compass: undertow's heading is turned onto the
                                   autopilot's (:mod:`.frame`), sending it back is circular
VISO_QUAL_MIN       0              position modes: take what undertow sends (it stops itself);
                                   VISION_POSITION_ESTIMATE arrives as quality 0, which any
                                   VISO_QUAL_MIN above 0 drops
VISO_POS_M_NSE      0.1            the floor of posErr: its least allowed value, so that
                                   undertow's std decides above 0.1 m (default 0.2)
VISO_ORIENT         0              velocity-delta: the deltas are rotated by it; undertow's
                                   are in the body frame
VISO_POS_X/Y/Z      0              velocity-delta: the lever arm of the velocity; undertow's
                                   is the body origin's
VISO_SCALE          1              positions are multiplied by it
==================  =====  ======  ==========================================================

Read and shown, not set: VISO_DELAY_MS (subtracted from the message time; undertow stamps the
state's own time, so it should be the least age of a state when it reaches the autopilot, which
the session measures and states), VISO_YAW_M_NSE, VISO_VEL_M_NSE, EK3_SRC_OPTIONS,
EK3_VIS_VERR_MIN and EK3_VIS_VERR_MAX (the confidence mapping of :mod:`.covariance`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

#: MAV_PARAM_TYPE_REAL32: the type of a PARAM_SET when the autopilot's own is not known
REAL32 = 9


@dataclass(frozen=True)
class Param:
    """One parameter: the value undertow needs (None: read only), the modes that need it
    (empty: every mode), why, whether a change needs a reboot, the older name."""

    name: str
    value: float | None
    why: str
    reboot: bool = False
    modes: tuple[str, ...] = ()
    alias: str | None = None


POSITION_MODES = ("odometry", "vision-position")
PARAMS = (
    Param("AHRS_EKF_TYPE", 3, "EKF3 is the filter the vehicle navigates on"),
    Param("EK3_ENABLE", 1, "EKF3 runs", reboot=True),
    Param("VISO_TYPE", 1, "the MAVLink visual-odometry backend takes the messages", reboot=True),
    Param("GPS1_TYPE", 0, "no GPS under water", reboot=True, alias="GPS_TYPE"),
    Param("EK3_SRC1_POSXY", 6, "horizontal position from external navigation"),
    Param("EK3_SRC1_VELXY", 6, "horizontal velocity from external navigation"),
    Param("EK3_SRC1_POSZ", 1, "depth from the barometer (undertow's depth is the same sensor's)"),
    Param("EK3_SRC1_VELZ", 0, "no vertical velocity source (the default, GPS, is absent)"),
    Param("EK3_SRC1_YAW", 1, "yaw from the compass: undertow's heading is turned onto it"),
    Param(
        "VISO_QUAL_MIN",
        0,
        "take what undertow sends (VISION_POSITION_ESTIMATE arrives as quality 0)",
        modes=POSITION_MODES,
    ),  # fmt: skip
    Param(
        "VISO_POS_M_NSE",
        0.1,
        "the floor of the position error (its least value)",
        modes=POSITION_MODES,
    ),  # fmt: skip
    Param(
        "VISO_ORIENT",
        0,
        "the deltas are rotated by it; undertow's are in the body frame",
        modes=("velocity-delta",),
    ),  # fmt: skip
    *(
        Param(
            f"VISO_POS_{a}",
            0,
            "the velocity's lever arm; undertow's is the body origin's",
            modes=("velocity-delta",),
        )
        for a in "XYZ"
    ),  # fmt: skip
    Param("VISO_SCALE", 1, "positions are multiplied by it", modes=POSITION_MODES),
    Param(
        "VISO_DELAY_MS",
        None,
        "subtracted from the message time (see the session's measured state age)",
    ),  # fmt: skip
    Param("VISO_YAW_M_NSE", None, "the floor of the yaw error (used with EK3_SRC1_YAW = 6)"),
    Param("VISO_VEL_M_NSE", None, "the velocity error of ODOMETRY's velocity"),
    Param("EK3_SRC_OPTIONS", None, "bit 0: fuse the velocities of every source set"),
    Param("EK3_VIS_VERR_MIN", None, "velocity error at confidence 100 (velocity-delta)"),
    Param("EK3_VIS_VERR_MAX", None, "velocity error at confidence 0 (velocity-delta)"),
)


def params_for(mode: str) -> tuple[Param, ...]:
    return tuple(p for p in PARAMS if not p.modes or mode in p.modes)


def _same(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-5, abs_tol=1e-6)


@dataclass
class ParamCheck:
    """What was read (name -> (value, MAV_PARAM_TYPE)) and set, for ``mode``."""

    mode: str
    values: dict[str, tuple[float, int]] = field(default_factory=dict)
    confirmed: dict[str, float] = field(default_factory=dict)
    failed: dict[str, str] = field(default_factory=dict)

    @property
    def params(self) -> tuple[Param, ...]:
        return params_for(self.mode)

    def names(self) -> list[str]:
        """Every name to read (the older name too where one exists)."""
        return [n for p in self.params for n in (p.name, p.alias) if n]

    def on_value(self, name, value, param_type) -> bool:
        """A PARAM_VALUE; True when it is one of ours."""
        name = name.decode("ascii", "replace") if isinstance(name, bytes) else str(name)
        name = name.split("\0", 1)[0].strip()
        if name not in self.names():
            return False
        try:
            value, param_type = float(value), int(param_type)
        except (TypeError, ValueError):
            return False
        if not math.isfinite(value):
            return False
        self.values[name] = (value, param_type)
        return True

    def missing(self) -> list[str]:
        """The parameters neither name of which was read yet."""
        have = self.values
        return [p.name for p in self.params
                if p.name not in have and (p.alias is None or p.alias not in have)]  # fmt: skip

    def read_value(self, p: Param) -> tuple[str, float, int] | None:
        for name in (p.name, p.alias):
            if name and name in self.values:
                return (name, *self.values[name])
        return None

    def to_set(self) -> list[tuple[str, float, int, Param]]:
        """(name as the autopilot knows it, value, type, param) of every read parameter whose
        value is not the one needed."""
        out = []
        for p in self.params:
            got = self.read_value(p)
            if p.value is not None and got is not None and not _same(got[1], float(p.value)):
                out.append((got[0], float(p.value), got[2], p))
        return out

    def confirm(self, name: str, wanted: float) -> bool | None:
        """After a PARAM_SET: True when the echo has the value, False when it has another,
        None when no echo came yet."""
        got = self.values.get(name)
        if got is None:
            return None
        ok = _same(got[0], wanted)
        if ok:
            self.confirmed[name] = wanted
        return ok

    def report(self) -> list[str]:
        """One line per parameter: its value and, where it differs, what to set and why."""
        lines = []
        for p in self.params:
            got = self.read_value(p)
            shown = p.name if got is None or got[0] == p.name else got[0]
            if got is None:
                need = f"; needs {_fmt(p.value)}" if p.value is not None else ""
                lines.append(f"{shown}: not read (absent on this firmware?){need}")
            elif p.value is None:
                lines.append(f"{shown} = {_fmt(got[1])} ({p.why})")
            elif _same(got[1], float(p.value)):
                lines.append(f"{shown} = {_fmt(got[1])} ok")
            else:
                reboot = ", then reboot" if p.reboot else ""
                lines.append(f"{shown} = {_fmt(got[1])}: set {_fmt(p.value)}{reboot} ({p.why})")
        return lines

    def needs_reboot(self, names) -> list[str]:
        by_name = {n: p for p in self.params for n in (p.name, p.alias) if n}
        return [n for n in names if n in by_name and by_name[n].reboot]


def _fmt(v: float) -> str:
    v = float(v)
    return str(int(v)) if v.is_integer() else f"{v:g}"
