"""Map a log along a trajectory end to end: training samples, one mapper pass, the map."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, DataError, MissingStreamError
from ..io.units import reading_record
from ..log import Log
from ..occupancy import OccupancyMap
from ..trajectory import Trajectory
from .config import MappingConfig
from .grid_map import GridOccupancy
from .mappers import mapper_from_config, out_of_memory
from .samples import samples_from_config
from .tpu import with_wave


@dataclass
class MappingResult:
    """The map, and what went into it (sample counts, dropped ranges, mapper settings);
    ``warnings``: what reading and mapping warned of (filled by
    :func:`undertow.commands.mapping.map_file`). ``map``: an OccupancyMap, or from
    :func:`map_pieces` a map that outgrew ``mapping.resident_mb`` as a
    :class:`~undertow.mapping.grid_map.GridOccupancy` (read out part by part; ``load()``)."""

    map: OccupancyMap | GridOccupancy
    config: MappingConfig
    metadata: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def map_log(
    log: Log, trajectory: Trajectory, config: MappingConfig | None = None, prior=None
) -> MappingResult:
    """Training samples from every valid range (DVL beams, sonar), then one mapper pass."""
    config = with_wave(config or MappingConfig(), trajectory, log)
    if config.use_dvl and log.sonar is None and log.multibeam is None:
        log.require("dvl", stage="map")
    try:
        samples = samples_from_config(log, trajectory, config)
        mapper = mapper_from_config(config, prior=prior)
        mapper.integrate(samples)
        occupancy = mapper.occupancy()
    except MemoryError:
        raise out_of_memory(config.resolution) from None
    except DataError as error:
        raise _implausible_trajectory(trajectory) or error from None
    # the threshold the map was made with, for `evaluate map` (older maps: 0.5)
    occupancy = dataclasses.replace(
        occupancy,
        metadata={**occupancy.metadata, "occupied_threshold": config.occupied_threshold},
    )
    metadata = map_metadata(mapper.metadata(), samples, occupancy, config, trajectory, log)
    return MappingResult(occupancy, config, metadata)


#: the mappers whose map of samples integrated in pieces is the map of them all at once (the
#: adaptive kernels normalize the pose variance over the session's samples; tpu's lengths are
#: each sample's own, capped by a setting)
PIECE_METHODS = ("csm", "bki", "tpu")


def map_pieces(pieces: Iterable[Log], trajectory, config: MappingConfig | None = None,
               prior=None) -> MappingResult:  # fmt: skip
    """:func:`map_log` of the log the consecutive ``pieces`` make
    (:func:`undertow.io.iter_log_pieces`), each piece's samples integrated in turn
    (:meth:`~undertow.mapping.mappers.Mapper.integrate` adds kernel mass), so that one piece's
    samples are in memory. The same cells (in another order); ``csm`` counts exactly, ``bki``
    sums float32 kernel weights in another grouping (alpha and beta within 2e-6). The
    metadata's ``n_integrations`` counts the pieces with ranges. ``trajectory``: a Trajectory
    or a lazy :class:`~undertow.trajectory_chunks.PoseTrack`. Methods: :data:`PIECE_METHODS`.
    A map that outgrew ``mapping.resident_mb`` (chunks spilled) comes back as a
    :class:`~undertow.mapping.grid_map.GridOccupancy`: a day's survey is never formed whole."""
    config = with_wave(config or MappingConfig(), trajectory)
    if config.method not in PIECE_METHODS:
        raise ConfigError(f"map in pieces: method {config.method} normalizes over the whole log;"
                          f" use one of {', '.join(PIECE_METHODS)}")  # fmt: skip
    mapper = mapper_from_config(config, prior=prior)
    counts = {"hits": 0, "free": 0, "dropped": {}}
    first = None
    for log in pieces:
        first = log if first is None else first
        ranges = [log.dvl if config.use_dvl else None, log.sonar if config.use_sonar else None,
                  log.multibeam if config.use_multibeam else None]  # fmt: skip
        if not any(r is not None and len(r) for r in ranges):
            continue
        try:
            samples = samples_from_config(log, _window(trajectory, ranges), config)
            mapper.integrate(samples)
        except MemoryError:
            raise out_of_memory(config.resolution) from None
        except DataError as error:
            raise _implausible_trajectory(trajectory) or error from None
        for key, value in sample_counts(samples).items():
            if key == "dropped":
                for k, v in value.items():
                    counts[key][k] = counts[key].get(k, 0) + v
            else:
                counts[key] += value
        del samples
    if mapper.n_integrations == 0:
        raise MissingStreamError("mapping needs a range stream but the log has none")
    meta = {**mapper.metadata(), "occupied_threshold": config.occupied_threshold}
    if len(mapper.grid.spill):  # larger than its resident budget: read out part by part
        occupancy = GridOccupancy(mapper, meta)
    else:
        occupancy = dataclasses.replace(mapper.occupancy(), metadata=meta)
    metadata = map_metadata(mapper.metadata(), counts, occupancy, config, trajectory, first)
    return MappingResult(occupancy, config, metadata)


def _window(trajectory, ranges):
    """The part of a lazy :class:`~undertow.trajectory_chunks.PoseTrack` around the times of
    ``ranges`` (the same poses: :meth:`~undertow.trajectory_chunks.PoseTrack.window`), so that a
    piece's interpolation costs its window, not the day; any other trajectory as it is."""
    if not hasattr(trajectory, "window"):
        return trajectory
    times = [r.t for r in ranges if r is not None and len(r)]
    return trajectory.window(min(float(t[0]) for t in times), max(float(t[-1]) for t in times))


def sample_counts(samples) -> dict:
    """hits, free and dropped ranges (by reason) of ``samples``."""
    return {
        "hits": int((samples.label == 1).sum()),
        "free": int((samples.label == 0).sum()),
        "dropped": {k: int(v) for k, v in samples.dropped.items()},
    }


def map_metadata(mapper: dict, samples, occupancy: OccupancyMap, config: MappingConfig,
                 trajectory: Trajectory, log: Log) -> dict:  # fmt: skip
    """What a map records of how it was made: the mapper's settings, the samples (hits, free,
    dropped; or those counts as :func:`sample_counts` gives them), its cells and where the
    poses and ranges came from."""
    return {
        "mapper": mapper,
        "samples": samples if isinstance(samples, dict) else sample_counts(samples),
        "cells_with_mass": len(occupancy),
        "occupied_cells": occupancy.n_occupied(config.occupied_threshold),
        "trajectory_variant": trajectory.variant,
        "source": log.source,
        "log": reading_record(log.metadata),
    }


def tiled_map_metadata(tiled, samples, log: Log, trajectory: Trajectory,
                       config: MappingConfig) -> dict:  # fmt: skip
    """What a tiled map (a :class:`~undertow.mapping.tiled.TiledMap` of ``samples``) records:
    the mapper's settings, the tiling (without its per-tile facts), then the rest of
    :func:`map_metadata`."""
    meta = map_metadata({k: v for k, v in tiled.metadata.items() if k != "tiling"}, samples,
                        tiled.map, config, trajectory, log)  # fmt: skip
    tiling = {k: v for k, v in tiled.metadata["tiling"].items() if k != "per_tile"}
    return {"mapper": meta.pop("mapper"), "tiling": tiling, **meta}


def check_prior(prior, config: MappingConfig) -> None:
    """Read a prior map given as a file and check it fits ``config`` before the log is read (the
    mapper reads it again and records where it came from)."""
    if prior is None:
        return
    prior_map = prior if isinstance(prior, OccupancyMap) else OccupancyMap.load(prior)
    if not np.isclose(prior_map.resolution, config.resolution):
        raise ConfigError(
            f"prior map resolution {prior_map.resolution} m differs from {config.resolution} m"
        )


# no underwater vehicle this package maps with moves faster than this (m/s)
PLAUSIBLE_SPEED_M_S = 20.0


def _implausible_trajectory(trajectory: Trajectory) -> DataError | None:
    """The error to raise instead of a map-extent one when the trajectory itself is
    implausible (a step faster than PLAUSIBLE_SPEED_M_S, or not finite): then the
    localization, not the map origin, is at fault. None when the trajectory looks sound."""
    p, t = np.asarray(trajectory.position, float), np.asarray(trajectory.t, float)
    if len(p) < 2:
        return None
    if not np.all(np.isfinite(p)):
        return DataError("map: the trajectory has non-finite positions: it is wrong, not the map"
                         " origin; check the localization's warnings")  # fmt: skip
    step, dt = np.linalg.norm(np.diff(p, axis=0), axis=1), np.diff(t)
    fast = np.flatnonzero((dt > 0) & (step > PLAUSIBLE_SPEED_M_S * dt))
    if fast.size == 0:
        return None
    k = fast[0]
    return DataError(
        f"map: the trajectory jumps {np.linalg.norm(p[k + 1] - p[k]):.3g} m in "
        f"{t[k + 1] - t[k]:.3g} s at t = {t[k]:.3f} s (faster than {PLAUSIBLE_SPEED_M_S:g} m/s): "
        "the localization is wrong, not the map origin; check its warnings and the counts in "
        "its config.yaml (localize with the default gate and envelopes)"
    )
