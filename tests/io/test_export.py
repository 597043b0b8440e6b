"""`undertow export`: every format read back with the library its users read it with (rasterio,
OctoMap's bindings, laspy, our PLY reader) and compared with the map: values, positions, axes
and georeference. Positions are checked against independent references: the map's own cell
indices, and geodesics on the WGS 84 ellipsoid (pyproj.Geod) for georeferenced ones."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import one_error_line
from typer.testing import CliRunner

from undertow.commands.export import export_map
from undertow.errors import ConfigError, DataError
from undertow.mapping.surface import map_surface
from undertow.occupancy import OccupancyMap

laspy = pytest.importorskip("laspy")
octomap = pytest.importorskip("octomap")
pyproj = pytest.importorskip("pyproj")
rasterio = pytest.importorskip("rasterio")

RES = 0.1
#: survey origin (Oslo harbour), 1.7 deg east of UTM 32N's central meridian (9 E): a meridian
#: convergence of about 1.47 deg, so a grid-aligned shortcut would be visibly wrong
LAT0, LON0 = 59.9, 10.7
ROCK = (7, 12)  # (i north, j east) of the rock's column: only in the north-east quadrant
FLOOR_K = 20  # floor cell index away from the rock: depth (20 + 1/2) * 0.1 = 2.05 m


def _floor_k(i: int, j: int) -> int:
    """The floor's cell index in column (i, j): a slope down to the north (k grows with i)
    and a rock three cells high at :data:`ROCK`; asymmetric in x and in y."""
    k = FLOOR_K + i // 4
    return k - 3 if (i, j) == ROCK else k


def _asymmetric_map() -> OccupancyMap:
    """Columns i in [-8, 9], j in [-5, 14] (more east than west, more north than south); per
    column a free cell above the floor, the floor cell, and a free cell below it."""
    cells, alpha, beta = [], [], []
    for i in range(-8, 10):
        for j in range(-5, 15):
            k = _floor_k(i, j)
            occupied_alpha = 6.0 + 0.1 * (i + 8) + 0.05 * (j + 5)  # distinct means per cell
            for dk, a, b in ((-1, 1.2, 7.0), (0, occupied_alpha, 2.0), (1, 1.1, 5.0)):
                cells.append((i, j, k + dk))
                alpha.append(a)
                beta.append(b)
    return OccupancyMap(np.array(cells), np.array(alpha), np.array(beta), RES, 1.0, 1.0,
                        {"occupied_threshold": 0.5})  # fmt: skip


@pytest.fixture(scope="module")
def occupancy():
    return _asymmetric_map()


@pytest.fixture(scope="module")
def map_file(tmp_path_factory, occupancy):
    return occupancy.save(tmp_path_factory.mktemp("export") / "map" / "map.npz")


def _geodesic_local(east, north):
    """Local (x north, y east) of projected UTM 32N points, independently of the exporter:
    UTM -> lat/lon (pyproj), then the geodesic from the origin (pyproj.Geod, WGS 84): distance
    and azimuth give x = d cos(az), y = d sin(az)."""
    lon, lat = pyproj.Transformer.from_crs(32632, 4326, always_xy=True).transform(east, north)
    az, _, dist = pyproj.Geod(ellps="WGS84").inv(np.full_like(lon, LON0), np.full_like(lat, LAT0),
                                                 lon, lat)  # fmt: skip
    az = np.radians(az)
    return dist * np.cos(az), dist * np.sin(az)


def _geodesic_utm(x, y):
    """UTM 32N (east, north) of local points by the geodesic from the origin (the reference)."""
    az = np.degrees(np.arctan2(y, x))
    lon, lat, _ = pyproj.Geod(ellps="WGS84").fwd(np.full_like(x, LON0), np.full_like(x, LAT0),
                                                 az, np.hypot(x, y))  # fmt: skip
    return pyproj.Transformer.from_crs(4326, 32632, always_xy=True).transform(lon, lat)


# --- GeoTIFF ------------------------------------------------------------------------------


def _read_tif(path):
    with rasterio.open(path) as src:
        bands = {name: src.read(b + 1) for b, name in enumerate(src.descriptions)}
        return bands, src.transform, src.crs, src.tags(), src.units


def test_geotiff_local_is_the_surface_cell_for_cell(tmp_path, map_file, occupancy):
    result = export_map(map_file, tmp_path / "bathy.tif")
    bands, transform, crs, tags, units = _read_tif(result.path)
    assert crs is None and "no CRS" in tags["UNDERTOW_FRAME"]
    assert set(bands) == {"depth", "std", "coverage"} and units == ("m", "m", "1")
    assert transform.a == pytest.approx(RES) and transform.e == pytest.approx(-RES)
    rows, cols = bands["depth"].shape
    assert (rows, cols) == (18, 20)  # 18 columns along x (north), 20 along y (east)
    surface = map_surface(occupancy, 0.5)
    for row in range(rows):
        for col in range(cols):
            east, north = transform @ (col + 0.5, row + 0.5)
            i, j = math.floor(north / RES), math.floor(east / RES)  # undertow's cell index
            si = round((north - surface.x0) / RES)
            sj = round((east - surface.y0) / RES)
            assert bands["depth"][row, col] == pytest.approx(surface.depth[sj, si], rel=1e-6)
            assert bands["std"][row, col] == pytest.approx(surface.std[sj, si], rel=1e-5)
            assert bands["coverage"][row, col] == 1.0
            # the floor the map was built on, within the surface's spread
            floor = (_floor_k(i, j) + 0.5) * RES
            assert abs(bands["depth"][row, col] - floor) < 0.5 * RES
    # north is up: the first row is the northernmost column (i = 9), east to the right
    assert transform @ (0, 0) == pytest.approx((-5 * RES, 10 * RES))
    rock_row, rock_col = 9 - ROCK[0], ROCK[1] + 5
    assert np.nanargmin(bands["depth"]) == rock_row * cols + rock_col  # the shallowest: the rock


def test_geotiff_coarser_cells_average_the_surface(tmp_path, map_file, occupancy):
    """R = 2 r: each raster cell holds whole surface cells (edges on multiples of 0.2 m);
    depth is their mean, std by the law of total variance, coverage the fraction of the four
    cells' area with data."""
    bands, transform, *_ = _read_tif(export_map(map_file, tmp_path / "b.tif", resolution=0.2).path)
    surface = map_surface(occupancy, 0.5)
    x, y = surface.centres()
    assert transform @ (0, 0) == pytest.approx((-0.6, 1.0))  # y from -0.5 snaps to -0.6
    rows, cols = bands["depth"].shape
    assert (rows, cols) == (9, 11)
    for row in range(rows):
        for col in range(cols):
            west, north = transform @ (col, row)
            inside = (y > west) & (y < west + 0.2) & (x < north) & (x > north - 0.2)
            inside &= surface.coverage
            d, s = surface.depth[inside], surface.std[inside]
            assert bands["coverage"][row, col] == pytest.approx(inside.sum() / 4)
            if inside.any():
                assert bands["depth"][row, col] == pytest.approx(d.mean(), rel=1e-6)
                total = math.sqrt(np.mean(s**2) + d.var())
                assert bands["std"][row, col] == pytest.approx(total, rel=1e-5)
    assert np.all(bands["coverage"][:, 0] == 0.5)  # the westmost cells: half has data


def test_geotiff_georeferenced_positions_follow_the_geodesics(tmp_path, map_file, occupancy):
    result = export_map(map_file, tmp_path / "g.tif", origin=f"{LAT0},{LON0}")
    bands, transform, crs, *_ = _read_tif(result.path)
    assert crs.to_epsg() == 32632
    surface = map_surface(occupancy, 0.5)
    rows, cols = np.nonzero(np.isfinite(bands["depth"]))
    east, north = transform @ (cols + 0.5, rows + 0.5)
    x, y = _geodesic_local(np.asarray(east), np.asarray(north))
    fx, fy = (x - surface.x0) / RES, (y - surface.y0) / RES
    clear = (np.abs(fx - np.rint(fx)) < 0.499) & (np.abs(fy - np.rint(fy)) < 0.499)
    assert clear.mean() > 0.95
    expected = surface.depth[np.rint(fy).astype(int), np.rint(fx).astype(int)]
    np.testing.assert_allclose(bands["depth"][rows, cols][clear], expected[clear], rtol=1e-6)
    # every surface cell appears (nearest sampling at the same cell size loses at most a few)
    assert len(rows) >= 0.97 * surface.coverage.sum()
    # the rock (north-east of the origin) is north-east in UTM too, where the geodesic puts it
    rock = np.nanargmin(bands["depth"])
    rock_e, rock_n = transform @ (rock % bands["depth"].shape[1] + 0.5,
                                  rock // bands["depth"].shape[1] + 0.5)  # fmt: skip
    ref_e, ref_n = _geodesic_utm(
        np.array([(ROCK[0] + 0.5) * RES]), np.array([(ROCK[1] + 0.5) * RES])
    )
    assert math.hypot(rock_e - ref_e[0], rock_n - ref_n[0]) < RES


def test_utm_origin_and_latlon_origin_agree(tmp_path, map_file):
    from undertow.io.export.georef import from_latlon, parse_utm

    by_latlon = from_latlon(LAT0, LON0)
    by_utm = parse_utm(f"{by_latlon.easting_m},{by_latlon.northing_m},32N")
    x, y = np.array([0.0, 800.0, -300.0]), np.array([0.0, 500.0, 900.0])
    for georef in (by_latlon, by_utm):
        east, north = georef.to_projected(x, y)
        ref_e, ref_n = _geodesic_utm(x, y)
        np.testing.assert_allclose(east, ref_e, atol=1e-4)  # TM at the origin vs geodesic
        np.testing.assert_allclose(north, ref_n, atol=1e-4)
        np.testing.assert_allclose(georef.to_local(east, north), (x, y), atol=1e-6)
    # the convergence is in: 800 m north is not straight up the UTM grid (tan 1.47 deg * 800)
    east, north = by_latlon.to_projected(np.array([800.0]), np.array([0.0]))
    assert by_latlon.easting_m - east[0] == pytest.approx(800 * math.tan(math.radians(1.47)), abs=1)


# --- OctoMap ------------------------------------------------------------------------------


def _enu(centres):
    return np.column_stack([centres[:, 1], centres[:, 0], -centres[:, 2]])


def test_octomap_ot_keeps_the_bki_mean(tmp_path, map_file, occupancy):
    result = export_map(map_file, tmp_path / "map.ot")
    tree = octomap.OcTree.read(str(result.path).encode())
    assert tree.getResolution() == pytest.approx(RES)
    assert tree.getNumLeafNodes() == len(occupancy) == result.count
    for centre, mean in zip(_enu(occupancy.centres), occupancy.mean, strict=True):
        node = tree.search(centre)
        assert node is not None
        assert node.getOccupancy() == pytest.approx(mean, rel=1e-6)
    # every leaf sits on a map cell centre, in ENU (z up: the floor below the origin)
    keys = set()
    for leaf in tree.begin_leafs():
        keys.add(tuple(np.floor(np.asarray(leaf.getCoordinate()) / RES).astype(int).tolist()))
        assert leaf.getSize() == pytest.approx(RES)
    expected = {(j, i, -k - 1) for i, j, k in occupancy.cells.tolist()}
    assert keys == expected
    rock = (ROCK[1], ROCK[0], -(_floor_k(*ROCK)) - 1)  # east, north, up
    assert tree.isNodeOccupied(tree.search((np.array(rock) + 0.5) * RES))


def test_octomap_bt_is_the_thresholded_map(tmp_path, map_file, occupancy):
    result = export_map(map_file, tmp_path / "map.bt", threshold=0.6)
    tree = octomap.OcTree(RES)
    assert tree.readBinary(str(result.path).encode())
    occupied = occupancy.mean > 0.6
    assert 0 < occupied.sum() < len(occupancy)  # the threshold splits the floor cells
    for centre, occ in zip(_enu(occupancy.centres), occupied, strict=True):
        assert tree.isNodeOccupied(tree.search(centre)) == occ
    volume = sum(leaf.getSize() ** 3 for leaf in tree.begin_leafs())  # pruned leaves are bigger
    assert volume == pytest.approx(len(occupancy) * RES**3)


def test_octomap_ned_frame_and_key_range(tmp_path, occupancy):
    from undertow.io.export.octree import write_octomap

    path = write_octomap(tmp_path / "ned.ot", occupancy, frame="ned")
    tree = octomap.OcTree.read(str(path).encode())
    for centre, mean in zip(occupancy.centres[:50], occupancy.mean[:50], strict=True):
        assert tree.search(centre).getOccupancy() == pytest.approx(mean, rel=1e-6)
    far = OccupancyMap(np.array([[2**15, 0, 0]]), [2.0], [1.0], RES, 1.0, 1.0)
    with pytest.raises(DataError, match="beyond OctoMap"):
        write_octomap(tmp_path / "far.bt", far)
    assert not (tmp_path / "far.bt").exists()


# --- LAS / LAZ / PLY ----------------------------------------------------------------------


@pytest.mark.parametrize("name", ["cloud.las", "cloud.laz"])
def test_las_local_points_and_extra_dimensions(tmp_path, map_file, occupancy, name):
    result = export_map(map_file, tmp_path / name)
    las = laspy.read(result.path)
    occ = occupancy.occupied(0.5)
    assert las.header.point_count == len(occ) == result.count
    assert las.header.parse_crs() is None
    got = np.column_stack([las.x, las.y, las.z])
    np.testing.assert_allclose(got, _enu(occ.centres), atol=0.5e-3 + 1e-9)  # 1 mm quantum
    np.testing.assert_allclose(las.mean, occ.mean, rtol=1e-6)
    np.testing.assert_allclose(las.variance, occ.variance, rtol=1e-6)
    assert np.all(np.asarray(las.classification) == 40)
    assert (result.path.read_bytes()[:4] == b"LASF") and result.path.stat().st_size > 0


def test_las_georeferenced_in_utm(tmp_path, map_file, occupancy):
    result = export_map(map_file, tmp_path / "cloud.laz", origin=(LAT0, LON0))
    las = laspy.read(result.path)
    assert las.header.parse_crs().to_epsg() == 32632
    occ = occupancy.occupied(0.5)
    ref_e, ref_n = _geodesic_utm(occ.centres[:, 0], occ.centres[:, 1])
    np.testing.assert_allclose(las.x, ref_e, atol=0.6e-3)  # the 1 mm quantum
    np.testing.assert_allclose(las.y, ref_n, atol=0.6e-3)
    np.testing.assert_allclose(las.z, -occ.centres[:, 2], atol=0.5e-3 + 1e-9)  # height, up


def test_laz_without_a_backend_is_one_line(tmp_path, map_file, monkeypatch):
    monkeypatch.setattr(laspy.LazBackend, "detect_available", staticmethod(lambda: ()))
    with pytest.raises(ConfigError, match="laspy\\[lazrs\\]") as info:
        export_map(map_file, tmp_path / "x.laz")
    assert "\n" not in str(info.value)
    assert not (tmp_path / "x.laz").exists()


def test_ply_is_todays_map_ply(tmp_path, map_file, occupancy):
    from undertow.io.ply import read_ply

    points, props = read_ply(export_map(map_file, tmp_path / "m.ply").path)
    occ = occupancy.occupied(0.5)
    np.testing.assert_allclose(points, occ.centres, atol=1e-6)  # undertow's frame, float32
    np.testing.assert_allclose(props["mean"], occ.mean, rtol=1e-6)


# --- mistakes -----------------------------------------------------------------------------

BAD = [
    ({"out": "x.tif", "fmt": "kml"}, "--format 'kml'"),
    ({"out": "x.xyz"}, "give --format"),
    ({"out": "x.tif", "fmt": "las"}, "ends in .las"),
    ({"out": "x.tif", "origin": "59.9"}, "LAT,LON"),
    ({"out": "x.tif", "origin": "91,10"}, "latitude"),
    ({"out": "x.tif", "origin": "-85,10"}, "outside UTM"),
    ({"out": "x.tif", "origin": "1,2", "utm": "1,2,32N"}, "not both"),
    ({"out": "x.bt", "origin": "59.9,10.7"}, "local metres"),
    ({"out": "x.tif", "utm": "595101,6641495,32"}, "hemisphere"),
    ({"out": "x.tif", "utm": "595101,6641495,EPSG:4326"}, "not a projected CRS"),
    ({"out": "x.tif", "utm": "6641495,595101,32N"}, "swapped"),
    ({"out": "x.las", "resolution": 0.5}, "applies to geotiff"),
    ({"out": "x.tif", "resolution": 0.0}, "positive"),
    ({"out": "x.tif", "resolution": 1e-5}, "coarser"),
    ({"out": "x.ply", "threshold": 1.5}, "(0, 1)"),
    ({"out": "x.ot", "threshold": 0.6}, ".ot"),
    ({"out": "x.tif", "frame": "ned"}, "frame applies"),
    ({"out": "x.las", "frame": "ned", "origin": "59.9,10.7"}, "east-north-up"),
]


@pytest.mark.parametrize(("kwargs", "message"), BAD, ids=[m for _, m in BAD])
def test_bad_options_are_one_config_error_line(tmp_path, map_file, kwargs, message):
    kwargs = dict(kwargs)
    out = tmp_path / kwargs.pop("out")
    with pytest.raises(ConfigError) as info:
        export_map(map_file, out, kwargs.pop("fmt", None), **kwargs)
    assert message in str(info.value) and "\n" not in str(info.value)
    assert not out.exists() and list(tmp_path.iterdir()) == []  # nothing written, no temporary


def test_empty_map_gives_no_grid_and_leaves_nothing(tmp_path):
    empty = OccupancyMap(np.zeros((0, 3)), [], [], RES, 1.0, 1.0).save(tmp_path / "e" / "map.npz")
    with pytest.raises(DataError, match="no seafloor"):
        export_map(empty, tmp_path / "e.tif")
    assert not (tmp_path / "e.tif").exists()
    assert export_map(empty, tmp_path / "e.las").count == 0  # an empty cloud is a valid file
    assert laspy.read(tmp_path / "e.las").header.point_count == 0


def test_cli_export(tmp_path, map_file):
    import undertow.cli.export  # noqa: F401  (registers the command if __init__ does not yet)
    from undertow.cli import app

    runner = CliRunner()
    out = tmp_path / "bathy.tif"
    utm = "595101.146,6641495.240,32N"
    ok = runner.invoke(app, ["export", str(map_file.parent), "--out", str(out), "--utm", utm,
                             "--resolution", "0.2"])  # fmt: skip
    assert ok.exit_code == 0, ok.output
    assert "EPSG:32632" in ok.output and out.exists()
    bad = runner.invoke(app, ["export", str(map_file), "--out", str(tmp_path / "x.bt"),
                              "--origin", "59.9,10.7"])  # fmt: skip
    assert "--origin/--utm apply to" in one_error_line(bad)
