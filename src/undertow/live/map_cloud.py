"""The live view's map as a point cloud kept up to date chunk by chunk, so that a redraw costs
what changed since the last one, not the size of the map.

The online map (:class:`~undertow.mapping.grid.ChunkedGrid`) records the box every write may
touch (:meth:`~undertow.mapping.grid.ChunkedGrid.take_touched`). :class:`MapCloud` keeps, per
tile of TILE^3 chunks, the occupied cells of those chunks (posterior mean
E[theta] = alpha / (alpha + beta) > threshold, ``eq:mean_var``, alpha = alpha_0 + alpha mass as
:meth:`~undertow.mapping.mappers.Mapper.occupancy` forms it) as ready-to-send points: x, y, z
(float32, the cell centre (i + 1/2) res) and red, green, blue, alpha (uint8). An update reads
only the touched chunks and rebuilds only their tiles. The cloud sent is the tiles joined;
beyond ``budget`` points every k-th point of each tile is sent, k = ceil(points / budget), so
a message never carries more than about ``budget`` points (a day's map stays a message the app
draws at once). What is held is bounded too: once the chunks' points exceed HELD x ``budget``,
every chunk keeps every second of its points (and every chunk read later every ``stride``-th),
so a day's map holds at most about HELD x ``budget`` points, not the map's cells.

Colours are on a fixed scale, so that a chunk's colours do not depend on the rest of the map:
the mean from the threshold (blue) to 1 (red), or the variance
V = alpha beta / ((alpha + beta)^2 (alpha + beta + 1)) from 0 (blue) to the prior's
V_0 (red, as uncertain as no evidence).
"""

from __future__ import annotations

import numpy as np

from ..occupancy import OCCUPIED_THRESHOLD
from .view import scale_colors

#: the most points a map message carries (16 bytes each: 3.2 MB)
MAX_MAP_POINTS = 200_000
TILE = 4  # chunks per tile edge
HELD = 2  # the points held, at most about HELD x budget
POINT = np.dtype([("xyz", "<f4", 3), ("rgba", "u1", 4)])


class MapCloud:
    """``cloud = MapCloud(mapper)``; ``cloud.update()`` after writes; ``cloud.points()``.

    ``mapper``: a :class:`~undertow.mapping.mappers.Mapper` (its grid starts recording the
    boxes written from now on: the chunks it holds already are read once, at the first
    update); ``color_by``: "mean" or "variance"."""

    def __init__(self, mapper, threshold: float = OCCUPIED_THRESHOLD, color_by: str = "mean",
                 budget: int = MAX_MAP_POINTS) -> None:  # fmt: skip
        self.grid = mapper.grid
        self.alpha0, self.beta0 = float(mapper.alpha0), float(mapper.beta0)
        self.resolution = float(self.grid.resolution)
        self.threshold, self.color_by, self.budget = float(threshold), color_by, int(budget)
        self._chunks: dict[tuple, np.ndarray] = {}  # chunk key -> its points
        self._tiles: dict[tuple, np.ndarray | None] = {}  # tile key -> its points (None: stale)
        self.n_points = 0  # points held
        self.stride = 1  # each chunk holds every stride-th of its occupied cells
        self.chunks_read = 0  # (what the updates cost: chunks read, in all)
        self._first = True
        self.grid.track_touched()

    def update(self) -> int:
        """Read the chunks written since the last update (every chunk at the first); returns
        how many."""
        if self._first:
            idx, self._first = np.arange(self.grid.n_chunks), False
            self.grid.take_touched()
        else:
            idx = self.grid.take_touched()
        if idx.size == 0:
            return 0
        keys, alpha, beta = self.grid.chunk_mass(idx)
        points = self._points(keys, alpha, beta)
        for key, pts in zip(map(tuple, keys.tolist()), points, strict=True):
            pts = pts[:: self.stride].copy()  # (a copy: not a view keeping the update's array)
            old = self._chunks.pop(key, None)
            self.n_points += len(pts) - (0 if old is None else len(old))
            if len(pts):
                self._chunks[key] = pts
            self._tiles[tuple(c // TILE for c in key)] = None
        self.chunks_read += int(idx.size)
        while self.budget > 0 and self.n_points > HELD * self.budget:
            self._thin()
        return int(idx.size)

    def _thin(self) -> None:
        """Every chunk keeps every second of its points; every tile is redrawn."""
        self.stride *= 2
        self._chunks = {key: pts[::2].copy() for key, pts in self._chunks.items()}
        self.n_points = sum(len(pts) for pts in self._chunks.values())
        self._tiles = dict.fromkeys(self._tiles)

    def _points(self, keys, alpha, beta) -> list[np.ndarray]:
        """Each chunk's occupied cells as points (module docstring)."""
        a = alpha.astype(float) + self.alpha0
        b = beta.astype(float) + self.beta0
        massed = (alpha + beta) > 0  # the cells the map holds (OccupancyMap's cells)
        mean = a / (a + b)
        occupied = massed & (mean > self.threshold)
        c, i, j, k = np.nonzero(occupied)
        if self.color_by == "variance":
            s = a + b
            a0, b0 = self.alpha0, self.beta0
            v0 = a0 * b0 / ((a0 + b0) ** 2 * (a0 + b0 + 1.0))
            value = (a * b / (s * s * (s + 1.0)))[c, i, j, k] / v0
        else:
            value = (mean[c, i, j, k] - self.threshold) / (1.0 - self.threshold)
        cells = keys[c] * alpha.shape[1] + np.stack([i, j, k], axis=1)
        pts = np.empty(c.size, POINT)
        pts["xyz"] = (cells + 0.5) * self.resolution
        pts["rgba"] = scale_colors(value)
        bounds = np.searchsorted(c, np.arange(len(keys) + 1))
        return [pts[bounds[n] : bounds[n + 1]] for n in range(len(keys))]

    def points(self) -> np.ndarray:
        """The cloud to send (module docstring): every tile's points, every k-th beyond the
        budget."""
        step = max(-(-self.n_points // self.budget), 1) if self.budget > 0 else 1
        parts = []
        for tile in list(self._tiles):
            pts = self._tiles[tile]
            if pts is None:
                pts = self._tile_points(tile)
                if pts is None:
                    del self._tiles[tile]
                    continue
                self._tiles[tile] = pts
            parts.append(pts[::step] if step > 1 else pts)
        return np.concatenate(parts) if parts else np.zeros(0, POINT)

    def _tile_points(self, tile) -> np.ndarray | None:
        tx, ty, tz = tile
        parts = [self._chunks[key] for key in _tile_keys(tx, ty, tz) if key in self._chunks]
        return np.concatenate(parts) if parts else None


def _tile_keys(tx: int, ty: int, tz: int):
    for a in range(TILE):
        for b in range(TILE):
            for c in range(TILE):
                yield (tx * TILE + a, ty * TILE + b, tz * TILE + c)
