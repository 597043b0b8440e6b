"""Map a log along a trajectory end to end and write the result folder (`undertow map`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from .._util.atomic import output_folder
from ..errors import ConfigError
from ..log import Log
from ..trajectory import Trajectory
from .config import MappingConfig, mapper_from_config, samples_from_config
from .grid import OccupancyMap
from .mappers import write_map_ply


@dataclass
class MappingResult:
    """The map, and what went into it (sample counts, dropped ranges, mapper settings)."""

    map: OccupancyMap
    config: MappingConfig
    metadata: dict = field(default_factory=dict)


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
        raise ConfigError(
            f"mapping ran out of memory at resolution {config.resolution:g} m: use a coarser "
            "resolution (or a lower mapping.max_memory_gb, checked before mapping)"
        ) from None
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


def save_map(result: MappingResult, out_dir: str | Path, overwrite: bool = False) -> Path:
    """Write ``map.npz``, ``map.ply`` (occupied cell centres with mean and variance) and
    ``config.yaml`` (mapping config and what went into the map), all at once (a non-empty
    folder is replaced only with ``overwrite``)."""
    with output_folder(out_dir, overwrite) as out:
        result.map.save(out / "map.npz")
        write_map_ply(out / "map.ply", result.map, threshold=result.config.occupied_threshold)
        doc = {"mapping": result.config.model_dump(mode="json"), "result": result.metadata}
        (out / "config.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return Path(out_dir)
