"""Onboard sea-state estimate (`undertow.seastate.estimate_sea_state`): speed and accuracy.

`main()` (run by run_all.py) prints the cost in seconds of estimation per hour of log, measured on
one hour of simulated free-vehicle survey (the rock-survey scenario in waves a = 0.07 m,
f = 0.9 Hz, 75 s, tiled 48 times with shifted times; barometer 10 Hz, DVL 8 Hz, dead reckoning
5 Hz, IMU 100 Hz) and on one hour of tiled carriage runs. Target (issue): under 2 s per hour.
The machine has 2 cores shared with other jobs: the figure is wall time, single-threaded.

`python benchmarks/bench_waves.py --accuracy [--seeds N]` prints the held-out accuracy table
(docs/waves.md): for the carriage (scenario `calm` with the wave overridden) and the free vehicle
(`rock-survey` with the wave overridden), conditions not among the built-ins, every window's
estimate against the simulated truth (log.metadata["wave"], read here only).
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
import time

import numpy as np

from undertow.log import Log
from undertow.seastate import estimate_sea_state
from undertow.sim import Scenario, load_scenario, simulate

#: held-out conditions (a m, f Hz); the built-ins are (0.05, 0.75), (0.10, 0.75), (0.10, 1.0)
CONDITIONS = ((0.07, 0.9), (0.06, 1.2), (0.04, 0.65), (0.12, 0.8))
SCENARIOS = {"carriage": "calm", "survey": "rock-survey"}


def scenario(kind: str, a: float, f: float, heading_deg: float = 180.0) -> Scenario:
    """The built-in of ``kind`` with the wave (a, f, heading) replaced, validated again."""
    data = load_scenario(SCENARIOS[kind]).to_yaml_dict()
    data["wave"].update(amplitude_m=a, frequency_hz=f, heading_deg=heading_deg)
    data["name"] = f"{kind}-a{a:.2f}-f{f:.2f}"
    return Scenario.model_validate(data)


def tile(log: Log, count: int) -> Log:
    """``count`` copies of the log's barometer, DVL, dead reckoning and IMU, one after another
    (times shifted by the span plus one sample)."""
    span = log.time_span[1] - log.time_span[0] + 0.01
    out = {}
    for name in ("imu", "dvl", "dead_reckoning", "pressure"):
        s = getattr(log, name)
        if s is None:
            continue
        changes = {"t": np.concatenate([s.t + i * span for i in range(count)])}
        for f in s._shapes:
            v = getattr(s, f)
            if v is not None:
                changes[f] = np.concatenate([v] * count)
        out[name] = dataclasses.replace(s, **changes)
    return Log(**out, mounting=log.mounting, metadata={})


def _seconds_per_hour(kind: str) -> dict:
    log = simulate(scenario(kind, 0.07, 0.9), seed=0).log
    span = log.time_span[1] - log.time_span[0]
    count = int(np.ceil(3600.0 / span))
    long = tile(log, count)
    estimate_sea_state(log)  # compile the numba kernels (cached on disk afterwards)
    start, cpu = time.perf_counter(), time.process_time()
    est = estimate_sea_state(long)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    hours = (long.time_span[1] - long.time_span[0]) / 3600.0
    return {
        "log_hours": round(hours, 3),
        "windows": len(est.windows),
        "window_s": round(est.window_s, 2),
        "seconds": round(seconds, 3),
        "seconds_per_hour_of_log": round(seconds / hours, 3),
        "cpu_seconds_per_hour_of_log": round(cpu / hours, 3),
    }


def main() -> dict:
    return {
        "survey": _seconds_per_hour("survey"),
        "carriage": _seconds_per_hour("carriage"),
        "target_seconds_per_hour": 2.0,
        "note": "wall and CPU time on this machine (2 cores shared with other jobs), one thread",
        "load_average_1min": round(os.getloadavg()[0], 2),
    }


def accuracy(seeds=(1, 2)) -> list[dict]:
    """One row per scenario x condition: truth, mean estimate over windows and seeds, the
    worst window's errors (%)."""
    rows = []
    for kind in SCENARIOS:
        for a, f in CONDITIONS:
            est_a, est_f, err_a, err_f, calm = [], [], [], [], 0
            for seed in seeds:
                log = simulate(scenario(kind, a, f), seed=seed).log
                truth = log.metadata["wave"]
                for w in estimate_sea_state(log).windows:
                    if w.frequency_hz is None:
                        calm += 1
                        err_a.append(-100.0)
                        continue
                    est_a.append(w.amplitude_m)
                    est_f.append(w.frequency_hz)
                    err_a.append(100 * (w.amplitude_m / truth["amplitude_m"] - 1))
                    err_f.append(100 * (w.frequency_hz / truth["frequency_hz"] - 1))
            worst_a = max(err_a, key=abs)
            worst_f = max(err_f, key=abs) if err_f else None
            rows.append({
                "scenario": kind, "a_true_m": a, "f_true_hz": f, "seeds": len(seeds),
                "windows": len(err_a), "calm_windows": calm,
                "a_mean_m": round(float(np.mean(est_a)), 4) if est_a else None,
                "f_mean_hz": round(float(np.mean(est_f)), 4) if est_f else None,
                "a_worst_err_pct": round(worst_a, 1),
                "f_worst_err_pct": None if worst_f is None else round(worst_f, 2),
                "a_rms_err_pct": round(float(np.sqrt(np.mean(np.square(err_a)))), 1),
                "pass": abs(worst_a) <= 15 and worst_f is not None and abs(worst_f) <= 5,
            })  # fmt: skip
    return rows


def _markdown(rows: list[dict]) -> str:
    head = (
        "| scenario | a true (m) | f true (Hz) | windows | a est. mean (m) | f est. mean (Hz) "
        "| worst a err (%) | worst f err (%) | rms a err (%) | within 15 % / 5 % |"
    )
    lines = [head, "|" + " --- |" * 10]
    for r in rows:
        lines.append(
            f"| {r['scenario']} | {r['a_true_m']} | {r['f_true_hz']} | {r['windows']} | "
            f"{r['a_mean_m']} | {r['f_mean_hz']} | {r['a_worst_err_pct']:+.1f} | "
            f"{r['f_worst_err_pct']:+.2f} | {r['a_rms_err_pct']} | "
            f"{'yes' if r['pass'] else 'NO'} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    if "--accuracy" in sys.argv:
        n = int(sys.argv[sys.argv.index("--seeds") + 1]) if "--seeds" in sys.argv else 2
        table = accuracy(seeds=tuple(range(1, n + 1)))
        print(_markdown(table))
        print(json.dumps(table, indent=1), file=sys.stderr)
    else:
        print(json.dumps(main(), indent=2))
