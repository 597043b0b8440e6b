"""Points between undertow's local frame and projected (or geographic) CRSs, both ways.

A frame is None (undertow's local frame: x north, y east, metres from the origin) or a pyproj
CRS; points are always given as (x, y) = (northing, easting) of their frame (for a geographic
CRS: latitude, longitude). Between the local frame and a CRS the map's :class:`.georef.
Georeference` is the bridge (its transverse Mercator at the origin, :mod:`.georef`): local ->
its CRS by :meth:`~.georef.Georeference.to_projected`, back by
:meth:`~.georef.Georeference.to_local`, and between two CRSs by pyproj's transformation.
"""

from __future__ import annotations

import numpy as np

from ...errors import ConfigError
from ._require import require

#: what to add when a georeference is needed and missing (the options of `undertow export`)
ORIGIN_OPTIONS = "--origin LAT,LON or --utm E,N,ZONE (the map's origin, as for `undertow export`)"


def frame_name(frame) -> str:
    """One line: "undertow's local frame" or the CRS's name and code."""
    if frame is None:
        return "undertow's local frame (x north, y east)"
    authority = frame.to_authority()
    return f"{frame.name} ({':'.join(authority) if authority else 'custom CRS'})"


def same_frame(a, b) -> bool:
    """Whether frames ``a`` and ``b`` are the same (both local, or equal CRSs)."""
    if a is None or b is None:
        return a is None and b is None
    return a == b


def _reproject(source, target, east, north):
    if same_frame(source, target):
        return np.asarray(east, float), np.asarray(north, float)
    pyproj = require("pyproj", "a transformation between CRSs")
    forward = pyproj.Transformer.from_crs(source, target, always_xy=True)
    e, n = forward.transform(np.asarray(east, float), np.asarray(north, float))
    return np.asarray(e, float), np.asarray(n, float)


def transfer(x, y, source, target, georef=None) -> tuple[np.ndarray, np.ndarray]:
    """Points (``x`` north, ``y`` east of frame ``source``) in frame ``target`` (the module doc);
    ``georef`` (a :class:`.georef.Georeference`) is needed between the local frame and a CRS,
    a ConfigError naming :data:`ORIGIN_OPTIONS` without it."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if same_frame(source, target):
        return x, y
    if (source is None or target is None) and georef is None:
        raise ConfigError(
            f"from {frame_name(source)} to {frame_name(target)} needs the map's origin: give "
            + ORIGIN_OPTIONS
        )
    if source is None:
        east, north = georef.to_projected(x, y)
        east, north = _reproject(georef.crs, target, east, north)
        return north, east
    if target is None:
        east, north = _reproject(source, georef.crs, y, x)
        return georef.to_local(east, north)
    east, north = _reproject(source, target, y, x)
    return north, east
