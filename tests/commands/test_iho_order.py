"""`undertow export --iho-order` and `undertow evaluate map --iho-order` on a tpu map of a flat
floor with two patches, one whose depth std (closed form, tests/mapping/test_iho.py) meets IHO
S-44 Order 1a and one that does not: the GeoTIFF keeps the first (and says the order in its
tags), evaluate map judges the first and says how many columns it withheld; "none" keeps both;
the option where it does not apply is one line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import one_error_line
from survey_patches import FLOOR, two_patches
from typer.testing import CliRunner

from undertow.cli import app
from undertow.io.ply import write_ply

rasterio = pytest.importorskip("rasterio")
runner = CliRunner()


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("iho")
    out = {"map": two_patches().save(root / "map" / "map.npz")}
    gx, gy = np.meshgrid(np.arange(-1.0, 5.0, 0.025), np.arange(-1.0, 2.0, 0.025))
    plane = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, FLOOR)], axis=1)
    out["truth"] = write_ply(root / "truth.ply", plane)
    return out


def _evaluate(*args):
    r = runner.invoke(app, ["evaluate", "map", *map(str, args), "--json"])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout), r.stderr


def test_evaluate_map_judges_the_columns_that_meet_the_order(files):
    held, stderr = _evaluate(files["map"], files["truth"])
    every, quiet = _evaluate(files["map"], files["truth"], "--iho-order", "none")
    assert held["iho_order"] == "1a" and every["iho_order"] is None
    assert every["withheld_columns"] == 0 and held["withheld_columns"] > 50
    # the poor patch is withheld: what is judged is the good patch only
    assert held["covered_columns"] + held["withheld_columns"] == every["covered_columns"]
    assert held["covered_columns"] < every["covered_columns"] / 2 + 10
    assert f"IHO S-44 order 1a: {held['withheld_columns']} columns withheld" in stderr
    assert "IHO S-44" not in quiet
    special, _ = _evaluate(files["map"], files["truth"], "--iho-order", "special")
    assert special["withheld_columns"] == held["withheld_columns"]
    table = runner.invoke(app, ["evaluate", "map", str(files["map"]), str(files["truth"])])
    assert (
        f"IHO S-44 order         1a ({held['withheld_columns']} columns withheld)" in table.stdout
    )


def test_the_geotiff_keeps_the_columns_that_meet_the_order(files, tmp_path):
    r = runner.invoke(app, ["export", str(files["map"]), "--out", str(tmp_path / "held.tif")])
    assert r.exit_code == 0, r.output
    assert "IHO S-44 order 1a" in r.stderr and "columns withheld" in r.stderr
    r = runner.invoke(app, ["export", str(files["map"]), "--out", str(tmp_path / "all.tif"),
                            "--iho-order", "none"])  # fmt: skip
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "held.tif") as a, rasterio.open(tmp_path / "all.tif") as b:
        assert a.tags()["UNDERTOW_IHO_ORDER"] == "1a" and "UNDERTOW_IHO_ORDER" not in b.tags()
        kept, every = a.read(3) > 0, b.read(3) > 0
        np.testing.assert_array_equal(a.read(1)[kept], b.read(1)[kept])
    assert kept.sum() < every.sum() and not (kept & ~every).any()
    # evaluate map on the GeoTIFF judges what it holds, as on the map.npz
    held, _ = _evaluate(tmp_path / "held.tif", files["truth"])
    npz, _ = _evaluate(files["map"], files["truth"])
    assert held["iho_order"] == "1a" and held["covered_columns"] == npz["covered_columns"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["export", "{map}", "--out", "{tmp}/m.ply", "--iho-order", "1a"],
         "--iho-order applies to geotiff; ply keeps the map's cells"),
        (["export", "{map}", "--out", "{tmp}/m.tif", "--iho-order", "3"],
         "IHO order '3': expected one of exclusive, special, 1a, 1b, 2, none"),
        (["evaluate", "map", "{map}", "{truth}", "--iho-order", "zero"],
         "IHO order 'zero': expected one of"),
        (["evaluate", "map", "{tmp}/t.tif", "{truth}", "--iho-order", "1a"],
         "--iho-order applies to a map.npz"),
    ],
)  # fmt: skip
def test_the_option_where_it_does_not_apply_is_one_line(files, tmp_path, args, message):
    runner.invoke(app, ["export", str(files["map"]), "--out", str(tmp_path / "t.tif")])
    fill = {"map": files["map"], "truth": files["truth"], "tmp": tmp_path}
    line = one_error_line(runner.invoke(app, [a.format(**fill) for a in args]))
    assert message in line
