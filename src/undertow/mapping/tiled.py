"""Tiled mapping on Dask: the map cut into square x-y tiles, each mapped as an independent task.

The concentration parameters of ``eq:alpha_param`` / ``eq:beta_param`` are sums over samples,

    alpha_* = alpha_0 + sum_i k(m_*, m_i) y_i,    beta_* = beta_0 + sum_i k(m_*, m_i)(1 - y_i),

and k(m_*, m_i) = 0 once m_i is farther than the kernel's support L from the cell centre m_*
(``eq:kernel`` is compactly supported: k(d) = 0 for d >= l). So a cell's sums need only the
samples within L of it. A tile owns the cells whose index (floor(p / res)) falls in its square
of ``cells_per_tile`` cells on x and y (every cell is owned by exactly one tile); its task is
given the samples whose support can reach one of its cells (its square grown by a halo of L plus
a cell), maps them with the ordinary mapper and keeps only the cells it owns. The samples keep
their global order inside a tile, so every owned cell receives the same terms in the same order
as in one mapper over all samples: the merged map (the concatenation of the tiles' cells) equals
the single-process map, not just to rounding.

The adaptive kernel's session normalization (``eq:lengthscale_1``: s~^2 = (s^2 - s_min^2) /
(s_max^2 - s_min^2)) takes its bounds over ALL samples before tiling, and every tile uses them.

Schedulers (``scheduler=``): ``"local"`` (None) a :class:`distributed.LocalCluster` of
single-threaded worker processes, ``"threads"`` an in-process cluster of threads (the scatter
passes release the GIL, so tiles overlap there too, apart from the Python and numpy work around
them; it avoids sending samples to other processes), ``"sync"`` sequential without Dask, or the
address of a running scheduler (``tcp://host:8786``). A task that raises is retried by Dask
(``retries``); one that fails again is reported by tile id, the other tiles are kept. At most
one task per worker is in flight, so a worker holds one tile's samples and grid at a time;
finished tiles can be written one by one to a tile directory (:func:`write_tile`) and read back
as one map (:func:`read_tiles`).
Each tile's scatter runs on one numba thread (:func:`~undertow.mapping.threads.scatter_threads`):
the tiles are the parallelism.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
import warnings
from collections.abc import Callable, Iterable
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._util.dask import check_scheduler, describe_exception
from ..errors import ConfigError, DataError, ReaderError
from ..occupancy import ColumnStats, OccupancyMap, column_arrays, stored_columns
from .config import MappingConfig
from .mappers import mapper_from_config
from .samples import Samples
from .threads import scatter_threads

TileId = tuple[int, int]
INDEX_FILE = "tiles.json"
DEFAULT_RETRIES = 1


#: the tpu mapper's settings, recorded with its map
TPU_FIELDS = (
    "base_length",
    "max_length",
    "range_std_dvl",
    "range_std_sonar",
    "range_std_multibeam",
    "range_std_fraction",
    "sonar_beam_width_deg",
    "sonar_carve",
    "wave_range_noise",
    "wave",
    "wave_depth_noise",
    "depth_noise",
)


def kernel_support(config: MappingConfig) -> float:
    """Largest distance (m) on x or y at which a sample still adds mass to a cell: the
    adaptive kernel's l_j <= max(l_min_j, l_max_j) (``eq:lengthscale_1``), the BKI length
    scale l, the tpu kernel's l_cap (``max_length``), and 0 for the counting sensor model
    (its own cell only)."""
    if config.method == "adaptive":
        return float(max(max(config.l_min[:2]), max(config.l_max[:2])))
    if config.method == "tpu":
        return float(config.max_length)
    if config.method == "bki":
        return float(config.length_scale)
    return 0.0


def tile_name(tile: TileId) -> str:
    """``"3_-2"`` for tile (3, -2): tile (i, j) owns cells with floor(cell_x / n) = i,
    floor(cell_y / n) = j."""
    return f"{tile[0]}_{tile[1]}"


@dataclass(frozen=True)
class Tiling:
    """Square x-y tiles of ``cells_per_tile`` cells of ``resolution`` m, with a ``halo`` (m)."""

    resolution: float
    cells_per_tile: int
    halo: float

    @classmethod
    def for_config(cls, config: MappingConfig, size_m: float) -> Tiling:
        """Tiles of about ``size_m`` metres (rounded to whole cells) and the halo of the
        config's kernel support."""
        if not (isinstance(size_m, int | float) and math.isfinite(size_m)) or size_m <= 0:
            raise ConfigError(f"tile size must be a positive number of metres, got {size_m!r}")
        if size_m < config.resolution:
            raise ConfigError(
                f"tile size {size_m:g} m is below the map resolution {config.resolution:g} m"
            )
        n = max(1, round(size_m / config.resolution))
        return cls(float(config.resolution), int(n), kernel_support(config))

    @property
    def size_m(self) -> float:
        return self.cells_per_tile * self.resolution

    def tiles_of_cells(self, cells: np.ndarray) -> np.ndarray:
        """(M, 2) tile index of each cell (M, 3): floor(cell / cells_per_tile) on x and y."""
        return np.floor_divide(np.asarray(cells)[:, :2], self.cells_per_tile)

    def sample_tile_ranges(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per sample, the first and last tile (x, y) its support can reach: cells
        floor(p / res -+ L / res) -+ 1 (one cell of margin over the scatter kernel's
        floor(p / res - L / res - 1/2) + 1 .. ceil(p / res + L / res - 1/2) - 1)."""
        p = np.asarray(points)[:, :2] / self.resolution
        r = self.halo / self.resolution
        lo = np.floor(p - r).astype(np.int64) - 1
        hi = np.floor(p + r).astype(np.int64) + 1
        return np.floor_divide(lo, self.cells_per_tile), np.floor_divide(hi, self.cells_per_tile)

    def partition(self, points: np.ndarray) -> dict[TileId, np.ndarray]:
        """Sample indices (ascending, i.e. in the samples' order) per tile whose cells their
        support can reach; a sample near a border goes to every tile it reaches."""
        lo, hi = self.sample_tile_ranges(points)
        span = hi - lo
        keys, index = [], []
        every = np.arange(len(lo))
        for dx in range(int(span[:, 0].max(initial=0)) + 1):
            for dy in range(int(span[:, 1].max(initial=0)) + 1):
                take = every[(span[:, 0] >= dx) & (span[:, 1] >= dy)]
                keys.append(lo[take] + (dx, dy))
                index.append(take)
        if not keys:
            return {}
        keys_all, index_all = np.concatenate(keys), np.concatenate(index)
        order = np.lexsort((index_all, keys_all[:, 1], keys_all[:, 0]))
        keys_all, index_all = keys_all[order], index_all[order]
        starts = np.flatnonzero(np.r_[True, np.any(keys_all[1:] != keys_all[:-1], axis=1)])
        ends = np.r_[starts[1:], len(order)]
        return {(int(keys_all[a, 0]), int(keys_all[a, 1])): index_all[a:b]
                for a, b in zip(starts, ends, strict=True)}  # fmt: skip


def session_bounds(samples: Samples, config: MappingConfig):
    """The adaptive kernel's variance bounds for the whole session (min, max over all samples
    per axis), or the config's fixed ones; None for the other methods."""
    if config.method != "adaptive":
        return None
    if config.variance_bounds is not None:
        return tuple(np.asarray(b, float) for b in config.variance_bounds)
    if len(samples) == 0:
        return None
    var = samples.pose_variance
    return var.min(axis=0), var.max(axis=0)


def subset(samples: Samples, index: np.ndarray) -> Samples:
    """The samples at ``index`` (in that order), with the origins of their rays only (the
    ``tpu`` mapper needs each hit's range)."""
    ray = samples.ray[index]
    origins = np.zeros((0, 3))
    if len(samples.origins):
        used = ray >= 0
        rays, inverse = np.unique(ray[used], return_inverse=True)
        ray = np.where(used, 0, -1)
        ray[used] = inverse
        origins = samples.origins[rays]
    return Samples(samples.points[index], samples.label[index], samples.sigma0[index],
                   samples.pose_variance[index], ray, samples.sensor[index],
                   origins)  # fmt: skip


@dataclass
class TileResult:
    """One tile's owned cells and their evidence mass (alpha - alpha_0, beta - beta_0), and
    its owned columns' sums (a ``tpu`` map's, else None)."""

    tile: TileId
    cells: np.ndarray
    alpha_mass: np.ndarray
    beta_mass: np.ndarray
    n_samples: int = 0
    seconds: float = 0.0
    grid_bytes: int = 0
    columns: ColumnStats | None = None


def map_tile(tile: TileId, samples: Samples, config: MappingConfig, tiling: Tiling,
             bounds=None) -> TileResult:  # fmt: skip
    """Map ``samples`` (those reaching ``tile``) with the config's mapper and keep the cells
    the tile owns; ``bounds``: the session's variance bounds (adaptive), used as fixed ones."""
    start = time.perf_counter()
    if bounds is not None:
        config = config.model_copy(update={"variance_bounds": tuple(bounds)})
    mapper = mapper_from_config(config)
    with scatter_threads(1):  # the tiles are the parallelism: one thread each
        mapper.integrate(samples)
    cells, alpha, beta = mapper.grid.cells()
    own = np.all(tiling.tiles_of_cells(cells) == np.asarray(tile), axis=1)
    columns = mapper.column_stats()
    if columns is not None:
        mine = np.all(tiling.tiles_of_cells(columns.cells) == np.asarray(tile), axis=1)
        carve = None if columns.carve is None else columns.carve[mine]
        columns = ColumnStats(columns.cells[mine], columns.sums[mine], carve)
    return TileResult(tile, cells[own], alpha[own], beta[own], len(samples),
                      time.perf_counter() - start, mapper.grid.nbytes, columns)  # fmt: skip


def _tile_task(tile: TileId, source, config, tiling, bounds) -> TileResult:
    """The Dask task: ``source`` is the tile's Samples or a callable returning them."""
    samples = source(tile) if callable(source) else source
    return map_tile(tile, samples, config, tiling, bounds)


@dataclass
class TileRun:
    """How a set of tile tasks ran: failures by tile (one line each), scheduler, workers."""

    failures: dict[TileId, str] = field(default_factory=dict)
    scheduler: str = ""
    workers: int = 0
    wall_s: float = 0.0


def run_tiles(task: Callable[..., Any], jobs, on_result,
              scheduler: str | None = None, retries: int = DEFAULT_RETRIES,
              n_workers: int | None = None) -> TileRun:  # fmt: skip
    """Run ``task(tile, *args)`` for every ``(tile, args)`` of ``jobs.items()`` (a dict, or
    anything with ``items()`` and ``len()``), ``on_result(result)`` as each ends (results are
    not kept here). A task that raises is run again up to ``retries`` times; one
    that still fails is recorded in ``TileRun.failures`` and the others go on."""
    mode = check_scheduler(scheduler)
    if retries < 0:
        raise ConfigError(f"retries must be >= 0, got {retries}")
    start = time.perf_counter()
    run = TileRun(scheduler=mode)
    if mode == "sync":
        for tile, args in jobs.items():
            for attempt in range(retries + 1):
                try:
                    on_result(task(tile, *args))
                    break
                except Exception as exc:  # a failing tile must not lose the others
                    if attempt == retries:
                        run.failures[tile] = describe_exception(exc)
        run.workers = 1
    elif jobs:
        _run_distributed(task, jobs, on_result, mode, retries, n_workers, run)
    run.wall_s = time.perf_counter() - start
    return run


@contextmanager
def _default_malloc():
    """Worker processes started inside keep glibc's default, adaptive malloc thresholds. Dask
    sets ``MALLOC_TRIM_THRESHOLD_`` for its workers (to hand freed memory back to the system at
    once), which also fixes glibc's mmap threshold: then every large array a tile allocates
    (samples, grid growth) is mapped and faulted in anew, which slowed the tiles measurably
    (docs/benchmarks.md). A worker's memory stays bounded by its largest tile either way
    (glibc keeps at most what a tile used). A nanny also copies its settings into this
    process's environment, which later workers inherit: that copy is lifted while the cluster
    starts (a value the user set is kept)."""
    import dask

    name = "MALLOC_TRIM_THRESHOLD_"
    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    dask_value = env.pop(name, None)
    inherited = dask_value is not None and os.environ.get(name) == str(dask_value)
    with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
        if inherited:
            del os.environ[name]
        try:
            yield
        finally:
            if inherited:
                os.environ[name] = str(dask_value)


def _run_distributed(task, jobs, on_result, mode, retries, n_workers, run: TileRun) -> None:
    from distributed import Client, LocalCluster

    if mode in ("local", "threads"):
        cpus = os.cpu_count() or 1
        n = max(1, min(n_workers or cpus, len(jobs)))
        processes = mode == "local"
        with warnings.catch_warnings(), _default_malloc():
            # the health-check HTTP server falls back from 8787
            warnings.filterwarnings("ignore", message="Port .* is already in use")
            cluster = LocalCluster(
                n_workers=n if processes else 1, threads_per_worker=1 if processes else n,
                processes=processes, dashboard_address=None, silence_logs=logging.ERROR,
            )  # fmt: skip
        with cluster, Client(cluster) as client:
            run.workers = n
            _submit_bounded(client, task, jobs, on_result, retries, n, run)
        run.scheduler = f"{mode} ({n} {'worker processes' if processes else 'threads'})"
        return
    try:
        client = Client(mode, timeout=3.0)
    except Exception as exc:  # nothing listens, or not a Dask scheduler
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ConfigError(f"cannot reach the Dask scheduler at {mode}: {reason}") from None
    with client:
        run.workers = max(1, len(client.scheduler_info().get("workers", {})))
        _submit_bounded(client, task, jobs, on_result, retries, run.workers, run)
    run.scheduler = f"{mode} ({run.workers} workers)"


def _submit_bounded(client, task, jobs, on_result, retries, in_flight, run: TileRun) -> None:
    """Keep at most ``in_flight`` tasks submitted (a worker holds one tile at a time); the
    tile's data travels with its task and is released when the task ends."""
    from distributed import as_completed

    pending = iter(jobs.items())
    tile_of = {}

    def submit_next(into) -> None:
        item = next(pending, None)
        if item is not None:
            tile, args = item
            future = client.submit(task, tile, *args, retries=retries, pure=False)
            tile_of[future.key] = tile
            into.add(future)

    running = as_completed([])
    for _ in range(in_flight):
        submit_next(running)
    for future in running:
        tile = tile_of.pop(future.key)
        try:
            result = future.result()
        except Exception as exc:  # failed after its retries, worker lost, not picklable
            run.failures[tile] = describe_exception(exc)
        else:
            on_result(result)
        future.release()
        submit_next(running)


class TileCollector:
    """Receives finished tiles: writes each to ``tile_dir`` (then drops it) or keeps it."""

    def __init__(self, tile_dir: str | Path | None = None) -> None:
        self.tile_dir = None if tile_dir is None else Path(tile_dir)
        self.results: list[TileResult] = []
        self.stats: dict[str, dict] = {}
        if self.tile_dir is not None:
            self.tile_dir.mkdir(parents=True, exist_ok=True)

    def __call__(self, result: TileResult) -> None:
        self.stats[tile_name(result.tile)] = {
            "cells": len(result.cells), "samples": result.n_samples,
            "seconds": round(result.seconds, 4), "grid_bytes": result.grid_bytes,
        }  # fmt: skip
        if self.tile_dir is None:
            self.results.append(result)
        else:
            write_tile(self.tile_dir, result)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(cells, alpha mass, beta mass) of every kept tile, concatenated."""
        if not self.results:
            return np.zeros((0, 3), np.int64), np.zeros(0), np.zeros(0)
        return (np.concatenate([r.cells for r in self.results]),
                np.concatenate([r.alpha_mass for r in self.results]),
                np.concatenate([r.beta_mass for r in self.results]))  # fmt: skip


class _TileJobs:
    """The tasks' arguments, each tile's samples cut out only when its task is submitted (the
    client holds the samples once, plus one tile per worker in flight)."""

    def __init__(self, samples: Samples, parts: dict, rest: tuple) -> None:
        self.samples, self.parts, self.rest = samples, parts, rest

    def __len__(self) -> int:
        return len(self.parts)

    def items(self):
        for tile, index in self.parts.items():
            yield tile, (subset(self.samples, index), *self.rest)


@dataclass
class TiledMap:
    """The merged map (None when written to a tile directory with ``read_back=False``), the
    tiles that failed (id -> one line), and the run's facts for the map's metadata."""

    map: OccupancyMap | None
    failed: dict[str, str]
    metadata: dict


def map_tiled(samples: Samples, config: MappingConfig, tile_size: float, *,
              scheduler: str | None = None, retries: int = DEFAULT_RETRIES,
              tile_dir: str | Path | None = None, n_workers: int | None = None,
              read_back: bool = True) -> TiledMap:  # fmt: skip
    """Map ``samples`` in tiles of ``tile_size`` m on Dask (module doc) and merge them.

    The adaptive kernel's session bounds are taken over all samples first. With ``tile_dir``
    each finished tile is written there (:func:`write_tile`) and the map read back from it
    (:func:`read_tiles`) when ``read_back``. Tiles that fail twice are left out, named in
    ``failed`` and in one warning."""
    tiling = Tiling.for_config(config, tile_size)
    check_scheduler(scheduler)
    bounds = session_bounds(samples, config)
    jobs = _TileJobs(samples, tiling.partition(samples.points), (config, tiling, bounds))
    collector = TileCollector(tile_dir)
    run = run_tiles(_tile_task, jobs, collector, scheduler, retries, n_workers)
    meta = tiled_metadata(config, tiling, bounds, run, collector, len(samples), len(jobs))
    if tile_dir is not None:
        write_index(tile_dir, config, tiling, meta)
        merged = read_tiles(tile_dir) if read_back else None
    else:
        cells, a, b = collector.arrays()
        merged = OccupancyMap(cells, config.alpha0 + a, config.beta0 + b, config.resolution,
                              config.alpha0, config.beta0, meta,
                              tile_columns(collector.results))  # fmt: skip
    failed = {tile_name(t): why for t, why in sorted(run.failures.items())}
    if failed:
        first = next(iter(failed.items()))
        warnings.warn(
            f"{len(failed)} of {len(jobs)} tiles failed after {retries} retr"
            f"{'y' if retries == 1 else 'ies'} and are missing from the map: tiles "
            f"{', '.join(failed)} (tile {first[0]}: {first[1]})",
            stacklevel=2,
        )
    return TiledMap(merged, failed, meta)


def check_tiling(tile_size: float | None, scheduler: str | None, prior,
                 config: MappingConfig) -> None:  # fmt: skip
    """The options of a tiled map (``tile_size`` m, or None for an untiled one; the
    ``scheduler``; a ``prior`` map, which tiling cannot take), checked one line each before any
    file is read; a scheduler address is reached once."""
    if tile_size is None:
        if scheduler is not None:
            raise ConfigError("--scheduler applies to tiled mapping: give --tiles SIZE_M too")
        return
    Tiling.for_config(config, tile_size)
    if prior is not None:
        raise ConfigError("--prior cannot be combined with --tiles (map the prior's area untiled)")
    check_scheduler(scheduler, reach=True)


def tiled_metadata(config, tiling: Tiling, bounds, run: TileRun, collector: TileCollector,
                   n_samples: int, n_tiles: int) -> dict:  # fmt: skip
    """What the merged map records: the mapper's settings, the tiling and how it ran."""
    meta = {"method": config.method, "resolution": config.resolution, "alpha0": config.alpha0,
            "beta0": config.beta0, "n_samples": n_samples, "n_integrations": 1,
            "seeded_from": ""}  # fmt: skip
    if config.method == "bki":
        meta["length_scale"] = config.length_scale
    if config.method == "tpu":
        meta.update({k: getattr(config, k) for k in TPU_FIELDS})
    if config.method == "adaptive":
        meta.update(l_min=list(config.l_min), l_max=list(config.l_max),
                    normalization="session" if config.variance_bounds is None else "fixed",
                    variance_bounds=None if bounds is None
                    else [np.asarray(b).tolist() for b in bounds])  # fmt: skip
    meta["tiling"] = {
        "tile_size_m": tiling.size_m, "cells_per_tile": tiling.cells_per_tile,
        "halo_m": tiling.halo, "tiles": n_tiles, "scheduler": run.scheduler,
        "workers": run.workers, "wall_s": round(run.wall_s, 3),
        "failed": {tile_name(t): why for t, why in sorted(run.failures.items())},
        "per_tile": collector.stats,
    }  # fmt: skip
    return meta


def write_tile(tile_dir: str | Path, result: TileResult) -> Path:
    """``tile_dir/tile_<i>_<j>.npz``: the tile's owned cells and evidence mass."""
    path = Path(tile_dir) / f"tile_{tile_name(result.tile)}.npz"
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, cells=result.cells, alpha_mass=result.alpha_mass,
             beta_mass=result.beta_mass, tile=np.asarray(result.tile),
             **column_arrays(result.columns))  # fmt: skip
    os.replace(tmp, path)
    return path


def write_index(tile_dir: str | Path, config: MappingConfig, tiling: Tiling, meta: dict) -> Path:
    """``tile_dir/tiles.json``: resolution, priors, tiling and the map's metadata."""
    path = Path(tile_dir) / INDEX_FILE
    doc = {"resolution": config.resolution, "alpha0": config.alpha0, "beta0": config.beta0,
           "cells_per_tile": tiling.cells_per_tile, "metadata": meta}  # fmt: skip
    path.write_text(json.dumps(doc, default=str, indent=1))
    return path


def iter_tiles(tile_dir: str | Path) -> Iterable[TileResult]:
    """The tiles of a tile directory, one at a time (for processing a map larger than memory)."""
    for path in sorted(Path(tile_dir).glob("tile_*.npz")):
        if path.name.endswith(".tmp.npz"):
            continue
        try:
            with np.load(path, allow_pickle=False) as d:
                tile = tuple(int(v) for v in d["tile"])
                columns = stored_columns(d)
                yield TileResult(tile, d["cells"], d["alpha_mass"], d["beta_mass"],
                                 columns=columns)  # fmt: skip
        except (KeyError, ValueError, OSError) as exc:
            raise ReaderError(f"{path}: not a map tile ({exc})") from None


def read_tiles(tile_dir: str | Path) -> OccupancyMap:
    """The map of a tile directory (:func:`write_tile` files plus ``tiles.json``) as one
    :class:`~undertow.occupancy.OccupancyMap` (cells in tile order)."""
    index = Path(tile_dir) / INDEX_FILE
    try:
        doc = json.loads(index.read_text())
        resolution, alpha0, beta0 = (float(doc[k]) for k in ("resolution", "alpha0", "beta0"))
    except FileNotFoundError:
        raise ReaderError(f"{index}: no such file; expected a tile directory") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise ReaderError(f"{index}: not a tile index ({exc})") from None
    tiles = list(iter_tiles(tile_dir))
    if tiles:
        cells = np.concatenate([t.cells for t in tiles])
        a = np.concatenate([t.alpha_mass for t in tiles])
        b = np.concatenate([t.beta_mass for t in tiles])
    else:
        cells, a, b = np.zeros((0, 3), np.int64), np.zeros(0), np.zeros(0)
    n = int(doc.get("cells_per_tile", 0))
    for t in tiles:  # each tile holds only cells it owns, so no cell is in two tiles
        if n > 0 and not np.all(np.floor_divide(t.cells[:, :2], n) == t.tile):
            raise DataError(f"{tile_dir}: tile {tile_name(t.tile)} holds cells of another tile")
    return OccupancyMap(cells, alpha0 + a, beta0 + b, resolution, alpha0, beta0,
                        doc.get("metadata", {}), tile_columns(tiles))  # fmt: skip


def tile_columns(tiles) -> ColumnStats | None:
    """The column sums of the tiles merged (each tile holds the columns it owns), or None when
    the tiles have none (not a ``tpu`` map)."""
    parts = [t.columns for t in tiles if t.columns is not None]
    return ColumnStats.merged(parts) if parts else None
