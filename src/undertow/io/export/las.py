"""LAS 1.4 / LAZ point clouds of an occupancy map's occupied cells (laspy), for GIS,
CloudCompare, PDAL and hydrographic tools.

One point per occupied cell (E[theta_*] > threshold, ``eq:mean_var``) at its centre, point
format 6, coordinates stored as integers of 1 mm (``SCALE``) around an offset; the posterior
mean and variance of the cell are float32 extra dimensions ``mean`` and ``variance`` (LAS 1.4
R15, ASPRS 2019, sec. 2.6 "Extra Bytes"), and every point has class 40, "bathymetry" (the
ASPRS LAS Domain Profile for topo-bathy lidar, table 3), since the map's occupied cells are the
seafloor.

Axes: with a :class:`~undertow.io.export.georef.Georeference`, X/Y are easting/northing of its
projected CRS (recorded as an OGC WKT VLR) and Z the height above the still water surface at
the origin, -z (no vertical datum). Without one, the local frame in metres, ``frame`` "enu"
(x east, y north, z up, as LAS readers expect) or "ned" (undertow's axes), no CRS.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..._util.atomic import atomic_path
from ...errors import ConfigError
from ...occupancy import OCCUPIED_THRESHOLD, OccupancyMap
from ._require import require
from .frames import points_in_frame

#: coordinate quantum, m
SCALE = 0.001
#: ASPRS class of a point on the seafloor (LAS Domain Profile, topo-bathy)
BATHYMETRY_CLASS = 40
SUFFIXES = {".las": False, ".laz": True}  # suffix -> compressed


def laz_backend():
    """The first LAZ backend laspy finds (lazrs or laszip), or one ConfigError line."""
    laspy = require("laspy", "LAS output")

    available = laspy.LazBackend.detect_available()
    if not available:
        raise ConfigError(
            "LAZ output needs a LAZ backend: pip install 'laspy[lazrs]' (or write .las)"
        )
    return available[0]


def map_cloud(occupancy_map: OccupancyMap, threshold: float, georef=None,
              frame: str = "enu") -> tuple[np.ndarray, OccupancyMap]:  # fmt: skip
    """(points (K, 3) in the export's axes, the occupied cells) as :func:`write_map_las`
    writes them."""
    occupied = occupancy_map.occupied(threshold)
    centres = occupied.centres
    if georef is None:
        return points_in_frame(centres, frame), occupied
    east, north = georef.to_projected(centres[:, 0], centres[:, 1])
    return np.column_stack([east, north, -centres[:, 2]]), occupied


def write_map_las(path, occupancy_map: OccupancyMap, threshold: float = OCCUPIED_THRESHOLD,
                  georef=None, frame: str = "enu") -> Path:  # fmt: skip
    """Occupied cells of ``occupancy_map`` as LAS (``.las``) or LAZ (``.laz``) points with
    ``mean`` and ``variance`` extra dimensions; georeferenced by ``georef`` if given. Atomic."""
    laspy = require("laspy", "LAS output")

    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ConfigError(f"{path}: a LAS file ends in .las (or .laz, compressed)")
    if georef is not None and frame != "enu":
        raise ConfigError("a georeferenced cloud is east-north-up; frame must be enu")
    compress = SUFFIXES[path.suffix.lower()]
    backend = laz_backend() if compress else None
    points, occupied = map_cloud(occupancy_map, threshold, georef, frame)
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_extra_dims([
        laspy.ExtraBytesParams(name="mean", type=np.float32,
                               description="occupancy posterior mean"),
        laspy.ExtraBytesParams(name="variance", type=np.float32,
                               description="occupancy posterior variance"),
    ])  # fmt: skip
    header.scales = np.full(3, SCALE)
    header.offsets = np.floor(points.min(axis=0)) if len(points) else np.zeros(3)
    header.generating_software = "undertow"
    if georef is not None:
        header.add_crs(georef.crs)
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    las.mean = occupied.mean.astype(np.float32)
    las.variance = occupied.variance.astype(np.float32)
    las.classification = np.full(len(points), BATHYMETRY_CLASS, np.uint8)
    with atomic_path(path) as tmp:
        las.write(str(tmp), do_compress=compress, laz_backend=backend)
    return path
