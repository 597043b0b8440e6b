"""The chunk hash table of the map's sparse storage, as numba kernels on plain arrays.

The grid (:class:`~undertow.mapping.grid.ChunkedGrid`) keeps dense CHUNK^3 blocks of cells; a
cell with index (ix, iy, iz) (i = floor(p / res)) lies in chunk (ix >> CHUNK_SHIFT, ...). Chunk
coordinates are packed into one int64 key (21 bits per axis, :func:`pack_key`) and found through
an open-addressing hash with linear probing (``table_keys``: the key in each slot, -1 empty;
``table_vals``: the chunk's index into the chunk arrays; a power-of-two size, load factor at
most 1/2). :func:`find_or_insert` and :func:`add_mass_to_cells` insert (returning -1 / the first
sample left when the chunk arrays are full, so the caller grows them and resumes);
:func:`lookup` and :func:`chunk_box` only read the table, so the scatter kernels
(:mod:`undertow.mapping.kernels`) can run them on several threads.
"""

from __future__ import annotations

import numpy as np
from numba import njit

CHUNK = 8  # cells per chunk edge
CHUNK_SHIFT = 3  # log2(CHUNK)
CHUNK_LIMIT = 1 << 20  # chunk coordinates are packed in 21 bits per axis: |c| < CHUNK_LIMIT


@njit(cache=True, inline="always")
def pack_key(cx, cy, cz):
    """The int64 key of chunk (cx, cy, cz): each coordinate + CHUNK_LIMIT in 21 bits."""
    return ((cx + CHUNK_LIMIT) << 42) | ((cy + CHUNK_LIMIT) << 21) | (cz + CHUNK_LIMIT)


@njit(cache=True, inline="always")
def home_slot(key, mask):
    """The first slot probed for ``key`` in a table of mask + 1 slots: the low bits of
    MurmurHash3's 64-bit finalizer of the key (Appleby, public domain), in which every bit of
    the key moves every bit of the hash. (A multiplication alone leaves the low bits depending
    on the key's low bits only, i.e. on z: a multibeam survey's chunks crowded into a few
    hundred home slots, probing 12 slots on average.) Only where chunks sit in the table
    depends on it, not their order or the map."""
    h = np.uint64(key)
    h ^= h >> np.uint64(33)
    h *= np.uint64(0xFF51AFD7ED558CCD)
    h ^= h >> np.uint64(33)
    h *= np.uint64(0xC4CEB9FE1A85EC53)
    h ^= h >> np.uint64(33)
    return np.int64(h & np.uint64(mask))


@njit(cache=True)
def find_or_insert(cx, cy, cz, table_keys, table_vals, chunk_keys, n_chunks):
    """Index of chunk (cx, cy, cz), inserting it if new; -1 when the chunk arrays are full."""
    key = pack_key(cx, cy, cz)
    mask = table_keys.shape[0] - 1
    s = home_slot(key, mask)
    while True:
        k = table_keys[s]
        if k == key:
            return table_vals[s]
        if k == -1:
            n = n_chunks[0]
            if n >= chunk_keys.shape[0]:
                return -1
            table_keys[s] = key
            table_vals[s] = n
            chunk_keys[n, 0] = cx
            chunk_keys[n, 1] = cy
            chunk_keys[n, 2] = cz
            n_chunks[0] = n + 1
            return n
        s = (s + 1) & mask


@njit(cache=True)
def rehash(chunk_keys, n, table_keys, table_vals):
    """Fill an empty (all -1) table with the first n chunks."""
    mask = table_keys.shape[0] - 1
    for c in range(n):
        key = pack_key(chunk_keys[c, 0], chunk_keys[c, 1], chunk_keys[c, 2])
        s = home_slot(key, mask)
        while table_keys[s] != -1:
            s = (s + 1) & mask
        table_keys[s] = key
        table_vals[s] = c


@njit(cache=True, inline="always")
def same_box(box, c0x, c0y, c0z, ncx, ncy, ncz):
    """Whether chunk box (first chunk, counts) is the one held in ``box``."""
    return (box[0] == c0x and box[1] == c0y and box[2] == c0z and box[3] == ncx
            and box[4] == ncy and box[5] == ncz)  # fmt: skip


@njit(cache=True, inline="always")
def set_box(box, c0x, c0y, c0z, ncx, ncy, ncz):
    box[0], box[1], box[2], box[3], box[4], box[5] = c0x, c0y, c0z, ncx, ncy, ncz


@njit(cache=True, inline="always")
def lookup(cx, cy, cz, table_keys, table_vals):
    """Index of chunk (cx, cy, cz), which must be in the table (read only: thread safe)."""
    key = pack_key(cx, cy, cz)
    mask = table_keys.shape[0] - 1
    s = home_slot(key, mask)
    while table_keys[s] != key:
        s = (s + 1) & mask
    return table_vals[s]


@njit(cache=True, inline="always")
def find(cx, cy, cz, table_keys, table_vals):
    """Index of chunk (cx, cy, cz), -1 if it is not in the table (read only: thread safe).
    Probing first and inserting only on a miss (:func:`find_or_insert`) costs a kernel that
    places chunks about what a lookup costs (8 ns; a loop around find_or_insert, inlined, takes
    30 ns a call)."""
    key = pack_key(cx, cy, cz)
    mask = table_keys.shape[0] - 1
    s = home_slot(key, mask)
    while table_keys[s] != key and table_keys[s] != -1:
        s = (s + 1) & mask
    return table_vals[s] if table_keys[s] == key else -1


@njit(cache=True)
def boxes_chunks(lo, hi, count, table_keys, table_vals):
    """The chunk index (-1 where none) of every chunk coordinate in the boxes lo[b]..hi[b]
    (inclusive, (B, 3) each; ``count`` coordinates in all)."""
    out = np.empty(count, np.int64)
    k = 0
    for b in range(lo.shape[0]):
        for cx in range(lo[b, 0], hi[b, 0] + 1):
            for cy in range(lo[b, 1], hi[b, 1] + 1):
                for cz in range(lo[b, 2], hi[b, 2] + 1):
                    out[k] = find(cx, cy, cz, table_keys, table_vals)
                    k += 1
    return out


@njit(cache=True, inline="always")
def chunk_box(lo, cnt, box, c0, chunks, table_keys, table_vals):
    """The chunks of the support box (first cell ``lo``, ``cnt`` cells per axis) into
    ``chunks``, indexed from chunk ``c0`` (set here), unless ``box`` already holds them:
    neighbouring samples share chunks. The table is only read (thread safe)."""
    c0x, c0y, c0z = lo[0] >> CHUNK_SHIFT, lo[1] >> CHUNK_SHIFT, lo[2] >> CHUNK_SHIFT
    ncx = ((lo[0] + cnt[0] - 1) >> CHUNK_SHIFT) - c0x + 1
    ncy = ((lo[1] + cnt[1] - 1) >> CHUNK_SHIFT) - c0y + 1
    ncz = ((lo[2] + cnt[2] - 1) >> CHUNK_SHIFT) - c0z + 1
    c0[0], c0[1], c0[2] = c0x, c0y, c0z
    if same_box(box, c0x, c0y, c0z, ncx, ncy, ncz):
        return
    for a in range(ncx):
        for b in range(ncy):
            for c in range(ncz):
                chunks[a, b, c] = lookup(c0x + a, c0y + b, c0z + c, table_keys, table_vals)
    set_box(box, c0x, c0y, c0z, ncx, ncy, ncz)


@njit(cache=True)
def add_mass_to_cells(start, cells, d_alpha, d_beta, table_keys, table_vals, chunk_keys, n_chunks,
              alpha, beta):  # fmt: skip
    """Add per-cell mass (seeding from a prior map); resumes as :func:`insert_chunks` does."""
    for s in range(start, cells.shape[0]):
        ix, iy, iz = cells[s, 0], cells[s, 1], cells[s, 2]
        ci = find_or_insert(ix >> CHUNK_SHIFT, iy >> CHUNK_SHIFT, iz >> CHUNK_SHIFT,
                             table_keys, table_vals, chunk_keys, n_chunks)  # fmt: skip
        if ci < 0:
            return s
        alpha[ci, ix & 7, iy & 7, iz & 7] += d_alpha[s]
        beta[ci, ix & 7, iy & 7, iz & 7] += d_beta[s]
    return cells.shape[0]


@njit(cache=True)
def insert_keys(start, keys, slots, table_keys, table_vals, chunk_keys, n_chunks):
    """The index of each chunk of coordinates ``keys`` (k, 3) into ``slots``, inserting those
    not held; resumes as :func:`insert_chunks` does (the first key left when full)."""
    for s in range(start, keys.shape[0]):
        ci = find_or_insert(keys[s, 0], keys[s, 1], keys[s, 2], table_keys, table_vals,
                            chunk_keys, n_chunks)  # fmt: skip
        if ci < 0:
            return s
        slots[s] = ci
    return keys.shape[0]
