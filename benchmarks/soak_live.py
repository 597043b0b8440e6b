"""The live soak (`make bench ONLY=soak`, its live half): hours of sensor time through `live`.

`undertow serve SCENARIO --loop --rate RATE` plays a simulated survey again and again (each lap's
clocks continue: :mod:`undertow.sim.robot.player`) into a :class:`LiveSession` in this process
with all three links (A50 TCP, Ping1D UDP, MAVLink UDP), the online map and the Foxglove view
on (one client subscribed to every channel, in another process), until HOURS of sensor time
have been served (the survey's path closed, :data:`CLOSED`, so that the laps map one site). A
sampler thread records, every SAMPLE_S of wall time until the data ends, the process's resident
memory (VmRSS), its CPU time, the sensor time the filter has reached and the DVL latencies so
far (a histogram); from these:

- ``rss_growth_mb_per_sensor_hour``: the slope of RSS against sensor time (least squares) over
  the samples after the first WARMUP_S of sensor time. Target: <= 50 MB per hour;
- ``cpu_s_per_sensor_s_by_hour``: CPU seconds per sensor second within each hour of sensor time
  (the first ten minutes apart: ``first_10_min``). Target: the last hour within 10 % of the
  first ten minutes;
- ``latency_p99_ms_by_hour``: the p99 of the DVL-arrival-to-pose latency per hour. Target:
  < 10 ms in every hour;
- ``realtime_factor``: sensor seconds per CPU second of the whole run (bench_live's figure);
- ``map``: the online map's own memory at the end (its chunk arrays in memory, the chunks
  spilled beyond ``mapping.resident_mb`` and taken back) and the view's points held, so that a
  growth which is the map's (a survey covering new ground) is told apart from a leak.

    .venv/bin/python benchmarks/soak_live.py [--hours 3] [--rate 20] [--scenario field-survey]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_live  # noqa: E402  (the viewer stand-in and the port helpers)

HOURS = 3.0
#: the survey's lawnmower closed (back to its first waypoint), so that the laps of ``--loop``
#: cover one site again and again: the map then holds the site, and what grows is not the map
CLOSED = True
RATE = 20.0
SCENARIO = "field-survey"
SAMPLE_S = 10.0  # wall seconds between samples
WARMUP_S = 600.0  # sensor seconds left out of the memory slope (the first ten minutes)


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


class _Sampler(threading.Thread):
    """Every ``period`` s of wall time: (wall, cpu, rss MB, sensor s, the latency histogram)."""

    def __init__(self, session, period: float) -> None:
        super().__init__(name="soak-sampler", daemon=True)
        self.session, self.period = session, period
        self.samples: list[tuple] = []
        self.stop = threading.Event()

    def sample(self) -> None:
        stats = self.session.stats
        self.samples.append((time.perf_counter(), time.process_time(), _rss_mb(),
                             float(stats.span_s), stats.latency.snapshot()))  # fmt: skip

    def run(self) -> None:
        while not self.stop.wait(self.period):
            self.sample()


def closed_survey(scenario: str, folder: Path) -> str:
    """A copy of the built-in ``scenario`` (YAML) whose waypoints end at the first one, or
    ``scenario`` itself when it has no waypoints."""
    import yaml

    src = Path(__file__).resolve().parents[1] / "src/undertow/data/scenarios" / f"{scenario}.yaml"
    if not src.is_file():
        return scenario
    doc = yaml.safe_load(src.read_text())
    points = doc.get("motion", {}).get("waypoints", {}).get("points")
    if not points:
        return scenario
    points.append(list(points[0]))
    doc["name"] = f"{doc['name']}-closed"
    path = folder / f"{doc['name']}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


def _serve(scenario: str, rate: float, dvl: int, ping: int, mav: int) -> subprocess.Popen:
    return subprocess.Popen(
        [str(bench_live.UNDERTOW), "serve", scenario, "--rate", str(rate), "--loop",
         "--dvl-port", str(dvl), "--ping-port", str(ping), "--mavlink",
         f"udpout:127.0.0.1:{mav}", "--wait-clients", "60", "-q"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def _viewer():
    from undertow.live.view import TOPICS, LiveView

    view = LiveView("127.0.0.1", 0)
    client = subprocess.Popen([sys.executable, str(HERE / "bench_live.py"), "--viewer",
                               str(view.port)])  # fmt: skip
    deadline = time.monotonic() + 30.0
    while not all(view.subscribed(topic) for topic in TOPICS):
        if time.monotonic() > deadline or client.poll() is not None:
            raise RuntimeError("soak: the viewer did not subscribe within 30 s")
        time.sleep(0.01)
    return view, client


def run(hours: float = HOURS, rate: float = RATE, scenario: str = SCENARIO,
        sample_s: float = SAMPLE_S) -> dict:  # fmt: skip
    from undertow.live.pipeline import LiveSession
    from undertow.settings import LiveSettings, Settings

    free = bench_live._free_port
    dvl, ping, mav = free(), free(socket.SOCK_DGRAM), free(socket.SOCK_DGRAM)
    scratch = tempfile.TemporaryDirectory()
    served = closed_survey(scenario, Path(scratch.name)) if CLOSED else scenario
    server = _serve(served, rate, dvl, ping, mav)
    live = LiveSettings(dvl=f"tcp://127.0.0.1:{dvl}", sonar=f"udp://127.0.0.1:{ping}",
                        mavlink=f"udpin:127.0.0.1:{mav}", time_scale=rate, idle_stop_s=2.0,
                        view=True, view_port=0, map=True)  # fmt: skip
    view, client = _viewer()
    with tempfile.TemporaryDirectory() as tmp:
        session = LiveSession(Settings(live=live), Path(tmp) / "out", view=view).start()
        if not session.wait_connected(timeout=120.0):
            raise RuntimeError("soak: a link did not connect to serve within 120 s")
        sampler = _Sampler(session, sample_s)
        sampler.sample()
        sampler.start()
        finish = session.finish

        def sampled_finish():  # the samples end with the data: writing the results is apart
            sampler.stop.set()
            sampler.join()
            sampler.sample()
            return finish()

        session.finish = sampled_finish
        stopper = threading.Timer(hours * 3600.0 / rate, server.terminate)
        stopper.start()
        cpu0 = time.process_time()
        result = session.run()
        cpu = time.process_time() - cpu0
        stopper.cancel()
        map_info = _map_info(session)
        latency = session.stats.latency
    server.wait(timeout=60)
    try:
        client.wait(timeout=10)
    except subprocess.TimeoutExpired:
        client.kill()
    scratch.cleanup()
    out = summarize(sampler.samples, latency, result.summary, cpu, map_info, rate, scenario)
    out["closed_path"] = served != scenario
    out["forced_commits"] = result.summary.get("forced_commits")
    return out


def _map_info(session) -> dict:
    mapper = getattr(session, "mapper", None)
    if mapper is None:
        return {}
    grid = getattr(mapper.mapper, "grid", None)
    out = {"pings": int(session.stats.pings)}
    if grid is not None:
        out.update({"chunks": int(grid.n_chunks), "grid_mb": round(grid.nbytes / 2**20, 1),
                    "resident_mb": grid.resident_bytes and grid.resident_bytes / 1e6,
                    "chunks_spilled": len(grid.spill), "spill_file_mb":
                    round(grid.spill.file_bytes / 2**20, 1), "chunks_taken_back":
                    grid.spill.takes})  # fmt: skip
    cloud = getattr(session, "_cloud", None)  # the view's map cloud (made at the first draw)
    if cloud is not None:
        out.update({"view_points_held": cloud.n_points, "view_stride": cloud.stride})
    return out


def summarize(samples, latency, summary: dict, cpu: float, map_info: dict, rate: float,
              scenario: str) -> dict:  # fmt: skip
    s = np.asarray([row[:4] for row in samples], float)  # wall, cpu, rss, sensor
    from undertow._util.histogram import percentile_of

    counts = [row[4] for row in samples]
    sensor = s[:, 3]
    late = sensor > WARMUP_S
    slope = None
    if late.sum() >= 3 and np.ptp(sensor[late]) > 0:
        slope = float(np.polyfit(sensor[late] / 3600.0, s[late, 2], 1)[0])
    buckets = [("first_10_min", 0.0, WARMUP_S)]
    hours = int(np.ceil(sensor.max() / 3600.0)) if sensor.size else 0
    buckets += [(f"hour_{h + 1}", 3600.0 * h, 3600.0 * (h + 1)) for h in range(hours)]
    by_hour, p99 = {}, {}
    for name, lo, hi in buckets:
        i = np.flatnonzero((sensor >= lo) & (sensor <= hi))
        if i.size < 2 or sensor[i[-1]] - sensor[i[0]] <= 0:
            continue
        a, b = i[0], i[-1]
        by_hour[name] = round((s[b, 1] - s[a, 1]) / (sensor[b] - sensor[a]), 5)
        q = percentile_of(counts[b] - counts[a], 99.0)
        p99[name] = None if q is None else round(q * 1e3, 2)
    first, last = by_hour.get("first_10_min"), by_hour.get(f"hour_{hours}")
    span = float(sensor.max()) if sensor.size else 0.0
    return {
        "scenario": scenario, "rate": rate, "sensor_hours": round(span / 3600.0, 3),
        "samples": len(samples),
        "rss_mb": {"start": round(float(s[0, 2]), 1), "end": round(float(s[-1, 2]), 1),
                   "max": round(float(s[:, 2].max()), 1)},
        "rss_growth_mb_per_sensor_hour": None if slope is None else round(slope, 1),
        "cpu_s_per_sensor_s_by_hour": by_hour,
        "cpu_last_hour_over_first_10_min": (round(last / first, 3) if first and last
                                            else None),
        "latency_p99_ms_by_hour": p99,
        "realtime_factor": round(span / cpu, 1) if cpu else None,
        "states": summary.get("states"), "late": summary.get("late"),
        "map": map_info,
        "targets": {"rss_growth_mb_per_sensor_hour": 50.0, "cpu_last_hour_over_first": 1.10,
                    "latency_p99_ms": 10.0},
    }  # fmt: skip


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--hours", type=float, default=HOURS)
    parser.add_argument("--rate", type=float, default=RATE)
    parser.add_argument("--scenario", default=SCENARIO)
    parser.add_argument("--sample", type=float, default=SAMPLE_S)
    args = parser.parse_args()
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    print(json.dumps(run(args.hours, args.rate, args.scenario, args.sample), indent=2))
