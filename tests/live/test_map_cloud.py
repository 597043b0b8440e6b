"""The live view's map cloud, kept chunk by chunk: the same occupied cells as a full readout,
reading only the chunks the writes touched."""

import numpy as np
import pytest

from undertow.live.map_cloud import MapCloud
from undertow.live.view import PathTrail, path_points
from undertow.mapping.config import MappingConfig
from undertow.mapping.mappers import mapper_from_config
from undertow.mapping.samples import expand

METHODS = ["csm", "bki", "adaptive", "tpu"]


def _config(method):
    bounds = ((0.0, 0.0, 0.0), (0.05, 0.05, 0.05))
    extra = {"variance_bounds": bounds} if method == "adaptive" else {}
    return MappingConfig(method=method, resolution=0.1, **extra)


def _rays(rng, x0, n=40):
    """Rays down onto a floor about 3 m below, from a short track starting at x0."""
    origin = np.column_stack([x0 + rng.uniform(0, 1.0, n), rng.uniform(-1, 1, n), np.zeros(n)])
    direction = np.column_stack([rng.normal(0, 0.2, n), rng.normal(0, 0.2, n), np.ones(n)])
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    r = rng.uniform(2.8, 3.2, n)
    var = np.tile(rng.uniform(1e-4, 0.05, (n, 1)), (1, 3))
    return expand(origin, direction, r, var, np.full(n, 0.9), np.ones(n, np.int8), 0.5, {})


def _masses(mapper):
    n = mapper.grid.n_chunks
    keys, a, b = mapper.grid.chunk_mass(np.arange(n))
    return {tuple(k): (x.copy(), y.copy()) for k, x, y in zip(keys.tolist(), a, b, strict=True)}


@pytest.mark.parametrize("method", METHODS)
def test_touched_chunks_cover_every_chunk_a_write_changed(method):
    """The invariant the view relies on: a chunk whose mass changed is among those reported."""
    rng = np.random.default_rng(1)
    mapper = mapper_from_config(_config(method))
    mapper.grid.track_touched()
    for x0 in (0.0, 0.5, 6.0):
        before = _masses(mapper)
        mapper.integrate(_rays(rng, x0))
        after = _masses(mapper)
        keys = {tuple(k) for k in mapper.grid.chunk_mass(mapper.grid.take_touched())[0].tolist()}
        changed = {k for k, (a, b) in after.items()
                   if k not in before or not (np.array_equal(a, before[k][0])
                                              and np.array_equal(b, before[k][1]))}  # fmt: skip
        assert changed and changed <= keys
        assert len(keys) < len(after) or x0 == 0.0  # not the whole map, once it has grown


@pytest.mark.parametrize("method", METHODS)
def test_cloud_is_the_occupied_cells_of_a_full_readout(method):
    rng = np.random.default_rng(2)
    config = _config(method)
    mapper = mapper_from_config(config)
    mapper.integrate(_rays(rng, 0.0))  # before the cloud exists: read at its first update
    cloud = MapCloud(mapper, config.occupied_threshold)
    read = []
    for x0 in (0.3, 5.0, 10.0, 10.2):
        mapper.integrate(_rays(rng, x0))
        read.append(cloud.update())
        occupied = mapper.occupancy().occupied(config.occupied_threshold)
        got = cloud.points()["xyz"]
        want = occupied.centres.astype(np.float32)
        assert len(got) == len(want) == cloud.n_points > 0
        order = np.lexsort(got.T[::-1])
        np.testing.assert_array_equal(got[order], want[np.lexsort(want.T[::-1])])
    # later updates read the chunks near the new track only, not the whole map
    assert read[-1] < mapper.grid.n_chunks
    assert cloud.update() == 0  # nothing written since


def test_budget_thins_the_cloud_and_colours_are_on_a_fixed_scale():
    rng = np.random.default_rng(3)
    config = _config("bki")
    mapper = mapper_from_config(config)
    for x0 in range(0, 12, 2):
        mapper.integrate(_rays(rng, float(x0), 200))
    full = MapCloud(mapper, config.occupied_threshold)
    full.update()
    n = len(full.points())
    thin = MapCloud(mapper, config.occupied_threshold, budget=n // 4)
    thin.update()
    pts = thin.points()
    assert n // 8 <= len(pts) <= n // 4 + 64  # every 4th point of each tile (64 tiles at most)

    # a cell's colour does not depend on the rest of the map: the same in both clouds
    def key(p):
        return {tuple(x) + tuple(c) for x, c in zip(p["xyz"].tolist(), p["rgba"].tolist(),
                                                    strict=True)}  # fmt: skip

    assert key(pts) <= key(full.points())


def test_path_trail_keeps_evenly_spaced_positions_in_bounded_memory():
    trail = PathTrail(limit=100)
    p = np.column_stack([np.arange(10_007.0), np.zeros(10_007), np.zeros(10_007)])
    for part in np.array_split(p, 37):
        trail.extend(part)
    kept = trail.positions()
    assert len(trail) <= 100 and kept[0, 0] == 0.0 and kept[-1, 0] == 10_006.0
    steps = np.diff(kept[:-1, 0])
    assert np.all(steps == trail.step)  # evenly spaced, the newest added last
    assert len(path_points(kept)) == len(kept)  # already within what the view sends


def test_a_growing_map_holds_a_bounded_cloud_even_when_its_chunks_spill():
    """A survey over new ground with a view budget of 400 points and a resident budget of 200
    chunks: the points held stay within HELD x budget (chunks thinned), the chunks in memory
    within theirs plus the tiles the latest write reaches (kept: one write, the first, is the
    allowance), and every point sent is a point of the full cloud (spilled chunks keep
    their points; chunks taken back and written again are read again)."""
    from undertow.live.map_cloud import HELD
    from undertow.mapping.grid import CHUNK_BYTES

    rng = np.random.default_rng(5)
    config = _config("bki").model_copy(update={"resident_mb": 200 * CHUNK_BYTES / 1e6})
    mapper = mapper_from_config(config)
    cloud = MapCloud(mapper, config.occupied_threshold, budget=400)
    allowance = None
    for x0 in [*range(0, 16, 2), *range(14, -1, -2)]:  # out and back over spilled ground
        mapper.integrate(_rays(rng, float(x0), 100))
        allowance = allowance or mapper.grid.n_chunks
        cloud.update()
        assert cloud.n_points <= HELD * 400
        assert mapper.grid.n_chunks <= 200 + allowance
    assert cloud.stride > 1 and mapper.grid.spill.takes > 0
    occupied = mapper.occupancy().points(config.occupied_threshold)
    centres = {tuple(np.round(c, 4)) for c in occupied.tolist()}
    sent = {tuple(np.round(p, 4)) for p in cloud.points()["xyz"].astype(float).tolist()}
    assert sent and sent <= centres
