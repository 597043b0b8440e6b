"""Maps in the formats surveyors and robots use: GeoTIFF bathymetric grids, OctoMap octrees,
LAS/LAZ point clouds (PLY is :mod:`undertow.io.ply`), and the georeference they share.

Each writer is atomic and imports its third-party library (rasterio, octomap-python, laspy,
pyproj) only when called."""

from .frames import FRAMES, cells_in_frame, points_in_frame
from .georef import Georeference, from_latlon, from_projected, parse_origin, parse_utm, utm_epsg
from .geotiff import write_geotiff, write_raster
from .las import map_cloud, write_map_las
from .octree import write_octomap
from .raster import Raster, resample_surface

__all__ = [
    "FRAMES", "Georeference", "Raster", "cells_in_frame", "from_latlon", "from_projected",
    "map_cloud", "parse_origin", "parse_utm", "points_in_frame", "resample_surface",
    "utm_epsg", "write_geotiff", "write_map_las", "write_octomap", "write_raster",
]  # fmt: skip
