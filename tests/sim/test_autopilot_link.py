"""The virtual autopilot on ``undertow serve``'s MAVLink link (UDP, and TCP as the SITL serves
it), driven by a pymavlink client on 127.0.0.1: the client's messages reach it, its replies
and streams come back on the link the sensors use, on the served clock."""

from __future__ import annotations

import math
import socket
import time

import pytest
from pymavlink import mavutil

from undertow.commands.serve import parse_origin, serve
from undertow.errors import ConfigError
from undertow.sim.robot.autopilot import AutopilotTiming
from undertow.sim.robot.autopilot_rules import covariance_for_error

pytestmark = pytest.mark.network

EXTNAV = {"VISO_TYPE": 1, "GPS1_TYPE": 0, "EK3_SRC1_POSXY": 6, "EK3_SRC1_VELXY": 6}
NAN = math.nan


def free_port(kind=socket.SOCK_DGRAM) -> int:
    s = socket.socket(socket.AF_INET, kind)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def collect(conn, seconds, send=None):
    """Messages received for ``seconds`` (wall), calling ``send(t)`` every 0.1 s."""
    out, t0, next_send = [], time.monotonic(), 0.0
    while (t := time.monotonic() - t0) < seconds:
        if send is not None and t >= next_send:
            send(t)
            next_send += 0.1
        msg = conn.recv_match(blocking=True, timeout=0.02)
        if msg is not None:
            out.append((t, msg))
    return out


def odometry(conn, x, y):
    cov = covariance_for_error(0.3, 0.05)
    conn.mav.odometry_send(
        0, 20, 12, x, y, 0.0, [1, 0, 0, 0], 0, 0, 0, NAN, NAN, NAN, cov, [NAN] * 21, 0, 0, 100
    )


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_the_autopilot_answers_on_the_served_link(simulation, transport):
    if transport == "udp":
        port = free_port()
        address, client = f"udpout:127.0.0.1:{port}", f"udpin:127.0.0.1:{port}"
    else:
        port = free_port(socket.SOCK_STREAM)
        address, client = f"tcpin:127.0.0.1:{port}", f"tcp:127.0.0.1:{port}"
    session = serve(
        simulation("calm").log,
        rate=4.0,
        dvl_port=None,
        ping_port=None,
        mavlink=address,
        autopilot=True,
        autopilot_params=EXTNAV,
        autopilot_origin="47.5,8.25",
        duration=20.0,
    )
    session.autopilot.autopilot.timing = AutopilotTiming(1.0, 1.0, 2.0, 1.0)
    # the client's socket before the autopilot boots: its first texts ("origin set" at 1 s of
    # its clock, 0.25 s of wall time) were lost when a loaded machine bound it later
    session.open()
    conn = mavutil.mavlink_connection(client, source_system=255, source_component=190)
    session.start()
    try:
        if transport == "udp":  # the sender's datagrams tell the client where to reply
            conn.wait_heartbeat(timeout=5)
        conn.mav.command_long_send(1, 1, 511, 0, 32, 100_000, 0, 0, 0, 0, 0)
        got = collect(conn, 2.5, send=lambda t: odometry(conn, 1.0, 2.0))
        # served at 4x: 2.5 s of wall time is 10 s of the autopilot's clock
        texts = [m.text for _, m in got if m.get_type() == "STATUSTEXT"]
        assert "EKF3 IMU0 origin set" in texts
        assert "EKF3 IMU0 is using external nav data" in texts
        acks = [m for _, m in got if m.get_type() == "COMMAND_ACK"]
        assert acks and acks[0].command == 511 and acks[0].result == 0
        positions = [m for _, m in got if m.get_type() == "LOCAL_POSITION_NED"]
        assert positions and (positions[-1].x, positions[-1].y) == pytest.approx((1, 2), abs=0.05)
        flags = [m.flags for _, m in got if m.get_type() == "EKF_STATUS_REPORT"]
        assert flags[-1] & mavutil.mavlink.EKF_POS_HORIZ_ABS
        kinds = {m.get_type() for _, m in got}
        assert {"ATTITUDE", "HEARTBEAT"} <= kinds  # the sensors share the link
        assert all(m.get_srcSystem() == 1 for _, m in got)
    finally:
        conn.close()
        summary = session.stop()
    ap = summary["autopilot"]
    assert ap["counts"]["ODOMETRY:fused"] > 5
    assert ap["origin"] == [475_000_000, 82_500_000, 0]
    served = {k for k in summary["messages"] if k.startswith("mavlink/")}
    assert {"mavlink/LOCAL_POSITION_NED", "mavlink/STATUSTEXT"} <= served


def test_serve_refuses_an_autopilot_without_a_link_and_bad_options(simulation, tmp_path):
    log = simulation("calm").log
    with pytest.raises(ConfigError, match="needs the MAVLink link"):
        serve(log, dvl_port=None, ping_port=None, mavlink=None, autopilot=True)
    with pytest.raises(ConfigError, match="--autopilot-origin"):
        parse_origin("47.5")
    bad = tmp_path / "bad.parm"
    bad.write_text("VISO_TYPE one\n")
    with pytest.raises(ConfigError, match="bad.parm:1"):
        serve(log, dvl_port=None, ping_port=None, autopilot=True, autopilot_params=bad)
    with pytest.raises(ConfigError, match="--autopilot-covariance"):
        serve(log, dvl_port=None, ping_port=None, autopilot=True, autopilot_covariance="cube")
