"""Where undertow's local frame sits on the Earth: a survey origin and a projected CRS.

undertow's world frame is local and flat: x north, y east, z down (NED), origin at the still
water surface (docs/conventions.md). Given the geodetic position of that origin, a local point
goes to a projected CRS (UTM by default) by way of a transverse Mercator projection centred at
the origin with scale factor 1 on the origin's own datum:

    (east, north) = (y, x)  --TM(lat0, lon0, k0 = 1)^-1-->  (lat, lon)  --target CRS-->  (E, N)

The TM at the origin is the flat local frame up to its scale error k - 1 ~ d^2 / (2 R^2) at a
distance d east of the origin (1.2e-8 at 1 km; Snyder 1987, "Map Projections: A Working
Manual", USGS PP 1395, eq. 8-12 with k0 = 1). Going through it (not E = E0 + y, N = N0 + x)
keeps the target grid's meridian convergence (up to 3 deg inside a UTM zone at mid latitudes:
50 m over 1 km) and its scale factor (0.9996 on a UTM central meridian: 0.4 m over 1 km) out of
the map. The local x axis is taken to point to true north at the origin.

UTM zones follow the standard grid with the Norway and Svalbard exceptions (NGA, "The
Universal Grids and the Transverse Mercator and Polar Stereographic Map Projections",
NGA.SIG.0012, 2014, sec. 3), on WGS 84 (EPSG 326zz north, 327zz south); UTM stops at 80 S and
84 N (the poles are UPS: give a polar CRS's EPSG code instead).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError
from ._require import require

#: UTM's latitude band (outside it the grid is UPS)
UTM_LATITUDES = (-80.0, 84.0)


@dataclass(frozen=True, eq=False)
class Georeference:
    """A projected CRS and where undertow's local origin lies in it.

    ``crs``: the target (pyproj ``CRS``, projected, metres); ``latitude_deg``/``longitude_deg``:
    the origin on the target's geodetic datum; ``easting_m``/``northing_m``: the origin in the
    target CRS."""

    crs: object
    latitude_deg: float
    longitude_deg: float
    easting_m: float
    northing_m: float

    def _local_crs(self):
        from pyproj.crs import ProjectedCRS
        from pyproj.crs.coordinate_operation import TransverseMercatorConversion

        conversion = TransverseMercatorConversion(
            latitude_natural_origin=self.latitude_deg,
            longitude_natural_origin=self.longitude_deg,
            false_easting=0.0, false_northing=0.0, scale_factor_natural_origin=1.0,
        )  # fmt: skip
        return ProjectedCRS(conversion=conversion, geodetic_crs=self.crs.geodetic_crs)

    def to_projected(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Local north ``x`` and east ``y`` (m) -> (easting, northing) in :attr:`crs`."""
        from pyproj import Transformer

        forward = Transformer.from_crs(self._local_crs(), self.crs, always_xy=True)
        east, north = forward.transform(np.asarray(y, float), np.asarray(x, float))
        return np.asarray(east, float), np.asarray(north, float)

    def to_local(self, easting, northing) -> tuple[np.ndarray, np.ndarray]:
        """(easting, northing) in :attr:`crs` -> local north ``x`` and east ``y`` (m)."""
        from pyproj import Transformer

        back = Transformer.from_crs(self.crs, self._local_crs(), always_xy=True)
        y, x = back.transform(np.asarray(easting, float), np.asarray(northing, float))
        return np.asarray(x, float), np.asarray(y, float)

    def describe(self) -> str:
        """One line: the CRS and the origin in it."""
        return (
            f"{self.crs.name} ({_code(self.crs)}), origin {self.latitude_deg:.7f}, "
            f"{self.longitude_deg:.7f} = E {self.easting_m:.3f} m, N {self.northing_m:.3f} m"
        )


def _code(crs) -> str:
    authority = crs.to_authority()
    return ":".join(authority) if authority else "custom CRS"


def utm_epsg(latitude_deg: float, longitude_deg: float) -> int:
    """EPSG code of the WGS 84 UTM zone holding a point (326zz north, 327zz south), with the
    Norway (32V) and Svalbard (31X-37X) exceptions (NGA.SIG.0012, sec. 3)."""
    lat, lon = float(latitude_deg), float(longitude_deg)
    if not UTM_LATITUDES[0] <= lat < UTM_LATITUDES[1]:
        raise ConfigError(
            f"origin latitude {lat} is outside UTM (80 S to 84 N); give --utm E,N,EPSG of a "
            "polar CRS (e.g. EPSG:5041 or 5042, UPS)"
        )
    lon = (lon + 180.0) % 360.0 - 180.0
    zone = min(int((lon + 180.0) // 6.0) + 1, 60)
    if 56.0 <= lat < 64.0 and 3.0 <= lon < 12.0:
        zone = 32
    elif lat >= 72.0 and 0.0 <= lon < 42.0:
        zone = 31 if lon < 9.0 else 33 if lon < 21.0 else 35 if lon < 33.0 else 37
    return (32600 if lat >= 0.0 else 32700) + zone


def from_latlon(latitude_deg: float, longitude_deg: float) -> Georeference:
    """The origin at WGS 84 ``latitude_deg``, ``longitude_deg``; the target its UTM zone."""
    require("pyproj", "a georeference (--origin)")
    from pyproj import CRS, Transformer

    lat, lon = _checked_latlon(latitude_deg, longitude_deg)
    crs = CRS.from_epsg(utm_epsg(lat, lon))
    east, north = Transformer.from_crs(crs.geodetic_crs, crs, always_xy=True).transform(lon, lat)
    return Georeference(crs, lat, lon, float(east), float(north))


def from_projected(easting_m: float, northing_m: float, zone: str | int) -> Georeference:
    """The origin at (``easting_m``, ``northing_m``) of a projected CRS: ``zone`` a UTM zone
    ("32N", "32S", on WGS 84) or an EPSG code ("EPSG:25832", 25832) of a projected CRS in m."""
    from pyproj import Transformer

    crs = projected_crs(zone)
    east, north = float(easting_m), float(northing_m)
    if not (math.isfinite(east) and math.isfinite(north)):
        raise ConfigError(f"--utm: easting and northing must be finite, got {east}, {north}")
    lon, lat = Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True).transform(east, north)
    if not (math.isfinite(lat) and math.isfinite(lon)) or abs(lat) > 90.0:
        raise ConfigError(f"--utm: E {east}, N {north} is not a point of {crs.name}")
    _check_area(crs, float(lat), float(lon), east, north)
    return Georeference(crs, float(lat), float(lon), east, north)


def _check_area(crs, lat: float, lon: float, east: float, north: float) -> None:
    """A ConfigError when the origin lies well outside the CRS's area of use (3 deg margin,
    which also admits UTM's Norway exception): easting and northing swapped, a wrong zone."""
    area = crs.area_of_use
    if area is None or area.west > area.east:  # unknown, or across the antimeridian
        return
    margin = 3.0
    if not (area.west - margin <= lon <= area.east + margin
            and area.south - margin <= lat <= area.north + margin):  # fmt: skip
        raise ConfigError(
            f"--utm: E {east}, N {north} is at {lat:.4f}, {lon:.4f}, outside {crs.name}'s area "
            f"({area.south:g} to {area.north:g} N, {area.west:g} to {area.east:g} E): easting "
            "and northing swapped, or the wrong zone?"
        )


def projected_crs(zone: str | int):
    """A pyproj CRS from a UTM zone ("32N", "32S") or an EPSG code of a projected CRS whose
    axes are in metres; anything else is one ConfigError line."""
    require("pyproj", "a georeference (--utm)")
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    text = str(zone).strip().upper()
    utm = re.fullmatch(r"([0-9]{1,2})\s*([NS])", text)
    if utm:
        number = int(utm[1])
        if not 1 <= number <= 60:
            raise ConfigError(f"--utm: UTM zone must be 1 to 60, got {number}")
        return CRS.from_epsg((32600 if utm[2] == "N" else 32700) + number)
    code = re.fullmatch(r"(?:EPSG:)?([0-9]+)", text)
    if code is None or int(code[1]) <= 60:
        raise ConfigError(
            f"--utm: zone {zone!r} is neither a UTM zone with its hemisphere (32N, 32S) nor an "
            "EPSG code (EPSG:25832)"
        )
    try:
        crs = CRS.from_epsg(int(code[1]))
    except CRSError:
        raise ConfigError(f"--utm: EPSG:{code[1]} is not a known CRS") from None
    units = {axis.unit_name for axis in crs.axis_info}
    if not crs.is_projected or units != {"metre"}:
        raise ConfigError(f"--utm: EPSG:{code[1]} ({crs.name}) is not a projected CRS in metres")
    return crs


def _checked_latlon(latitude_deg, longitude_deg) -> tuple[float, float]:
    lat, lon = float(latitude_deg), float(longitude_deg)
    if not (math.isfinite(lat) and -90.0 <= lat <= 90.0):
        raise ConfigError(f"--origin: latitude must be in [-90, 90] degrees, got {lat}")
    if not (math.isfinite(lon) and -180.0 <= lon <= 180.0):
        raise ConfigError(f"--origin: longitude must be in [-180, 180] degrees, got {lon}")
    return lat, lon


def parse_origin(text: str) -> Georeference:
    """``--origin LAT,LON`` (WGS 84 decimal degrees) -> its UTM :class:`Georeference`."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        lat, lon = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(
            f"--origin: expected LAT,LON in decimal degrees (59.91,10.75), got {text!r}"
        ) from None
    return from_latlon(lat, lon)


def parse_utm(text: str) -> Georeference:
    """``--utm E,N,ZONE`` (ZONE: 32N, 32S or an EPSG code) -> :class:`Georeference`."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        if len(parts) != 3:
            raise ValueError
        east, north = float(parts[0]), float(parts[1])
    except ValueError:
        raise ConfigError(
            f"--utm: expected E,N,ZONE (595101.1,6641495.2,32N or ...,EPSG:25832), got {text!r}"
        ) from None
    return from_projected(east, north, parts[2])
