"""Points between undertow's local frame and CRSs: the local -> UTM -> local round trip, UTM
positions against geodesics on the WGS 84 ellipsoid (pyproj.Geod, independent of the transverse
Mercator used), CRS -> CRS against pyproj, and a missing origin named in one line."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.io.export.georef import from_latlon
from undertow.io.export.transfer import frame_name, same_frame, transfer

pyproj = pytest.importorskip("pyproj")
LAT0, LON0 = -33.86, 151.21  # Sydney: southern hemisphere, UTM 56S


def test_local_to_utm_follows_the_geodesics_and_comes_back():
    georef = from_latlon(LAT0, LON0)
    utm = georef.crs
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-800, 800, 50), rng.uniform(-800, 800, 50)  # north, east (m)
    north, east = transfer(x, y, None, utm, georef)
    az = np.degrees(np.arctan2(y, x))
    lon, lat, _ = pyproj.Geod(ellps="WGS84").fwd(np.full(50, LON0), np.full(50, LAT0), az,
                                                 np.hypot(x, y))  # fmt: skip
    ref_e, ref_n = pyproj.Transformer.from_crs(4326, utm, always_xy=True).transform(lon, lat)
    np.testing.assert_allclose(east, ref_e, atol=1e-3)
    np.testing.assert_allclose(north, ref_n, atol=1e-3)
    back_x, back_y = transfer(north, east, utm, None, georef)
    np.testing.assert_allclose(back_x, x, atol=1e-6)
    np.testing.assert_allclose(back_y, y, atol=1e-6)


def test_between_two_crss_no_origin_is_needed():
    mga = pyproj.CRS.from_epsg(7856)  # GDA2020 / MGA zone 56
    utm = pyproj.CRS.from_epsg(32756)
    e, n = np.array([334000.0, 335000.0]), np.array([6252000.0, 6253000.0])
    north, east = transfer(n, e, utm, mga)
    ref_e, ref_n = pyproj.Transformer.from_crs(utm, mga, always_xy=True).transform(e, n)
    np.testing.assert_allclose(east, ref_e) and np.testing.assert_allclose(north, ref_n)
    x, y = np.array([1.0]), np.array([2.0])
    assert transfer(x, y, None, None) == (x, y) and same_frame(utm, pyproj.CRS(32756))
    assert not same_frame(None, utm) and "local" in frame_name(None)


def test_a_missing_origin_names_the_options():
    utm = pyproj.CRS.from_epsg(32756)
    for source, target in ((None, utm), (utm, None)):
        with pytest.raises(ConfigError) as info:
            transfer(np.zeros(1), np.zeros(1), source, target)
        assert "--origin LAT,LON or --utm E,N,ZONE" in str(info.value)
        assert "32756" in str(info.value)
