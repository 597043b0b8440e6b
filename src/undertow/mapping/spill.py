"""Chunks of the map moved out of memory: the grid's resident budget
(:class:`~undertow.mapping.grid.ChunkedGrid`, ``resident_bytes``).

A survey of hours maps ground it will not see again for a while. When the grid holds more
chunks than its budget, it hands the chunks of the tiles (TILE^3 chunks) farthest from its
latest write to a :class:`ChunkSpill`: their evidence mass (alpha and beta, CHUNK^3 float32 each:
4 kB a chunk) goes to fixed-size records of an unnamed temporary file (``tempfile.TemporaryFile``:
the file has no name, so nothing is left behind when the process ends, by a crash or not), their
coordinates and birth numbers (the order in which the grid created them) stay in memory, 32 bytes
a chunk, indexed by tile. Before a write the grid takes back every spilled tile the write may
reach, so a chunk is always in one place and its sums are formed in the same order as if it had
never left: the map is the same bit for bit. Records freed by a take are reused by later puts,
so the file is as large as the most chunks spilled at once.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from .chunks import CHUNK

TILE = 4  # chunks per tile edge: the unit spilled and taken back
RECORD_FLOATS = 2 * CHUNK**3  # alpha then beta of one chunk, float32
RECORD_BYTES = 4 * RECORD_FLOATS
INDEX_BYTES = 32  # per spilled chunk in memory: its key (3 int64) and birth (int64)


def tiles_of(keys: np.ndarray) -> np.ndarray:
    """Tile coordinates (k, 3) of chunk coordinates ``keys`` (k, 3) (floor division)."""
    return np.floor_divide(keys, TILE)


class ChunkSpill:
    """The spilled chunks (module docstring). ``directory``: where the temporary file is
    created (None: the system's temporary directory)."""

    def __init__(self, directory=None) -> None:
        self.directory = directory
        self._file = None
        self._free: list[int] = []  # record slots to reuse
        self._slots = 0  # records in the file
        self._tiles: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._count = 0
        self.puts = 0  # chunks written, in all
        self.takes = 0  # chunks read back before a write, in all

    def __len__(self) -> int:
        return self._count

    @property
    def index_bytes(self) -> int:
        """Memory the index of the spilled chunks takes (32 bytes a chunk)."""
        return self._count * INDEX_BYTES

    @property
    def file_bytes(self) -> int:
        return self._slots * RECORD_BYTES

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def put(self, keys: np.ndarray, births: np.ndarray, alpha: np.ndarray,
            beta: np.ndarray) -> None:  # fmt: skip
        """Spill chunks: coordinates (k, 3), births (k,), mass (k, C, C, C) each; every chunk of
        a tile the grid spills at once, so no tile is spilled twice without a take between."""
        if len(keys) == 0:
            return
        slots = self._new_slots(len(keys))
        records = np.concatenate([alpha.reshape(len(keys), -1), beta.reshape(len(keys), -1)],
                                 axis=1).astype(np.float32, copy=False)  # fmt: skip
        self._write(slots, records)
        tiles = tiles_of(keys)
        order = np.lexsort(tiles.T[::-1])
        bounds = np.flatnonzero(np.any(np.diff(tiles[order], axis=0) != 0, axis=1)) + 1
        for part in np.split(order, bounds):
            tile = tuple(tiles[part[0]].tolist())
            if tile in self._tiles:
                raise RuntimeError(f"tile {tile} spilled twice")  # the grid's invariant
            self._tiles[tile] = (keys[part].copy(), births[part].copy(), slots[part])
        self._count += len(keys)
        self.puts += len(keys)

    def tiles_in(self, lo: np.ndarray, hi: np.ndarray) -> list[tuple]:
        """The spilled tiles that hold chunks in the chunk box lo..hi (inclusive, (3,))."""
        if not self._tiles:
            return []
        t_lo, t_hi = np.floor_divide(lo, TILE), np.floor_divide(hi, TILE)
        if int(np.prod(t_hi - t_lo + 1)) <= len(self._tiles):
            axes = [range(int(a), int(b) + 1) for a, b in zip(t_lo, t_hi, strict=True)]
            return [(x, y, z) for x in axes[0] for y in axes[1] for z in axes[2]
                    if (x, y, z) in self._tiles]  # fmt: skip
        a, b = t_lo.tolist(), t_hi.tolist()
        return [t for t in self._tiles if all(a[i] <= t[i] <= b[i] for i in range(3))]

    def take(self, tiles: list[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(keys, births, alpha, beta) of the chunks of ``tiles``, removed from the spill."""
        parts = [self._tiles.pop(t) for t in tiles]
        keys = np.concatenate([p[0] for p in parts])
        births = np.concatenate([p[1] for p in parts])
        slots = np.concatenate([p[2] for p in parts])
        alpha, beta = self._read(slots)
        self._free.extend(slots.tolist())
        self._count -= len(keys)
        self.takes += len(keys)
        return keys, births, alpha, beta

    def index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(keys (k, 3), births (k,), record slots (k,)) of every spilled chunk."""
        parts = list(self._tiles.values())
        if not parts:
            return np.zeros((0, 3), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
        return tuple(np.concatenate([p[i] for p in parts]) for i in range(3))

    def read(self, slots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(alpha, beta) (k, C, C, C) float32 of the records ``slots``, left in the spill."""
        return self._read(np.asarray(slots, np.int64))

    def _new_slots(self, k: int) -> np.ndarray:
        reuse = min(k, len(self._free))
        slots = [self._free.pop() for _ in range(reuse)]
        slots.extend(range(self._slots, self._slots + k - reuse))
        self._slots += k - reuse
        return np.asarray(slots, np.int64)

    def _fd(self) -> int:
        if self._file is None:
            self._file = tempfile.TemporaryFile(prefix="undertow-map-", dir=self.directory)
        return self._file.fileno()

    def _write(self, slots: np.ndarray, records: np.ndarray) -> None:
        fd = self._fd()
        for s, start, n in _runs(slots):
            os.pwrite(fd, records[start : start + n].tobytes(), int(s) * RECORD_BYTES)

    def _read(self, slots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out = np.empty((len(slots), RECORD_FLOATS), np.float32)
        fd = self._fd()
        for s, start, n in _runs(slots):
            data = os.pread(fd, n * RECORD_BYTES, int(s) * RECORD_BYTES)
            if len(data) != n * RECORD_BYTES:
                raise OSError(f"map spill file: short read at record {s}")
            out[start : start + n] = np.frombuffer(data, np.float32).reshape(n, -1)
        half = CHUNK**3
        shape = (len(slots), CHUNK, CHUNK, CHUNK)
        return out[:, :half].reshape(shape), out[:, half:].reshape(shape)


def _runs(slots: np.ndarray):
    """(first slot, first position, length) of each run of consecutive slots in ``slots``."""
    if len(slots) == 0:
        return
    breaks = np.flatnonzero(np.diff(slots) != 1) + 1
    starts = np.concatenate([[0], breaks])
    ends = np.concatenate([breaks, [len(slots)]])
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        yield slots[a], a, b - a
