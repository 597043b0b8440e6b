"""Seafloor occupancy mapping: counting sensor model, BKI and the paper's adaptive BKI.

The map itself, :class:`~undertow.occupancy.OccupancyMap`, is the hand-off type other stages
read; it lives in :mod:`undertow.occupancy`.
"""

from .config import MappingConfig
from .mappers import make_mapper, mapper_from_config
from .online import OnlineMapper
from .run import MappingResult, map_log
from .samples import Samples, build_samples, samples_from_config
from .tiled import map_tiled, read_tiles

__all__ = [
    "MappingConfig",
    "MappingResult",
    "OnlineMapper",
    "Samples",
    "build_samples",
    "make_mapper",
    "map_log",
    "map_tiled",
    "mapper_from_config",
    "read_tiles",
    "samples_from_config",
]
