"""`undertow evaluate map MAP TRUTH` on a map whose every column's error is known: one occupied
cell per column, so the map's depth is the cell centre (k + 1/2) r and its std r / sqrt(12)
(mapping/surface.py's equations), under a tilted plane floor. Every truth format (PLY, XYZ,
GeoTIFF in the local frame or in UTM, XYZ in UTM) must give the metrics computed here directly
from the plane; positions in UTM come from geodesics on the WGS 84 ellipsoid (pyproj.Geod), not
from undertow's transverse Mercator."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import one_error_line
from typer.testing import CliRunner

from undertow.cli import app
from undertow.commands.export import export_map
from undertow.commands.mapping import evaluate_map_file
from undertow.io.ply import write_ply
from undertow.occupancy import OccupancyMap

pyproj = pytest.importorskip("pyproj")
rasterio = pytest.importorskip("rasterio")
from rasterio.transform import Affine  # noqa: E402

runner = CliRunner()
RES = 0.1
NX, NY = 30, 20  # columns along x (north) and y (east)
LAT0, LON0 = 59.9, 10.7  # the map's origin (UTM 32N)
ORIGIN = f"{LAT0},{LON0}"
SIGMA = RES / math.sqrt(12)  # the std of a column holding one cell


def plane(x, y):
    """The true floor (m, z down): tilted differently along x and y, so a swap shows."""
    return 2.0 + 0.13 * np.asarray(x) + 0.07 * np.asarray(y)


def _columns():
    i, j = np.meshgrid(np.arange(NX), np.arange(NY), indexing="ij")
    return i.ravel(), j.ravel()


def _column_k(i, j, shift):
    """The floor's cell index under each column's centre, ``shift`` cells off."""
    return np.floor(plane((i + 0.5) * RES, (j + 0.5) * RES) / RES).astype(int) + shift


def _map(shift: int = 0) -> OccupancyMap:
    i, j = _columns()
    k = _column_k(i, j, shift)
    cells = np.stack([i, j, k], axis=1)
    return OccupancyMap(cells, np.full(len(cells), 8.0), np.full(len(cells), 2.0), RES, 1.0,
                        1.0, {"occupied_threshold": 0.5})  # fmt: skip


def _expected(shift: int = 0, defined=None) -> dict:
    """The surface error and calibration straight from the plane at the column centres."""
    i, j = _columns()
    x, y = (i + 0.5) * RES, (j + 0.5) * RES
    error = (_column_k(i, j, shift) + 0.5) * RES - plane(x, y)
    if defined is not None:
        error = error[defined(x, y)]
    z = np.abs(error) / SIGMA
    return {"surface_rmse_m": math.sqrt(np.mean(error**2)), "surface_bias_m": np.mean(error),
            "within_1sigma": np.mean(z <= 1), "within_2sigma": np.mean(z <= 2),
            "mean_abs_z": np.mean(z), "calibrated_columns": len(z)}  # fmt: skip


def _grid(x0, x1, y0, y1, spacing):
    xs, ys = np.arange(x0, x1 + 1e-9, spacing), np.arange(y0, y1 + 1e-9, spacing)
    x, y = np.meshgrid(xs, ys, indexing="ij")
    return x.ravel(), y.ravel()


def _to_utm(x, y):
    """UTM 32N (E, N) of local points (x north, y east) along the geodesic from the origin."""
    az = np.degrees(np.arctan2(y, x))
    lon, lat, _ = pyproj.Geod(ellps="WGS84").fwd(np.full_like(x, LON0), np.full_like(x, LAT0),
                                                 az, np.hypot(x, y))  # fmt: skip
    return pyproj.Transformer.from_crs(4326, 32632, always_xy=True).transform(lon, lat)


def _to_local(east, north):
    lon, lat = pyproj.Transformer.from_crs(32632, 4326, always_xy=True).transform(east, north)
    az, _, dist = pyproj.Geod(ellps="WGS84").inv(np.full_like(lon, LON0), np.full_like(lat, LAT0),
                                                 lon, lat)  # fmt: skip
    az = np.radians(az)
    return dist * np.cos(az), dist * np.sin(az)


def _write_tif(path, values, west, north, res, crs=None, nodata=np.nan):
    """A one-band GeoTIFF, rows north to south, as a survey package writes one."""
    rows, cols = values.shape
    with rasterio.open(path, "w", driver="GTiff", height=rows, width=cols, count=1,
                       dtype="float32", nodata=nodata, crs=crs,
                       transform=Affine(res, 0, west, 0, -res, north)) as dst:  # fmt: skip
        dst.write(values.astype(np.float32), 1)
    return path


def _hole(x, y):
    """Where the local GeoTIFF truth has data: not in a 0.5 m square of nodata."""
    return ~((x > 1.0) & (x < 1.5) & (y > 0.5) & (y < 1.0))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("evaluate_map")
    out = {"map": _map().save(root / "map" / "map.npz")}
    out["deep"] = _map(shift=1).save(root / "deep" / "map.npz")
    x, y = _grid(-0.5, 3.5, -0.5, 2.5, 0.025)
    out["ply"] = write_ply(root / "truth.ply", np.stack([x, y, plane(x, y)], axis=1))
    rows = np.stack([x, y, -plane(x, y)], axis=1).tolist()
    lines = ["# a survey, elevation", "x, y, z", *(f"{a!r},{b!r},{c!r}" for a, b, c in rows)]
    (root / "truth.xyz").write_text("\n".join(lines) + "\n")
    out["xyz"] = root / "truth.xyz"
    # local GeoTIFF, elevation, with a nodata square: east = y, north = x; pixel centres on a
    # 0.05 m grid from the edges at west -0.5, north 3.5
    r = 0.05
    east = -0.5 + (np.arange(60) + 0.5) * r
    north = 3.5 - (np.arange(80) + 0.5) * r
    e, n = np.meshgrid(east, north)
    elevation = np.where(_hole(n, e), -plane(n, e), -9999.0)
    out["tif_local"] = _write_tif(root / "local.tif", elevation, -0.5, 3.5, r, nodata=-9999.0)
    # UTM GeoTIFF, depth: the plane at each pixel centre's local position (by the geodesic)
    e0, n0 = _to_utm(np.array([-0.5]), np.array([-0.5]))
    west, south = math.floor(e0[0]) - 1.0, math.floor(n0[0]) - 1.0
    e, n = np.meshgrid(west + (np.arange(140) + 0.5) * r, south + 8.0 - (np.arange(160) + 0.5) * r)
    lx, ly = _to_local(e.ravel(), n.ravel())
    out["tif_utm"] = _write_tif(root / "utm.tif", plane(lx, ly).reshape(e.shape), west,
                                south + 8.0, r, crs="EPSG:32632")  # fmt: skip
    east, north = _to_utm(x, y)
    (root / "utm.xyz").write_text(
        "".join(
            f"{a!r} {b!r} {c!r}\n" for a, b, c in np.stack([east, north, plane(x, y)], 1).tolist()
        )
    )
    out["xyz_utm"] = root / "utm.xyz"
    return out


def _json(*args):
    r = runner.invoke(app, ["evaluate", "map", *map(str, args), "--json"])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout), r.stderr


@pytest.mark.parametrize(
    ("truth", "extra", "defined"),
    [("ply", (), None), ("xyz", (), None), ("tif_local", (), _hole),
     ("tif_utm", ("--origin", ORIGIN), None), ("xyz_utm", ("--origin", ORIGIN), None)],
)  # fmt: skip
def test_every_truth_format_gives_the_plane_s_metrics(files, truth, extra, defined):
    data, _ = _json(files["map"], files[truth], *extra)
    want = _expected(defined=defined)
    # the truth's own gridding and, in UTM, the geodesic against the transverse Mercator
    # (1e-8 relative) move the truth by well under a millimetre: a column or two may flip
    assert data["surface_rmse_m"] == pytest.approx(want["surface_rmse_m"], abs=1e-4)
    assert data["surface_bias_m"] == pytest.approx(want["surface_bias_m"], abs=1e-4)
    n = want["calibrated_columns"]
    assert data["calibrated_columns"] == n
    for key in ("within_1sigma", "within_2sigma"):
        assert data[key] == pytest.approx(want[key], abs=2 / n), key
    assert data["mean_abs_z"] == pytest.approx(want["mean_abs_z"], abs=1e-3)
    assert data["coverage"] == 1.0 and data["covered_columns"] == NX * NY
    assert data["recall_20cm"] == 1.0
    if defined is None:  # errors within +-5 cm of a plane: every map sample within 10 cm of it
        assert data["precision_10cm"] == data["precision_20cm"] == data["fscore_20cm"] == 1.0
    else:  # no truth in the hole: the map's samples at its middle are far from any
        assert data["precision_20cm"] < 1.0


def test_json_has_every_metric_and_matches_the_library(files):
    data, _ = _json(files["map"], files["ply"])
    taus = ("5cm", "10cm", "20cm")
    keys = {"c2c_mean_m", "c2c_median_m", "c2c_rmse_m", "coverage_mean_m", "occupied_cells",
            "surface_rmse_m", "surface_bias_m", "coverage", "within_1sigma", "within_2sigma",
            "mean_abs_z", "calibrated_columns", "std_kind", "threshold", "threshold_from",
            "truth_z",
            *(f"{m}_{t}" for m in ("precision", "recall", "fscore") for t in taus)}  # fmt: skip
    assert keys <= set(data)
    assert all(not isinstance(v, dict | list) for v in data.values())  # flat
    assert evaluate_map_file(files["map"], files["ply"]).to_dict() == data
    assert data["occupied_cells"] == NX * NY and data["truth_z"] is None


def test_a_map_one_cell_too_deep_is_outside_two_sigma_and_misses_at_5_cm(files):
    """Shifted one cell down, every error is in [5, 15) cm: |z| >= sqrt(3) (mostly > 2), no
    map sample within 5 cm of the plane's points... except on the steepest, counted directly."""
    data, _ = _json(files["deep"], files["ply"])
    want = _expected(shift=1)
    assert data["surface_bias_m"] == pytest.approx(want["surface_bias_m"], abs=5e-4)
    assert data["within_1sigma"] == want["within_1sigma"] == 0.0
    assert data["within_2sigma"] == pytest.approx(want["within_2sigma"], abs=0.02)
    assert data["precision_5cm"] < 0.2 and data["precision_20cm"] == 1.0


def test_the_human_table_and_the_notes(files):
    r = runner.invoke(app, ["evaluate", "map", str(files["map"]), str(files["xyz"])])
    assert r.exit_code == 0, r.output
    text = r.stdout
    for label in ("C2C map -> truth", "surface", "accuracy (precision)", "completeness (recall)",
                  "F-score", "calibration", "threshold"):  # fmt: skip
        assert label in text
    want = _expected()
    assert f"{100 * want['within_1sigma']:.1f} % within 1 sigma" in text
    # the header line "x, y, z" is malformed: skipped with one warning naming it
    warnings = [ln for ln in r.stderr.splitlines() if ln.startswith("warning:")]
    assert len(warnings) == 1 and "line 2 'x, y, z'" in warnings[0]
    assert "z read as elevation" in r.stderr and "--truth-z depth to override" in r.stderr


def test_truth_z_overrides_the_detected_sign(files):
    data, stderr = _json(files["map"], files["xyz"], "--truth-z", "depth")
    assert data["truth_z"] == "depth" and "z read as depth (--truth-z)" in stderr
    # depth read as -z: the truth is 2 x ~2.2 m away, outside every threshold
    assert data["surface_bias_m"] > 4.0 and data["fscore_20cm"] == 0.0


def test_a_map_ply_has_no_calibration(files, tmp_path):
    ply = tmp_path / "map.ply"
    export_map(files["map"], ply)
    data, stderr = _json(ply, files["ply"])
    assert all(data[k] is None for k in ("within_1sigma", "within_2sigma", "mean_abs_z",
                                         "calibrated_columns"))  # fmt: skip
    assert "holds no depth std: calibration null" in stderr
    # the gridded cell centres are the map.npz's surface
    want = _expected()
    assert data["surface_rmse_m"] == pytest.approx(want["surface_rmse_m"], abs=1e-6)


def test_the_geotiff_s_depth_std_band_is_calibrated_as_the_map(files, tmp_path):
    """The issue's check of the exported depth-std band against the truth: at the map's cell
    size the local GeoTIFF is the surface cell for cell (float32), so its calibration is the
    map's; georeferenced (UTM, 1.5 deg of meridian convergence), each raster cell takes the map
    cell its centre falls in, another sample of the same columns: within 3 binomial sigma."""
    npz, _ = _json(files["map"], files["ply"])
    local = export_map(files["map"], tmp_path / "local.tif").path
    tif, stderr = _json(local, files["ply"])
    assert "C2C and cells are the GeoTIFF's cells with data" in stderr
    assert tif["calibrated_columns"] == npz["calibrated_columns"]
    n = npz["calibrated_columns"]
    for key in ("within_1sigma", "within_2sigma"):
        assert abs(tif[key] - npz[key]) <= 1 / n
    assert tif["surface_rmse_m"] == pytest.approx(npz["surface_rmse_m"], abs=1e-6)
    assert npz["std_kind"] == tif["std_kind"] == "first-occupied"  # the file's UNDERTOW_STD
    utm = export_map(files["map"], tmp_path / "utm.tif", origin=ORIGIN).path
    line = one_error_line(runner.invoke(app, ["evaluate", "map", str(utm), str(files["ply"])]))
    assert "--origin LAT,LON or --utm E,N,ZONE" in line
    geo, _ = _json(utm, files["ply"], "--origin", ORIGIN)
    assert abs(geo["calibrated_columns"] - n) <= 0.03 * n
    for key in ("within_1sigma", "within_2sigma"):
        p = npz[key]
        assert abs(geo[key] - p) <= 3 * math.sqrt(max(p * (1 - p), 1 / n) / n), key
    # a UTM map against a UTM truth of the same CRS needs no origin
    same, _ = _json(utm, files["tif_utm"])
    assert same["within_1sigma"] == pytest.approx(geo["within_1sigma"], abs=0.02)


@pytest.mark.parametrize(
    ("truth", "args", "message"),
    [
        ("tif_utm", (), "(x north, y east): give --origin LAT,LON or --utm E,N,ZONE"),
        ("xyz_utm", (), "give --origin LAT,LON or --utm E,N,ZONE"),
        ("ply", ("--truth-z", "depth"), "--truth-z applies to an XYZ or GeoTIFF truth"),
        ("xyz", ("--truth-z", "up"), "--truth-z 'up': expected depth or elevation"),
        ("tif_local", ("--truth-frame", "local"), "--truth-frame applies to an XYZ truth"),
        ("xyz", ("--origin", ORIGIN, "--utm", "1,2,32N"), "not both"),
        ("xyz", ("--origin", "91,0"), "--origin: latitude"),
    ],
)  # fmt: skip
def test_wrong_truths_and_options_are_one_line(files, truth, args, message):
    result = runner.invoke(app, ["evaluate", "map", str(files["map"]), str(files[truth]), *args])
    line = one_error_line(result)
    assert message in line


def test_unusable_truth_files_are_one_line(files, tmp_path):
    bad = tmp_path / "bad.xyz"
    bad.write_text("x y z\n1 2\n")
    line = one_error_line(runner.invoke(app, ["evaluate", "map", str(files["map"]), str(bad)]))
    assert line.startswith(f"error: {bad}: no usable x y z point")
    tif = tmp_path / "broken.tif"
    tif.write_bytes(b"II*\x00garbage")
    line = one_error_line(runner.invoke(app, ["evaluate", "map", str(files["map"]), str(tif)]))
    assert line.startswith(f"error: {tif}: not a readable GeoTIFF")
    line = one_error_line(
        runner.invoke(app, ["evaluate", "map", str(files["tif_local"]), str(files["ply"])])
    )
    assert "bands band1; a map GeoTIFF has bands depth, std, coverage" in line
    line = one_error_line(runner.invoke(app, ["evaluate", "map", str(files["map"]),
                                              str(files["ply"]), "--threshold", "0.7",
                                              "--truth-z", "depth"]))  # fmt: skip
    assert "--truth-z applies" in line
