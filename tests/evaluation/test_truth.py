"""Reading a ground truth: the sign of z detected, stated and overridden; an XYZ file's frame
from its coordinates' size; a GeoTIFF heightfield sampled in the map's frame; wrong options one
line."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import ConfigError, DataError
from undertow.evaluation.truth import check_truth_options, load_truth, truth_kind, z_sign
from undertow.io.export.georef import from_latlon
from undertow.io.ply import write_ply

rasterio = pytest.importorskip("rasterio")
from rasterio.transform import Affine  # noqa: E402


def test_z_sign_is_detected_stated_and_overridden():
    depth = np.array([2.0, 2.5, -0.1, np.nan])
    z, note = z_sign(depth, None, False, "f")
    assert z == "depth" and "33% of the values are negative" in note
    z, note = z_sign(-depth, None, False, "f")
    assert z == "elevation" and "67%" in note and "--truth-z depth to override" in note
    assert z_sign(-depth, None, True, "f")[0] == "depth"  # undertow's tag wins
    assert z_sign(depth, "elevation", True, "f") == (
        "elevation",
        "f: z read as elevation (--truth-z)",
    )


def test_an_xyz_s_frame_follows_its_coordinates(tmp_path):
    local = tmp_path / "l.xyz"
    local.write_text("1 2 -3\n4 5 -6\n")
    truth = load_truth(local)
    np.testing.assert_array_equal(truth.cloud, [[1, 2, 3], [4, 5, 6]])
    assert truth.z == "elevation" and "undertow's local frame" in truth.notes[0]
    # E N z of UTM 32N: needs an origin, then lands in the local frame
    georef = from_latlon(59.9, 10.7)
    far = tmp_path / "p.xyz"
    far.write_text(f"{georef.easting_m + 3.0!r} {georef.northing_m + 4.0!r} 2\n")
    with pytest.raises(ConfigError, match="--origin LAT,LON or --utm E,N,ZONE"):
        load_truth(far)
    truth = load_truth(far, None, georef)
    assert truth.z == "depth" and "E N of WGS 84 / UTM zone 32N" in truth.notes[0]
    x, y = georef.to_local(georef.easting_m + 3.0, georef.northing_m + 4.0)
    np.testing.assert_allclose(truth.cloud[0], [x, y, 2.0])
    assert truth.cloud[0, 0] == pytest.approx(4.0, abs=0.2)  # about 4 m north, 3 m east
    # --truth-frame projected forces it for small coordinates too
    assert "E N of" in load_truth(local, None, georef, truth_frame="projected").notes[0]


def test_a_geotiff_truth_is_its_band_sampled_in_the_map_frame(tmp_path):
    """A local GeoTIFF of elevation -(2 + 0.1 x + 0.2 y): east = y, north = x."""
    path = tmp_path / "t.tif"
    r = 0.5
    east = (np.arange(8) + 0.5) * r
    north = 4.0 - (np.arange(8) + 0.5) * r
    e, n = np.meshgrid(east, north)
    with rasterio.open(path, "w", driver="GTiff", height=8, width=8, count=1, dtype="float32",
                       transform=Affine(r, 0, 0, 0, -r, 4.0)) as dst:  # fmt: skip
        dst.write(-(2 + 0.1 * n + 0.2 * e).astype(np.float32), 1)
    truth = load_truth(path)
    assert truth.kind == "geotiff" and truth.z == "elevation"
    x, y = np.array([1.1, 2.6]), np.array([0.7, 3.2])
    np.testing.assert_allclose(truth.height(x, y), 2 + 0.1 * x + 0.2 * y, rtol=1e-6)
    cx, cy, cz = truth.cloud.T
    np.testing.assert_allclose(cz, 2 + 0.1 * cx + 0.2 * cy, rtol=1e-6)
    near = load_truth(path, near=(0.0, 0.4, 0.0, 0.4))  # a map near the origin: a window
    assert len(near.cloud) < len(truth.cloud)


def test_options_that_do_not_apply_are_one_line(tmp_path):
    assert [truth_kind(p) for p in ("a.ply", "b.TIF", "c.tiff", "d.xyz", "e.csv")] == [
        "ply", "geotiff", "geotiff", "xyz", "xyz"]  # fmt: skip
    with pytest.raises(ConfigError, match="applies to an XYZ or GeoTIFF"):
        check_truth_options("ply", "depth", None)
    with pytest.raises(ConfigError, match="--truth-frame applies to an XYZ truth"):
        check_truth_options("geotiff", None, "local")
    with pytest.raises(ConfigError, match="expected local or projected"):
        check_truth_options("xyz", None, "utm")
    empty = tmp_path / "e.ply"
    write_ply(empty, np.zeros((0, 3)))
    with pytest.raises(DataError, match="the ground-truth cloud has no points"):
        load_truth(empty)
