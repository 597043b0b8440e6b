"""The chunk hash table (mapping/chunks.py): a survey's chunks spread over the table as a random
hash would spread them, and the read-only probe agrees with the inserting one."""

from __future__ import annotations

import numpy as np

from undertow.mapping.chunks import find, find_or_insert, home_slot, lookup, pack_key
from undertow.mapping.grid import ChunkedGrid


def _survey_chunks():
    """The chunks of a mapped strip: 40 x 44 chunks across, 4 deep (a multibeam survey's)."""
    x, y, z = np.meshgrid(np.arange(40), np.arange(-3, 41), np.arange(6, 10), indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


def test_a_surveys_chunks_spread_over_the_table_as_a_random_hash_spreads_them():
    """Linear probing with a uniform hash at load factor a: a share (1 - exp(-a)) / a of the keys
    get distinct home slots, and a successful search probes (1 + 1 / (1 - a)) / 2 slots on
    average (Knuth, TAOCP vol. 3, 6.4)."""
    chunks = _survey_chunks()
    grid = ChunkedGrid(0.1, capacity=len(chunks))
    tk, tv, keys, n, _, _ = grid._tables()
    for cx, cy, cz in chunks:
        assert find_or_insert(cx, cy, cz, tk, tv, keys, n) >= 0
    mask = tk.size - 1
    a = len(chunks) / tk.size
    homes = {home_slot(pack_key(*c), mask) for c in chunks}
    assert len(homes) / len(chunks) > 0.9 * (1 - np.exp(-a)) / a
    probes = []
    for c in chunks:
        key, s, length = pack_key(*c), home_slot(pack_key(*c), mask), 1
        while tk[s] != key:
            s, length = (s + 1) & mask, length + 1
        probes.append(length)
    assert np.mean(probes) < 1.2 * (1 + 1 / (1 - a)) / 2


def test_find_is_lookup_for_chunks_held_and_minus_one_for_the_others():
    chunks = _survey_chunks()[::3]
    grid = ChunkedGrid(0.1, capacity=len(chunks))
    tk, tv, keys, n, _, _ = grid._tables()
    for i, (cx, cy, cz) in enumerate(chunks):
        assert find(cx, cy, cz, tk, tv) == -1
        assert find_or_insert(cx, cy, cz, tk, tv, keys, n) == i
    for i, (cx, cy, cz) in enumerate(chunks):
        assert find(cx, cy, cz, tk, tv) == lookup(cx, cy, cz, tk, tv) == i
    assert find(-5, 7, 1000, tk, tv) == -1
