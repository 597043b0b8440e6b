"""Reader throughput: messages per second reading a ROS 2 mcap bag (written here with
``write_log``, a few tens of thousands of messages) and a Water Linked JSON log.

Run: ``python benchmarks/bench_readers.py`` (prints JSON).
"""

from __future__ import annotations

import json
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from undertow.io import read_log, write_log
from undertow.io.a50_json import velocity_report_line
from undertow.log import Dvl, Imu, Log, Pressure


def _log(seconds: float) -> Log:
    rng = np.random.default_rng(0)
    t_imu = 1.7e9 + np.arange(0, seconds, 0.01)  # 100 Hz
    t_dvl = 1.7e9 + np.arange(0, seconds, 0.1)  # 10 Hz
    imu = Imu(
        t=t_imu,
        angular_velocity=rng.normal(0, 0.1, (t_imu.size, 3)),
        linear_acceleration=rng.normal(0, 1, (t_imu.size, 3)),
    )
    dvl = Dvl.from_velocity(
        t_dvl,
        rng.normal(0, 0.3, (t_dvl.size, 3)),
        altitude=rng.uniform(1, 2, t_dvl.size),
        beam_range=rng.uniform(1, 3, (t_dvl.size, 4)),
        beam_valid=np.ones((t_dvl.size, 4), bool),
        beam_velocity=rng.normal(0, 0.1, (t_dvl.size, 4)),
    )
    pressure = Pressure(t=t_dvl, pressure=101325 + rng.uniform(0, 3e4, t_dvl.size))
    return Log(imu=imu, dvl=dvl, pressure=pressure)


def _rate(fn, n_messages: int, repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return n_messages / best


def main() -> dict:
    log = _log(seconds=250.0)  # 25000 IMU + 2500 DVL + 2500 JSON + 2500 pressure messages
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        start = time.perf_counter()
        bag = write_log(log, Path(tmp) / "bench", flavor="driver")
        write_s = time.perf_counter() - start
        n_bag = len(log.imu) + 3 * len(log.dvl)
        bag_rate = _rate(lambda: read_log(bag), n_bag)
        d = log.dvl
        lines = [velocity_report_line(d, i, 100.0, d.t[i]) for i in range(len(d))]
        text = Path(tmp) / "dvl.jsonl"
        text.write_text("\n".join(lines) + "\n")
        json_rate = _rate(lambda: read_log(text), len(lines))
    return {
        "bag_messages": n_bag,
        "bag_write_messages_per_s": n_bag / write_s,
        "bag_read_messages_per_s": bag_rate,
        "json_reports": len(lines),
        "json_read_reports_per_s": json_rate,
    }


if __name__ == "__main__":
    print(json.dumps(main()))
