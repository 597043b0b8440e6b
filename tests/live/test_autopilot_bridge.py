"""`undertow live --autopilot` end to end on 127.0.0.1: the virtual robot (`undertow serve`)
serves a simulated dive, a fake autopilot (tests/mavlink_peer.py, pymavlink) relays its
telemetry to undertow over UDP or TCP and decodes what undertow sends back.

Checked from the peer's side, against the session's own saved trajectory: the frames, that each
message carries the state of the trajectory at its time (position turned by the heading offset,
the pose covariance k T P T^T in MAVLink's 21-term layout; a message carries the preview of that
state, filtered before a later record of its time may have arrived and before the later depths
judged its pressure rows, so nine in ten agree to a centimetre and a few percent, where a wrong
layout, turn or factor would not), the rate's bound and EKF3's spacings, a
constant reset_counter in a clean run, the parameters set and their reboots named, the origin
set once or adopted, another sender named, the autopilot's reports recorded (EKF flags decoded,
its position turned back onto undertow's), DVL loss stopping the messages and the resume
raising reset_counter, and nothing sent without --autopilot.
"""

from __future__ import annotations

import json
import math
import socket
import threading
import time

import numpy as np
import pytest
from mavlink_peer import FakeAutopilot
from pymavlink.dialects.v20 import ardupilotmega as m
from rosbags.highlevel import AnyReader

from undertow.commands.serve import serve
from undertow.io.msgdefs import dvl_typestore
from undertow.live.autopilot import covariance as cov
from undertow.live.autopilot.schedule import SPACING_S
from undertow.live.pipeline import LiveSession
from undertow.settings import LiveSettings, Settings
from undertow.sim.robot import Faults
from undertow.trajectory import Trajectory

# one worker runs this module's tests, so its module fixtures are built once (make test:
# --dist loadgroup)
pytestmark = [pytest.mark.network, pytest.mark.slow, pytest.mark.xdist_group("autopilot_bridge")]

RATE = 2.0  # the log is served twice as fast as real time
SPAN_S = 16.0
WAVE = "wave-a0.10-f1.00"
MESSAGE = {"odometry": "ODOMETRY", "vision-position": "VISION_POSITION_ESTIMATE",
           "velocity-delta": "VISION_POSITION_DELTA"}  # fmt: skip


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def dive(simulation):
    log = simulation(WAVE).log
    t0 = log.time_span[0]
    return log.replace(**{n: s.select(s.t < t0 + SPAN_S) for n, s in log.streams().items()})


def _session(log, out, *, transport="udp", faults=None, during=None, peer_kw=None, **live):
    """Serve ``log``, relay through a fake autopilot, run live until the data ends; (result,
    peer). ``during(peer)`` runs in a thread while it plays."""
    port = _free_udp_port()
    peer = FakeAutopilot(transport, port, **(peer_kw or {})).start()
    telemetry = f"udpout:127.0.0.1:{peer.telemetry_port}"
    robot = serve(log, rate=RATE, dvl_port=0, ping_port=None, faults=faults, mavlink=telemetry,
                  wait_for_clients=10.0)  # fmt: skip
    robot.open()
    mavlink = f"udpin:127.0.0.1:{port}" if transport == "udp" else peer.tcp_address
    settings = Settings(live=LiveSettings(dvl=robot.endpoints.dvl, mavlink=mavlink,
                                          time_scale=RATE, reorder_s=0.3 * RATE, map=False,
                                          idle_stop_s=60.0, **live))  # fmt: skip
    session = LiveSession(settings, out).start()
    assert session.wait_connected(10.0)
    robot.start()
    if during is not None:
        threading.Thread(target=during, args=(peer,), daemon=True).start()

    def stop_after_the_last_message():
        robot.wait()
        time.sleep(1.0)
        session.request_stop()

    threading.Thread(target=stop_after_the_last_message, daemon=True).start()
    try:
        result = session.run()
    finally:
        robot.stop()
        peer.stop()
    return result, peer


def _recorded(recording) -> dict[str, list]:
    got: dict[str, list] = {}
    with AnyReader([recording], default_typestore=dvl_typestore()) as reader:
        conns = [c for c in reader.connections if c.topic.startswith("/autopilot/")]
        for conn, ns, raw in reader.messages(connections=conns):
            got.setdefault(conn.topic, []).append((ns, reader.deserialize(raw, conn.msgtype)))
    return got


def _json(got, topic) -> list[dict]:
    return [json.loads(msg.data) for _, msg in got.get(topic, [])]


@pytest.fixture(scope="module")
def odometry_run(dive, tmp_path_factory):
    def another_sender(peer):  # the Water Linked extension, for a moment
        time.sleep(3.0)
        for _ in range(3):
            delta = [0.01, 0.0, 0.0]
            peer.extra(m.MAVLink_vision_position_delta_message(0, 100_000, [0.0] * 3, delta, 100.0))
            time.sleep(0.1)

    out = tmp_path_factory.mktemp("ap") / "odometry"
    return _session(dive, out, during=another_sender, autopilot=True, autopilot_set_params=True,
                    autopilot_origin=(47.5, 8.25, 400.0))  # fmt: skip


def _check_states(result, peer, mode: str):
    """Each message carries a state of the saved trajectory (module docstring)."""
    summary = result.summary["autopilot"]
    traj = Trajectory.load_npz(result.localization / "trajectory.npz")
    index = {float(t): k for k, t in enumerate(traj.t)}
    got = _recorded(result.recording)
    sent = {r["time_usec"]: r for r in _json(got, "/autopilot/sent")}
    msgs = peer.messages(MESSAGE[mode])
    assert len(msgs) == summary["sent"] == len(sent) > 0
    dpsi = math.radians(summary["heading_offset_deg"])
    k = summary["covariance_inflation"]
    agree = []
    for msg in msgs:
        usec = msg.time_usec if mode != "vision-position" else msg.usec
        i = index.get(sent[usec]["state_t"])
        assert i is not None  # every state time is one of the trajectory's
        if mode == "velocity-delta":
            v = np.asarray(msg.position_delta) / sent[usec]["dt_s"]
            agree.append(np.allclose(v, traj.x[i][6:9], atol=0.002))
            continue
        R = cov.rotate_z(dpsi)
        c = np.asarray(msg.pose_covariance if mode == "odometry" else msg.covariance)
        expected = np.asarray(cov.upper_triangle(cov.pose_covariance(traj.P[i], dpsi, k)))
        scale = expected[list(cov.DIAGONAL)].max()
        agree.append(np.allclose([msg.x, msg.y, msg.z], R @ traj.x[i][0:3], atol=0.01)
                     and np.allclose(c, expected, rtol=0.05, atol=0.05 * scale))  # fmt: skip
    # a preview run before a record of its time arrived differs from the committed state
    assert np.mean(agree) >= 0.9
    return summary, got, sent


def _check_schedule(sent: dict, mode: str, rate: float = 10.0):
    """The token bucket's invariants on the session clock: at most r W + 3 messages in any
    window W, EKF3's spacings between the states' times and between sends."""
    records = sorted(sent.values(), key=lambda r: r["sent_at"])
    t = np.array([r["sent_at"] for r in records])
    for w in (0.1, 0.5, 2.0):
        counts = np.searchsorted(t, t + w, side="left") - np.arange(len(t))
        assert counts.max() <= rate * w + 3
    send_spacing, state_spacing = SPACING_S[mode]
    assert np.diff(t).min() >= send_spacing - 1e-9
    assert np.diff([r["state_t"] for r in records]).min() >= state_spacing - 1e-9


def test_odometry_carries_the_states_at_the_rate(odometry_run):
    result, peer = odometry_run
    summary, got, sent = _check_states(result, peer, "odometry")
    msgs = peer.messages("ODOMETRY")
    assert {(msg.frame_id, msg.child_frame_id) for msg in msgs} == {(20, 12)}
    assert {(msg.get_srcSystem(), msg.get_srcComponent()) for msg in msgs} == {(255, 197)}
    assert {msg.reset_counter for msg in msgs} == {summary["reset_counter"]["start"]}
    assert all(1 <= msg.quality <= 100 for msg in msgs)
    _check_schedule(sent, "odometry")
    # the state's time in the autopilot's clock: increasing, as the states
    usec = [msg.time_usec for msg in msgs]
    assert all(b > a for a, b in zip(usec, usec[1:], strict=False))


def test_parameters_origin_and_another_sender(odometry_run):
    result, peer = odometry_run
    summary = result.summary["autopilot"]
    for name, value in {"VISO_TYPE": 1, "GPS1_TYPE": 0, "EK3_SRC1_POSXY": 6,
                        "EK3_SRC1_VELXY": 6, "EK3_SRC1_VELZ": 0}.items():  # fmt: skip
        assert peer.params[name] == value, name
    notes = "\n".join(result.warnings)
    assert "reboot the autopilot for VISO_TYPE, GPS1_TYPE" in notes
    (origin,) = peer.messages("SET_GPS_GLOBAL_ORIGIN")
    assert (origin.latitude, origin.longitude, origin.altitude) == (475000000, 82500000, 400000)
    assert summary["origin"]["state"] == "set"
    assert "another component, 255/0" in notes and "Water Linked" in notes
    assert summary["other_sources"] == {"255/0": ["VISION_POSITION_DELTA"]}


def test_what_the_autopilot_says_is_recorded_next_to_undertow(odometry_run):
    result, peer = odometry_run
    got = _recorded(result.recording)
    ekf = _json(got, "/autopilot/ekf_status")
    assert ekf and any("pos_horiz_abs" in r["names"] and r["horizontal_position"] for r in ekf)
    # the fake EKF reports the last fix it got: turned back, a position undertow sent, in its
    # own frame (next to its trajectory)
    traj = Trajectory.load_npz(result.localization / "trajectory.npz")
    dpsi = math.radians(result.summary["autopilot"]["heading_offset_deg"])
    sent = np.array([[msg.x, msg.y, msg.z] for msg in peer.messages("ODOMETRY")])
    back = sent @ cov.rotate_z(dpsi)  # rows Rz(-dpsi) p
    poses = got["/autopilot/pose"]
    assert poses and all(p.header.frame_id == "world" for _, p in poses)
    for _, pose in poses:
        q = pose.pose.pose.position
        assert np.linalg.norm(back - [q.x, q.y, q.z], axis=1).min() < 1e-5
        assert np.linalg.norm(traj.x[:, 0:3] - [q.x, q.y, q.z], axis=1).min() < 0.01


@pytest.mark.parametrize(("mode", "transport", "origin"), [
    ("vision-position", "udp", (471234567, 85432100, 420000)),
    ("velocity-delta", "tcp", None),
    ("odometry", "tcp", (471234567, 85432100, 420000)),
])  # fmt: skip
def test_every_mode_over_both_transports(dive, tmp_path, mode, transport, origin):
    result, peer = _session(dive, tmp_path / "dive", transport=transport, autopilot=True,
                            autopilot_mode=mode, autopilot_origin=(1.0, 2.0),
                            peer_kw={"origin": origin})  # fmt: skip
    summary, _, sent = _check_states(result, peer, mode)
    _check_schedule(sent, mode)
    if mode == "velocity-delta":
        msgs = peer.messages("VISION_POSITION_DELTA")
        assert all(0 <= msg.confidence <= 100 for msg in msgs)
        assert all(20_000 <= msg.time_delta_usec <= 1_000_000 for msg in msgs)
    if origin is not None:  # on the vehicle already: adopted, --origin never sent
        assert not peer.messages("SET_GPS_GLOBAL_ORIGIN")
        assert summary["origin"]["state"] == "adopted"
    else:
        assert len(peer.messages("SET_GPS_GLOBAL_ORIGIN")) == 1
    assert not peer.messages("PARAM_SET")  # never without --set-params


def test_dvl_loss_stops_the_messages_and_the_resume_is_a_reset(dive, tmp_path):
    faults = Faults(drop_dvl=((7.0, 4.0),))  # 4 s without the DVL link, 7 s in
    result, peer = _session(dive, tmp_path / "dive", faults=faults, autopilot=True)
    summary = result.summary["autopilot"]
    records = sorted(_json(_recorded(result.recording), "/autopilot/sent"),
                     key=lambda r: r["state_t"])  # fmt: skip
    gaps = np.diff([r["state_t"] for r in records])
    assert gaps.max() >= 4.0 - 1.0 - 0.5  # silent from the timeout to the DVL's return
    counters = [r["reset_counter"] for r in records]
    k = int(np.argmax(gaps)) + 1
    start = summary["reset_counter"]["start"]
    assert set(counters[:k]) == {start} and counters[k] == (start + 1) % 256
    assert any("DVL" in reason for reason in summary["holds"])
    msgs = peer.messages("ODOMETRY")
    assert [msg.reset_counter for msg in msgs] == counters


def test_without_autopilot_nothing_is_sent(dive, tmp_path):
    short = dive.replace(**{n: s.select(s.t < dive.time_span[0] + 4.0)
                            for n, s in dive.streams().items()})  # fmt: skip
    result, peer = _session(short, tmp_path / "dive")
    assert peer.messages() == [] and "autopilot" not in result.summary
