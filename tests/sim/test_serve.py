"""The virtual robot (``undertow serve``) against the project's own live links, on 127.0.0.1 with
ports chosen free: what each link receives is compared with the log served (its values to the
precision of the message fields, its times with the served sensor clock) and every injected
fault must show in the link's counters exactly as the manifest lists it."""

from __future__ import annotations

import json
import math
import socket
import time

import numpy as np
import pytest
from conftest import REAL_DATA, one_error_line

from undertow._util.clocks import ScaledClock
from undertow.commands.serve import serve
from undertow.errors import ConfigError
from undertow.io import read_log
from undertow.io.mavlink import MavlinkConfig
from undertow.live.links import A50TcpLink, Backoff, ClockPolicy, LinkCounters
from undertow.live.links.mavlink_udp import MavlinkLink
from undertow.live.links.ping1d import Ping1DLink
from undertow.log import G0
from undertow.records import records_to_log
from undertow.rotations import rpy_to_quaternion
from undertow.sim.robot import Faults
from undertow.sim.robot.a50 import DEFAULT_CONFIG

#: opens sockets on 127.0.0.1 (servers it starts)
pytestmark = pytest.mark.network

FAST = Backoff(initial=0.02, factor=2.0, maximum=0.1)


@pytest.fixture(scope="module")
def short_log(simulation):
    """The first 6 s of the simulated carriage run (every stream)."""
    log = simulation("calm").log
    return log.replace(**{n: s.select(s.t < 6.0) for n, s in log.streams().items()})


def free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def _port(url: str) -> int:
    return int(url.rsplit(":", 1)[1])


def wait_for(condition, what: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.01)


def settle(links, quiet: float = 0.3, timeout: float = 10.0) -> None:
    """Until no link received anything new for ``quiet`` s."""
    deadline, last, since = time.monotonic() + timeout, None, time.monotonic()
    while time.monotonic() < deadline:
        now = [link.counters.received for link in links]
        if now != last:
            last, since = now, time.monotonic()
        elif time.monotonic() - since > quiet:
            return
        time.sleep(0.02)


def play(session, links, scaled: bool = False):
    """Connect ``links`` (name -> link) to the open ``session``, play the whole log, stop; the
    records per link. ``scaled``: the links' arrival clock runs with the session's."""
    records = {name: [] for name in links}
    if scaled:  # before anything arrives: the served clock c(w) = A + rate (w - A)
        clock = ScaledClock(session.rate)
        for link in links.values():
            link.now = clock
    for name, link in links.items():
        link.callback = records[name].append
        link.start()
    try:
        for name, link in links.items():
            wait_for(lambda link=link: link.counters.connects >= 1, f"{name} connects")
        if session.a50 is not None:  # accepted by the server too, not only by the kernel
            wait_for(lambda: session.a50.clients() >= 1, "the A50 server accepts")
        session.start()
        assert session.wait(60)
        # a Ping answers each poll at once; the others may still have bytes in flight
        settle([link for link in links.values() if not isinstance(link, Ping1DLink)])
    finally:
        for link in links.values():
            link.stop()
        session.stop()
    return records


def trusting_a50(port: int) -> A50TcpLink:
    """An A50 link that takes the sensor's time whatever the arrival (a replay at a rate)."""
    trust = ClockPolicy(LinkCounters(), max_offset_s=math.inf)
    return A50TcpLink("127.0.0.1", port, backoff=FAST, clock=trust)


def test_a50_link_receives_the_log_with_the_served_clock(short_log):
    session = serve(short_log, rate=10, dvl_port=0, ping_port=None, mavlink=None).open()
    link = trusting_a50(_port(session.endpoints.dvl))
    records = play(session, {"a50": link})["a50"]
    live, epoch = records_to_log(records), session.epoch
    dvl, dr = short_log.dvl, short_log.dead_reckoning
    assert len(live.dvl) == len(dvl) and len(live.dead_reckoning) == len(dr)
    assert link.counters.malformed == link.counters.duplicate == link.counters.out_of_order == 0
    # sensor clock = epoch + log time (time_of_validity in whole microseconds)
    np.testing.assert_allclose(live.dvl.t - epoch, dvl.t, rtol=0, atol=1e-6)
    np.testing.assert_allclose(live.dead_reckoning.t - epoch, dr.t, rtol=0, atol=1e-6)
    served = sorted((e.stream, e.sensor_time) for e in session.manifest.select("a50"))
    assert sorted((r.stream, r.sensor_time) for r in records) == served
    for name in (
        "velocity",
        "valid",
        "fom",
        "covariance",
        "altitude",
        "beam_valid",
        "beam_velocity",
        "beam_range",
    ):
        np.testing.assert_array_equal(getattr(live.dvl, name), getattr(dvl, name), name)
    np.testing.assert_array_equal(live.dead_reckoning.position, dr.position)
    np.testing.assert_allclose(live.dead_reckoning.orientation, dr.orientation, atol=1e-12)
    # the configuration the A50 answers: its defaults, with the sound speed the served reports
    # were made with (the simulated DVL's setting)
    expected = {**DEFAULT_CONFIG, "speed_of_sound": short_log.metadata["dvl_sound_speed_m_s"]}
    assert link.info["config"] == expected and session.a50.commands == ["get_config"]
    # played at 10x: 6 s of log in about 0.6 s of wall time
    walls = [e.wall for e in session.manifest.select("a50")]
    assert 0.45 < walls[-1] - walls[0] < 1.5


def test_a50_answers_commands_like_the_sensor(short_log):
    session = serve(short_log, rate=20, dvl_port=0, ping_port=None, mavlink=None).open()
    link = A50TcpLink(
        "127.0.0.1",
        _port(session.endpoints.dvl),
        backoff=FAST,
        reset_dead_reckoning=True,
        calibrate_gyro=True,
    )
    play(session, {"a50": link})
    assert session.a50.commands == ["get_config", "reset_dead_reckoning", "calibrate_gyro"]
    assert [r["response_to"] for r in link.responses] == session.a50.commands
    assert all(r["success"] and r["format"] == "json_v3" for r in link.responses)
    bad = json.loads(session.a50.answer(b'{"command": "self_destruct"}'))
    assert bad["success"] is False and "unknown command" in bad["error_message"]


def test_ping1d_link_gets_the_range_at_the_request_time(short_log):
    rate = 5.0
    session = serve(
        short_log, rate=rate, dvl_port=None, ping_port=0, mavlink=None, wait_for_clients=5.0
    ).open()
    link = Ping1DLink(session.endpoints.sonar, rate_hz=40.0, backoff=FAST)
    records = play(session, {"ping": link})["ping"]
    sonar, clock = short_log.sonar, session.player.clock
    assert len(records) > 0.5 * len(sonar) and link.counters.malformed == 0
    # the request left shortly before the reply arrived: the range is the newest row at a
    # playback time between (arrival - 50 ms of wall time) and arrival
    for r in records:
        tau = clock.t0 + rate * (r.arrival - clock.wall0)
        hi = max(int(np.searchsorted(sonar.t, tau, side="right")) - 1, 0)
        lo = max(int(np.searchsorted(sonar.t, tau - rate * 0.05, side="right")) - 1, 0)
        window = sonar.range[lo : hi + 1]
        assert np.min(np.abs(window - r.data["range"])) <= 5e-4 + 1e-12, (tau, r.data)
        c = sonar.confidence[lo : hi + 1]
        assert np.min(np.abs(c - r.data["confidence"])) <= 5e-3 + 1e-12
    # and exactly the replies the manifest lists (one per ping: repeated polls are duplicates)
    replies = [e for e in session.manifest.select("ping1d") if e.index >= 0]
    for e in replies:
        assert sonar.t[e.index] <= e.at and (
            e.index + 1 == len(sonar) or sonar.t[e.index + 1] > e.at
        )
    unique = [e for k, e in enumerate(replies) if k == 0 or e.index != replies[k - 1].index]
    got = [r.data["range"] for r in records]
    want = [round(1000 * sonar.range[e.index]) / 1000 for e in unique]
    assert got == want[: len(got)] and len(got) >= len(want) - 1  # the last may be in flight
    assert link.counters.received == len(got) + link.counters.duplicate


def test_mavlink_link_gets_imu_and_pressure(short_log):
    port = free_udp_port()
    session = serve(
        short_log, rate=5, dvl_port=None, ping_port=None, mavlink=f"udpout:127.0.0.1:{port}"
    ).open()
    assert session.endpoints.mavlink_listen == f"udpin:127.0.0.1:{port}"
    link = MavlinkLink(f"udpin:127.0.0.1:{port}", backoff=FAST)
    records = play(session, {"mavlink": link})["mavlink"]
    live, imu, p = records_to_log(records), short_log.imu, short_log.pressure
    assert len(live.imu) == len(imu) and len(live.pressure) == len(p)
    assert link.message_counts["HEARTBEAT"] >= 5 and link.counters.malformed == 0
    # time_boot_ms = 1000 (log time - t0): the autopilot booted when the log starts
    boot = np.array([r.sensor_time for r in records if r.stream == "imu"])
    np.testing.assert_allclose(boot, np.round(imu.t * 1e3) * 1e-3, atol=1e-9)
    # ATTITUDE: float32 rates and angles; the attitude is the simulator's truth (the AHRS)
    np.testing.assert_allclose(
        live.imu.angular_velocity, imu.angular_velocity, rtol=1e-6, atol=1e-7
    )
    _, rpy, _ = short_log.ground_truth.interpolate(imu.t)
    np.testing.assert_allclose(live.imu.orientation, rpy_to_quaternion(rpy), atol=1e-6)
    # SCALED_PRESSURE2: press_abs in hPa as float32
    np.testing.assert_allclose(live.pressure.pressure, p.pressure, rtol=1e-7)
    # SCALED_IMU2 (what a link with gyro="scaled_imu2" reads): mrad/s and mG integers
    raw = session.served_log(mavlink=MavlinkConfig(gyro="scaled_imu2"))
    np.testing.assert_allclose(raw.imu.angular_velocity, imu.angular_velocity, atol=0.5e-3 + 1e-12)
    np.testing.assert_allclose(
        raw.imu.linear_acceleration, imu.linear_acceleration, atol=0.5e-3 * G0 + 1e-9
    )


def test_the_manifest_is_what_the_links_receive(short_log):
    port = free_udp_port()
    session = serve(
        short_log, rate=10, dvl_port=0, ping_port=0, mavlink=f"udpout:127.0.0.1:{port}"
    ).open()
    links = {
        "a50": trusting_a50(_port(session.endpoints.dvl)),
        "ping": Ping1DLink(session.endpoints.sonar, rate_hz=30.0, backoff=FAST),
        "mavlink": MavlinkLink(f"udpin:127.0.0.1:{port}", backoff=FAST),
    }
    records = play(session, links)
    served = session.served_log()
    live = records_to_log(records["a50"] + records["mavlink"])
    for stream in ("dvl", "dead_reckoning", "imu", "pressure"):
        assert len(live.streams()[stream]) == len(served.streams()[stream]), stream
    # the A50 reports carry the sensor clock: epoch + playback time
    np.testing.assert_allclose(live.dvl.t - session.epoch, served.dvl.t, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(live.dvl.velocity, served.dvl.velocity)
    np.testing.assert_array_equal(live.dead_reckoning.position, served.dead_reckoning.position)
    np.testing.assert_array_equal(live.imu.angular_velocity, served.imu.angular_velocity)
    np.testing.assert_array_equal(live.pressure.pressure, served.pressure.pressure)
    ranges = [r.data["range"] for r in records["ping"]]
    np.testing.assert_array_equal(ranges, served.sonar.range[: len(ranges)])
    summary = session.summary()
    assert summary["messages"]["a50/velocity"] == len(short_log.dvl)
    assert summary["a50_connections"] == 1 and summary["ping_requests"] >= len(ranges)


def test_tcp_drop_refuses_then_reconnects(short_log):
    faults = Faults(drop_dvl=((2.0, 1.0),))
    session = serve(
        short_log, rate=10, dvl_port=0, ping_port=None, mavlink=None, faults=faults
    ).open()
    link = trusting_a50(_port(session.endpoints.dvl))
    records = play(session, {"a50": link})["a50"]
    c, entries = link.counters, session.manifest.select("a50")
    dropped = [e for e in entries if e.fault == "dropped"]
    assert dropped and all(2.0 <= e.t < 3.0 for e in dropped)
    assert c.disconnects >= 1 and c.connects >= 2 and session.a50.connections >= 2
    delivered = sorted((e.stream, e.sensor_time) for e in entries if e.delivered)
    assert sorted((r.stream, r.sensor_time) for r in records) == delivered
    # the rest: the window's reports, and those sent while the link was reconnecting
    unsent = sum(e.fault == "" and e.clients == 0 for e in entries)
    assert len(delivered) + len(dropped) + unsent == len(entries)
    assert not any(2.0 <= r.sensor_time - session.epoch < 3.0 for r in records)


def test_corruption_is_counted_as_malformed(short_log):
    port = free_udp_port()
    session = serve(
        short_log,
        rate=10,
        dvl_port=0,
        ping_port=0,
        mavlink=f"udpout:127.0.0.1:{port}",
        faults=Faults(corrupt=0.1),
        seed=3,
    ).open()
    links = {
        "a50": trusting_a50(_port(session.endpoints.dvl)),
        "ping": Ping1DLink(
            session.endpoints.sonar,
            rate_hz=30.0,
            request_timeout_s=0.05,
            max_timeouts=50,
            backoff=FAST,
        ),
        "mavlink": MavlinkLink(f"udpin:127.0.0.1:{port}", backoff=FAST),
    }
    play(session, links)
    corrupt = {
        p: sum(e.fault == "corrupt" for e in session.manifest.select(p))
        for p in ("a50", "ping1d", "mavlink")
    }
    assert all(n > 0 for n in corrupt.values()), corrupt
    assert links["a50"].counters.malformed == corrupt["a50"]
    assert 1 <= links["ping"].counters.malformed <= corrupt["ping1d"]
    assert links["mavlink"].counters.malformed >= corrupt["mavlink"]
    good = [e for e in session.manifest.select("mavlink") if e.stream and e.delivered]
    assert sum(
        links["mavlink"].message_counts.get(n, 0)
        for n in ("ATTITUDE", "SCALED_IMU2", "SCALED_PRESSURE2")
    ) == len(good)


def test_duplicates_and_reordering_are_counted(short_log):
    faults = Faults(duplicate=0.1, reorder=0.1)
    session = serve(
        short_log, rate=10, dvl_port=0, ping_port=None, mavlink=None, faults=faults, seed=1
    ).open()
    link = trusting_a50(_port(session.endpoints.dvl))
    records = play(session, {"a50": link})["a50"]
    entries = session.manifest.select("a50")
    dup = sum(e.fault == "duplicate" for e in entries)
    moved = sum(e.fault == "reordered" for e in entries)
    assert dup > 0 and moved > 0
    assert link.counters.duplicate == dup and link.counters.out_of_order == moved
    live = records_to_log(records)  # nothing lost: sorted again, it is the log
    np.testing.assert_array_equal(live.dvl.velocity, short_log.dvl.velocity)
    np.testing.assert_array_equal(live.dead_reckoning.position, short_log.dead_reckoning.position)


def test_clock_jumps_are_seen_by_the_links(short_log):
    port = free_udp_port()
    jumps = (("dvl", 2.0, 30.0), ("imu", 2.0, -1.5))
    session = serve(
        short_log,
        rate=4,  # a wall delay d is 4 d sensor s: well under the links' 1 s clock tolerance
        dvl_port=0,
        ping_port=None,
        mavlink=f"udpout:127.0.0.1:{port}",
        faults=Faults(clock_jumps=jumps),
    ).open()
    a50 = A50TcpLink("127.0.0.1", _port(session.endpoints.dvl), backoff=FAST)
    mav = MavlinkLink(f"udpin:127.0.0.1:{port}", backoff=FAST, time_source="sensor")
    records = play(session, {"a50": a50, "mavlink": mav}, scaled=True)
    # the A50's clock agreed with arrival (no offset) until it jumped 30 s ahead
    assert a50.counters.clock_jumps == 1 and len(a50.counters.clock_offsets) == 1
    assert a50.counters.clock_offsets[0][1] == pytest.approx(-30.0, abs=0.5)
    tov = [r.sensor_time - session.epoch for r in records["a50"] if r.stream == "dvl"]
    t = short_log.dvl.t
    np.testing.assert_allclose(tov, t + np.where(t >= 2.0, 30.0, 0.0), atol=1e-6)
    # the autopilot's boot clock: one offset latched per stream, then the IMU's jump
    imu_offsets = len(mav.counters.clock_offsets) - 1  # the pressure stream latched once
    assert mav.counters.clock_jumps == 1 and imu_offsets == 2
    boot = np.array([r.sensor_time for r in records["mavlink"] if r.stream == "imu"])
    ti = short_log.imu.t
    np.testing.assert_allclose(boot, ti + np.where(ti >= 2.0, -1.5, 0.0), atol=1e-3)


def test_loop_keeps_the_served_clock_increasing(short_log):
    log = short_log.replace(**{n: s.select(s.t < 1.0) for n, s in short_log.streams().items()})
    session = serve(log, rate=20, loop=True, dvl_port=0, ping_port=None, mavlink=None).open()
    link = trusting_a50(_port(session.endpoints.dvl))
    records = []
    link.callback = records.append
    with link:
        wait_for(lambda: link.counters.connects >= 1, "a50 connects")
        session.start()
        wait_for(lambda: session.player.laps >= 3, "three laps")
        assert not session.wait(0.01)  # a loop never ends by itself
        session.stop()
        settle([link])
    assert session.done
    dvl = [r.t for r in records if r.stream == "dvl"]
    assert len(dvl) >= 3 * len(log.dvl) and np.all(np.diff(dvl) > 0)
    assert link.counters.out_of_order == link.counters.stale == link.counters.duplicate == 0
    # period: the span of the served rows plus the smallest median spacing (DVL, 8 Hz)
    last = max(log.dvl.t[-1], log.dead_reckoning.t[-1])
    step = min(np.median(np.diff(log.dvl.t)), np.median(np.diff(log.dead_reckoning.t)))
    assert session.player.clock.period == pytest.approx(last - log.dvl.t[0] + step, abs=1e-9)


@pytest.mark.realdata
def test_serves_a_recorded_a50_log():
    path = REAL_DATA / "a50_tcp_json_v1_straight.txt"
    with pytest.warns(UserWarning):
        offline = read_log(path)
    with pytest.warns(UserWarning, match="duplicate"):  # the recording repeats lines
        session = serve(path, rate=20, dvl_port=0, ping_port=None, mavlink=None, duration=3.0)
    session.open()
    link = trusting_a50(_port(session.endpoints.dvl))
    live = records_to_log(play(session, {"a50": link})["a50"])
    n = int(np.sum(offline.dvl.t < offline.dvl.t[0] + 3.0))
    assert len(live.dvl) == n
    np.testing.assert_array_equal(live.dvl.velocity, offline.dvl.velocity[:n])
    np.testing.assert_allclose(live.dvl.t - session.epoch, offline.dvl.t[:n], atol=1e-6)


def test_bad_options_are_one_line():
    with pytest.raises(ConfigError, match="--rate"):
        serve("calm", rate=0)
    with pytest.raises(ConfigError, match="not a scenario"):
        serve("no-such-thing")
    with pytest.raises(ConfigError, match="--clock-jump"):
        Faults.from_options(clock_jump=["gps:1:2"])
    with pytest.raises(ConfigError, match="--drop-dvl"):
        Faults.from_options(drop_dvl=["1"])
    with pytest.raises(ConfigError, match="--duplicate"):
        Faults(duplicate=1.5)
    with pytest.raises(ConfigError, match="--dvl-port"):
        serve("calm", dvl_port=70000)


def test_cli_serve(tmp_path):
    from typer.testing import CliRunner

    import undertow.cli.serve  # noqa: F401  (registers the command)
    from undertow.cli import app

    runner = CliRunner()
    out = tmp_path / "served.jsonl"
    args = [
        "serve",
        "calm",
        "--rate",
        "20",
        "--duration",
        "1",
        "--dvl-port",
        "0",
        "--ping-port",
        "0",
        "--mavlink",
        "off",
        "--json",
        "--manifest",
        str(out),
    ]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout[result.stdout.index("{") :])
    assert summary["messages"]["a50/velocity"] == 8  # 8 Hz for 1 s
    assert summary["messages"]["a50/position_local"] == 5  # 5 Hz for 1 s
    lines = out.read_text().splitlines()
    assert len(lines) == summary["served"] == 13
    assert json.loads(json.loads(lines[0])["payload"])["format"] == "json_v3"
    bad = runner.invoke(app, ["serve", "calm", "--corrupt", "2"])
    assert "--corrupt" in one_error_line(bad)
