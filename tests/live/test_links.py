"""Live sensor links against servers these tests start on 127.0.0.1 (ephemeral ports): an A50
TCP JSON server replaying the real recording and a simulated log with faults, a Ping1D UDP
server answering with frames encoded by brping's message definitions, and MAVLink packets sent
with pymavlink's encoder."""

from __future__ import annotations

import json
import math
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import REAL_DATA

from undertow.io import read_log
from undertow.io.a50_json import velocity_report_line
from undertow.live.links import A50TcpLink, Backoff, ClockPolicy, LinkCounters
from undertow.records import RECORD_FIELDS, records_to_log

#: opens sockets on 127.0.0.1 (servers it starts)
pytestmark = pytest.mark.network

V1 = REAL_DATA / "a50_tcp_json_v1_straight.txt"
CORPUS = Path(__file__).resolve().parents[2] / "fuzz" / "corpus"
FAST = Backoff(initial=0.02, factor=2.0, maximum=0.1)
CONFIG = {"speed_of_sound": 1475, "acoustic_enabled": True, "mounting_rotation_offset": 0}


class A50Server:
    """A TCP server on 127.0.0.1 that sends ``lines`` to its clients, resuming where the last
    connection stopped; the first connection is dropped after ``drop_after`` lines (None: never).
    It answers ``get_config`` and records every command it receives."""

    def __init__(self, lines: list[str], drop_after: int | None = None) -> None:
        self.lines, self.drop_after = lines, drop_after
        self.sent = 0
        self.connections = 0
        self.commands: list[str] = []
        self.done = threading.Event()
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while self.sent < len(self.lines):
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.connections += 1
            with conn:
                self._commands(conn)
                limit = self.drop_after if self.connections == 1 else None
                stop = len(self.lines) if limit is None else min(limit, len(self.lines))
                chunk = "".join(ln + "\n" for ln in self.lines[self.sent : stop])
                conn.sendall(chunk.encode())
                self.sent = stop
                if self.sent >= len(self.lines):
                    self._commands(conn)
                    self.done.set()
                    time.sleep(0.2)

    def _commands(self, conn: socket.socket) -> None:
        conn.settimeout(0.1)
        data = b""
        while True:
            try:
                chunk = conn.recv(4096)
            except TimeoutError:
                break
            if not chunk:
                break
            data += chunk
        for line in data.decode().splitlines():
            cmd = json.loads(line)["command"]
            self.commands.append(cmd)
            reply = {
                "response_to": cmd,
                "success": True,
                "error_message": "",
                "result": CONFIG if cmd == "get_config" else None,
                "format": "json_v3",
                "type": "response",
            }
            conn.sendall((json.dumps(reply) + "\n").encode())

    def close(self) -> None:
        self.sock.close()


def settle(link, quiet: float = 0.3, timeout: float = 10.0) -> None:
    """Wait until the link received nothing new for ``quiet`` s."""
    deadline = time.monotonic() + timeout
    last, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        link.pump()  # (a deferred link's data is decoded here; nothing to do otherwise)
        now = link.counters.received + len(link._raw)
        if now != last:
            last, since = now, time.monotonic()
        elif time.monotonic() - since > quiet:
            return
        time.sleep(0.02)


def run_link(link, server, timeout: float = 10.0):
    """Start ``link``, wait until ``server`` sent everything and the link is quiet, stop it."""
    records = []
    link.callback = records.append
    with link:
        assert server.done.wait(timeout), "server did not finish"
        settle(link)
    link.pump()
    server.close()
    return records


def _v1_unique() -> list[str]:
    return list(dict.fromkeys(ln for ln in V1.read_text().splitlines() if ln.strip()))


@pytest.mark.realdata
@pytest.mark.parametrize("deferred", [False, True])
def test_real_v1_recording_with_a_drop_and_garbage(deferred):
    """The same records and counters whether the link's thread decodes the lines or
    (deferred) pump() in the caller's thread does, the thread waking it for each read."""
    raw = [ln for ln in V1.read_text().splitlines() if ln.strip()]  # as the A50 sent it
    unique = _v1_unique()
    lines = list(raw)
    lines[10:10] = ["this is not json {", '{"vx": "fast"}', "[" * 100_000]
    server = A50Server(lines, drop_after=len(lines) // 2)
    wakes = []
    link = A50TcpLink("127.0.0.1", server.port, backoff=FAST, deferred=deferred,
                      wake=lambda: wakes.append(1))  # fmt: skip
    records = run_link(link, server)
    assert (len(wakes) > 0) == deferred
    c = link.counters
    assert server.connections == 2 and c.connects >= 2 and c.disconnects >= 1
    assert c.malformed == 3 and c.stale == 0
    assert c.duplicate == len(raw) - len(unique)  # the recording repeats lines
    assert len(records) == len(unique) == c.delivered
    with pytest.warns(UserWarning, match="duplicate"):
        offline = read_log(V1)
    live = records_to_log(records)
    for name in ("velocity", "valid", "fom", "altitude", "beam_range", "beam_valid"):
        np.testing.assert_array_equal(getattr(live.dvl, name), getattr(offline.dvl, name), name)
    assert all(math.isnan(r.sensor_time) for r in records)  # json_v1: stamped on arrival
    assert all(r.t == r.arrival for r in records)
    assert server.commands == ["get_config", "get_config"]  # after each connection
    assert link.info["config"] == CONFIG


def test_real_v3_lines_use_time_of_validity():
    lines = [ln for ln in (CORPUS / "a50_json_v3.txt").read_text().splitlines() if ln.strip()]
    server = A50Server(lines)
    link = A50TcpLink("127.0.0.1", server.port, backoff=FAST)
    records = run_link(link, server)
    tov = [json.loads(ln).get("time_of_validity") for ln in lines]
    velocity = [r for r in records if r.stream == "dvl"]
    assert len(velocity) == sum(v is not None for v in tov) > 0
    np.testing.assert_array_equal(
        [r.sensor_time for r in velocity], [v * 1e-6 for v in tov if v is not None]
    )
    # recorded long ago and replayed ~1000x faster than real time: the policy shifts the sensor
    # clock by a recorded offset and re-latches whenever a report would lie in the future
    c = link.counters
    streams = {r.stream for r in records}  # each latches its own first offset
    assert len(c.clock_offsets) == c.clock_jumps + len(streams)
    assert all(r.t <= r.arrival + 1.0 for r in records)


def _position_line(ts: float, p, rpy_rad) -> str:
    roll, pitch, yaw = np.rad2deg(rpy_rad)
    return json.dumps(
        {
            "ts": ts,
            "x": p[0],
            "y": p[1],
            "z": p[2],
            "std": 0.01,
            "roll": roll,
            "pitch": pitch,
            "yaw": yaw,
            "type": "position_local",
            "status": 0,
            "format": "json_v3",
        }
    )


def simulated_lines(log, epoch: float = 1_700_000_000.0) -> list[str]:
    """The simulated DVL and dead reckoning as A50 json_v3 lines in time order."""
    dvl, dr = log.dvl, log.dead_reckoning
    rows = [(t, velocity_report_line(dvl, i, 125.0, epoch + t)) for i, t in enumerate(dvl.t)]
    rows += [
        (t, _position_line(epoch + t, dr.position[i], dr.orientation[i]))
        for i, t in enumerate(dr.t)
    ]
    return [line for _, line in sorted(rows, key=lambda r: r[0])]


def test_simulated_log_matches_the_offline_reader(simulation, tmp_path):
    log = simulation("calm")
    log = log.log if hasattr(log, "log") else log
    lines = simulated_lines(log)
    swapped = list(lines)
    i = next(
        k for k in range(5, len(lines)) if '"velocity"' in lines[k] and '"velocity"' in lines[k + 1]
    )
    swapped[i], swapped[i + 1] = swapped[i + 1], swapped[i]  # one reordered pair
    swapped.insert(i + 5, lines[i + 3])  # one duplicate
    server = A50Server(swapped, drop_after=len(lines) // 3)
    counters = LinkCounters()
    trust = ClockPolicy(counters, max_offset_s=math.inf)  # replayed faster than real time
    link = A50TcpLink("127.0.0.1", server.port, backoff=FAST, clock=trust)
    records = run_link(link, server)
    assert link.counters.out_of_order == 1 and link.counters.duplicate == 1
    path = tmp_path / "a50.jsonl"
    path.write_text("\n".join(lines) + "\n")
    offline = read_log(path)
    live = records_to_log(records)
    for name in ("t", *RECORD_FIELDS["dvl"]):
        np.testing.assert_array_equal(getattr(live.dvl, name), getattr(offline.dvl, name), name)
    for name in ("t", "position", "orientation", "std"):
        np.testing.assert_array_equal(
            getattr(live.dead_reckoning, name), getattr(offline.dead_reckoning, name), name
        )
    np.testing.assert_allclose(live.dvl.velocity, log.dvl.velocity, rtol=0, atol=0)


def test_optional_commands_only_when_asked():
    server = A50Server(_v1_unique()[:20])
    link = A50TcpLink(
        "127.0.0.1", server.port, backoff=FAST, reset_dead_reckoning=True, calibrate_gyro=True
    )
    run_link(link, server)
    assert server.commands == ["get_config", "reset_dead_reckoning", "calibrate_gyro"]
    assert [r["response_to"] for r in link.responses] == server.commands


def test_reconnects_with_backoff_when_nothing_listens():
    sock = socket.create_server(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()  # nothing listens on this port now
    link = A50TcpLink("127.0.0.1", port, backoff=Backoff(0.01, 2.0, 0.05))
    with link:
        time.sleep(0.4)
        assert link.running
    assert link.counters.connects == 0 and "connect" in link.counters.last_error
    assert Backoff(0.2, 2.0, 5.0).delay(0) == 0.2 and Backoff(0.2, 2.0, 5.0).delay(10) == 5.0


def test_clock_policy_far_off_clock_and_stale_reports():
    c = LinkCounters()
    policy = ClockPolicy(c, max_offset_s=1.0, stale_after_s=5.0, confirm=3)
    boot, a = 49_056.8, 1_700_000_000.0  # a sensor clock counting from boot; arrival (Unix)
    times = [policy.stamp("dr", a + k * 0.2 + 0.01, boot + k * 0.2) for k in range(10)]
    offset = a + 0.01 - boot
    np.testing.assert_allclose(times, [boot + k * 0.2 + offset for k in range(10)], atol=1e-9)
    assert c.clock_offsets == [(a + 0.01, offset)] and c.clock_jumps == 0
    # the sensor clock jumps 100 s forward: in the future of arrival, so stamped on arrival
    # until three reports agree on the new offset, then re-latched
    assert policy.stamp("dr", a + 2.01, boot + 102.0) == a + 2.01
    assert policy.stamp("dr", a + 2.21, boot + 102.2) == a + 2.21 and c.clock_jumps == 0
    assert abs(policy.stamp("dr", a + 2.41, boot + 102.4) - (a + 2.41)) < 1e-6
    assert c.clock_jumps == 1 and len(c.clock_offsets) == 2
    # one late report is transport delay: it keeps the sensor's time
    assert abs(policy.stamp("dr", a + 4.6, boot + 102.6) - (a + 2.61)) < 1e-6
    # an old report far behind the newest is stale and dropped; a slightly older one is kept
    assert policy.stamp("dr", a + 4.7, boot + 95.0) is None and c.stale == 1
    assert policy.stamp("dr", a + 2.75, boot + 102.5) is not None and c.out_of_order == 1
    # a single absurd sensor time is stamped on arrival and neither moves the clock nor makes
    # the next good reports stale
    assert policy.stamp("dr", a + 2.8, boot + 1e9) == a + 2.8
    assert abs(policy.stamp("dr", a + 2.85, boot + 102.8) - (a + 2.81)) < 1e-6
    assert c.stale == 1 and c.clock_jumps == 1
    # without a sensor time: the arrival time
    assert policy.stamp("sonar", 123.0, None) == 123.0


def test_trusted_sensor_clock_survives_one_absurd_time():
    c = LinkCounters()
    policy = ClockPolicy(c, max_offset_s=math.inf)
    assert [policy.stamp("dvl", 0.0, s) for s in (10.0, 10.1, 9e18, 10.2)] == [
        10.0,
        10.1,
        9e18,
        10.2,
    ]
    assert c.stale == 0 and c.out_of_order == 0  # 9e18 was never confirmed as the newest


def test_sensor_clock_agreeing_with_arrival_is_trusted():
    c = LinkCounters()
    policy = ClockPolicy(c, max_offset_s=1.0)
    now = time.time()
    assert policy.stamp("dvl", now + 0.3, now) == now and c.clock_offsets == []


def test_records_queue_is_bounded():
    lines = [ln for ln in (CORPUS / "a50_json_v3.txt").read_text().splitlines() if ln.strip()]
    server = A50Server(lines[:50])
    link = A50TcpLink("127.0.0.1", server.port, backoff=FAST, max_queue=10, max_offset_s=math.inf)
    with link:
        assert server.done.wait(10)
        settle(link)
    server.close()
    got = list(link.records(idle_timeout=0.05))
    assert len(got) == 10 and link.counters.overflow == 40 and link.counters.delivered == 50


def test_stop_is_prompt():
    server = A50Server(["{}"] * 3)
    link = A50TcpLink("127.0.0.1", server.port, backoff=FAST).start()
    time.sleep(0.2)
    t0 = time.monotonic()
    link.stop()
    assert not link.running and time.monotonic() - t0 < 2.0
    server.close()


# -- Ping1D ---------------------------------------------------------------------------------


class PingServer:
    """A UDP Ping1D on 127.0.0.1 answering requests with frames packed by brping's own message
    definitions; distances (mm), confidences (%) and ping numbers come from ``pings`` (one per
    distance request, the last repeated); requests numbered inside ``silent`` (a range) are not
    answered, as when the tether drops."""

    def __init__(self, pings, silent: range = range(0), garbage_every: int = 0) -> None:
        from brping import definitions, pingmessage

        self.defs, self.pm = definitions, pingmessage
        self.pings, self.silent, self.garbage_every = pings, silent, garbage_every
        self.requests = 0
        self.served = 0
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.port = self.sock.getsockname()[1]
        self.running = True
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _reply(self, msg_id: int) -> bytes:
        msg = self.pm.PingMessage(msg_id)
        if msg_id == self.defs.PING1D_DISTANCE:
            i = min(self.served, len(self.pings) - 1)
            msg.distance, msg.confidence, msg.ping_number = self.pings[i]
            msg.scan_length = 30_000
            self.served += 1
        elif msg_id == self.defs.COMMON_PROTOCOL_VERSION:
            msg.version_major = 1
        msg.pack_msg_data()
        return bytes(msg.msg_data)

    def _serve(self) -> None:
        parser = self.pm.PingParser()
        while self.running:
            try:
                data, addr = self.sock.recvfrom(4096)
            except (TimeoutError, OSError):
                continue
            out = self.answer(parser, data)
            if out:
                self.sock.sendto(out, addr)

    def answer(self, parser, data: bytes) -> bytes:
        """The reply frames to the requests in ``data``."""
        replies = b""
        for byte in data:
            if parser.parse_byte(byte) != self.pm.PingParser.NEW_MESSAGE:
                continue
            msg = parser.rx_msg
            wanted = (
                msg.requested_id
                if msg.message_id == self.defs.COMMON_GENERAL_REQUEST
                else msg.message_id
            )
            self.requests += 1
            if self.requests in self.silent:
                continue
            out = self._reply(wanted)
            if self.garbage_every and self.requests % self.garbage_every == 0:
                bad = bytearray(out)
                bad[-1] ^= 0xFF  # a checksum error, then the good frame
                out = b"\x00garbage" + bytes(bad) + out
            replies += out
        return replies

    def close(self) -> None:
        self.running = False
        self.thread.join(1)
        self.sock.close()


def test_ping1d_udp_distance_confidence_and_duplicates():
    from undertow.live.links.ping1d import Ping1DLink

    pings = [(1000 + 10 * k, 50 + k, k) for k in range(30)]
    pings[10] = pings[9]  # the same ping polled twice: a duplicate
    server = PingServer(pings, garbage_every=7)
    records = []
    link = Ping1DLink(f"udp://127.0.0.1:{server.port}", records.append, rate_hz=100.0, backoff=FAST)
    with link:
        deadline = time.monotonic() + 10
        while server.served < len(pings) and time.monotonic() < deadline:
            time.sleep(0.02)
    server.close()
    unique = [p for k, p in enumerate(pings) if k != 10]
    got = records[: len(unique)]
    np.testing.assert_array_equal([r.data["range"] for r in got], [p[0] / 1000.0 for p in unique])
    np.testing.assert_allclose([r.data["confidence"] for r in got], [p[1] / 100 for p in unique])
    assert link.counters.duplicate >= 1 and link.counters.malformed >= 1
    assert all(r.t == r.arrival and math.isnan(r.sensor_time) for r in records)
    assert np.all(np.diff([r.t for r in records]) >= 0)
    log = records_to_log(records)
    assert len(log.sonar) == len(records)


def test_ping1d_reconnects_after_silence():
    from undertow.live.links.ping1d import Ping1DLink

    server = PingServer([(2000, 90, k) for k in range(1000)], silent=range(11, 14))
    records = []
    link = Ping1DLink(
        f"udp://127.0.0.1:{server.port}",
        records.append,
        rate_hz=100.0,
        request_timeout_s=0.05,
        max_timeouts=3,
        backoff=FAST,
    )
    with link:
        deadline = time.monotonic() + 10
        while not (link.counters.connects >= 2 and len(records) > 15):
            assert time.monotonic() < deadline, link.counters
            time.sleep(0.02)
    server.close()
    c = link.counters
    assert c.disconnects >= 1 and link.timeouts >= 3 and c.connects >= 2
    assert len(records) > 15 and c.delivered == len(records)  # pings again after reconnecting


def test_ping_device_strings():
    from undertow.errors import ConfigError
    from undertow.live.links.ping1d import parse_device

    assert parse_device("udp://192.168.2.2:9090") == ("udp", "192.168.2.2", 9090)
    assert parse_device("192.168.2.2:9090") == ("udp", "192.168.2.2", 9090)
    assert parse_device("/dev/ttyUSB0") == ("serial", "/dev/ttyUSB0", 115200)
    assert parse_device("serial:///dev/ttyAMA0?baud=9600") == ("serial", "/dev/ttyAMA0", 9600)
    with pytest.raises(ConfigError, match="udp://HOST:PORT"):
        parse_device("udp://host:notaport")


# -- MAVLink --------------------------------------------------------------------------------


def _free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


@pytest.fixture
def kernel_stamps():
    """The kernel's receive timestamps switched on before a test relies on them, and kept on
    by an open socket that asks for them: Linux enables them for the whole stack the first time
    a socket asks, in deferred work (net/core/dev.c, ``netstamp_work``), and stamps a datagram
    received before that with the time it is read (net/socket.c, ``__sock_recv_timestamp``:
    "Race occurred between timestamp enabling and packet receiving")."""
    from undertow.live.links import stamped

    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    stamped.enable(receiver)
    reader = stamped.Reader(receiver, time.time)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    deadline = time.monotonic() + 10.0
    try:
        while True:  # a probe stamped well before its read: the stamps are on
            sender.sendto(b"probe", receiver.getsockname())
            time.sleep(0.05)
            read_at = time.time()
            got = reader.read()
            if got is not None and got[1] < read_at - 0.025:
                break
            assert time.monotonic() < deadline, "the kernel never stamped a datagram on receipt"
        yield
    finally:
        sender.close()
        receiver.close()


def _wait(condition, link, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, link.message_counts
        time.sleep(0.005)


@pytest.mark.parametrize("mode", ["thread", "deferred", "polled"])
def test_mavlink_udp_same_mapping_as_tlog(tmp_path, simulation, mode, kernel_stamps):
    """The link's records are the .tlog reader's, decoded in the link's thread or (deferred)
    by pump() in the caller's, which is woken by the datagrams holding DVL messages, or
    (polled) read and decoded by pump() alone, stamped with the kernel's receive times."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2
    from tlog_fixtures import attitude_rows, pressure_rows, sonar_rows, vision_rows, write_tlog

    from undertow.live.links.mavlink_udp import MavlinkLink

    log = simulation("calm")
    log = log.log if hasattr(log, "log") else log
    log = log.replace(**{n: s.select(s.t < 3.0) for n, s in log.streams().items()})
    vision, _ = vision_rows(log)
    rows = sorted(
        attitude_rows(log) + pressure_rows(log) + vision + sonar_rows(log), key=lambda r: r[0]
    )
    port = _free_udp_port()
    records, wakes, sent = [], [], []
    deferred = mode != "thread"
    link = MavlinkLink(f"udpin:127.0.0.1:{port}", records.append, backoff=FAST,
                       deferred=deferred, wake=lambda: wakes.append(len(records)),
                       polled=mode == "polled")  # fmt: skip
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def received(n):
        link.pump()  # (nothing to do in the thread mode)
        return sum(link.message_counts.values()) >= n

    with link:
        _wait(lambda: link.counters.connects >= 1, link)  # bound before anything is sent
        if mode == "polled":
            _wait(lambda: link._polling is not None, link)
        if deferred:
            sent.append(time.time())
            sender.sendto(rows[0][1].pack(mav), ("127.0.0.1", port))
            if mode == "deferred":
                _wait(lambda: len(link._raw) == 1, link)
            else:  # long enough that a loaded machine's scheduling delays stay well inside it
                time.sleep(0.5)
            assert records == [] and link.message_counts == {}  # queued, not decoded
            read_at = time.time()
            received(1)
            assert len(records) == 1
            if mode == "polled":  # the kernel's receive time, not the read 0.5 s later
                assert sent[0] <= records[0].arrival < read_at - 0.25
        for k, (_, msg) in enumerate(rows[1:] if deferred else rows):
            sender.sendto(msg.pack(mav), ("127.0.0.1", port))
            if k == 50:  # a whole frame whose CRC fails
                bad = bytearray(msg.pack(mav))
                bad[12] ^= 0xFF
                sender.sendto(bytes(bad), ("127.0.0.1", port))
            if k % 20 == 19:  # let the receiver keep up: loopback UDP drops what overflows
                _wait(lambda n=k + 1: received(n), link)
        _wait(lambda: received(len(rows)), link)
    sender.close()
    assert link.counters.malformed >= 1
    n_vision = sum(m.get_type() == "VISION_POSITION_DELTA" for _, m in rows)
    assert len(wakes) == (n_vision if mode == "deferred" else 0) and n_vision > 0
    path = tmp_path / "same.tlog"
    write_tlog(path, rows)
    offline = read_log(path)
    live = records_to_log(records)
    for name in ("imu", "pressure", "sonar", "dvl", "dead_reckoning"):
        assert len(live.streams()[name]) == len(offline.streams()[name]), name
    np.testing.assert_array_equal(live.imu.angular_velocity, offline.imu.angular_velocity)
    np.testing.assert_array_equal(live.imu.orientation, offline.imu.orientation)
    np.testing.assert_array_equal(live.pressure.pressure, offline.pressure.pressure)
    np.testing.assert_array_equal(live.sonar.range, offline.sonar.range)
    np.testing.assert_array_equal(live.dvl.velocity, offline.dvl.velocity)
    np.testing.assert_array_equal(live.dead_reckoning.position, offline.dead_reckoning.position)
    assert all(r.t == r.arrival for r in records)  # stamped on arrival, as a tlog's receive time
    arrivals = np.array([r.arrival for r in records])
    assert np.all(np.diff(arrivals) >= 0)


def test_polled_mavlink_counts_the_kernels_drops_and_stamps_on_its_clock(kernel_stamps):
    """A polled link's socket (with a small receive buffer) not read while 3000 datagrams
    arrive: the kernel drops what its receive buffer cannot hold (counted as overflow: every
    datagram sent is a record or a drop), and each record is stamped with its receive time
    through the link's clock (a ScaledClock at 10x: c(w), not the read time); a link silent
    for idle_timeout_s reconnects."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    from undertow._util.clocks import ScaledClock
    from undertow.live.links.mavlink_udp import MavlinkLink

    port = _free_udp_port()
    records = []
    clock = ScaledClock(10.0)
    link = MavlinkLink(f"udpin:127.0.0.1:{port}", records.append, backoff=FAST, deferred=True,
                       polled=True, now=clock, idle_timeout_s=0.5)  # fmt: skip
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    n = 3000
    with link:
        _wait(lambda: link._polling is not None, link)
        # a small receive buffer (the kernel's minimum: a few datagrams) to make it drop some
        link._polling[1].sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        first = clock()
        for k in range(n):
            msg = mavlink2.MAVLink_attitude_message(k, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0)
            sender.sendto(msg.pack(mav), ("127.0.0.1", port))
        last = clock()
        time.sleep(0.1)
        read = clock()
        link.pump()
        assert first <= records[0].arrival and records[-1].arrival <= last < read - 0.5
        kept = len(records)
        assert kept < n and link.counters.overflow == 0  # (a drop is told with the next one)
        sender.sendto(msg.pack(mav), ("127.0.0.1", port))
        _wait(lambda: link.pump() or len(records) > kept, link)
        assert len(records) + link.counters.overflow == n + 1
        _wait(lambda: link.counters.disconnects >= 1 and link._polling is not None, link)
    sender.close()
    assert link.counters.connects >= 2


def test_deferred_mavlink_wakes_on_dvl_frames_in_either_protocol_version():
    """The DVL message's id is taken from the MAVLink 2 module even while the connection still
    parses MAVLink 1 (whose module lacks ids above 255), and read off both frame layouts."""
    from pymavlink.dialects.v10 import ardupilotmega as mavlink1
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    from undertow.live.links.mavlink_udp import _frame_id, _message_id

    assert not hasattr(mavlink1, "MAVLINK_MSG_ID_VISION_POSITION_DELTA")
    dvl = mavlink2.MAVLINK_MSG_ID_VISION_POSITION_DELTA
    assert _message_id(mavlink1.MAVLink(None), "VISION_POSITION_DELTA") == dvl
    assert _message_id(mavlink2.MAVLink(None), "VISION_POSITION_DELTA") == dvl
    mav2, mav1 = mavlink2.MAVLink(None), mavlink1.MAVLink(None)
    frame = mavlink2.MAVLink_vision_position_delta_message(1, 100_000, [0.0] * 3, [0.0] * 3, 90.0)
    assert _frame_id(frame.pack(mav2)) == dvl
    assert _frame_id(mavlink1.MAVLink_heartbeat_message(12, 3, 0, 0, 0, 3).pack(mav1)) == 0
    assert _frame_id(b"\x00junk") is None


def test_deferred_mavlink_queue_is_bounded():
    """A deferred link keeps at most max_queue datagrams for pump(): the oldest are dropped
    and counted as overflow; pump() then delivers the newest."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    from undertow.live.links.mavlink_udp import MavlinkLink

    port = _free_udp_port()
    records = []
    link = MavlinkLink(f"udpin:127.0.0.1:{port}", records.append, backoff=FAST, deferred=True,
                       max_queue=5)  # fmt: skip
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    with link:
        _wait(lambda: link.counters.connects >= 1, link)
        for k in range(20):
            msg = mavlink2.MAVLink_scaled_pressure2_message(k, 1000.0 + k, 0.0, 1500)
            sender.sendto(msg.pack(mav), ("127.0.0.1", port))
        _wait(lambda: link.counters.overflow + len(link._raw) >= 20, link)
        link.pump()
    sender.close()
    assert link.counters.overflow == 15
    assert [r.data["pressure"] for r in records] == [100.0 * (1000.0 + k) for k in range(15, 20)]


def test_ping1d_serial_device():
    """The serial path of the link (brping's connect_serial) against a pseudo-terminal whose
    other end answers like a Ping1D."""
    import os
    import select
    import tty

    from undertow.live.links.ping1d import Ping1DLink

    master, slave = os.openpty()
    tty.setraw(slave)
    server = PingServer([(3000 + k, 60, k) for k in range(1000)])
    server.close()  # only its answers are used, over the pseudo-terminal
    stop = threading.Event()

    def serve():
        parser = server.pm.PingParser()
        while not stop.is_set():
            if select.select([master], [], [], 0.05)[0]:
                out = server.answer(parser, os.read(master, 4096))
                if out:
                    os.write(master, out)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    records = []
    link = Ping1DLink(os.ttyname(slave), records.append, rate_hz=50.0, backoff=FAST)
    with link:
        deadline = time.monotonic() + 10
        while len(records) < 5:
            assert time.monotonic() < deadline, link.counters
            time.sleep(0.02)
    stop.set()
    thread.join(1)
    os.close(master)
    os.close(slave)
    assert len(records) >= 5 and link.counters.connects == 1
    ranges = [r.data["range"] for r in records]
    np.testing.assert_array_equal(ranges, [(3000 + k) / 1000.0 for k in range(len(records))])


def test_mavlink_serial_device():
    """The link on a serial device (a pseudo-terminal fed with MAVLink frames)."""
    import os
    import tty

    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    from undertow.live.links.mavlink_udp import MavlinkLink

    master, slave = os.openpty()
    tty.setraw(slave)
    records = []
    link = MavlinkLink(os.ttyname(slave), records.append, backoff=FAST)
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    with link:
        # the device opened (a fixed sleep lost the first frames on a clean clone's slow first
        # import: the open discards what the terminal already held)
        _wait(lambda: link.counters.connects >= 1, link)
        for k in range(20):
            os.write(
                master, mavlink2.MAVLink_scaled_pressure2_message(k, 1000.0 + k, 0, 0).pack(mav)
            )
            time.sleep(0.005)
        deadline = time.monotonic() + 5
        while len(records) < 20 and time.monotonic() < deadline:
            time.sleep(0.02)
    os.close(master)
    os.close(slave)
    np.testing.assert_allclose([r.data["pressure"] for r in records], 1e5 + 100.0 * np.arange(20))


def test_links_and_grid_load_their_code_ahead():
    """load() imports a link's protocol library in the calling thread (a live session calls it
    before freezing its long-lived objects out of the collector's reach) and load_kernels()
    loads the grid's growth kernel, so neither happens mid-session. Checked in a fresh
    interpreter, where nothing is loaded yet."""
    import subprocess
    import sys

    script = """
import sys
from undertow.live.links.mavlink_udp import MavlinkLink
from undertow.live.links.ping1d import Ping1DLink
from undertow.mapping import chunks, grid
mav, ping = MavlinkLink("udpin:127.0.0.1:0"), Ping1DLink("udp://127.0.0.1:9")
loaded = lambda prefix: any(m.startswith(prefix) for m in sys.modules)
assert not loaded("pymavlink.dialects.v20") and not loaded("brping")
assert not chunks.rehash.signatures
mav.load(); ping.load(); grid.load_kernels()
from pymavlink import mavutil
assert "pymavlink.dialects.v20." + mavutil.current_dialect in sys.modules
assert loaded("brping") and chunks.rehash.signatures
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
