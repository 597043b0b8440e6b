"""Map a log along a trajectory end to end: training samples, one mapper pass, the map."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from ..log import Log
from ..occupancy import OccupancyMap
from ..trajectory import Trajectory
from .config import MappingConfig
from .mappers import mapper_from_config, out_of_memory
from .samples import samples_from_config


@dataclass
class MappingResult:
    """The map, and what went into it (sample counts, dropped ranges, mapper settings);
    ``warnings``: what reading and mapping warned of (filled by
    :func:`undertow.jobs.map.map_file`)."""

    map: OccupancyMap
    config: MappingConfig
    metadata: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def map_log(
    log: Log, trajectory: Trajectory, config: MappingConfig | None = None, prior=None
) -> MappingResult:
    """Training samples from every valid range (DVL beams, sonar), then one mapper pass."""
    config = config or MappingConfig()
    log.require("dvl", stage="map") if config.use_dvl and log.sonar is None else None
    try:
        samples = samples_from_config(log, trajectory, config)
        mapper = mapper_from_config(config, prior=prior)
        mapper.integrate(samples)
        occupancy = mapper.occupancy()
    except MemoryError:
        raise out_of_memory(config.resolution) from None
    # the threshold the map was made with, for `evaluate map` (older maps: 0.5)
    occupancy = dataclasses.replace(
        occupancy,
        metadata={**occupancy.metadata, "occupied_threshold": config.occupied_threshold},
    )
    metadata = {
        "mapper": mapper.metadata(),
        "samples": {
            "hits": int((samples.label == 1).sum()),
            "free": int((samples.label == 0).sum()),
            "dropped": {k: int(v) for k, v in samples.dropped.items()},
        },
        "cells_with_mass": len(occupancy),
        "occupied_cells": len(occupancy.occupied(config.occupied_threshold)),
        "trajectory_variant": trajectory.variant,
        "source": log.source,
    }
    return MappingResult(occupancy, config, metadata)
