"""Seafloor occupancy mapping: counting sensor model, BKI and the paper's adaptive BKI."""

from .config import MappingConfig
from .grid import OccupancyMap
from .mappers import make_mapper, write_map_ply
from .samples import Samples, build_samples

__all__ = [
    "MappingConfig",
    "OccupancyMap",
    "Samples",
    "build_samples",
    "make_mapper",
    "write_map_ply",
]
