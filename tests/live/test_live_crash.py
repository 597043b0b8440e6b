"""`undertow live` killed with SIGKILL mid-session: `info`, `check`, `localize` and `map` read
what it recorded up to its last flushed chunk, and the recording is left byte for byte as it
was.

A simulated log is served (`undertow serve`, in this process) to `undertow live` in a child
process, which is killed (SIGKILL: no handler, no cleanup) some seconds into the dive. The
recorder closes a chunk at the first record at least ``flush_every_s`` = 1 s of record time
after the previous one (:mod:`undertow.live.recorder`), so what is lost is the open chunk: at
most 1 s of records, plus the records still between the sender and the recorder at the kill
(the sockets, the links' queues, the loop's wait: ``TRANSIT_WALL_S`` of wall time at most,
``RATE`` times that in sensor time).
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from undertow.commands.serve import serve
from undertow.io import read_log
from undertow.trajectory import Trajectory

# one worker runs this module's tests, so its module fixtures are built once (make test:
# --dist loadgroup)
pytestmark = [pytest.mark.network, pytest.mark.slow, pytest.mark.xdist_group("live_crash")]

RATE = 2.0  # served at twice real time
SPAN_S = 40.0  # seconds of the simulated log served (the kill comes before its end)
KILL_AT_S = 14.0  # sensor seconds played when live is killed
WAVE = "wave-a0.10-f1.00"
FLUSH_S = 1.0  # the recorder's flush_every_s (its default, which live uses)
#: wall time a record may spend between the sender and the recorder on a loaded machine
TRANSIT_WALL_S = 0.25
CLI = [sys.executable, "-c", "from undertow.cli import app; app()"]


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _digest(folder: Path) -> dict:
    return {
        str(p.relative_to(folder)): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_size)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _wait_for(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.01)


@pytest.fixture(scope="module")
def crashed(simulation, tmp_path_factory):
    """(served log up to the kill, live's output folder, env of the commands run after)."""
    log = simulation(WAVE).log
    t0 = log.time_span[0]
    log = log.replace(**{n: s.select(s.t < t0 + SPAN_S) for n, s in log.streams().items()})
    root = tmp_path_factory.mktemp("crash")
    out = root / "dive"
    env = {**os.environ, "UNDERTOW_CACHE_DIR": str(root / "cache")}
    port = _free_udp_port()
    session = serve(log, rate=RATE, dvl_port=0, ping_port=0,
                    mavlink=f"udpout:127.0.0.1:{port}", wait_for_clients=20.0).open()  # fmt: skip
    ends = session.endpoints
    args = ["live", "--out", str(out), "--dvl", ends.dvl, "--sonar", ends.sonar,
            "--mavlink", ends.mavlink_listen, "--time-scale", str(RATE), "--wave", WAVE,
            "--idle-stop", "60", "--quiet"]  # fmt: skip
    proc = subprocess.Popen([*CLI, *args], env=env, stderr=subprocess.PIPE, text=True)
    try:
        # the recorder opens just before the links: then give the MAVLink link time to bind
        _wait_for(lambda: any(out.glob("recording.partial-*")) or proc.poll() is not None, 120,
                  "live to start")  # fmt: skip
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(1.0)
        session.start()
        _wait_for(lambda: session.summary()["played_s"] >= KILL_AT_S, 120, "the playback")
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(30)
        served = session.served_log()
    finally:
        session.stop()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    return served, out, env


def test_the_kill_leaves_only_the_partial_recording(crashed):
    _, out, _ = crashed
    assert not (out / "recording").exists()
    (partial,) = out.glob("recording.partial-*")
    assert (partial / "recording" / "recording.mcap").stat().st_size > 0


def test_info_localize_and_map_read_it_up_to_a_second_before_the_kill(crashed, tmp_path):
    served, out, env = crashed
    before = _digest(out)
    target = out / "recording"

    def run(*args):
        done = subprocess.run([*CLI, *args], env=env, capture_output=True, text=True,
                              timeout=600)  # fmt: skip
        assert done.returncode == 0, done.stderr
        lines = [ln for ln in done.stderr.splitlines() if "incomplete recording" in ln]
        assert len(lines) == 1 and "recovered" in lines[0], done.stderr
        return done

    info = json.loads(run("info", str(target), "--json").stdout)
    run("check", str(target))  # exit 0: ready to localize
    run("localize", str(target), "--out", str(tmp_path / "loc"), "--wave", WAVE)
    run("map", str(target), "--trajectory", str(tmp_path / "loc"), "--out", str(tmp_path / "map"))
    assert _digest(out) == before  # the original, byte for byte

    recovered = read_log(target)
    n = len(recovered.imu)
    counts = {s["name"]: s["messages"] for s in info["streams"]}
    assert counts["imu"] == n and counts["dvl"] == len(recovered.dvl) > 0
    # every record recovered is one served, in order: the first n of each stream
    np.testing.assert_allclose(recovered.imu.angular_velocity, served.imu.angular_velocity[:n],
                               rtol=0, atol=1e-6)  # fmt: skip
    k = len(recovered.dvl)
    assert np.ptp(recovered.dvl.t - served.dvl.t[:k]) < 1e-5  # the A50's clock: one offset
    np.testing.assert_allclose(recovered.dvl.velocity, served.dvl.velocity[:k], atol=1e-9)
    # what is lost: from the last recovered IMU record to the kill, in served sensor time (an
    # overestimate if a datagram was lost on the way)
    killed_at = max(s.t[-1] for s in served.streams().values() if len(s))
    lost = killed_at - served.imu.t[n - 1]
    assert 0 <= lost <= FLUSH_S + RATE * TRANSIT_WALL_S, lost
    trajectory = Trajectory.load_npz(tmp_path / "loc" / "trajectory.npz")
    assert trajectory.t[-1] >= recovered.time_span[1] - 0.05
    assert (tmp_path / "map" / "map.npz").is_file()
