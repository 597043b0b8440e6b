"""The whole live pipeline against the virtual robot (`make bench ONLY=live`).

`undertow serve` plays a simulated run at RATE x real time in a separate process (A50 over TCP,
Ping1D over UDP, MAVLink over UDP on 127.0.0.1); a :class:`LiveSession` in this process runs
the links, the recording, the filter, the online map (and the Foxglove view, in the second run,
with one client subscribed to every channel: another process, the Foxglove app's stand-in)
with its clock scaled by RATE.

**One core.** The target is a speed on one core: every thread of this process (links, loop,
the view's server) is pinned to one core, and serve and the viewer (the sensors and the
Foxglove app, other devices on a robot) to another. The same two runs are then made unpinned
(``unpinned``: every process free on every core, the sensors' stand-in sharing this process's
cores and caches), for comparison.

Figures:
- ``cpu_s_per_realtime_s``: CPU seconds of this process (every thread: links, recording,
  filter, map, view) per second of sensor data while the session runs; ``realtime_factor`` =
  its inverse, the speed at which one core keeps up. Target: >= 50 (a Raspberry Pi 4 is about
  5-10x slower than this machine, so >= 5-10x real time there). The one-off cost of writing
  the final results after the data stops (compressed trajectory and map, closing the
  recording) is ``finish_cpu_s``, apart: it does not grow with the rate of the sensors.
- ``sensor_seconds``: the span of the log served (``dvl_span_s``: of the DVL reports recorded,
  on the A50's clock, which a late arrival may relatch; ``filter_span_s``: of the filter's
  states, which also counts the arrival stamps of the clockless MAVLink and Ping records,
  stretched when this process falls behind);
  ``cpu_s_by_thread``: where the CPU went (MainThread: decoding the A50's data, which its
  thread only receives, reading and decoding MAVLink's socket, recording, filter, map, view; the
  rest of ``cpu_s`` is the view server's native threads).
- ``latency_ms``: wall time from a DVL report's arrival (its bytes received by the link's thread)
  to its pose being published (the preview on the committed filter), median and p99. Target:
  p99 < 10 ms.
- ``autopilot`` (``undertow live --autopilot``, ODOMETRY at 10 Hz, at real time: serve plays
  the first AUTOPILOT_S of the run at rate 1, its MAVLink relayed by a stand-in autopilot that
  decodes what undertow sends): ``latency_ms``, from a DVL report's arrival to the send of the
  first message carrying it (target: p99 < 20 ms); ``interval_ms``, the spacing of the messages
  as sent (mean, std, p99 of |interval - 100 ms|: the rate's jitter) and ``received``, the same
  at the stand-in (after the loopback); ``state_age_ms``, how old the state is when it leaves.

    .venv/bin/python benchmarks/bench_live.py [--rate 20] [--scenario wave-a0.10-f1.00]
        [--commit-every S]  (the results are the same at any commit interval: a longer one
                             trades the committed estimate's lag for fewer filter calls)
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

RATE = 20.0
SCENARIO = "wave-a0.10-f1.00"
AUTOPILOT_S = 30.0  # sensor (= wall) seconds of the real-time autopilot run
HERE = Path(__file__).resolve().parent
UNDERTOW = Path(sys.executable).with_name("undertow")


def _free_port(kind=socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _subscriber(port: int) -> None:
    """A Foxglove client subscribed to every channel, reading until the server closes."""
    import websockets

    async def run():
        async with websockets.connect(f"ws://127.0.0.1:{port}",
                                      subprotocols=["foxglove.sdk.v1"]) as ws:  # fmt: skip
            subscribed = set()
            while True:
                frame = await ws.recv()
                if isinstance(frame, str):
                    msg = json.loads(frame)
                    if msg.get("op") == "advertise":
                        new = [c["id"] for c in msg["channels"] if c["id"] not in subscribed]
                        subscribed.update(new)
                        subs = [{"id": c, "channelId": c} for c in new]
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    try:
        asyncio.run(run())
    except websockets.exceptions.ConnectionClosed:
        pass  # the live session closed its server first: the end of the run


def _thread_cpu() -> dict:
    """CPU seconds of each live thread so far (Linux /proc; empty elsewhere)."""
    out = {}
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    for thread in threading.enumerate():
        try:
            stat = Path(f"/proc/self/task/{thread.native_id}/stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        out[thread.name] = round((int(fields[11]) + int(fields[12])) / tick, 2)  # utime + stime
    return out


def _pin(cpus: set[int] | None) -> None:
    """Every thread of this process (and those it starts later) on ``cpus`` (None: all)."""
    cpus = cpus or set(range(os.cpu_count() or 1))
    for task in Path("/proc/self/task").iterdir():
        try:
            os.sched_setaffinity(int(task.name), cpus)
        except OSError:  # a thread that ended meanwhile
            pass


def cores() -> tuple[int, int] | None:
    """(the pipeline's core, the virtual robot's core) when this machine can pin two apart."""
    if not hasattr(os, "sched_setaffinity") or not Path("/proc/self/task").is_dir():
        return None
    usable = sorted(os.sched_getaffinity(0))
    return (usable[0], usable[1]) if len(usable) >= 2 else None


def run_once(rate: float, scenario: str, view: bool, commit_every_s: float | None = None,
             served_s: float | None = None,
             pin: tuple[int, int] | None = None) -> dict:  # fmt: skip
    from undertow.io import read_log
    from undertow.live.pipeline import LiveSession
    from undertow.settings import LiveSettings, Settings

    _pin({pin[0]} if pin else None)

    dvl, ping, mav = _free_port(), _free_port(socket.SOCK_DGRAM), _free_port(socket.SOCK_DGRAM)
    server = subprocess.Popen(
        [str(UNDERTOW), "serve", scenario, "--rate", str(rate), "--dvl-port", str(dvl),
         "--ping-port", str(ping), "--mavlink", f"udpout:127.0.0.1:{mav}",
         "--wait-clients", "30", "-q"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    if pin:
        os.sched_setaffinity(server.pid, {pin[1]})  # (its threads start after: they inherit it)
    live = LiveSettings(dvl=f"tcp://127.0.0.1:{dvl}", sonar=f"udp://127.0.0.1:{ping}",
                        mavlink=f"udpin:127.0.0.1:{mav}", time_scale=rate, idle_stop_s=2.0,
                        view=view, view_port=0)  # fmt: skip
    if commit_every_s is not None:
        live = live.model_copy(update={"commit_every_s": commit_every_s})
    view_server = client = None
    if view:  # the Foxglove app's stand-in: another process (on serve's core when pinned)
        from undertow.live.view import TOPICS, LiveView

        view_server = LiveView("127.0.0.1", 0)
        client = subprocess.Popen([sys.executable, __file__, "--viewer", str(view_server.port)])
        if pin:
            os.sched_setaffinity(client.pid, {pin[1]})
        deadline = time.monotonic() + 30.0
        while not all(view_server.subscribed(topic) for topic in TOPICS):
            if time.monotonic() > deadline or client.poll() is not None:
                raise RuntimeError("bench_live: the viewer did not subscribe within 30 s")
            time.sleep(0.01)
    with tempfile.TemporaryDirectory() as tmp:
        session = LiveSession(Settings(live=live), Path(tmp) / "out", view=view_server).start()
        # set-up (each link thread imports its protocol library and connects) is not the
        # pipeline's steady work: measured from when every link is up (serve then plays)
        if not session.wait_connected(timeout=30.0):
            raise RuntimeError("bench_live: a link did not connect to serve within 30 s")
        loop_end, threads = [], {}
        finish = session.finish

        def timed_finish():  # the end of the live loop: the final results are written after
            loop_end.append(time.process_time())
            threads.update(_thread_cpu())
            return finish()

        session.finish = timed_finish
        threads0 = _thread_cpu()
        cpu0, wall0 = time.process_time(), time.perf_counter()
        result = session.run()
        cpu_all = time.process_time() - cpu0
        cpu = loop_end[0] - cpu0
        wall = time.perf_counter() - wall0 - live.idle_stop_s
        dvl = read_log(result.recording).dvl  # the A50's own clock: the served sensor time
        dvl_span = float(dvl.t[-1] - dvl.t[0]) if dvl is not None and len(dvl) > 1 else None
    server.wait(timeout=60)
    if client is not None:  # (the session closed the view's server: the viewer ends)
        try:
            client.wait(timeout=10)
        except subprocess.TimeoutExpired:
            client.kill()
    _pin(None)
    s = result.summary
    span = served_s or dvl_span
    return {
        "view": view,
        "cores": {"pipeline": pin[0], "serve": pin[1]} if pin else "any",
        "records": s["records"],
        "late": s["late"],
        "states": s["states"],
        "pings_mapped": s["pings_mapped"],
        "sensor_seconds": span,
        "dvl_span_s": dvl_span,
        "filter_span_s": s.get("filter_span_s"),
        "wall_s": round(wall, 2),
        "cpu_s": round(cpu, 3),
        "finish_cpu_s": round(cpu_all - cpu, 3),
        "cpu_s_per_realtime_s": round(cpu / span, 4) if span else None,
        "realtime_factor": round(span / cpu, 1) if span and cpu else None,
        "latency_ms": s["latency"],
        "cpu_s_by_thread": {k: round(v - threads0.get(k, 0.0), 2) for k, v in threads.items()},
    }


class _Relay:
    """The stand-in autopilot: serve's MAVLink (to ``port``) on to undertow's ``target`` port;
    what undertow sends back decoded (pymavlink) with its receive time."""

    def __init__(self, target: int) -> None:
        from pymavlink.dialects.v20 import ardupilotmega

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.port, self.target = self.sock.getsockname()[1], ("127.0.0.1", target)
        self.parser = ardupilotmega.MAVLink(None)
        self.got: list[tuple[float, str]] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.is_set():
            try:
                data, addr = self.sock.recvfrom(65535)
            except OSError:
                continue
            if addr[1] != self.target[1]:
                self.sock.sendto(data, self.target)
                continue
            now = time.perf_counter()
            self.got += [(now, m.get_type()) for m in self.parser.parse_buffer(data) or ()]

    def close(self) -> None:
        self.stop.set()
        self.thread.join(2.0)
        self.sock.close()


def run_autopilot(scenario: str, pin: tuple[int, int] | None = None,
                  seconds: float = AUTOPILOT_S) -> dict:  # fmt: skip
    """The real-time --autopilot run (module docstring)."""
    import numpy as np

    from undertow.live.pipeline import LiveSession
    from undertow.settings import LiveSettings, Settings

    _pin({pin[0]} if pin else None)
    dvl, ping, mav = _free_port(), _free_port(socket.SOCK_DGRAM), _free_port(socket.SOCK_DGRAM)
    relay = _Relay(mav)
    server = subprocess.Popen(
        [str(UNDERTOW), "serve", scenario, "--rate", "1", "--duration", str(seconds),
         "--dvl-port", str(dvl), "--ping-port", str(ping),
         "--mavlink", f"udpout:127.0.0.1:{relay.port}", "--wait-clients", "30", "-q"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    if pin:
        os.sched_setaffinity(server.pid, {pin[1]})
    live = LiveSettings(dvl=f"tcp://127.0.0.1:{dvl}", sonar=f"udp://127.0.0.1:{ping}",
                        mavlink=f"udpin:127.0.0.1:{mav}", idle_stop_s=2.0,
                        autopilot=True)  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        session = LiveSession(Settings(live=live), Path(tmp) / "out").start()
        if not session.wait_connected(timeout=30.0):
            raise RuntimeError("bench_live: a link did not connect to serve within 30 s")
        result = session.run()
    server.wait(timeout=60)
    relay.close()
    _pin(None)
    a = result.summary["autopilot"]
    got = np.array([t for t, name in relay.got if name == "ODOMETRY"])
    iv = np.diff(got) * 1e3
    received = ({"n": int(iv.size), "mean_ms": float(iv.mean()), "std_ms": float(iv.std()),
                 "p99_abs_deviation_ms": float(np.percentile(np.abs(iv - 100.0), 99))}
                if iv.size else {"n": 0})  # fmt: skip
    return {
        "cores": {"pipeline": pin[0], "serve": pin[1]} if pin else "any",
        "seconds": seconds,
        "sent": a["sent"],
        "latency_ms": a["latency"],
        "interval_ms": a["interval"],
        "received": received,
        "state_age_ms": a["state_age"],
        "holds": a["holds"],
        "missed_periods": a["missed_periods"],
    }


def main(rate: float = RATE, scenario: str = SCENARIO, commit_every_s: float | None = None) -> dict:
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # one core (before numba is imported)
    from undertow.commands.serve import load_source

    t0, t1 = load_source(scenario).time_span  # what serve plays (simulated the same way)
    served = t1 - t0
    pin = cores()
    out = {
        "rate": rate,
        "scenario": scenario,
        "commit_every_s": commit_every_s,
        "view_off": run_once(rate, scenario, False, commit_every_s, served, pin),
        "view_on": run_once(rate, scenario, True, commit_every_s, served, pin),
    }
    if pin:  # the same with the pipeline's threads free to use every core (serve's too)
        out["unpinned"] = {
            "view_off": run_once(rate, scenario, False, commit_every_s, served),
            "view_on": run_once(rate, scenario, True, commit_every_s, served),
        }
    out["autopilot"] = run_autopilot(scenario, pin)
    out["targets"] = {"realtime_factor": ">= 50 on one core", "latency_p99_ms": "< 10",
                      "autopilot_latency_p99_ms": "< 20 at real time"}  # fmt: skip
    return out


if __name__ == "__main__":
    if sys.argv[1:2] == ["--viewer"]:  # the viewer process run_once starts
        _subscriber(int(sys.argv[2]))
        sys.exit(0)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=RATE)
    parser.add_argument("--scenario", default=SCENARIO)
    parser.add_argument("--commit-every", type=float, default=None,
                        help="live.commit_every_s (default: the settings' default)")  # fmt: skip
    parser.add_argument("--autopilot-only", action="store_true",
                        help="only the real-time --autopilot run")  # fmt: skip
    args = parser.parse_args()
    if args.autopilot_only:
        print(json.dumps({"autopilot": run_autopilot(args.scenario, cores())}, indent=2))
        sys.exit(0)
    print(json.dumps(main(args.rate, args.scenario, args.commit_every), indent=2))
