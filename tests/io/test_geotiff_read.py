"""GeoTIFF grids read back: `undertow export`'s raster is the surface it was made from, cell for
cell; any row and column order reads the same; rotated grids, non-square pixels and broken files
are one ReaderError line; nodata is NaN; ``bounds`` reads only the part asked for."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import ReaderError
from undertow.io.export.geotiff import write_geotiff
from undertow.io.export.geotiff_read import geotiff_crs, read_geotiff_grid, read_map_geotiff
from undertow.mapping.surface import Surface

rasterio = pytest.importorskip("rasterio")
from rasterio.transform import Affine  # noqa: E402

RES = 0.1


def _surface() -> Surface:
    """7 columns along x (north) by 4 along y (east), every depth distinct, one hole."""
    depth = 2.0 + 0.01 * np.arange(28, dtype=float).reshape(4, 7)
    depth[2, 5] = np.nan
    std = 0.03 + 0.001 * np.arange(28, dtype=float).reshape(4, 7)
    return Surface(-0.25, 0.35, RES, depth, std, np.isfinite(depth))


def test_the_export_reads_back_as_its_surface(tmp_path):
    surface = _surface()
    grid = read_map_geotiff(write_geotiff(tmp_path / "s.tif", surface))
    assert grid.crs is None and "UNDERTOW_DEPTH" in grid.tags
    assert (grid.x0, grid.y0, grid.resolution) == pytest.approx((-0.25, 0.35, RES))
    np.testing.assert_allclose(grid.bands["depth"], surface.depth, rtol=1e-6)
    np.testing.assert_allclose(grid.bands["std"], np.where(surface.coverage, surface.std, np.nan),
                               rtol=1e-6)  # fmt: skip
    np.testing.assert_array_equal(grid.bands["coverage"] > 0, surface.coverage)
    x, y = grid.centres()
    sx, sy = surface.centres()
    np.testing.assert_allclose(x, sx) and np.testing.assert_allclose(y, sy)


def _write(path, values, transform, nodata=None, crs=None):
    rows, cols = values.shape
    with rasterio.open(path, "w", driver="GTiff", height=rows, width=cols, count=1,
                       dtype="float32", nodata=nodata, transform=transform,
                       crs=crs) as dst:  # fmt: skip
        dst.write(values.astype(np.float32), 1)
    return path


@pytest.mark.parametrize("flip_rows", [False, True])
@pytest.mark.parametrize("flip_cols", [False, True])
def test_any_row_and_column_order_reads_the_same(tmp_path, flip_rows, flip_cols):
    """Pixel (row, col) of the north-up file has its centre at east 10 + (col + 1/2) 0.5,
    north 20 - (row + 1/2) 0.5; the same pixels stored south-up or east-to-west read alike."""
    values = np.arange(12, dtype=float).reshape(3, 4)  # rows north to south, cols west to east
    ref = read_geotiff_grid(_write(tmp_path / "ref.tif", values, Affine(0.5, 0, 10, 0, -0.5, 20)))
    a, c, stored = 0.5, 10.0, values
    e, f = -0.5, 20.0
    if flip_cols:
        a, c, stored = -0.5, 12.0, stored[:, ::-1]
    if flip_rows:
        e, f, stored = 0.5, 18.5, stored[::-1, :]
    grid = read_geotiff_grid(_write(tmp_path / "f.tif", stored, Affine(a, 0, c, 0, e, f)))
    np.testing.assert_array_equal(grid.band(1), ref.band(1))
    assert (grid.x0, grid.y0) == pytest.approx((ref.x0, ref.y0))
    # grid[j, i]: x = x0 + i R north, y = y0 + j R east; the north-west pixel (0 at row 0,
    # col 0) is at the largest x and the smallest y
    assert ref.band(1)[0, -1] == 0.0 and ref.band(1)[-1, 0] == 11.0
    assert ref.x0 + 2 * 0.5 == pytest.approx(20 - 0.25) and ref.y0 == pytest.approx(10.25)


def test_nodata_is_nan_and_bounds_read_a_window(tmp_path):
    values = np.arange(100, dtype=float).reshape(10, 10)
    values[0, 0] = -9999.0
    path = _write(tmp_path / "n.tif", values, Affine(1, 0, 0, 0, -1, 10), nodata=-9999.0)
    grid = read_geotiff_grid(path)
    assert np.isnan(grid.band(1)).sum() == 1 and np.isnan(grid.band(1)[0, -1])
    part = read_geotiff_grid(path, bounds=(2.2, 3.5, 4.1, 6.0))  # west, south, east, north
    x, y = part.centres()
    assert x.min() == pytest.approx(3.5) and x.max() == pytest.approx(5.5)  # rows 4..6
    assert y.min() == pytest.approx(2.5) and y.max() == pytest.approx(4.5)  # cols 2..4
    assert part.band(1).shape == (3, 3)
    assert read_geotiff_grid(path, bounds=(50, 50, 60, 60)).band(1).size == 0


def test_bad_grids_and_files_are_one_error_line(tmp_path):
    values = np.ones((3, 3))
    rotated = _write(tmp_path / "r.tif", values, Affine(1, 0.2, 0, 0.1, -1, 10))
    with pytest.raises(ReaderError, match="rotated or sheared"):
        read_geotiff_grid(rotated)
    oblong = _write(tmp_path / "o.tif", values, Affine(1, 0, 0, 0, -2, 10))
    with pytest.raises(ReaderError, match="square pixels"):
        read_geotiff_grid(oblong)
    with pytest.warns(rasterio.errors.NotGeoreferencedWarning):  # GDAL drops the identity
        bare = _write(tmp_path / "i.tif", values, Affine.identity())
    with pytest.raises(ReaderError, match="no geotransform"):
        read_geotiff_grid(bare)
    broken = tmp_path / "b.tif"
    broken.write_bytes(b"II*\x00" + bytes(range(40)))
    for path in (broken, tmp_path / "none.tif"):
        with pytest.raises(ReaderError) as info:
            read_geotiff_grid(path)
        assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)
    with pytest.raises(ReaderError, match="a map GeoTIFF has bands depth, std, coverage"):
        read_map_geotiff(_write(tmp_path / "one.tif", values, Affine(1, 0, 0, 0, -1, 10)))


def test_the_crs_is_read_without_the_pixels(tmp_path):
    pytest.importorskip("pyproj")
    path = _write(tmp_path / "u.tif", np.ones((2, 2)), Affine(1, 0, 5e5, 0, -1, 6e6),
                  crs="EPSG:32632")  # fmt: skip
    assert geotiff_crs(path).to_epsg() == 32632
    assert read_geotiff_grid(path).crs.to_epsg() == 32632
    assert (
        geotiff_crs(_write(tmp_path / "l.tif", np.ones((2, 2)), Affine(2, 0, 0, 0, -2, 0))) is None
    )
