"""Tiled mapping on Dask: the merged map equals one mapper over all samples (alpha, beta to
1e-12 relative, every cell in exactly one tile) on a survey crossing many tile borders; a tile
that fails is retried, one that fails again is named and the others kept; a tile directory reads
back as the same map; the command's tiling options fail in one line."""

import warnings

import numpy as np
import pytest
from typer.testing import CliRunner

from undertow.cli import app
from undertow.errors import ConfigError
from undertow.mapping import tiled
from undertow.mapping.config import MappingConfig
from undertow.mapping.mappers import mapper_from_config
from undertow.mapping.samples import SENSOR_MULTIBEAM, Samples
from undertow.mapping.tiled import Tiling, map_tiled, read_tiles

runner = CliRunner()
TILE_M = 0.8  # 8 cells at 0.1 m: a 5 m x 4 m survey crosses ~30 tile borders


def fan_survey(n_pings=150, beams=16, seed=0) -> Samples:
    """A lawnmower of multibeam-like fans over a wavy floor 1.5 m below: per ray a hit at the
    floor and free samples every 0.1 m from the origin, the pose variance growing along the run
    (so the adaptive kernel's session bounds matter)."""
    rng = np.random.default_rng(seed)
    k = np.arange(n_pings)
    lines = 3
    u = (k % (n_pings // lines)) / (n_pings // lines) * 5.0
    line = k // (n_pings // lines)
    origin = np.stack([np.where(line % 2 == 0, u, 5.0 - u), 0.6 + 1.4 * line, np.zeros(k.size)], 1)
    angle = np.linspace(-0.9, 0.9, beams)
    v = np.stack([np.zeros(beams), np.sin(angle), -np.cos(angle)], 1)
    o = np.repeat(origin, beams, axis=0)
    d = np.tile(v, (n_pings, 1))
    r = (1.5 + 0.1 * np.sin(o[:, 0] * 2.0)) / np.cos(np.tile(angle, n_pings))
    r += rng.normal(0, 0.01, r.size)
    var = np.repeat(1e-4 + 1e-3 * k[:, None] / n_pings * [1.0, 1.2, 0.2], beams, axis=0)
    rays = np.arange(r.size)
    pts, lab, pv, ray = [o + r[:, None] * d], [np.ones(r.size)], [var], [rays]
    for s in np.arange(0.0, r.max(), 0.1):
        keep = s <= r - 0.1
        pts.append(o[keep] + s * d[keep])
        lab.append(np.zeros(keep.sum()))
        pv.append(var[keep])
        ray.append(rays[keep])
    ray = np.concatenate(ray)
    return Samples(np.concatenate(pts), np.concatenate(lab), 0.9, np.concatenate(pv), ray,
                   np.full(ray.size, SENSOR_MULTIBEAM), o)  # fmt: skip


@pytest.fixture(scope="module")
def survey():
    return fan_survey()


def sorted_map(m):
    order = np.lexsort(m.cells.T[::-1])
    return m.cells[order], m.alpha[order], m.beta[order]


def assert_same_map(tiled_map, single, rtol=1e-12):
    cells, a, b = sorted_map(tiled_map)
    cells0, a0, b0 = sorted_map(single)
    assert len(np.unique(cells, axis=0)) == len(cells), "a cell in two tiles"
    np.testing.assert_array_equal(cells, cells0)
    np.testing.assert_allclose(a, a0, rtol=rtol, atol=0)
    np.testing.assert_allclose(b, b0, rtol=rtol, atol=0)


def single_process(samples, config):
    mapper = mapper_from_config(config)
    mapper.integrate(samples)
    return mapper.occupancy()


@pytest.mark.parametrize("method", ["adaptive", "bki", "csm", "tpu"])
def test_tiled_equals_single_process(survey, method):
    config = MappingConfig(method=method)
    result = map_tiled(survey, config, TILE_M, scheduler="sync")
    tiling = result.metadata["tiling"]
    assert tiling["tiles"] >= 40 and not result.failed
    assert_same_map(result.map, single_process(survey, config))
    if method == "adaptive":  # session bounds over all samples, not per tile
        var = survey.pose_variance
        assert np.allclose(result.metadata["variance_bounds"], [var.min(0), var.max(0)])


def test_tiled_tpu_with_a_wave_equals_single_process(survey):
    """The wave's range noise and its swell in the poses' depth depend on each hit alone (its
    depth, its sensor's, its pose's): tiles map as the whole, and differ from the map without."""
    config = MappingConfig(method="tpu", wave=(0.15, 0.33), depth_noise=(0.01, 0.1))
    result = map_tiled(survey, config, TILE_M, scheduler="sync")
    single = single_process(survey, config)
    assert_same_map(result.map, single)
    np.testing.assert_array_equal(result.map.columns.cells, single.columns.cells)
    np.testing.assert_allclose(result.map.columns.sums, single.columns.sums, rtol=1e-12)
    assert result.metadata["wave"] == (0.15, 0.33)
    assert result.metadata["depth_noise"] == (0.01, 0.1)
    calm = single_process(survey, MappingConfig(method="tpu"))
    assert not np.array_equal(sorted_map(calm)[1], sorted_map(single)[1])


def test_halo_is_needed(survey):
    """Without the halo the border cells lose the samples of the neighbouring tile: the
    comparison above can fail."""
    config = MappingConfig(method="adaptive")
    single = single_process(survey, config)
    no_halo = Tiling(config.resolution, 8, 0.0)
    parts = no_halo.partition(survey.points)
    cells = []
    for tile, index in parts.items():
        r = tiled.map_tile(tile, tiled.subset(survey, index), config, no_halo,
                           tiled.session_bounds(survey, config))  # fmt: skip
        cells.append(r.alpha_mass.sum() + r.beta_mass.sum())
    assert not np.isclose(sum(cells), (single.alpha - config.alpha0).sum() +
                          (single.beta - config.beta0).sum(), rtol=1e-6)  # fmt: skip


def test_partition_keeps_order_and_reaches_every_owner(survey):
    tiling = Tiling.for_config(MappingConfig(), TILE_M)
    parts = tiling.partition(survey.points)
    for index in parts.values():
        assert np.all(np.diff(index) > 0)
    # every sample is in the tile of its own cell
    own = tiling.tiles_of_cells(np.floor(survey.points / 0.1).astype(np.int64))
    member = {tile: set(index.tolist()) for tile, index in parts.items()}
    assert all(i * 97 in member[tuple(t)] for i, t in enumerate(own[::97].tolist()))


@pytest.mark.network  # a Dask cluster on 127.0.0.1
def test_local_cluster_equals_single_process(survey, tmp_path):
    """Two worker processes (the default scheduler), the tiles written one by one to a
    directory and read back as one map."""
    config = MappingConfig()
    result = map_tiled(survey, config, 1.6, scheduler="local", n_workers=2,
                       tile_dir=tmp_path / "tiles")  # fmt: skip
    assert result.metadata["tiling"]["workers"] == 2
    assert len(list((tmp_path / "tiles").glob("tile_*.npz"))) == result.metadata["tiling"]["tiles"]
    single = single_process(survey, config)
    assert_same_map(result.map, single)
    assert_same_map(read_tiles(tmp_path / "tiles"), result.map, rtol=0)
    np.testing.assert_allclose(result.map.columns.sums, single.columns.sums, rtol=1e-12)


def test_local_workers_keep_glibc_malloc_defaults(monkeypatch):
    """The local cluster's worker processes run without Dask's MALLOC_TRIM_THRESHOLD_ (which
    fixes glibc's thresholds, so every large array is faulted in anew), keeping Dask's other
    pre-spawn settings; the caller's Dask configuration is left as it was."""
    import os

    import dask
    import distributed  # noqa: F401 (loads Dask's distributed defaults)

    before = dict(dask.config.get("distributed.nanny.pre-spawn-environ"))
    # as an earlier default Dask cluster in this process leaves it (its nanny copies it here)
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", str(before["MALLOC_TRIM_THRESHOLD_"]))
    got = []

    def worker_env(name, default):  # nested: pickled by value, runs on the worker
        return os.environ.get(name, default)

    jobs = {"MALLOC_TRIM_THRESHOLD_": ("unset",), "OMP_NUM_THREADS": ("unset",)}
    run = tiled.run_tiles(worker_env, jobs, got.append, scheduler="local", n_workers=1)
    assert not run.failures and sorted(got) == ["1", "unset"]
    assert "MALLOC_TRIM_THRESHOLD_" in before
    assert dict(dask.config.get("distributed.nanny.pre-spawn-environ")) == before
    assert os.environ["MALLOC_TRIM_THRESHOLD_"] == str(before["MALLOC_TRIM_THRESHOLD_"])


def test_failed_tile_is_retried_then_reported(survey, monkeypatch):
    config = MappingConfig()
    full = map_tiled(survey, config, TILE_M, scheduler="sync").map
    real = tiled.map_tile
    calls: dict = {}
    tiles = sorted(Tiling.for_config(config, TILE_M).partition(survey.points))
    flaky, broken = tiles[3], tiles[7]

    def failing(tile, *args):
        calls[tile] = calls.get(tile, 0) + 1
        if tile == broken or (tile == flaky and calls[tile] == 1):
            raise RuntimeError(f"disk full on tile {tile}")
        return real(tile, *args)

    monkeypatch.setattr(tiled, "map_tile", failing)
    for scheduler in ("threads", "sync"):
        calls.clear()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = map_tiled(survey, config, TILE_M, scheduler=scheduler, retries=1)
        name = tiled.tile_name(broken)
        assert list(result.failed) == [name] and "disk full" in result.failed[name]
        assert calls[flaky] == 2 and calls[broken] == 2
        ours = [str(w.message) for w in caught if "missing from the map" in str(w.message)]
        assert len(ours) == 1 and name in ours[0], [str(w.message) for w in caught]
        owned = np.all(Tiling.for_config(config, TILE_M).tiles_of_cells(full.cells) == broken, 1)
        assert_same_map(result.map, full.select(~owned))


def test_tile_directory_errors(tmp_path):
    from undertow.errors import ReaderError

    with pytest.raises(ReaderError, match="tiles.json"):
        read_tiles(tmp_path)
    (tmp_path / "tiles.json").write_text("{}")
    with pytest.raises(ReaderError, match="not a tile index"):
        read_tiles(tmp_path)


@pytest.mark.parametrize(
    ("size", "scheduler", "message"),
    [(-1.0, None, "tile size"), (0.01, None, "below the map resolution"),
     (1.0, "bogus", "unknown scheduler")],
)  # fmt: skip
def test_option_errors(size, scheduler, message):
    with pytest.raises(ConfigError, match=message):
        map_tiled(fan_survey(4, 2), MappingConfig(), size, scheduler=scheduler)


@pytest.mark.parametrize(
    ("args", "message"),
    [(["--tiles", "-2"], "tile size"), (["--tiles", "5", "--scheduler", "nowhere"],
      "unknown scheduler"), (["--scheduler", "threads"], "--tiles"),
     (["--tiles", "5", "--scheduler", "tcp://127.0.0.1:9"], "cannot reach")],
)  # fmt: skip
def test_cli_option_errors_are_one_line(tmp_path, args, message):
    out = runner.invoke(app, ["map", str(tmp_path / "log.bag"), "--trajectory",
                              str(tmp_path), "--out", str(tmp_path / "m"), *args])  # fmt: skip
    assert out.exit_code == 1
    lines = out.output.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], out.output


def test_cli_tiled_map_equals_untiled(tmp_path, simulation, simulated_run):
    """`undertow map --tiles` on a simulated run: the same map.npz as without tiles, the tile
    directory beside it, the tiling recorded in config.yaml."""
    import yaml

    from undertow.occupancy import OccupancyMap
    from undertow.trajectory import Trajectory

    gt = simulation("calm", 0).log.ground_truth
    t = gt.t[::20]
    x = np.zeros((t.size, 18))
    x[:, :3], x[:, 3:6] = gt.position[::20], gt.orientation[::20]
    P = np.zeros((t.size, 18, 18))
    for k in range(3):
        P[:, k, k] = 1e-4 + 1e-3 * (t - t[0]) / (t[-1] - t[0])
    Trajectory(t, x, P).save_npz(tmp_path / "est" / "trajectory.npz")
    log = str(simulated_run("calm", 0) / "log")
    base = ["map", log, "--trajectory", str(tmp_path / "est"), "-q", "--method", "adaptive"]
    assert runner.invoke(app, [*base, "--out", str(tmp_path / "one")]).exit_code == 0
    r = runner.invoke(app, [*base, "--out", str(tmp_path / "tiled"), "--tiles", "0.5",
                            "--scheduler", "threads"])  # fmt: skip
    assert r.exit_code == 0, r.output
    one, tiled_map = (OccupancyMap.load(tmp_path / d) for d in ("one", "tiled"))
    assert_same_map(tiled_map, one)
    assert_same_map(read_tiles(tmp_path / "tiled" / "tiles"), one)
    doc = yaml.safe_load((tmp_path / "tiled" / "config.yaml").read_text())
    assert doc["result"]["tiling"]["tiles"] > 4 and not doc["result"]["tiling"]["failed"]
    assert doc["result"]["mapper"]["normalization"] == "session"
