"""Latitude/longitude to local metres: north-east-down about an origin.

A fix (latitude phi, longitude lambda in degrees on WGS 84, ellipsoidal altitude h) is projected
with pyproj on a transverse Mercator centred on the origin (``+proj=tmerc +lat_0=phi0
+lon_0=lambda0 +k=1``): at the origin the projection's scale is exactly 1 and its grid north is
true north, so over a survey's few kilometres x = northing, y = easting are metres on the
ground to well under a millimetre per 100 m; z = -(h - h0) (down). The same local projection as
the map export's georeference (:mod:`undertow.io.export.georef`).
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError


def check_origin(origin) -> tuple[float, float, float]:
    """(latitude deg, longitude deg, altitude m) checked: finite, |lat| <= 90, |lon| <= 180;
    one ConfigError line otherwise (the altitude may be omitted: 0)."""
    values = [float(v) for v in origin]
    if len(values) == 2:
        values.append(0.0)
    if len(values) != 3 or not np.isfinite(values).all():
        raise ConfigError(f"gps origin: expected latitude, longitude[, altitude], got {origin!r}")
    lat, lon, alt = values
    if abs(lat) > 90 or abs(lon) > 180:
        raise ConfigError(f"gps origin: latitude {lat} / longitude {lon} out of range")
    return lat, lon, alt


def local_ned(latitude, longitude, altitude, origin) -> np.ndarray:
    """(N, 3) north, east, down metres of the fixes about ``origin`` (lat, lon, alt)."""
    from pyproj import Transformer

    lat0, lon0, alt0 = check_origin(origin)
    proj = f"+proj=tmerc +lat_0={lat0!r} +lon_0={lon0!r} +k=1 +x_0=0 +y_0=0 +ellps=WGS84"
    forward = Transformer.from_crs("EPSG:4326", proj, always_xy=True)
    east, north = forward.transform(np.asarray(longitude, float), np.asarray(latitude, float))
    down = -(np.asarray(altitude, float) - alt0)
    return np.column_stack([np.asarray(north, float), np.asarray(east, float), down])
