"""The map's resident budget (mapping/grid.py with mapping/spill.py): over its budget the grid
moves the tiles farthest from its latest write to a temporary file and takes them back before a
write that may reach them. The map must be the one kept all in memory, bit for bit (same cells,
same order, same alpha and beta), for every write path, while the chunks in memory stay under
the budget."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import multibeam_fan

from undertow.mapping import make_mapper
from undertow.mapping.chunks import CHUNK
from undertow.mapping.grid import CHUNK_BYTES, ChunkedGrid
from undertow.mapping.samples import expand
from undertow.mapping.spill import RECORD_BYTES, ChunkSpill

SETTINGS = {
    "tpu": {"max_length": 1.0},
    "adaptive": {"variance_bounds": ((0, 0, 0), (6e-3, 6e-3, 1e-3)), "l_max": (0.6, 0.6, 0.6)},
    "bki": {"length_scale": 0.3},
    "csm": {},
}


def _route():
    """Multibeam fans along a line out and back (legs 7 m apart, as multibeam_fan places them),
    so that the way back writes on ground spilled on the way out."""
    legs = [*range(6), *range(5, -1, -1)]
    return [multibeam_fan(np.random.default_rng(k), 4, 48, leg, [6e-3, 6e-3, 1e-3])
            for k, leg in enumerate(legs)]  # fmt: skip


def _map(method: str, resident_mb, spill_dir=None, prior=None):
    mapper = make_mapper(method, resolution=0.1, resident_mb=resident_mb, prior=prior,
                         **SETTINGS[method])  # fmt: skip
    if spill_dir is not None:
        mapper.grid.spill.directory = spill_dir
    held = []
    for o, v, r, var in _route():  # multibeam rays (sensor 2), sigma_0 0.6, free samples 0.1 m
        mapper.integrate(expand(o, v, r, var, np.full(len(r), 0.6), np.full(len(r), 2), 0.1, {}))
        held.append(mapper.grid.n_chunks)
    return mapper, held


def _same_cells(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(a.grid.cells(), b.grid.cells(), strict=True))


@pytest.mark.parametrize("method", ["tpu", "adaptive", "bki", "csm"])
def test_a_map_over_its_budget_is_the_map_kept_in_memory_bit_for_bit(method, tmp_path):
    whole, _ = _map(method, None)
    budget_mb = whole.grid.n_chunks // 3 * CHUNK_BYTES / 1e6  # a third of the map
    spilled, held = _map(method, budget_mb, spill_dir=tmp_path)
    spill = spilled.grid.spill
    assert spill.puts > 0 and spill.takes > 0  # spilled, and written again after
    assert max(held) * CHUNK_BYTES <= budget_mb * 1e6
    assert spilled.grid.n_chunks + len(spill) == whole.grid.n_chunks  # each chunk in one place
    assert _same_cells(whole, spilled)
    occupancy = spilled.occupancy()
    assert np.array_equal(occupancy.alpha, whole.occupancy().alpha)
    if method == "tpu":  # the column sums spill with an eighth of the budget, the same sums
        assert spilled.columns.grid.spill.puts > 0
        columns, kept = occupancy.columns, whole.occupancy().columns
        assert np.array_equal(columns.cells, kept.cells)
        assert np.array_equal(columns.sums, kept.sums)
    assert list(tmp_path.iterdir()) == []  # the spill file has no name: nothing left behind


def test_a_prior_seeded_over_spilled_ground_gives_the_same_map():
    """A seed (add_mass) is a write like the others: the prior's cells reach spilled tiles."""
    prior = _map("csm", None)[0].occupancy()
    whole, _ = _map("csm", None, prior=prior)
    spilled, _ = _map("csm", whole.grid.n_chunks // 3 * CHUNK_BYTES / 1e6, prior=prior)
    assert spilled.grid.spill.takes > 0
    assert _same_cells(whole, spilled)


def test_the_spill_round_trips_chunks_and_reuses_its_records():
    rng = np.random.default_rng(0)
    spill = ChunkSpill()
    keys = np.array([[0, 0, 0], [1, 2, 3], [4, 0, 0], [-1, -5, 2]], np.int64)  # tiles of 4^3
    alpha = rng.random((4, CHUNK, CHUNK, CHUNK)).astype(np.float32)
    beta = rng.random((4, CHUNK, CHUNK, CHUNK)).astype(np.float32)
    for _ in range(3):
        spill.put(keys, np.arange(4), alpha, beta)
        assert len(spill) == 4
        tiles = spill.tiles_in(np.array([-8, -8, -8]), np.array([8, 8, 8]))
        assert sorted(tiles) == [(-1, -2, 0), (0, 0, 0), (1, 0, 0)]
        assert spill.tiles_in(np.array([1, 0, 0]), np.array([3, 3, 3])) == [(0, 0, 0)]
        got_keys, births, a, b = spill.take(tiles)
        order = np.argsort(births)
        assert np.array_equal(got_keys[order], keys)
        assert np.array_equal(a[order], alpha) and np.array_equal(b[order], beta)
        assert len(spill) == 0
    assert spill.file_bytes == 4 * RECORD_BYTES  # the records of a take are written again
    spill.close()


def test_without_a_budget_nothing_spills():
    grid = ChunkedGrid(0.1)
    cells = np.random.default_rng(1).integers(-500, 500, (20_000, 3))
    grid.add_mass(cells, np.ones(len(cells)), np.ones(len(cells)))
    assert grid.n_chunks > 1000 and len(grid.spill) == 0 and grid.spill.file_bytes == 0


def test_a_view_that_stops_taking_its_boxes_does_not_stop_the_spill(monkeypatch):
    """A live view records the boxes written (track_touched) and takes them when it draws; one
    that stops drawing (its client gone) must neither keep every chunk in memory (only the
    latest boxes' tiles stay) nor grow the record without bound (merged into one box). Here a
    write is a leg 7 m on: two latest boxes kept (16 are seconds of a survey)."""
    from undertow.mapping import grid as grid_module

    monkeypatch.setattr(grid_module, "KEEP_TOUCHED", 2)

    fans = [multibeam_fan(np.random.default_rng(0), 2, 24, leg, [0, 0, 0]) for leg in range(40)]
    budget_mb = 400 * CHUNK_BYTES / 1e6
    mapper = make_mapper("csm", resolution=0.1, resident_mb=budget_mb)
    mapper.grid.track_touched()
    for o, v, r, var in fans * 8:  # 320 writes along 280 m, never taken
        mapper.integrate(expand(o, v, r, var, np.full(len(r), 0.6), np.full(len(r), 2), 0.1, {}))
    grid = mapper.grid
    assert len(grid.spill) > grid.n_chunks and grid.n_chunks * CHUNK_BYTES <= budget_mb * 1e6
    assert 320 > grid_module.MAX_TOUCHED
    taken = grid.take_touched()  # the merged box and the latest cover every chunk held
    assert np.array_equal(taken, np.arange(grid.n_chunks))
