"""Soak: long missions (issue 27, section 4). `make bench ONLY=soak` prints JSON.

Offline (:func:`bench_offline`): a simulated survey of ``hours`` of sensor time (one lap of the
field-survey scenario simulated, then repeated into one bag message by message with shifted
times, :func:`repeat_bag`: disk, not memory; in a temporary folder, not kept) is localized with
the smoother and mapped (BKI), each step in its own process, whose peak RSS (``VmHWM``) is
reported. ``chunked``: the bag read and filtered in 600 s pieces, the states on disk, the map
integrated piece by piece: what `localize` and `map` do by default with a bag whose index
spans more than 2 hours (``undertow.io.PIECES_ABOVE_S``; asked for with ``in_pieces=True``
below that); when ``today`` is set (default up to 2 hours) also ``memory``: the whole log read
and filtered in memory (the path before issue 27), with ``compare``: whether the two wrote the
same trajectory (TUM bytes, npz arrays) and where their config.yaml differ (:func:`_compare`;
the 1-hour log is 4086 s: its pieces' first hour misses the last 486 s in the evidence figures
of the log's choices, the same choices). Target: peak
RSS under 2 GB at 24 hours. The hours are ``UNDERTOW_SOAK_HOURS`` (default 24: about 75 min
of wall time here), run with the 1-hour log beside it (``UNDERTOW_SOAK_HOURS=1``: that one).

Live (:func:`bench_live`, :mod:`soak_live`): ``serve`` plays the closed field survey again and
again at 20x into `live` (all three links, view and map on) for ``UNDERTOW_SOAK_LIVE_HOURS`` of
sensor time (default 3); RSS growth per sensor hour after the first ten minutes, CPU per
sensor-second by hour, p99 latency by hour. Targets: <= 50 MB per hour, the last hour's CPU
within 10 % of the first ten minutes', p99 < 10 ms.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

#: the field survey's one pass of its lawnmower, s (laps repeat it)
LAP_S = 649.0

_STEP = r"""
import json, sys, time, warnings
from pathlib import Path
warnings.simplefilter("ignore")
step, log, out, chunked = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
# "auto": the default (pieces above 2 h), "1": pieces asked, "0": the whole log, states in memory
pieces = {"auto": None, "1": True, "0": False}[chunked]
t0 = time.perf_counter()
if step == "generate":
    sys.path.insert(0, sys.argv[5])
    from bench_soak import simulate_hours
    simulate_hours(float(out), Path(log))
    extra = {}
elif step == "localize":
    from undertow.commands.localization import localize_file
    r = localize_file(log, smooth=True, out_dir=out, in_pieces=pieces,
                      chunked=False if pieces is False else None)
    extra = {"states": len(r.trajectory)}
else:
    from undertow.commands.mapping import map_file
    r = map_file(log, out, out_dir=out + "-map", method="bki", in_pieces=pieces)
    extra = {"cells": len(r.map)}
# VmHWM: this process's peak RSS (ru_maxrss would keep the parent's peak across fork + exec)
hwm = next(ln for ln in open("/proc/self/status") if ln.startswith("VmHWM"))
print(json.dumps({"wall_s": round(time.perf_counter() - t0, 1),
                  "peak_rss_mb": round(int(hwm.split()[1]) / 1024), **extra}))
"""


def simulate_hours(hours: float, folder: Path) -> Path:
    """``hours`` of the field survey as one bag in ``folder``/log: one lap simulated
    (``folder``/lap) and repeated (:func:`repeat_bag`), so that a long log costs disk, not
    memory; returns the log folder. The lawnmower is closed (back to its first waypoint), as the
    live soak's (:data:`soak_live.CLOSED`), so that the laps survey one site: the memory measured
    is the log's length, not the area mapped (a map of new ground all day is the map's size)."""
    from undertow.sim import load_scenario, simulate, write_simulation

    s = load_scenario("field-survey")
    points = list(s.motion.waypoints.points)
    route = s.motion.waypoints.model_copy(update={"laps": 1, "points": [*points, points[0]]})
    s = s.model_copy(update={"motion": s.motion.model_copy(update={"waypoints": route})})
    write_simulation(simulate(s), folder / "lap", overwrite=True)
    return repeat_bag(folder / "lap" / "log", folder / "log", hours)


def repeat_bag(lap: Path, dest: Path, hours: float) -> Path:
    """A bag of ``hours`` made of the bag ``lap`` repeated, as ``undertow serve --loop`` plays
    a log: lap k's record times and header stamps shifted by k periods (period = the lap's span
    + the smallest spacing of its messages; ``/tf_static`` written once), message by message
    (the raw CDR bytes, the stamp patched in place: sec int32, nanosec uint32 after the 4-byte
    encapsulation header of a message that starts with a ``std_msgs/Header``). The lap's
    sidecar ``undertow.yaml`` is copied beside it."""
    import shutil
    import struct

    import numpy as np
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer

    from undertow.io.msgdefs import dvl_typestore
    from undertow.io.rosbag_write import TF_STATIC_QOS

    store = dvl_typestore()
    with AnyReader([lap], default_typestore=store) as reader:
        times = np.array([ns for _, ns, _ in reader.messages()], dtype=np.int64)
        spacing = int(np.diff(np.unique(times)).min()) if times.size > 1 else 1
        period = int(times.max() - times.min()) + spacing
        laps = max(1, math.ceil(hours * 3600e9 / period))
        stamped = {}
        for conn, _, raw in reader.messages():
            if conn.id not in stamped:
                msg = reader.deserialize(raw, conn.msgtype)
                fields = getattr(msg, "__dataclass_fields__", {})
                stamped[conn.id] = bool(fields) and next(iter(fields)) == "header"
        with Writer(dest, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            out = {
                c.id: writer.add_connection(
                    c.topic, c.msgtype, typestore=store,
                    offered_qos_profiles=(TF_STATIC_QOS,) if c.topic == "/tf_static" else (),
                )
                for c in reader.connections
            }  # fmt: skip
            for k in range(laps):
                shift = k * period
                for conn, ns, raw in reader.messages():
                    if k and conn.topic == "/tf_static":
                        continue
                    data = raw
                    if k and stamped[conn.id]:
                        data = bytearray(raw)
                        sec, nsec = struct.unpack_from("<iI", data, 4)
                        total = sec * 1_000_000_000 + nsec + shift
                        struct.pack_into("<iI", data, 4, total // 1_000_000_000,
                                         total % 1_000_000_000)  # fmt: skip
                    writer.write(out[conn.id], ns + shift, data)
    sidecar = lap / "undertow.yaml"
    if sidecar.exists():
        shutil.copy(sidecar, dest / "undertow.yaml")
    return dest


def _step(step: str, log: Path, out, chunked: str = "0") -> dict:
    """One step in a fresh process (``chunked``: "auto", "1" or "0", see ``_STEP``); its JSON
    line (peak RSS of that process)."""
    args = [step, str(log), str(out), chunked, str(Path(__file__).parent)]
    done = subprocess.run([sys.executable, "-c", _STEP, *args], capture_output=True, text=True,
                          check=False)  # fmt: skip
    if done.returncode:
        return {"error": done.stderr.strip().splitlines()[-1:]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def _compare(a: Path, b: Path) -> dict:
    """What the two runs' folders share: ``same_trajectory`` (trajectory.tum's bytes and every
    array of trajectory.npz but its metadata, which is config.yaml's) and ``config_differs_at``
    (the dotted keys where the config.yaml differ: the pieces' ``read_in_pieces`` record, and
    for a log longer than the pieces' first hour the evidence figures of the log's choices,
    which the pieces take from that hour)."""
    import numpy as np
    import yaml

    same = (a / "trajectory.tum").read_bytes() == (b / "trajectory.tum").read_bytes()
    with np.load(a / "trajectory.npz") as x, np.load(b / "trajectory.npz") as y:
        arrays = [k for k in x.files if k != "metadata_json"]
        same = same and x.files == y.files and all(np.array_equal(x[k], y[k]) for k in arrays)
    configs = [_flat(yaml.safe_load((f / "config.yaml").read_text())) for f in (a, b)]
    keys = sorted(k for k in configs[0].keys() | configs[1].keys()
                  if configs[0].get(k) != configs[1].get(k))  # fmt: skip
    return {"same_trajectory": same, "config_differs_at": keys}


def _flat(doc, prefix: str = "") -> dict:
    if not isinstance(doc, dict):
        return {prefix: doc}
    out = {}
    for k, v in doc.items():
        out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
    return out


def bench_offline(hours: float = 24.0, today: bool | None = None) -> dict:
    """Localize (smoothed) and map ``hours`` of simulated survey; peak RSS per step (module
    doc). ``today`` (default: up to 2 hours) also runs the in-memory path to compare."""
    today = hours <= 2.0 if today is None else today
    with tempfile.TemporaryDirectory(prefix="undertow-soak-") as tmp:
        root = Path(tmp)
        out = {"hours": hours, "generate": _step("generate", root / "sim", hours)}
        log = root / "sim" / "log"
        out["log_mb"] = round(sum(p.stat().st_size for p in log.rglob("*")) / 1e6)
        for mode in ("chunked", "memory") if today else ("chunked",):
            folder = root / mode
            how = "0" if mode == "memory" else "1" if hours <= 2.0 else "auto"
            out[mode] = {
                "localize": _step("localize", log, folder, how),
                "map": _step("map", log, folder, how),
            }
        if today:
            out["compare"] = _compare(root / "chunked", root / "memory")
    return out


def bench_live(hours: float = 3.0) -> dict:
    """The live soak (:mod:`soak_live`): ``hours`` of sensor time at 20x into `live`."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import soak_live

    return soak_live.run(hours=hours)


def main() -> dict:
    """``UNDERTOW_SOAK_HOURS`` (offline, default 24, printed beside the 1-hour run) and
    ``UNDERTOW_SOAK_LIVE_HOURS`` (live, default 3; 0 skips it)."""
    live_hours = float(os.environ.get("UNDERTOW_SOAK_LIVE_HOURS", "3"))
    out = {"live": bench_live(live_hours)} if live_hours > 0 else {}
    hours = float(os.environ.get("UNDERTOW_SOAK_HOURS", "24"))
    out["offline"] = {f"{h:g}h": bench_offline(h) for h in sorted({1.0, hours})}
    return out


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
