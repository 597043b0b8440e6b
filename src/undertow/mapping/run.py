"""Map a log along a trajectory end to end: training samples, one mapper pass, the map."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, DataError
from ..io.units import reading_record
from ..log import Log
from ..occupancy import OccupancyMap
from ..trajectory import Trajectory
from .config import MappingConfig
from .mappers import mapper_from_config, out_of_memory
from .samples import samples_from_config
from .tpu import with_wave


@dataclass
class MappingResult:
    """The map, and what went into it (sample counts, dropped ranges, mapper settings);
    ``warnings``: what reading and mapping warned of (filled by
    :func:`undertow.commands.mapping.map_file`)."""

    map: OccupancyMap
    config: MappingConfig
    metadata: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def map_log(
    log: Log, trajectory: Trajectory, config: MappingConfig | None = None, prior=None
) -> MappingResult:
    """Training samples from every valid range (DVL beams, sonar), then one mapper pass."""
    config = with_wave(config or MappingConfig(), trajectory)
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


def map_metadata(mapper: dict, samples, occupancy: OccupancyMap, config: MappingConfig,
                 trajectory: Trajectory, log: Log) -> dict:  # fmt: skip
    """What a map records of how it was made: the mapper's settings, the samples (hits, free,
    dropped), its cells and where the poses and ranges came from."""
    return {
        "mapper": mapper,
        "samples": {
            "hits": int((samples.label == 1).sum()),
            "free": int((samples.label == 0).sum()),
            "dropped": {k: int(v) for k, v in samples.dropped.items()},
        },
        "cells_with_mass": len(occupancy),
        "occupied_cells": len(occupancy.occupied(config.occupied_threshold)),
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
