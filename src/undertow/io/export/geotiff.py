"""Bathymetric grids as GeoTIFF (rasterio/GDAL), for GIS and hydrographic tools.

Three float32 bands on a north-up grid (:mod:`.raster`): 1 ``depth`` (m, positive down, below
the still water surface at the origin: no vertical datum), 2 ``std`` (its standard deviation,
m), 3 ``coverage`` (fraction of the cell with data, 0 to 1). No data is NaN (the GDAL nodata
value of bands 1 and 2). Geotransform (R, 0, W, 0, -R, N): rows north to south.

With a georeference the file carries its projected CRS (UTM by default). Without one it has no
CRS at all, rather than an engineering (LOCAL_CS) one, which GIS readers handle unevenly (QGIS
treats it as unknown or asks); east is then undertow's y, north its x, in metres from the map's
origin, and the file's metadata (``UNDERTOW_FRAME``) says so. ``UNDERTOW_STD`` says what the
std band is (for a ``tpu`` map: the hits' propagated uncertainty).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..._util.atomic import atomic_path
from ...errors import ConfigError
from ._require import require
from .raster import Raster, resample_surface

SUFFIXES = (".tif", ".tiff")
BANDS = ("depth", "std", "coverage")
UNITS = {"depth": "m", "std": "m", "coverage": "1"}
DEPTH = "positive down, m, below the still water surface at the origin (no vertical datum)"
LOCAL_FRAME = "local metres, no CRS: east = undertow y, north = undertow x, origin (0, 0)"


def write_geotiff(path, surface, resolution: float | None = None, georef=None) -> Path:
    """Write ``surface`` (a :class:`undertow.mapping.surface.Surface`) as a three-band GeoTIFF
    (depth, std, coverage) at cell size ``resolution`` (default: the surface's), georeferenced
    by ``georef`` if given. Atomic."""
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ConfigError(f"{path}: a GeoTIFF file ends in .tif or .tiff")
    raster = resample_surface(surface, resolution, georef)
    write_raster(path, raster, georef, surface.std_kind, surface.iho_order)
    return path


def write_raster(path, raster: Raster, georef=None, std_kind: str = "",
                 iho_order: str = "") -> Path:  # fmt: skip
    """Write a :class:`~.raster.Raster` as a deflate-compressed, tiled GeoTIFF. Atomic.
    ``std_kind``: what the std band is (the surface's :attr:`~undertow.mapping.surface.
    Surface.std_kind`), in the tag ``UNDERTOW_STD`` when given; ``iho_order``: the IHO S-44
    order its columns were held to (:attr:`~undertow.mapping.surface.Surface.iho_order`), in
    the tag ``UNDERTOW_IHO_ORDER`` when given."""
    rasterio = require("rasterio", "GeoTIFF output")
    from rasterio.transform import Affine

    path = Path(path)
    rows, cols = raster.depth.shape
    transform = Affine(raster.resolution, 0.0, raster.west, 0.0, -raster.resolution, raster.north)
    profile = {
        "driver": "GTiff", "height": rows, "width": cols, "count": len(BANDS),
        "dtype": "float32", "nodata": np.nan, "transform": transform,
        "crs": None if georef is None else georef.crs.to_wkt(), "compress": "deflate",
        "tiled": rows >= 256 and cols >= 256,
    }  # fmt: skip
    frame = LOCAL_FRAME if georef is None else georef.describe()
    with atomic_path(path) as tmp, rasterio.open(tmp, "w", **profile) as dst:
        for band, (name, values) in enumerate(
            zip(BANDS, (raster.depth, raster.std, raster.coverage), strict=True), start=1
        ):
            dst.write(values.astype(np.float32), band)
            dst.set_band_description(band, name)
            dst.set_band_unit(band, UNITS[name])
        dst.update_tags(UNDERTOW_FRAME=frame, UNDERTOW_DEPTH=DEPTH)
        if std_kind:
            dst.update_tags(UNDERTOW_STD=std_kind)
        if iho_order:
            dst.update_tags(UNDERTOW_IHO_ORDER=iho_order)
    return path
