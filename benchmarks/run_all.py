"""Run every benchmarks/bench_*.py and print one JSON document (`make bench`).

Each benchmark module has `main() -> dict`. Figures are measurements of this machine, never
assertions: compare them with the targets quoted in each module's docstring.
"""

from __future__ import annotations

import importlib.util
import json
import platform
import sys
import time
from pathlib import Path


def main() -> dict:
    here = Path(__file__).parent
    results: dict = {
        "machine": {"python": sys.version.split()[0], "platform": platform.platform()},
    }
    only = set(sys.argv[1:])
    for path in sorted(here.glob("bench_*.py")):
        name = path.stem.removeprefix("bench_")
        if only and name not in only:
            continue
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        start = time.perf_counter()
        try:
            results[name] = module.main()
        except Exception as exc:  # a broken benchmark must not hide the others
            results[name] = {"error": f"{type(exc).__name__}: {exc}"}
        results[name + "_wall_s"] = round(time.perf_counter() - start, 2)
        print(f"{name}: done", file=sys.stderr)
    return results


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
