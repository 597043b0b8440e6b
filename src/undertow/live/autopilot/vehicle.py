"""The conversation with the vehicle: every message undertow observes on the MAVLink link
(:data:`OBSERVED`) is taken here, and what undertow asks of the vehicle is sent from here.

From the autopilot's HEARTBEAT on (:mod:`.traffic`: its system and component are the target):

- its clock (ATTITUDE / SYSTEM_TIME / LOCAL_POSITION_NED ``time_boot_ms``, :mod:`.frame`), a
  reboot starting everything below again;
- the parameters (:mod:`.params`): PARAM_REQUEST_READ for each, asked again every
  ``PARAM_RETRY_S`` up to ``PARAM_ROUNDS`` times, then one report; with ``set_params`` the
  PARAM_SET of each wrong value, confirmed by the PARAM_VALUE echo, then which need a reboot;
- the EKF origin (:mod:`.origin`), the streams undertow needs (:mod:`.streams`);
- what it reports back: EKF_STATUS_REPORT (:func:`~.traffic.ekf_report`), LOCAL_POSITION_NED,
  ATTITUDE, STATUSTEXT, kept for the record and the view;
- other senders of external navigation (:class:`~.traffic.OtherSources`).

Every message is processed in the session's loop thread (the link's thread only queues it), so
this state needs no lock.
"""

from __future__ import annotations

import math

from .frame import AutopilotClock
from .messages import dialect
from .origin import GPS_GLOBAL_ORIGIN_ID, MAV_CMD_REQUEST_MESSAGE, OriginKeeper
from .params import REAL32, ParamCheck
from .streams import MAV_CMD_SET_MESSAGE_INTERVAL, NEEDED_RATES_HZ, StreamRequests
from .traffic import NAV_MESSAGES, OtherSources, ekf_report, is_autopilot

#: the messages the link hands over (with the mapper's pressure message, added by the bridge)
OBSERVED = (
    "HEARTBEAT", "ATTITUDE", "SYSTEM_TIME", "PARAM_VALUE", "COMMAND_ACK", "GPS_GLOBAL_ORIGIN",
    "EKF_STATUS_REPORT", "LOCAL_POSITION_NED", "STATUSTEXT", *NAV_MESSAGES,
)  # fmt: skip
PARAM_RETRY_S = 1.0
PARAM_ROUNDS = 3
#: the pressure message's requested rate (Hz), when it does not come
PRESSURE_RATE_HZ = 10.0


def _text(value) -> str:
    if isinstance(value, bytes | bytearray):
        value = bytes(value).decode("utf-8", "replace")
    return str(value).split("\0", 1)[0]


def _int(value, default: int = 0) -> int:
    try:
        return int(value)
    except (TypeError, ValueError, OverflowError):
        return default


class Vehicle:
    """The vehicle as undertow sees it (module docstring). ``send(msg) -> bool`` writes on the
    link; ``note(line)`` tells the user; ``record(kind, t, payload)`` records."""

    def __init__(self, *, mode: str, own: tuple[int, int], pressure: str, origin=None,
                 set_params: bool = False, send, note, record,
                 dvl_from_mavlink: bool = False) -> None:  # fmt: skip
        self.send, self.note, self.record = send, note, record
        self.own = own
        self.dvl_from_mavlink = dvl_from_mavlink
        self.set_params = bool(set_params)
        self.target: tuple[int, int] | None = None
        self.clock = AutopilotClock()
        self.params = ParamCheck(mode)
        self.origin = OriginKeeper(origin)
        self.streams = StreamRequests({**NEEDED_RATES_HZ, pressure: PRESSURE_RATE_HZ})
        self.others = OtherSources(own)
        self.attitude: tuple[float, float, float, float] | None = None  # (t, roll, pitch, yaw)
        self.position: tuple[float, float, float, float] | None = None  # (t, x, y, z) NED
        self.ekf: dict | None = None
        self.acks: dict[str, int] = {}
        self.statustexts = 0
        self._param_phase = "idle"  # idle, reading, setting, done
        self._param_round = 0
        self._param_next = 0.0
        self._setting: dict[str, tuple[float, int]] = {}
        self.params_set: list[str] = []
        self.params_failed: list[str] = []

    # -- incoming ------------------------------------------------------------------------------
    def take(self, msg, arrival: float) -> dict | None:
        """One observed message; returns what changed for the caller to show (EKF report,
        autopilot position) or None."""
        name = msg.get_type()
        try:
            sender = (_int(msg.get_srcSystem()), _int(msg.get_srcComponent()))
        except AttributeError:
            return None
        if name in NAV_MESSAGES:
            line = self.others.observe(name, sender, self.dvl_from_mavlink)
            if line:
                self.note(line)
            return None
        if name == "HEARTBEAT":
            return self._heartbeat(msg, sender, arrival)
        if self.target is None or sender != self.target:
            return None
        self.streams.seen(name, arrival)
        boot = getattr(msg, "time_boot_ms", None)
        if isinstance(boot, int) and self.clock.observe(boot * 1e-3, arrival):
            self._rebooted()
        handler = getattr(self, f"_{name.lower()}", None)
        return handler(msg, arrival) if handler is not None else None

    def _heartbeat(self, msg, sender, arrival) -> None:
        if self.target is None and is_autopilot(msg, sender[1]) and sender != self.own:
            self.target = sender
            self.streams.found(arrival)
            self._param_phase, self._param_next = "reading", arrival
            self.note(f"autopilot: system {sender[0]}, component {sender[1]} (MAV_TYPE "
                      f"{_int(getattr(msg, 'type', -1), -1)})")  # fmt: skip
        return None

    def _rebooted(self) -> None:
        self.note("autopilot rebooted (its time since boot went back): reading its parameters "
                  "and origin again; the next message is a reset")  # fmt: skip
        self.origin.rebooted()
        self.streams.rebooted()
        self._param_phase, self._param_round = "reading", 0
        self.params.values.clear()

    def _attitude(self, msg, arrival):
        t = self.clock.to_session(_int(msg.time_boot_ms) * 1e-3)
        values = (msg.roll, msg.pitch, msg.yaw)
        if t is not None and all(isinstance(v, float) and math.isfinite(v) for v in values):
            self.attitude = (t, *values)
        return None

    def _param_value(self, msg, arrival):
        self.params.on_value(msg.param_id, msg.param_value, msg.param_type)
        return None

    def _command_ack(self, msg, arrival):
        key = f"{_int(msg.command)}:{_int(msg.result)}"
        self.acks[key] = self.acks.get(key, 0) + 1
        return None

    def _gps_global_origin(self, msg, arrival):
        for line in self.origin.seen(msg.latitude, msg.longitude, msg.altitude):
            self.note(line)
        return None

    def _ekf_status_report(self, msg, arrival):
        self.ekf = ekf_report(msg)
        self.record("ekf_status", arrival, self.ekf)
        return {"ekf": self.ekf}

    def _local_position_ned(self, msg, arrival):
        t = self.clock.to_session(_int(msg.time_boot_ms) * 1e-3)
        p = (msg.x, msg.y, msg.z)
        if t is None or not all(isinstance(v, float) and math.isfinite(v) for v in p):
            return None
        self.position = (t, *p)
        return {"position": self.position}

    def _statustext(self, msg, arrival):
        self.statustexts += 1
        self.record(
            "statustext", arrival, {"severity": _int(msg.severity), "text": _text(msg.text)}
        )
        return None

    # -- outgoing ------------------------------------------------------------------------------
    def housekeeping(self, now: float) -> None:
        """Send what is due: parameter reads and sets, origin requests, stream requests."""
        if self.target is None:
            return
        self._params(now)
        actions, notes = self.origin.step(now)
        for line in notes:
            self.note(line)
        for action in actions:
            self._origin_action(action)
        requests, notes = self.streams.due(now)
        for line in notes:
            self.note(line)
        for name, interval_us in requests:
            msg_id = getattr(dialect(), f"MAVLINK_MSG_ID_{name}", None)
            if msg_id is not None:
                self._command(MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval_us)

    def _command(self, command: int, *params: float) -> bool:
        p = [float(v) for v in params] + [0.0] * (7 - len(params))
        return self.send(dialect().MAVLink_command_long_message(*self.target, command, 0, *p))

    def _origin_action(self, action) -> None:
        if action[0] == "request":
            self._command(MAV_CMD_REQUEST_MESSAGE, GPS_GLOBAL_ORIGIN_ID)
        else:
            _, lat, lon, alt = action
            self.send(dialect().MAVLink_set_gps_global_origin_message(self.target[0], lat, lon,
                                                                      alt, 0))  # fmt: skip

    def _params(self, now: float) -> None:
        if self._param_phase in ("idle", "done") or now < self._param_next:
            return
        self._param_next = now + PARAM_RETRY_S
        if self._param_phase == "reading":
            missing = self.params.missing()
            if missing and self._param_round < PARAM_ROUNDS:
                self._param_round += 1
                names = [n for n in self.params.names()
                         if n in missing or any(n == p.alias for p in self.params.params
                                                if p.name in missing)]  # fmt: skip
                for name in names:
                    self.send(dialect().MAVLink_param_request_read_message(
                        *self.target, name.encode("ascii"), -1))  # fmt: skip
                return
            self._report_params()
            return
        self._confirm_sets()

    def _report_params(self) -> None:
        mode = self.params.mode
        self.note(f"autopilot parameters for the {mode} mode:")
        for line in self.params.report():
            self.note(f"  {line}")
        wrong = self.params.to_set()
        if not wrong:
            self._param_phase = "done"
            return
        if not self.set_params:
            self.note("  set these (QGroundControl, or run again with --set-params)")
            self._param_phase = "done"
            return
        self._param_phase, self._param_round = "setting", 0
        self._setting = {name: (value, ptype) for name, value, ptype, _ in wrong}
        for name, (value, ptype) in self._setting.items():
            self.params.values.pop(name, None)  # the echo fills it again
            self._param_set(name, value, ptype)

    def _param_set(self, name: str, value: float, ptype: int) -> None:
        self.send(dialect().MAVLink_param_set_message(*self.target, name.encode("ascii"), value,
                                                      ptype or REAL32))  # fmt: skip

    def _confirm_sets(self) -> None:
        pending = {}
        for name, (value, ptype) in self._setting.items():
            ok = self.params.confirm(name, value)
            if ok:
                self.params_set.append(name)
            elif ok is False or self._param_round >= PARAM_ROUNDS:
                self.params_failed.append(name)
            else:
                pending[name] = (value, ptype)
        self._setting = pending
        if pending:
            self._param_round += 1
            for name, (value, ptype) in pending.items():
                self._param_set(name, value, ptype)
            return
        self._param_phase = "done"
        if self.params_set:
            reboot = self.params.needs_reboot(self.params_set)
            then = f"; reboot the autopilot for {', '.join(reboot)}" if reboot else ""
            done = ", ".join(self.params_set)
            self.note(f"autopilot parameters set (PARAM_VALUE confirmed): {done}{then}")
        if self.params_failed:
            self.note(f"autopilot parameters NOT set (no or another echo): "
                      f"{', '.join(self.params_failed)}")  # fmt: skip

    def summary(self) -> dict:
        read = {n: v for n, (v, _) in self.params.values.items()}
        return {
            "target": None if self.target is None else f"{self.target[0]}/{self.target[1]}",
            "params": read,
            "params_to_set": [n for n, *_ in self.params.to_set()],
            "params_set": list(self.params_set),
            "params_failed": list(self.params_failed),
            "origin": {"state": self.origin.state, "lat_lon_alt": self.origin.origin},
            "streams_requested": dict(self.streams.requested),
            "streams_absent": list(self.streams.absent),
            "command_acks": dict(self.acks),
            "other_sources": self.others.as_dict(),
            "ekf": self.ekf,
            "reboots": self.clock.reboots,
            "statustexts": self.statustexts,
        }
