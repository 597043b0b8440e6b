"""Seconds to simulate the default scenario in memory, and to write it to disk."""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

from undertow.sim import load_scenario, simulate, write_simulation

DEFAULT_SCENARIO = "wave-a0.10-f1.00"


def main() -> dict:
    scenario = load_scenario(DEFAULT_SCENARIO)
    simulate(scenario, seed=0)  # warm-up: numba compilation / cache load
    t0 = time.perf_counter()
    result = simulate(scenario, seed=0)
    t1 = time.perf_counter()
    out = {
        "scenario": DEFAULT_SCENARIO,
        "simulate_s": round(t1 - t0, 3),
        "ground_truth_samples": len(result.log.ground_truth),
        "floor_cloud_points": int(result.floor_cloud.shape[0]),
    }
    try:
        with tempfile.TemporaryDirectory() as tmp:
            t2 = time.perf_counter()
            write_simulation(result, Path(tmp) / "run")
            out["write_s"] = round(time.perf_counter() - t2, 3)
    except ImportError as exc:  # the io package may not be there yet
        out["write_s"] = None
        out["write_error"] = str(exc)
    return out


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
