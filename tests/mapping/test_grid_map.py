"""A map read out part by part (mapping/grid_map.py): a log mapped in pieces past its resident
budget gives a GridOccupancy whose map.npz arrays, map.ply bytes and config.yaml are those of
the same map formed whole and written by io.results.save_map, and whose counts are its."""

import warnings
import zipfile

import numpy as np
import pytest
import yaml

from undertow.estimation.localizer import localize
from undertow.io import iter_log_pieces, read_log
from undertow.io.npz_parts import write_npz_parts
from undertow.io.results import save_map
from undertow.mapping.config import MappingConfig
from undertow.mapping.grid import CHUNK_BYTES
from undertow.mapping.grid_map import GridOccupancy
from undertow.mapping.run import map_pieces
from undertow.occupancy import OccupancyMap


@pytest.mark.parametrize("method", ["csm", "tpu"])
def test_a_map_past_its_budget_is_written_part_by_part_as_the_whole_map(
    simulated_run, tmp_path, method
):
    """(tpu: with its column sums, which go to map.npz whole.)"""
    log = simulated_run("calm") / "log"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        truth = localize(read_log(log))
        maps = {}
        for name, resident in (("whole", None), ("parts", 6 * CHUNK_BYTES / 1e6)):
            config = MappingConfig(method=method, resolution=0.1, resident_mb=resident)
            maps[name] = map_pieces(iter_log_pieces(log, 4.0), truth, config)
    whole, parts = maps["whole"], maps["parts"]
    assert isinstance(whole.map, OccupancyMap) and isinstance(parts.map, GridOccupancy)
    assert len(parts.map) == len(whole.map)
    assert parts.map.n_occupied(0.5) == whole.map.n_occupied(0.5) > 0
    assert parts.metadata == whole.metadata
    for name, result in maps.items():
        save_map(result.map, result.config.model_dump(mode="json"), result.metadata,
                 tmp_path / name, threshold=0.5)  # fmt: skip
    a, b = OccupancyMap.load(tmp_path / "whole"), OccupancyMap.load(tmp_path / "parts")
    for field in ("cells", "alpha", "beta"):
        assert np.array_equal(getattr(a, field), getattr(b, field))
    assert (a.resolution, a.alpha0, a.beta0) == (b.resolution, b.alpha0, b.beta0)
    assert (a.columns is None) == (method == "csm") == (b.columns is None)
    if method == "tpu":
        assert np.array_equal(a.columns.cells, b.columns.cells) and len(a.columns) > 100
        assert np.array_equal(a.columns.sums, b.columns.sums)
    loaded = parts.map.load()
    assert np.array_equal(loaded.alpha, a.alpha) and loaded.metadata == a.metadata
    assert (tmp_path / "whole" / "map.ply").read_bytes() == (
        tmp_path / "parts" / "map.ply"
    ).read_bytes()
    docs = [yaml.safe_load((tmp_path / name / "config.yaml").read_text()) for name in maps]
    assert [d["mapping"].pop("resident_mb") for d in docs] == [None, 6 * CHUNK_BYTES / 1e6]
    assert docs[0] == docs[1]  # the rest of the record is the same


def test_a_streamed_member_must_hold_its_shape(tmp_path):
    parts = {"x": (np.float64, (5,), lambda: iter([np.zeros(2), np.zeros(2)]))}
    with pytest.raises(Exception, match="member x got 32 bytes of 40"):
        write_npz_parts(tmp_path / "a.npz", parts, {})
    assert not (tmp_path / "a.npz").exists()  # atomic: nothing half-written
    write_npz_parts(tmp_path / "b.npz", {"x": (np.int64, (4, 3), lambda: (np.ones((2, 3)),) * 2)},
                    {"s": np.array("z")})  # fmt: skip
    with np.load(tmp_path / "b.npz") as d:
        assert np.array_equal(d["x"], np.ones((4, 3), np.int64)) and str(d["s"]) == "z"
    assert (
        zipfile.ZipFile(tmp_path / "b.npz").getinfo("x.npy").compress_type == zipfile.ZIP_DEFLATED
    )
