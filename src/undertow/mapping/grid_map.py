"""A map larger than memory, read out of its grid part by part: :class:`GridOccupancy`.

The grid keeps its chunks beyond the resident budget on disk (:mod:`undertow.mapping.spill`),
but an :class:`~undertow.occupancy.OccupancyMap` holds every cell in memory (40 bytes a cell:
cells int64 x 3, alpha and beta float64), and a day-long survey has as many cells as the ground
it covered. :class:`GridOccupancy` answers what the map's outputs and record need without
forming it: its length, its occupied cells, ``map.npz`` and ``map.ply`` written part by part
(:func:`~undertow.io.npz_parts.write_npz_parts`, :func:`~undertow.io.ply.write_ply_parts`),
with the same arrays and bytes as :meth:`OccupancyMap.save
<undertow.occupancy.OccupancyMap.save>` and :func:`~undertow.io.ply.write_map_ply` of the map
formed whole (alpha_* = alpha_0 + alpha mass, eq:alpha_param; the mean and variance of
eq:mean_var per cell). :meth:`load` forms it whole when it fits.
"""

from __future__ import annotations

import json

import numpy as np

from ..io.npz_parts import write_npz_parts
from ..io.ply import write_ply_parts
from ..occupancy import OCCUPIED_THRESHOLD, OccupancyMap, column_arrays


class GridOccupancy:
    """The occupancy map of ``mapper`` (a :class:`~undertow.mapping.mappers.Mapper`), read out
    part by part (module docstring); ``metadata`` as an OccupancyMap's."""

    def __init__(self, mapper, metadata: dict) -> None:
        self._mapper = mapper
        self.resolution = float(mapper.resolution)
        self.alpha0, self.beta0 = float(mapper.alpha0), float(mapper.beta0)
        self.metadata = dict(metadata)
        self._len: int | None = None
        self._occupied: dict[float, int] = {}

    def parts(self):
        """(cells (k, 3), alpha_* (k,), beta_* (k,)) part by part, in the whole map's order."""
        for cells, a, b in self._mapper.grid.iter_cells():
            yield cells, self.alpha0 + a, self.beta0 + b

    def __len__(self) -> int:
        if self._len is None:
            self.n_occupied(float(self.metadata.get("occupied_threshold", OCCUPIED_THRESHOLD)))
        return self._len

    def n_occupied(self, threshold: float = OCCUPIED_THRESHOLD) -> int:
        """Cells with mean occupancy E[theta] = alpha / (alpha + beta) > ``threshold`` (the
        cells counted in the same pass)."""
        if threshold not in self._occupied:
            cells = occupied = 0
            for _, a, b in self.parts():
                cells += len(a)
                occupied += int(np.count_nonzero(a / (a + b) > threshold))
            self._len, self._occupied[threshold] = cells, occupied
        return self._occupied[threshold]

    def load(self) -> OccupancyMap:
        """The map formed whole in memory."""
        whole = self._mapper.occupancy()
        return OccupancyMap(whole.cells, whole.alpha, whole.beta, self.resolution, self.alpha0,
                            self.beta0, self.metadata, whole.columns)  # fmt: skip

    def columns(self):
        """The map's column sums (:class:`~undertow.occupancy.ColumnStats`; a ``tpu`` map's,
        else None), whole."""
        return self._mapper.column_stats()

    def save(self, path):
        """``map.npz`` as :meth:`OccupancyMap.save <undertow.occupancy.OccupancyMap.save>`,
        written part by part."""
        n = len(self)

        def column(i):
            return lambda: (part[i] for part in self.parts())

        streamed = {"cells": (np.int64, (n, 3), column(0)),
                    "alpha": (np.float64, (n,), column(1)),
                    "beta": (np.float64, (n,), column(2))}  # fmt: skip
        small = {"resolution": np.array(self.resolution), "alpha0": np.array(self.alpha0),
                 "beta0": np.array(self.beta0),
                 "metadata": np.array(json.dumps(self.metadata, default=str)),
                 **column_arrays(self.columns())}  # fmt: skip
        return write_npz_parts(path, streamed, small)

    def write_ply(self, path, threshold: float = OCCUPIED_THRESHOLD):
        """``map.ply`` as :func:`~undertow.io.ply.write_map_ply`, written part by part."""

        def parts():
            for cells, a, b in self.parts():
                mean = a / (a + b)
                keep = mean > threshold
                a, b, s = a[keep], b[keep], a[keep] + b[keep]
                yield ((cells[keep] + 0.5) * self.resolution,
                       {"mean": mean[keep], "variance": a * b / (s * s * (s + 1.0))})  # fmt: skip

        return write_ply_parts(path, self.n_occupied(threshold), ["mean", "variance"], parts())
