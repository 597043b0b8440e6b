"""The conversation with the vehicle, message by message with a fake clock (no sockets): the
parameters read, reported and set with their echo, the origin adopted or set once, the streams
asked for when absent, other senders named once, EKF flags decoded as ardupilotmega.xml names
them."""

from __future__ import annotations

import pytest
from mavlink_peer import DEFAULT_PARAMS
from pymavlink.dialects.v20 import ardupilotmega as m

from undertow.live.autopilot.origin import OriginKeeper
from undertow.live.autopilot.params import PARAMS, ParamCheck, params_for
from undertow.live.autopilot.streams import StreamRequests
from undertow.live.autopilot.traffic import OtherSources, ekf_flag_names, ekf_report
from undertow.live.autopilot.vehicle import Vehicle


def _from(msg, sysid=1, compid=1):
    """``msg`` as received from (sysid, compid): packed and parsed by pymavlink."""
    data = bytes(msg.pack(m.MAVLink(None, srcSystem=sysid, srcComponent=compid)))
    (out,) = m.MAVLink(None).parse_buffer(data)
    return out


class _Peer:
    """Answers the vehicle's requests as the fake autopilot does, synchronously."""

    def __init__(self, params=None, origin=None):
        self.params = dict(DEFAULT_PARAMS if params is None else params)
        self.origin = origin
        self.sent, self.replies = [], []

    def send(self, msg) -> bool:
        self.sent.append(msg)
        name = msg.get_type()
        if name == "PARAM_REQUEST_READ" and msg.param_id in self.params:
            self.replies.append(self._value(msg.param_id))
        elif name == "PARAM_SET" and msg.param_id in self.params:
            self.params[msg.param_id] = msg.param_value
            self.replies.append(self._value(msg.param_id))
        elif name == "COMMAND_LONG" and msg.command == 512 and self.origin:
            self.replies.append(m.MAVLink_gps_global_origin_message(*self.origin))
        elif name == "SET_GPS_GLOBAL_ORIGIN" and self.origin is None:
            self.origin = (msg.latitude, msg.longitude, msg.altitude)
            self.replies.append(m.MAVLink_gps_global_origin_message(*self.origin))
        return True

    def _value(self, name):
        return m.MAVLink_param_value_message(name.encode(), float(self.params[name]), 9, 1, 0)


def _vehicle(peer, **kw):
    notes = []
    v = Vehicle(mode=kw.pop("mode", "odometry"), own=(255, 197), pressure="SCALED_PRESSURE2",
                send=peer.send, note=notes.append, record=lambda *a: None, **kw)  # fmt: skip
    return v, notes


def _converse(v, peer, until=10.0, dt=0.1):
    t = 0.0
    v.take(_from(m.MAVLink_heartbeat_message(12, 3, 0, 0, 4, 3)), t)
    while t < until:
        v.take(_from(m.MAVLink_attitude_message(int(t * 1000), 0.0, 0.0, 0.5, 0, 0, 0)), t)
        v.housekeeping(t)
        replies, peer.replies = peer.replies, []
        for msg in replies:
            v.take(_from(msg), t)
        t += dt


def test_parameters_are_read_reported_and_left_alone_by_default():
    peer = _Peer()
    v, notes = _vehicle(peer)
    _converse(v, peer)
    assert v.target == (1, 1)
    text = "\n".join(notes)
    assert "VISO_TYPE = 0: set 1, then reboot" in text
    assert "EK3_SRC1_POSXY = 3: set 6 (" in text and "AHRS_EKF_TYPE = 3 ok" in text
    assert "--set-params" in text
    assert not [s for s in peer.sent if s.get_type() == "PARAM_SET"]
    assert peer.params["VISO_TYPE"] == 0


def test_set_params_sets_checks_the_echo_and_names_the_reboots():
    peer = _Peer()
    v, notes = _vehicle(peer, set_params=True)
    _converse(v, peer)
    wanted = {p.name: p.value for p in params_for("odometry") if p.value is not None}
    for name, value in wanted.items():
        assert peer.params[name] == pytest.approx(value), name
    assert set(v.params_set) == {"VISO_TYPE", "GPS1_TYPE", "EK3_SRC1_POSXY", "EK3_SRC1_VELXY",
                                 "EK3_SRC1_VELZ", "VISO_POS_M_NSE"}  # fmt: skip
    reboot = [n for n in notes if "reboot the autopilot for" in n]
    assert reboot and reboot[0].split("reboot the autopilot for ")[1] == "VISO_TYPE, GPS1_TYPE"


def test_a_parameter_without_an_echo_is_reported_not_set():
    class Deaf(_Peer):
        def send(self, msg):
            if msg.get_type() == "PARAM_SET" and msg.param_id == "VISO_TYPE":
                self.sent.append(msg)
                return True
            return super().send(msg)

    peer = Deaf()
    v, notes = _vehicle(peer, set_params=True)
    _converse(v, peer)
    assert "VISO_TYPE" in v.params_failed and any("NOT set" in n for n in notes)


def test_the_older_gps_parameter_name_is_taken():
    params = {k: v for k, v in DEFAULT_PARAMS.items() if k != "GPS1_TYPE"} | {"GPS_TYPE": 1}
    peer = _Peer(params)
    v, notes = _vehicle(peer, set_params=True)
    _converse(v, peer)
    assert peer.params["GPS_TYPE"] == 0 and "GPS_TYPE" in v.params_set


def test_an_origin_on_the_vehicle_is_adopted_not_fought():
    peer = _Peer(origin=(471234567, 85432100, 420000))
    v, notes = _vehicle(peer, origin=(10.0, 20.0))
    _converse(v, peer)
    assert not [s for s in peer.sent if s.get_type() == "SET_GPS_GLOBAL_ORIGIN"]
    (line,) = [n for n in notes if "EKF origin" in n]
    assert "47.1234567, 8.5432100, 420.0 m; adopted (--origin not sent)" in line
    assert v.origin.state == "adopted"


def test_origin_set_once_when_none_and_said_when_not_asked():
    peer = _Peer()
    v, notes = _vehicle(peer, origin=(47.5, 8.25, 400.0))
    _converse(v, peer)
    (sent,) = [s for s in peer.sent if s.get_type() == "SET_GPS_GLOBAL_ORIGIN"]
    assert (sent.latitude, sent.longitude, sent.altitude) == (475000000, 82500000, 400000)
    assert v.origin.state == "set" and any("EKF origin set" in n for n in notes)
    peer = _Peer()
    v, notes = _vehicle(peer)
    _converse(v, peer)
    assert v.origin.state == "none" and any("has none" in n for n in notes)


def test_origin_keeper_sends_again_while_unconfirmed():
    keeper = OriginKeeper((1.0, 2.0), asks=1, every_s=1.0, sets=2)
    keeper.step(0.0)
    set_ = ("set", 10_000_000, 20_000_000, 0)
    assert keeper.step(1.0)[0] == [set_]
    keeper.step(2.0)  # asks: no reply (an EKF not yet running refused it)
    actions, notes = keeper.step(3.0)
    assert actions == [set_] and "again" in notes[0]
    keeper.step(4.0)
    actions, notes = keeper.step(5.0)  # two sent: gives up
    assert not actions and "no GPS_GLOBAL_ORIGIN came back" in notes[0]
    assert keeper.step(9.0) == ([], [])


def test_origin_keeper_after_a_refusal_and_a_reboot():
    keeper = OriginKeeper((1.0, 2.0), asks=1, every_s=1.0, sets=1)
    assert keeper.step(0.0)[0] == [("request",)]
    actions, notes = keeper.step(1.0)
    assert actions == [("set", 10_000_000, 20_000_000, 0)]
    keeper.step(2.0)  # asks again
    actions, notes = keeper.step(3.0)
    assert not actions and "no GPS_GLOBAL_ORIGIN came back" in notes[0]
    keeper.rebooted()  # a new boot has no origin: once more
    keeper.step(4.0)
    assert keeper.step(5.0)[0][0][0] == "set"
    assert keeper.seen(10**12, 0, 0) == [] and keeper.seen("x", 0, 0) == []


def test_streams_are_asked_for_only_when_absent():
    s = StreamRequests({"ATTITUDE": 25.0, "EKF_STATUS_REPORT": 2.0}, grace_s=2.0, retry_s=5.0,
                       tries=2)  # fmt: skip
    s.found(0.0)
    for t in (0.5, 1.0, 1.5, 2.0, 2.5):
        s.seen("ATTITUDE", t)
    assert s.due(1.0) == ([], [])  # within the grace
    asked, _ = s.due(2.5)
    assert asked == [("EKF_STATUS_REPORT", 500_000)]
    assert s.due(3.0) == ([], [])  # retried only after retry_s
    assert s.due(7.5)[0] == [("ATTITUDE", 40_000), ("EKF_STATUS_REPORT", 500_000)]
    asked, notes = s.due(12.6)  # ATTITUDE's second ask; EKF_STATUS_REPORT asked twice already
    assert asked == [("ATTITUDE", 40_000)] and notes == [
        "EKF_STATUS_REPORT does not arrive although asked for 2 times "
        "(MAV_CMD_SET_MESSAGE_INTERVAL)"]  # fmt: skip
    s.seen("ATTITUDE", 17.0)  # it came: nothing more to ask
    assert s.due(17.7) == ([], []) and s.absent == ["EKF_STATUS_REPORT"]


def test_other_senders_are_named_once_each():
    others = OtherSources(own=(255, 197))
    assert others.observe("ODOMETRY", (255, 197)) is None  # undertow's own
    line = others.observe("VISION_POSITION_DELTA", (255, 0), dvl_from_mavlink=True)
    assert "255/0" in line and "Water Linked" in line and "--dvl" in line
    assert others.observe("VISION_SPEED_ESTIMATE", (255, 0)) is None
    assert "1/197" in others.observe("ODOMETRY", (1, 197))
    assert others.observe("ATTITUDE", (9, 9)) is None
    assert others.as_dict() == {"255/0": ["VISION_POSITION_DELTA", "VISION_SPEED_ESTIMATE"],
                                "1/197": ["ODOMETRY"]}  # fmt: skip


def test_ekf_flags_are_ardupilotmega_names():
    enum = m.enums["EKF_STATUS_FLAGS"]
    for bit, entry in enum.items():
        if entry.name.endswith("ENUM_END"):
            continue
        assert ekf_flag_names(bit) == [entry.name.removeprefix("EKF_").lower()]
    report = ekf_report(_from(m.MAVLink_ekf_status_report_message(1 | 16 | 32, 0.1, 0.2, 0, 0, 0)))
    assert report["horizontal_position"] and report["names"] == [
        "attitude", "pos_horiz_abs", "pos_vert_abs"]  # fmt: skip
    const = ekf_report(_from(m.MAVLink_ekf_status_report_message(1 | 8 | 128, 0, 0, 0, 0, 0)))
    assert not const["horizontal_position"]
    assert (
        ekf_flag_names(-1) == [] and ekf_flag_names("x") == [] and "bit11" in ekf_flag_names(2048)
    )


def test_param_check_tables_cover_every_mode():
    for mode in ("odometry", "vision-position", "velocity-delta"):
        names = {p.name for p in params_for(mode)}
        assert {"EK3_SRC1_POSXY", "EK3_SRC1_VELXY", "VISO_TYPE", "GPS1_TYPE"} <= names
    assert "VISO_ORIENT" in {p.name for p in params_for("velocity-delta")}
    assert "VISO_ORIENT" not in {p.name for p in params_for("odometry")}
    check = ParamCheck("odometry")
    assert not check.on_value(b"NOT_OURS\0\0", 1.0, 9)
    assert check.on_value(b"VISO_TYPE\0\0\0", 1.0, 1) and check.values["VISO_TYPE"] == (1.0, 1)
    assert not check.on_value("VISO_TYPE", float("nan"), 1)
    assert check.needs_reboot(["VISO_TYPE", "EK3_SRC1_YAW", "GPS_TYPE"]) == [
        "VISO_TYPE",
        "GPS_TYPE",
    ]
    assert len({p.name for p in PARAMS}) == len(PARAMS)
