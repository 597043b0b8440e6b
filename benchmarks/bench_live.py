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
    out["targets"] = {"realtime_factor": ">= 50 on one core", "latency_p99_ms": "< 10"}
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
    args = parser.parse_args()
    print(json.dumps(main(args.rate, args.scenario, args.commit_every), indent=2))
