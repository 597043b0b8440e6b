"""Reading what comes over the link besides the sensor streams: which component is the
autopilot, who else sends external navigation to it, and what its EKF says.

- The autopilot is the first MAV_COMP_ID_AUTOPILOT1 (component 1, ArduPilot's own) whose
  HEARTBEAT has ``autopilot`` other than MAV_AUTOPILOT_INVALID (8: "no valid autopilot, e.g. a
  GCS or other MAVLink component", common.xml); its system and component ids are the target of
  undertow's requests.
- Another source: a message of :data:`NAV_MESSAGES` (what ArduPilot's GCS_Common.cpp feeds to
  its visual-odometry library) whose sender (system id, component id) is not undertow's. EKF3
  fuses every one of them, two sources fighting over the position; :class:`OtherSources` names
  each new sender in one warning. The Water Linked DVL BlueOS extension sends
  VISION_POSITION_DELTA (also VISION_SPEED_ESTIMATE, GLOBAL_VISION_POSITION_ESTIMATE) through
  mavlink2rest as system 255, component 0 (its mavlink2resthelper.py).
- EKF_STATUS_REPORT ``flags``: the bits of ArduPilot's EKF_STATUS_FLAGS (ardupilotmega.xml),
  decoded to their names by :func:`ekf_flag_names`; the variances are EKF3's normalized test
  ratios (1 = at its gate).
"""

from __future__ import annotations

import math

MAV_AUTOPILOT_INVALID = 8
MAV_COMP_ID_AUTOPILOT1 = 1
#: the external-navigation messages ArduPilot fuses (GCS_Common.cpp)
NAV_MESSAGES = (
    "VISION_POSITION_DELTA",
    "ODOMETRY",
    "VISION_POSITION_ESTIMATE",
    "VISION_SPEED_ESTIMATE",
    "GLOBAL_VISION_POSITION_ESTIMATE",
    "VICON_POSITION_ESTIMATE",
    "ATT_POS_MOCAP",
)
#: EKF_STATUS_FLAGS (ardupilotmega.xml): bit -> name
EKF_FLAGS = {
    1: "attitude",
    2: "velocity_horiz",
    4: "velocity_vert",
    8: "pos_horiz_rel",
    16: "pos_horiz_abs",
    32: "pos_vert_abs",
    64: "pos_vert_agl",
    128: "const_pos_mode",
    256: "pred_pos_horiz_rel",
    512: "pred_pos_horiz_abs",
    1024: "uninitialized",
    32768: "gps_glitching",
}
#: the extension's sender (mavlink2resthelper.py of bluerobotics/BlueOS-Water-Linked-DVL)
WATER_LINKED_SENDER = (255, 0)


def is_autopilot(heartbeat, compid: int) -> bool:
    """Whether a HEARTBEAT sent by component ``compid`` is an autopilot's (module docstring)."""
    value = getattr(heartbeat, "autopilot", MAV_AUTOPILOT_INVALID)
    return (
        compid == MAV_COMP_ID_AUTOPILOT1
        and isinstance(value, int)
        and (value != MAV_AUTOPILOT_INVALID)
    )


def ekf_flag_names(flags) -> list[str]:
    """The names of the set bits of an EKF_STATUS_REPORT ``flags`` (unknown bits as bitN)."""
    try:
        flags = int(flags)
    except (TypeError, ValueError, OverflowError):
        return []
    if flags < 0:
        return []
    names = []
    bit = 1
    while bit <= flags:
        if flags & bit:
            names.append(EKF_FLAGS.get(bit, f"bit{bit.bit_length() - 1}"))
        bit <<= 1
    return names


def _num(value) -> float | None:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def ekf_report(msg) -> dict:
    """An EKF_STATUS_REPORT as plain values: flags, their names, whether EKF3 has a
    horizontal position (pos_horiz_abs or pos_horiz_rel, not const_pos_mode), the test ratios."""
    try:
        flags = max(int(getattr(msg, "flags", 0)), 0)
    except (TypeError, ValueError, OverflowError):
        flags = 0
    names = ekf_flag_names(flags)
    horizontal = ("pos_horiz_abs" in names or "pos_horiz_rel" in names) and (
        "const_pos_mode" not in names
    )
    return {
        "flags": flags,
        "names": names,
        "horizontal_position": horizontal,
        **{k: _num(getattr(msg, k, None)) for k in (
            "velocity_variance", "pos_horiz_variance", "pos_vert_variance", "compass_variance")},
    }  # fmt: skip


class OtherSources:
    """Senders of external navigation other than undertow (module docstring)."""

    def __init__(self, own: tuple[int, int]) -> None:
        self.own = own
        self.seen: dict[tuple[int, int], set[str]] = {}

    def observe(self, name: str, sender: tuple[int, int], dvl_from_mavlink: bool = False):
        """A message ``name`` from ``sender``: a warning line when the sender is new."""
        if name not in NAV_MESSAGES or sender == self.own:
            return None
        names = self.seen.setdefault(sender, set())
        new = not names
        names.add(name)
        if not new:
            return None
        who = (
            " (the Water Linked DVL extension sends as 255/0)"
            if sender == WATER_LINKED_SENDER
            else ""
        )
        line = (f"another component, {sender[0]}/{sender[1]}{who}, sends {name} to the "
                "vehicle: EKF3 fuses both it and undertow; switch its output off "
                "(docs/bluerov2.md)")  # fmt: skip
        if dvl_from_mavlink and name == "VISION_POSITION_DELTA":
            line += ("; undertow's DVL is these same messages (--mavlink): connect undertow to "
                     "the A50 itself (--dvl) before switching them off")  # fmt: skip
        return line

    def as_dict(self) -> dict:
        return {f"{s}/{c}": sorted(n) for (s, c), n in self.seen.items()}
