"""Mapping benchmark: ms per ping for csm / bki / adaptive and OctoMap on the same rays, memory,
and a scaled survey. Prints JSON; ``main() -> dict``.

Like for like: OctoMap's insert time includes its ray casting (the free cells along each beam),
so the headline for our mappers (``per_ping.headline``) includes building the training samples
from the ranges (pose interpolation, mounting, free samples every 0.1 m: ``build_samples``) plus
``integrate``; the kernel-only time (``integrate`` alone) is reported beside it. OctoMap is
given world end points and origins computed outside its timing (it has no pose interpolation).

A ping is one DVL report (4 beams) plus one sonar range, 1.5-2 m above an undulating floor,
with free samples every ``free_resolution`` along each beam. The rays come from a synthetic
lawnmower survey built here (no simulator needed); ranges are exact ray/floor intersections.

Multibeam (``per_ping.multibeam``): pings of a 256-beam fan (120 deg swath across track) at
the same altitude over a seabed heightfield, each beam a hit plus free samples, built from the
detections (world rays, computed outside the timing as OctoMap's end points are) and integrated
one call per ping, on all numba threads and on one, by the adaptive mapper and by the default
``tpu`` (also with a wave, whose term each hit adds); OctoMap inserts the same end points. Threads
(``per_ping.threads``): the adaptive figures with numba limited to 1 and to 2 threads.

Targets (``four_beam_target_met``, ``multibeam_target_met`` at the top, from the figures of the
same run): the 4-beam ping at least 2x faster than OctoMap (``per_ping.headline``), the 256-beam
ping no slower than OctoMap (``multibeam_adaptive_over_octomap`` <= 1); the same for the default
mapper ``tpu`` (``four_beam_tpu_target_met``, ``multibeam_tpu_over_octomap``,
``multibeam_tpu_target_met``).

Km-scale (``km_survey``): a lawnmower of 256-beam pings (>= 10^7 rays) over a 1 km x 1 km seabed
heightfield 10 m below, mapped at 1 m (length scales and free spacing scaled with the cell),
in one worker process (one mapper, pings streamed in batches) with the scatter on one numba
thread and on two (slabs of cells per thread, ``mapping/grid.py``), and tiled
(:mod:`undertow.mapping.tiled`) on a LocalCluster of 2 single-threaded workers, each tile task
generating the pings that reach its tile; wall time, peak RSS per worker, per-tile cost, the
merge (reading the tile directory back as one map) and the extrapolation to 16 workers.

    .venv/bin/python benchmarks/bench_mapping.py [--pings 20000] [--survey-pings 100000]
                                                 [--survey-area 100] [--no-survey]
                                                 [--km-rays 10000000] [--km-area 1000]
                                                 [--km-tile 250] [--no-km]
    .venv/bin/python benchmarks/bench_mapping.py --smoke      # small sizes, a minute
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")  # OctoMap on one core, like our kernels

import numba  # noqa: E402
import numpy as np  # noqa: E402

from undertow.log import Dvl, Log, SonarRange  # noqa: E402
from undertow.mapping.config import MappingConfig  # noqa: E402
from undertow.mapping.mappers import make_mapper  # noqa: E402
from undertow.mapping.samples import (  # noqa: E402
    SENSOR_MULTIBEAM,
    RaySamples,
    Samples,
    build_samples,
    expand,
)
from undertow.mapping.tiled import Tiling  # noqa: E402
from undertow.robot import Mounting  # noqa: E402
from undertow.rotations import rpy_to_matrix  # noqa: E402
from undertow.trajectory import Trajectory  # noqa: E402

RATE_HZ, LINE_SPACING, FLOOR_DEPTH, ALTITUDE = 10.0, 1.5, 6.0, 1.75
VARIANCE_BOUNDS = ((1e-4, 1e-4, 1e-4), (1.1e-3, 1.1e-3, 2e-4))


def _floor(x, y):
    return FLOOR_DEPTH + 0.2 * np.sin(2 * np.pi * x / 9.0) * np.cos(2 * np.pi * y / 7.0)


def survey_batch(k0: int, k1: int, n_pings: int, area: float) -> tuple[Log, Trajectory, dict]:
    """Pings k0..k1-1 of an n_pings lawnmower survey over area x area m (lines 1.5 m apart)."""
    k = np.arange(k0, k1)
    t = k / RATE_HZ
    n_lines = max(int(area / LINE_SPACING), 1)
    s = k / n_pings * n_lines * area
    line = np.minimum((s // area).astype(int), n_lines - 1)
    u = s - line * area
    x = np.zeros((k.size, 18))
    x[:, 0] = np.where(line % 2 == 0, u, area - u)
    x[:, 1] = (line + 0.5) * area / n_lines
    x[:, 2] = FLOOR_DEPTH - ALTITUDE + 0.1 * np.sin(2 * np.pi * 0.2 * t)  # wave heave
    x[:, 3], x[:, 4] = 0.03 * np.sin(2 * np.pi * 0.25 * t), 0.02 * np.cos(2 * np.pi * 0.2 * t)
    x[:, 5] = np.where(line % 2 == 0, 0.0, np.pi) + 0.02 * np.sin(0.1 * t)
    P = np.zeros((k.size, 18, 18))
    P[:, 0, 0] = P[:, 1, 1] = 1e-4 + 1e-3 * u / area  # drift grows along a line
    P[:, 2, 2] = 1e-4 + 1e-4 * (0.5 + 0.5 * np.sin(2 * np.pi * 0.2 * t))
    traj = Trajectory(t, x, P)
    m = Mounting()
    R = rpy_to_matrix(x[:, 3:6])
    units = Dvl.from_velocity(t[:1], np.zeros((1, 3))).beam_unit[0]
    rays = {}
    for name, mount, unit in (("dvl", m.dvl, units), ("sonar", m.sonar, np.array([[0, 0, 1.0]]))):
        o = x[:, :3] + R @ np.array(mount.translation)
        v = np.einsum("nij,bj->nbi", R @ mount.rotation_matrix(), unit)
        r = np.full(v.shape[:2], ALTITUDE)
        for _ in range(8):  # fixed point r = (floor(o + r v) - o_z) / v_z (contraction here)
            p = o[:, None, :] + r[..., None] * v
            r = (_floor(p[..., 0], p[..., 1]) - o[:, None, 2]) / v[..., 2]
        rays[name] = (o, o[:, None, :] + r[..., None] * v, r)
    dvl_r, sonar_r = rays["dvl"][2], rays["sonar"][2][:, 0]
    dvl = Dvl.from_velocity(t, np.zeros((k.size, 3)), beam_range=dvl_r, beam_valid=dvl_r > 0)
    log = Log(dvl=dvl, sonar=SonarRange(t=t, range=sonar_r), mounting=m)
    return log, traj, rays


def _per_ping(samples: Samples, n_pings: int) -> list[Samples]:
    """Split samples by ping (rays: 4 DVL per ping in order, then 1 sonar per ping): samples
    kept as rays (``build_samples``' RaySamples) into each ping's rays expanded again, as the
    online mapper of the live pipeline gives them to ``integrate`` (``expand``), others as
    written samples."""
    if isinstance(samples, RaySamples):
        rays = samples.rays
        ray = np.arange(len(rays.r))
        ping = np.where(ray < 4 * n_pings, ray // 4, ray - 4 * n_pings)
        order = np.argsort(ping, kind="stable")
        bounds = np.searchsorted(ping[order], np.arange(n_pings + 1))
        fields = (rays.origin, rays.direction, rays.r, rays.var, rays.sig, rays.sensor)
        return [expand(*(a[order[i:j]] for a in fields), rays.f, {})
                for i, j in zip(bounds[:-1], bounds[1:], strict=True)]  # fmt: skip
    ping = np.where(samples.ray < 4 * n_pings, samples.ray // 4, samples.ray - 4 * n_pings)
    order = np.argsort(ping, kind="stable")
    bounds = np.searchsorted(ping[order], np.arange(n_pings + 1))
    out = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        i = order[a:b]
        fields = (samples.points, samples.label, samples.sigma0, samples.pose_variance)
        out.append(Samples(*(f[i] for f in fields), samples.ray[i], samples.sensor[i]))
    return out


def _mapper(method):
    return make_mapper(method, variance_bounds=VARIANCE_BOUNDS if method == "adaptive" else None)


def bench_per_ping(n_pings: int, area: float, repeats: int = 5) -> dict:
    log, traj, rays = survey_batch(0, n_pings, n_pings, area)
    # untimed: numba's compile / cache load and thread pool, and the allocator's steady state
    # (glibc raises its mmap threshold after the first large frees, so the first few builds
    # also take page faults on every fresh array; a long mapping run is in the steady state)
    for _ in range(5):
        samples = build_samples(log, traj, free_resolution=0.1)
    build_ms = float("inf")
    for _ in range(repeats):  # best of `repeats`, as every figure here
        t0 = time.perf_counter()
        samples = build_samples(log, traj, free_resolution=0.1)
        build_ms = min(build_ms, (time.perf_counter() - t0) * 1e3 / n_pings)
    pings = _per_ping(samples, n_pings)
    out = {"pings": n_pings, "area_m": area, "samples_per_ping": len(samples) / n_pings,
           "build_samples_ms_per_ping": build_ms, "mappers": {}}  # fmt: skip
    warm = Samples.from_points(np.zeros((1, 3)), [1.0])
    for method in ("csm", "bki", "adaptive", "tpu"):
        _mapper(method).integrate(warm)  # numba compile / cache load outside the timing
        batch = stream = float("inf")
        for _ in range(repeats):  # best of `repeats`: the machine is shared
            mapper = _mapper(method)
            t0 = time.perf_counter()
            mapper.integrate(samples)
            batch = min(batch, (time.perf_counter() - t0) * 1e3 / n_pings)
            mapper = _mapper(method)
            t0 = time.perf_counter()
            for p in pings:
                mapper.integrate(p)
            stream = min(stream, (time.perf_counter() - t0) * 1e3 / n_pings)
        tracemalloc.start()
        mem_mapper = _mapper(method)
        mem_mapper.integrate(samples)
        occ = mem_mapper.occupancy()
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        out["mappers"][method] = {
            "integrate_ms_per_ping_batched": batch,
            "integrate_ms_per_ping_streaming": stream,
            "build_plus_integrate_ms_per_ping_batched": batch + build_ms,
            "build_plus_integrate_ms_per_ping_streaming": stream + build_ms,
            "grid_bytes": mapper.grid.nbytes, "chunks": mapper.grid.n_chunks,
            "tracemalloc_peak_bytes_integrate_and_readout": peak,
            "cells_with_mass": len(occ), "occupied_cells": int(np.sum(occ.mean > 0.5)),
        }  # fmt: skip
    out["octomap"] = _bench_octomap(rays, n_pings, repeats)
    adaptive, octo = out["mappers"]["adaptive"], out["octomap"].get("insert_ms_per_ping")
    headline = adaptive["build_plus_integrate_ms_per_ping_batched"]
    out["headline"] = {
        "adaptive_build_plus_integrate_ms_per_ping": headline,
        "adaptive_integrate_only_ms_per_ping": adaptive["integrate_ms_per_ping_batched"],
        "adaptive_build_plus_integrate_per_call_ms_per_ping": adaptive[
            "build_plus_integrate_ms_per_ping_streaming"
        ],
        "octomap_insert_ms_per_ping": octo,
        "adaptive_over_octomap": None if octo is None else headline / octo,
    }
    tpu = out["mappers"]["tpu"]["build_plus_integrate_ms_per_ping_batched"]
    out["headline"]["tpu_build_plus_integrate_ms_per_ping"] = tpu
    out["headline"]["tpu_over_octomap"] = None if octo is None else tpu / octo
    return out


def _octomap_ms_per_ping(octomap, clouds, repeats: int):
    """(best of ``repeats`` ms per ping, the last tree) of OctoMap (res 0.1 m) inserting each
    ping's point clouds ``clouds[i]`` (a sequence of (end points (n, 3), origin (3,)))."""
    ms = float("inf")
    for _ in range(repeats):
        tree = octomap.OcTree(0.1)
        t0 = time.perf_counter()
        for ping in clouds:
            for ends, origin in ping:
                tree.insertPointCloud(ends, origin)
        ms = min(ms, (time.perf_counter() - t0) * 1e3 / len(clouds))
    return ms, tree


def _bench_octomap(rays, n_pings: int, repeats: int) -> dict:
    try:
        import octomap
    except ImportError:
        return {"skipped": "pip install octomap-python"}
    (od, hd, _), (os_, hs, _) = rays["dvl"], rays["sonar"]
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    clouds = [((hd[i], od[i]), (hs[i], os_[i])) for i in range(n_pings)]
    ms, tree = _octomap_ms_per_ping(octomap, clouds, repeats)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {
        "insert_ms_per_ping": ms, "resolution_m": 0.1, "threads": os.environ["OMP_NUM_THREADS"],
        "memory_usage_bytes": int(tree.memoryUsage()), "leaf_nodes": int(tree.getNumLeafNodes()),
        "ru_maxrss_delta_kib": int(rss - rss0),
    }  # fmt: skip


def bench_survey(n_pings: int, area: float, batch: int = 10_000) -> dict:
    """Adaptive BKI (fixed variance bounds, i.e. online) over a lawnmower survey, in batches."""
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    mapper = _mapper("adaptive")
    t_build = t_map = 0.0
    n_samples = 0
    t0 = time.perf_counter()
    for k0 in range(0, n_pings, batch):
        log, traj, _ = survey_batch(k0, min(k0 + batch, n_pings), n_pings, area)
        t1 = time.perf_counter()
        samples = build_samples(log, traj, free_resolution=0.1)
        t2 = time.perf_counter()
        mapper.integrate(samples)
        t_build, t_map = t_build + t2 - t1, t_map + time.perf_counter() - t2
        n_samples += len(samples)
    total = time.perf_counter() - t0
    occ = mapper.occupancy()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    per_ping = (t_build + t_map) / n_pings
    return {
        "method": "adaptive (fixed variance bounds)", "pings": n_pings, "area_m": [area, area],
        "samples": n_samples, "wall_s_total_incl_synthetic_data": total,
        "build_samples_s": t_build, "integrate_s": t_map, "chunks": mapper.grid.n_chunks,
        "grid_bytes": mapper.grid.nbytes, "cells_with_mass": len(occ),
        "occupied_cells": int(np.sum(occ.mean > 0.5)), "ru_maxrss_delta_kib": int(rss - rss0),
        "extrapolated_1M_pings_s_build_plus_integrate": per_ping * 1_000_000,
        "extrapolation_note": "linear in pings from this run (measured, not a 1M run)"
        if n_pings != 1_000_000 else "measured 1M run",
    }  # fmt: skip


# --- multibeam fans over a seabed heightfield ------------------------------------------------

BEAMS, SWATH_DEG = 256, 120.0
FAN_WAVE = (0.25, 0.2)  # amplitude m, frequency Hz: the tpu mapper's wave term, timed


def seabed(x, y, depth, relief=1.0):
    """A synthetic seabed (depth, m, z down): long swells, a 37 m ripple field and small bumps,
    heights times ``relief`` (at most 2.65 m); slopes stay under 0.3 so the range fixed point
    below contracts."""
    return depth + relief * (
        2.0 * np.sin(2 * np.pi * x / 230.0) * np.cos(2 * np.pi * y / 170.0)
        + 0.5 * np.sin(2 * np.pi * (x + y) / 37.0)
        + 0.15 * np.sin(2 * np.pi * x / 9.0) * np.cos(2 * np.pi * y / 7.0))  # fmt: skip


def fan_geometry(area: float, altitude: float, n_pings: int) -> dict:
    """A lawnmower of fans over area x area m: lines along x, spaced 0.7 of the flat swath."""
    half = altitude * np.tan(np.radians(SWATH_DEG / 2))
    n_lines = max(int(np.ceil(area / (1.4 * half))), 1)
    return {"area": area, "altitude": altitude, "n_pings": n_pings, "n_lines": n_lines,
            "per_line": int(np.ceil(n_pings / n_lines)), "spacing": area / n_lines,
            "half_swath": half}  # fmt: skip


def ping_variance(k, g: dict) -> np.ndarray:
    """Pose variance per ping (m^2): drift growing along each line, a small z variance."""
    u = (k % g["per_line"]) / g["per_line"]
    var = np.empty((k.size, 3))
    var[:, 0] = var[:, 1] = 1e-4 + 1e-3 * u
    var[:, 2] = 1e-4 + 1e-4 * (0.5 + 0.5 * np.sin(0.7 * k))
    return var


def _fan(k: np.ndarray, g: dict):
    """Origins (P, 3) and unit directions (P, B, 3) of pings k: the fan across track, heading
    along the line, a small roll/pitch wobble."""
    line, j = k // g["per_line"], k % g["per_line"]
    u = (j + 0.5) / g["per_line"] * g["area"]
    o = np.stack([np.where(line % 2 == 0, u, g["area"] - u), (line + 0.5) * g["spacing"],
                  np.full(k.size, 5.0)], axis=1)  # fmt: skip
    rpy = np.stack([0.03 * np.sin(0.31 * k), 0.02 * np.cos(0.23 * k),
                    np.where(line % 2 == 0, 0.0, np.pi)], axis=1)  # fmt: skip
    a = np.radians(np.linspace(-SWATH_DEG / 2, SWATH_DEG / 2, BEAMS))
    beam = np.stack([np.zeros(BEAMS), np.sin(a), np.cos(a)], axis=1)  # z down
    return o, np.einsum("nij,bj->nbi", rpy_to_matrix(rpy), beam)


def _seabed_params(g: dict):
    """(depth, relief, largest range factor): the seabed is within 2.65 relief m of depth."""
    depth, relief = g["altitude"] + 5.0, min(1.0, 0.25 * g["altitude"])  # ROV: 0.44 m at most
    return depth, relief, (g["altitude"] + 2.65 * relief) / g["altitude"]


def _ranges(o: np.ndarray, v: np.ndarray, g: dict) -> np.ndarray:
    """Exact ray/seabed ranges (N,) of rays o + r v (N, 3): the fixed point
    r = (seabed(o + r v) - o_z) / v_z, contracting by < 0.5 (mm after 10 steps)."""
    depth, relief, _ = _seabed_params(g)
    r = np.full(len(v), g["altitude"]) / v[:, 2]
    for _ in range(10):
        p = o + r[:, None] * v
        r = (seabed(p[:, 0], p[:, 1], depth, relief) - o[:, 2]) / v[:, 2]
    if not np.all(r > 0):
        raise RuntimeError("the synthetic seabed rose above the sonar")
    return r


def fan_rays(k: np.ndarray, g: dict):
    """Origins (P, 3), unit directions (P, B, 3), exact ranges (P, B) of pings k."""
    o, v = _fan(k, g)
    r = _ranges(np.repeat(o, BEAMS, axis=0), v.reshape(-1, 3), g)
    return o, v, r.reshape(v.shape[:2])


def _meets(origin, end, box) -> np.ndarray:
    """Rays whose segment's x-y bounding box meets ``box`` (x0, y0, x1, y1)."""
    lo, hi = np.minimum(origin[:, :2], end[:, :2]), np.maximum(origin[:, :2], end[:, :2])
    return np.all((hi >= box[:2]) & (lo <= box[2:]), axis=1)


def fan_samples(k: np.ndarray, g: dict, f: float, sigma0: float = 0.9, box=None) -> Samples:
    """Training samples of pings k (one hit per beam, free samples every f from the origin),
    through the same numba expansion as ``samples_from_config``; with ``box`` (x0, y0, x1, y1)
    only the rays whose segment's x-y bounding box meets it (found first with the longest
    range the seabed allows, then with the exact one)."""
    o, v = _fan(k, g)
    origin, v = np.repeat(o, BEAMS, axis=0), v.reshape(-1, 3)
    var = np.repeat(ping_variance(k, g), BEAMS, axis=0)
    if box is not None:
        far = origin + (_seabed_params(g)[2] * g["altitude"] / v[:, 2])[:, None] * v
        keep = _meets(origin, far, box)
        origin, v, var = origin[keep], v[keep], var[keep]
    r = _ranges(origin, v, g)
    if box is not None:
        keep = _meets(origin, origin + r[:, None] * v, box)
        origin, v, r, var = origin[keep], v[keep], r[keep], var[keep]
    return samples_from_rays(origin, v, r, var, f, sigma0)


def samples_from_rays(origin, v, r, var, f: float, sigma0: float = 0.9,
                      sensor: int = 0) -> Samples:  # fmt: skip
    """Training samples of world rays (origins, unit directions, ranges, pose variances; one
    row per beam): a hit per beam and free samples every f from the origin, through the same
    numba expansion as ``samples_from_config``; ``sensor`` the code every ray carries (0 DVL,
    2 multibeam: the tpu mapper's range noise)."""
    from undertow.mapping.samples import expand

    n = r.size
    return expand(origin, v, r, var, np.full(n, sigma0), np.full(n, sensor, np.int8), f, {})


def _fan_ms(mapper_of, rays, whole) -> tuple[float, float]:
    """(ms per ping one call per ping, ms per ping all pings in one call) of a fresh mapper
    ``mapper_of()`` building the samples of the multibeam rays and integrating them."""
    mapper = mapper_of()
    t0 = time.perf_counter()
    for ray in rays:
        mapper.integrate(samples_from_rays(*ray, 0.1, sensor=SENSOR_MULTIBEAM))
    ping_ms = (time.perf_counter() - t0) * 1e3 / len(rays)
    mapper = mapper_of()
    t0 = time.perf_counter()
    mapper.integrate(samples_from_rays(*whole, 0.1, sensor=SENSOR_MULTIBEAM))
    return ping_ms, (time.perf_counter() - t0) * 1e3 / len(rays)


def bench_multibeam(n_pings: int = 2000, altitude: float = ALTITUDE, repeats: int = 5) -> dict:
    """One 256-beam fan per call (build the samples from the rays + integrate) vs OctoMap
    inserting the same end points, res 0.1 m, free samples every 0.1 m, for the paper's
    adaptive mapper and the default ``tpu`` (without a wave, and with :data:`FAN_WAVE`, whose
    term each hit adds). Each repeat times our mappers (on all numba threads, then on one)
    and then OctoMap, so that a machine shared with other work slows all alike; every figure
    is the best of its repeats."""
    g = fan_geometry(30.0, altitude, n_pings)
    k = np.arange(n_pings)
    fan_samples(k[:1], g, 0.1)  # compile / cache load
    mappers = {"adaptive": lambda: _mapper("adaptive"), "tpu": lambda: _mapper("tpu"),
               "tpu_wave": lambda: make_mapper("tpu", wave=FAN_WAVE)}  # fmt: skip
    for make in mappers.values():
        make().integrate(fan_samples(k[:1], g, 0.1))
    o, v, r = fan_rays(k, g)
    var = ping_variance(k, g)
    # the detections (rays) come from the sensor, outside the timing, as OctoMap's end points
    rays = [(np.repeat(o[i : i + 1], BEAMS, axis=0), v[i], r[i], np.repeat(var[i : i + 1], BEAMS,
             axis=0)) for i in range(n_pings)]  # fmt: skip
    whole = (np.repeat(o, BEAMS, axis=0), v.reshape(-1, 3), r.ravel(), np.repeat(var, BEAMS, 0))
    samples = len(samples_from_rays(*whole, 0.1)) / n_pings
    all_threads = numba.get_num_threads()
    out = {"beams": BEAMS, "swath_deg": SWATH_DEG, "altitude_m": altitude, "pings": n_pings,
           "samples_per_ping": samples, "numba_threads": all_threads,
           "tpu_wave": {"amplitude_m": FAN_WAVE[0], "frequency_hz": FAN_WAVE[1]}}  # fmt: skip
    try:
        import octomap
    except ImportError:
        octomap = None
    ends = o[:, None, :] + r[..., None] * v
    clouds = [((ends[i], o[i]),) for i in range(n_pings)]
    best: dict = {}

    def keep(name: str, ms: float) -> None:
        best[name] = min(best.get(name, float("inf")), ms)

    for _ in range(repeats):
        for threads in (all_threads, 1):  # both cores (the headline), then one
            numba.set_num_threads(threads)
            names = [""] if threads == all_threads else []
            names += ["_1_thread"] if threads == 1 else []
            for method, make in mappers.items():
                if method == "tpu_wave" and threads != all_threads:
                    continue
                ping_ms, whole_ms = _fan_ms(make, rays, whole)
                for suffix in names:
                    keep(f"{method}_build_plus_integrate_ms_per_ping{suffix}", ping_ms)
                    keep(f"{method}_whole_set_ms_per_ping{suffix}", whole_ms)
        numba.set_num_threads(all_threads)
        if octomap is not None:
            keep("octomap_insert_ms_per_ping", _octomap_ms_per_ping(octomap, clouds, 1)[0])
    out.update(best)
    if octomap is None:
        return {**out, "octomap": {"skipped": "pip install octomap-python"}}
    octo = out["octomap_insert_ms_per_ping"]
    for method in mappers:
        out[f"{method}_over_octomap"] = out[f"{method}_build_plus_integrate_ms_per_ping"] / octo
        if method != "tpu_wave":
            out[f"{method}_over_octomap_1_thread"] = out[
                f"{method}_build_plus_integrate_ms_per_ping_1_thread"] / octo  # fmt: skip
    return {**out, "target": "X_over_octomap <= 1: a ping no slower than OctoMap's insert",
            "met": out["adaptive_over_octomap"] <= 1.0,
            "tpu_met": out["tpu_over_octomap"] <= 1.0}  # fmt: skip


def bench_threads(n_pings: int, area: float, repeats: int = 5) -> dict:
    """The per-ping adaptive figure (build + integrate, whole log) with numba limited to 1 and
    2 threads (the scatter runs on that many threads, one slab of cells each), and OctoMap's,
    same run."""
    log, traj, rays = survey_batch(0, n_pings, n_pings, area)
    out = {}
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        numba.set_num_threads(threads)
        best = float("inf")
        for _ in range(repeats):
            mapper = _mapper("adaptive")
            t0 = time.perf_counter()
            mapper.integrate(build_samples(log, traj, free_resolution=0.1))
            best = min(best, (time.perf_counter() - t0) * 1e3 / n_pings)
        out[f"adaptive_ms_per_ping_{threads}_thread"] = best
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    octo = _bench_octomap(rays, n_pings, repeats).get("insert_ms_per_ping")
    out["octomap_insert_ms_per_ping"] = octo
    out["octomap_threads"] = "1 (the octomap-python wheel is built without OpenMP)"
    if octo:
        best = min(v for k, v in out.items() if k.startswith("adaptive_ms"))
        out["octomap_over_adaptive_best"] = octo / best
        out["target_2x_met"] = octo / best >= 2.0
    return out


# --- km-scale survey: one worker vs tiles on two ----------------------------------------------

KM_RES, KM_ALTITUDE, KM_BATCH_PINGS = 1.0, 10.0, 1000


def km_config(bounds) -> MappingConfig:
    """The adaptive BKI at 1 m: the paper's length scales and free spacing scaled by 10."""
    return MappingConfig(method="adaptive", resolution=KM_RES, l_min=(1.0, 1.0, 0.5),
                         l_max=(1.8, 1.8, 0.8),
                         free_resolution=KM_RES,
                         variance_bounds=tuple(tuple(map(float, b)) for b in bounds))  # fmt: skip


def tile_pings(tile, g: dict, tiling: Tiling) -> np.ndarray:
    """Pings whose fan can reach the tile (the ping within a halo + 2 m of roll/pitch of the
    tile on x, its line's swath + margin overlapping the tile on y) and the tile's box grown
    by that reach (x0, y0, x1, y1), m."""
    k = np.arange(g["n_pings"])
    size, reach = tiling.size_m, tiling.halo + 2 * tiling.resolution + 2.0
    x0, y0 = tile[0] * size - reach, tile[1] * size - reach
    x1, y1 = x0 + size + 2 * reach, y0 + size + 2 * reach
    line, j = k // g["per_line"], k % g["per_line"]
    u = (j + 0.5) / g["per_line"] * g["area"]
    x = np.where(line % 2 == 0, u, g["area"] - u)
    y, half = (line + 0.5) * g["spacing"], 1.6 * g["half_swath"]  # deeper seabed: wider fan
    keep = (x >= x0) & (x <= x1) & (y + half >= y0) & (y - half <= y1)
    return k[keep], np.array([x0, y0, x1, y1])


def km_tile_task(tile, g: dict, tiling: Tiling | None, config: MappingConfig, threads: int = 1):
    """One Dask task: generate, in batches, the rays of the pings that reach ``tile`` whose
    segment meets the tile grown by the halo, integrate all their samples (those outside the
    halo only touch cells the tile does not own, which it drops) with the scatter on
    ``threads`` numba threads, return the cells it owns and the costs (``tiling`` None: the
    whole survey in one mapper, every cell kept)."""
    from undertow.mapping.mappers import mapper_from_config
    from undertow.mapping.threads import scatter_threads
    from undertow.mapping.tiled import TileResult

    with scatter_threads(threads):
        return _km_tile(tile, g, tiling, config, mapper_from_config, TileResult)


def _km_tile(tile, g, tiling, config, mapper_from_config, TileResult):  # noqa: N803
    t0, cpu0 = time.perf_counter(), time.process_time()
    mapper = mapper_from_config(config)
    gen = integ = 0.0
    if tiling is None:
        pings, box = np.arange(g["n_pings"]), None
    else:
        pings, box = tile_pings(tile, g, tiling)
    for a in range(0, pings.size, KM_BATCH_PINGS):
        t1 = time.perf_counter()
        samples = fan_samples(pings[a : a + KM_BATCH_PINGS], g, config.free_resolution, box=box)
        t2 = time.perf_counter()
        mapper.integrate(samples)
        gen, integ = gen + t2 - t1, integ + time.perf_counter() - t2
    cells, alpha, beta = mapper.grid.cells()
    if tiling is not None:
        own = np.all(tiling.tiles_of_cells(cells) == np.asarray(tile), axis=1)
        cells, alpha, beta = cells[own], alpha[own], beta[own]
    result = TileResult(tile, cells, alpha, beta, mapper.n_samples, time.perf_counter() - t0,
                        mapper.grid.nbytes)  # fmt: skip
    rss_mib = _peak_rss_mib()
    stats = {"pings": int(pings.size), "samples": mapper.n_samples, "generate_s": gen,
             "integrate_s": integ, "total_s": result.seconds, "grid_bytes": mapper.grid.nbytes,
             "cpu_s": time.process_time() - cpu0, "worker_pid": os.getpid(),
             "worker_ru_maxrss_mib": rss_mib}  # fmt: skip
    return result, stats


def _peak_rss_mib() -> float:
    """This process's peak resident memory (VmHWM; unlike ru_maxrss it does not carry the
    parent's peak across fork + exec), MiB."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def lpt_makespan(costs, workers: int) -> float:
    """Wall time of running tasks of ``costs`` on ``workers`` (longest first, each to the
    least-loaded worker: Graham's LPT rule, within 4/3 of the optimum)."""
    load = np.zeros(workers)
    for c in sorted(costs, reverse=True):
        load[np.argmin(load)] += c
    return float(load.max())


def km_tiles(g: dict, tiling: Tiling) -> list:
    """Every tile the survey's rays can reach (the fans stick out of the area at its edges)."""
    reach = 1.6 * g["half_swath"] + tiling.halo + 2 * tiling.resolution + 2.0
    lo, hi = -reach, g["area"] + reach
    first, last = int(np.floor(lo / tiling.size_m)), int(np.floor(hi / tiling.size_m))
    return [(i, j) for i in range(first, last + 1) for j in range(first, last + 1)]


def _run_km(g: dict, tiling: Tiling | None, config, workers: int, tile_dir,
            threads: int = 1) -> dict:  # fmt: skip
    """All tiles of ``tiling`` the survey reaches (None: one task, the whole survey) on a
    LocalCluster of ``workers`` single-threaded processes, each task's scatter on ``threads``
    numba threads."""
    from undertow.mapping.tiled import run_tiles, write_tile

    tiles = [(0, 0)] if tiling is None else km_tiles(g, tiling)
    jobs = {tile: (g, tiling, config, threads) for tile in tiles}
    per_tile, sums = {}, np.zeros(3)

    def collect(item) -> None:
        result, stats = item
        per_tile[f"{result.tile[0]}_{result.tile[1]}"] = stats
        sums[:] += (len(result.cells), result.alpha_mass.sum(), result.beta_mass.sum())
        if tile_dir is not None:
            write_tile(tile_dir, result)

    run = run_tiles(km_tile_task, jobs, collect, scheduler="local", n_workers=workers)
    if run.failures:
        raise RuntimeError(f"km survey tiles failed: {run.failures}")
    seconds = [t["total_s"] for t in per_tile.values()]
    cpu: dict = {}
    for t in per_tile.values():
        cpu[t["worker_pid"]] = cpu.get(t["worker_pid"], 0.0) + t["cpu_s"]
    return {"workers": run.workers, "tiles": len(jobs), "wall_s": run.wall_s,
            "cpu_s_per_worker": sorted(cpu.values()),
            "sum_tile_s": float(np.sum(seconds)), "max_tile_s": float(np.max(seconds)),
            "peak_worker_rss_mib": max(t["worker_ru_maxrss_mib"] for t in per_tile.values()),
            "max_tile_grid_bytes": max(t["grid_bytes"] for t in per_tile.values()),
            "samples": int(sum(t["samples"] for t in per_tile.values())),
            "generate_s": float(sum(t["generate_s"] for t in per_tile.values())),
            "integrate_s": float(sum(t["integrate_s"] for t in per_tile.values())),
            "cells": int(sums[0]), "alpha_mass": sums[1], "beta_mass": sums[2],
            "per_tile": per_tile if len(per_tile) <= 64 else "omitted"}  # fmt: skip


def bench_km(rays: int = 10_000_000, area: float = 1000.0, tile_m: float = 250.0) -> dict:
    """Single worker (one tile covering the survey) vs tiles of ``tile_m`` on 2 workers."""
    import tempfile

    from undertow.mapping.tiled import read_tiles, write_index

    g = fan_geometry(area, KM_ALTITUDE, int(np.ceil(rays / BEAMS)))
    var = ping_variance(np.arange(g["n_pings"]), g)
    config = km_config((var.min(axis=0), var.max(axis=0)))  # session bounds, before tiling
    single = _run_km(g, None, config, 1, None)  # one mapper over the whole survey, one thread
    # the same with the scatter on both cores (mapping/grid.py: slabs of cells per thread)
    single_2 = _run_km(g, None, config, 1, None, threads=2)
    tiling = Tiling.for_config(config, tile_m)
    with tempfile.TemporaryDirectory() as tmp:
        tiled = _run_km(g, tiling, config, 2, Path(tmp))
        write_index(tmp, config, tiling, {})
        t0 = time.perf_counter()
        merged = read_tiles(tmp)
        merge_s = time.perf_counter() - t0
        merged_cells = len(merged)
        del merged
    cpu = (
        [t["cpu_s"] for t in tiled["per_tile"].values()]
        if isinstance(tiled["per_tile"], dict)
        else [tiled["sum_tile_s"] / tiled["tiles"]] * tiled["tiles"]
    )
    startup = max(single["wall_s"] - single["sum_tile_s"], 0.0)
    t16 = lpt_makespan(cpu, 16)
    return {
        "rays": g["n_pings"] * BEAMS, "pings": g["n_pings"], "area_m": [area, area],
        "lines": g["n_lines"], "altitude_m": KM_ALTITUDE, "resolution_m": KM_RES,
        "tile_m": tiling.size_m, "halo_m": tiling.halo,
        "single_worker": single, "single_worker_2_threads": single_2, "tiled_2_workers": tiled,
        "speedup": single["wall_s"] / tiled["wall_s"], "speedup_target": 1.6,
        "speedup_over_single_2_threads": single_2["wall_s"] / tiled["wall_s"],
        "single_2_threads_speedup": single["wall_s"] / single_2["wall_s"],
        "speedup_cpu_bound": sum(single["cpu_s_per_worker"]) / max(tiled["cpu_s_per_worker"]),
        "load_average_after": os.getloadavg(),
        "same_map": {"cells": [single["cells"], tiled["cells"], merged_cells],
                     "alpha_mass_rel_diff": abs(tiled["alpha_mass"] / single["alpha_mass"] - 1),
                     "beta_mass_rel_diff": abs(tiled["beta_mass"] / single["beta_mass"] - 1)},
        "merge_read_back_s": merge_s,
        "extrapolation_16_workers": {
            "formula": "longest-processing-time schedule of the measured per-tile CPU seconds "
            "on 16 workers + cluster start (single run: wall - task) + merge (read back)",
            "tile_cpu_s_sum": float(np.sum(cpu)), "tile_cpu_s_max": float(np.max(cpu)),
            "tile_work_s": t16, "startup_s": startup, "merge_s": merge_s,
            "wall_s": t16 + startup + merge_s,
            "single_cpu_s": single["cpu_s_per_worker"][0],
        },
    }  # fmt: skip


def main(pings: int = 20_000, area: float = 30.0, survey_pings: int = 1_000_000,
         survey_area: float = 100.0, survey: bool = True, km_rays: int = 10_000_000,
         km_area: float = 1000.0, km_tile: float = 250.0, km: bool = True,
         multibeam_pings: int = 2000) -> dict:  # fmt: skip
    result = {"per_ping": bench_per_ping(pings, area), "cpu_count": os.cpu_count()}
    result["per_ping"]["multibeam"] = multibeam = bench_multibeam(multibeam_pings)
    four_beam = result["per_ping"]["headline"]["adaptive_over_octomap"]
    # the targets, read off the figures above (same run): OctoMap / adaptive >= 2 for the 4-beam
    # ping, adaptive / OctoMap <= 1 for the 256-beam one (per_ping.multibeam)
    result["four_beam_target_met"] = None if four_beam is None else bool(four_beam <= 0.5)
    result["multibeam_adaptive_over_octomap"] = multibeam.get("adaptive_over_octomap")
    result["multibeam_target_met"] = multibeam.get("met")
    # the same targets for the default mapper, tpu
    tpu_four = result["per_ping"]["headline"]["tpu_over_octomap"]
    result["four_beam_tpu_target_met"] = None if tpu_four is None else bool(tpu_four <= 0.5)
    result["multibeam_tpu_over_octomap"] = multibeam.get("tpu_over_octomap")
    result["multibeam_tpu_target_met"] = multibeam.get("tpu_met")
    result["per_ping"]["threads"] = bench_threads(pings, area)
    if survey:
        result["survey"] = bench_survey(survey_pings, survey_area)
    if km:
        result["km_survey"] = bench_km(km_rays, km_area, km_tile)
    return result


SMOKE = {"pings": 2000, "survey_pings": 20_000, "km_rays": 300_000, "km_area": 150.0,
         "km_tile": 50.0, "multibeam_pings": 200}  # fmt: skip


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pings", type=int, default=20_000)
    ap.add_argument("--area", type=float, default=30.0)
    ap.add_argument("--survey-pings", type=int, default=1_000_000)
    ap.add_argument("--survey-area", type=float, default=100.0)
    ap.add_argument("--no-survey", action="store_true")
    ap.add_argument("--km-rays", type=int, default=10_000_000)
    ap.add_argument("--km-area", type=float, default=1000.0)
    ap.add_argument("--km-tile", type=float, default=250.0)
    ap.add_argument("--no-km", action="store_true")
    ap.add_argument("--multibeam-pings", type=int, default=2000)
    ap.add_argument("--smoke", action="store_true", help="small sizes (about a minute)")
    a = vars(ap.parse_args())
    if a.pop("smoke"):
        a.update(SMOKE)
    a["survey"], a["km"] = not a.pop("no_survey"), not a.pop("no_km")
    res = main(**a)
    json.dump(res, sys.stdout, indent=2)
    print()
