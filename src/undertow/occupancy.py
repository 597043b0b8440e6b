"""The occupancy map, the hand-off type between mapping and what reads a map (io, evaluation,
report): a posterior Beta(alpha_*, beta_*) per mapped cell.

Cell index i = floor(p / res), centre (i + 1/2) res. :class:`OccupancyMap` answers
``eq:mean_var`` per cell:
E[theta_*] = alpha_* / (alpha_* + beta_*),
V[theta_*] = alpha_* beta_* / ((alpha_* + beta_*)^2 (alpha_* + beta_* + 1)).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._util.atomic import atomic_path
from .errors import DataError, ReaderError

#: a cell is occupied when its mean occupancy exceeds this (the paper evaluates maps at 0.5)
OCCUPIED_THRESHOLD = 0.5
#: what a map file is, for messages about a wrong kind of file given as one
MAP_FILE = "a map.npz written by `undertow map` (or its folder)"


#: what each column of :attr:`ColumnStats.sums` holds, per (x, y) column of the map
COLUMN_SUMS = ("weight", "weight_var_v", "weight_var_x", "weight_var_y", "weight_var_r",
               "weight2_var_r", "weight_sonar_r2", "weight_dx2", "weight_dy2",
               "weight_var_lattice")  # fmt: skip
#: the sums of the maps written before the last six (those read as zeros)
LEGACY_SUMS = 4
#: the values of :attr:`ColumnStats.carve` per column: two free intervals' bottoms and tops
CARVE_FIELDS = 4


@dataclass(frozen=True, eq=False)
class ColumnStats:
    """Per (x, y) column (index i = floor(x / res), j = floor(y / res)): the hit evidence it
    received and that evidence's uncertainties, the sums of :data:`COLUMN_SUMS` (W, V, X, Y,
    R, U, Q, D_x, D_y, L of :mod:`undertow.mapping.depth_std`): sum_i w_i, and sum_i w_i of
    sigma_v,i^2, s_x,i^2, s_y,i^2, s_r,i^2, then sum_i w_i^2 s_r,i^2, and sum_i w_i of r_s,i^2,
    dx_i^2, dy_i^2, c_i (w_i the kernel-weighted mass of hit i in the column, sigma_v,i its
    vertical standard deviation, s_x,i and s_y,i its horizontal ones, s_r,i the share of
    sigma_v,i that is its range's own noise, independent from hit to hit, r_s,i its range when
    a sonar's, else 0, dx_i and dy_i the column centre's offset from it, c_i the variance of
    the cells the mapper put it on; sums of :data:`LEGACY_SUMS` columns, a map written before
    the last six, read them as zeros). ``carve`` (K, 4) or None: the two
    deepest depth intervals a sonar's cone found free in the column, F_1, T_1, F_2, T_2 (m, z
    down; F_1 >= F_2 the intervals' bottoms, T their tops; NaN where fewer;
    :mod:`undertow.mapping.carve`). Written by the ``tpu`` mapper
    (:mod:`undertow.mapping.columns`); read by
    :func:`~undertow.mapping.surface.evidence_surface`."""

    cells: np.ndarray
    sums: np.ndarray
    carve: np.ndarray | None = None

    def __post_init__(self) -> None:
        cells = np.asarray(self.cells, dtype=np.int64).reshape(-1, 2)
        sums = np.asarray(self.sums, dtype=float)
        if sums.ndim == 2 and sums.shape[1] == LEGACY_SUMS:
            sums = np.hstack([sums, np.zeros((len(sums), len(COLUMN_SUMS) - LEGACY_SUMS))])
        sums = sums.reshape(-1, len(COLUMN_SUMS))
        if len(cells) != len(sums):
            raise DataError(f"ColumnStats: {len(cells)} columns but {len(sums)} rows of sums")
        object.__setattr__(self, "cells", cells)
        object.__setattr__(self, "sums", sums)
        if self.carve is not None:
            carve = np.asarray(self.carve, dtype=float).reshape(-1, CARVE_FIELDS)
            if len(carve) != len(cells):
                raise DataError(f"ColumnStats: {len(cells)} columns but {len(carve)} carve rows")
            object.__setattr__(self, "carve", carve)

    def __len__(self) -> int:
        return int(self.cells.shape[0])

    @classmethod
    def merged(cls, parts) -> ColumnStats:
        """The sums of several ColumnStats added column by column (tiles, a prior)."""
        parts = [p for p in parts if p is not None and len(p)]
        if not parts:
            return cls(np.zeros((0, 2), np.int64), np.zeros((0, len(COLUMN_SUMS))))
        cells = np.concatenate([p.cells for p in parts])
        sums = np.concatenate([p.sums for p in parts])
        unique, inverse = np.unique(cells, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        out = np.zeros((len(unique), sums.shape[1]))
        np.add.at(out, inverse, sums)
        if all(p.carve is None for p in parts):
            return cls(unique, out)
        carve = np.concatenate([np.full((len(p), CARVE_FIELDS), np.nan) if p.carve is None
                                else p.carve for p in parts])  # fmt: skip
        return cls(unique, out, deepest_two(carve, inverse, len(unique)))


def column_keys(ij: np.ndarray) -> np.ndarray:
    """One int64 per (i, j) column index pair ((n, 2+); i and j within int32), equal only for
    equal pairs (not ordered as (i, j))."""
    ij = np.asarray(ij, dtype=np.int64)
    return (ij[:, 0] << 32) + (ij[:, 1] & 0xFFFFFFFF)


def deepest_two(carve: np.ndarray, group: np.ndarray, groups: int) -> np.ndarray:
    """Per group of rows of ``carve`` ((n, 4): F_1, T_1, F_2, T_2, NaN where none; ``group``
    (n,) the row's group in [0, groups)), the two intervals with the deepest bottoms F among
    all the rows' intervals: (groups, 4), as :attr:`ColumnStats.carve`."""
    pairs = np.concatenate([carve[:, :2], carve[:, 2:]])
    gid = np.concatenate([group, group])
    ok = np.isfinite(pairs[:, 0])
    pairs, gid = pairs[ok], gid[ok]
    order = np.lexsort((-pairs[:, 0], gid))
    pairs, gid = pairs[order], gid[order]
    index = np.arange(len(gid))
    first = np.ones(len(gid), bool)
    first[1:] = gid[1:] != gid[:-1]
    rank = index - np.maximum.accumulate(np.where(first, index, 0))
    out = np.full((groups, CARVE_FIELDS), np.nan)
    for k in (0, 1):
        sel = rank == k
        out[gid[sel], 2 * k : 2 * k + 2] = pairs[sel]
    return out


@dataclass(frozen=True, eq=False)
class OccupancyMap:
    """Posterior Beta(alpha, beta) per mapped cell; ``alpha``/``beta`` include the priors
    ``alpha0``/``beta0`` (kept to recover the evidence alpha - alpha0, beta - beta0).
    ``columns``: the hits' uncertainties per (x, y) column (:class:`ColumnStats`, the ``tpu``
    mapper's; None for the others and for maps written before them)."""

    cells: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    resolution: float
    alpha0: float
    beta0: float
    metadata: dict = field(default_factory=dict)
    columns: ColumnStats | None = None

    def __post_init__(self) -> None:
        cells = np.asarray(self.cells, dtype=np.int64).reshape(-1, 3)
        alpha = np.asarray(self.alpha, dtype=float).reshape(-1)
        beta = np.asarray(self.beta, dtype=float).reshape(-1)
        if not (len(cells) == alpha.size == beta.size):
            raise DataError(
                f"OccupancyMap: {len(cells)} cells but {alpha.size} alpha / {beta.size} beta"
            )
        object.__setattr__(self, "cells", cells)
        object.__setattr__(self, "alpha", alpha)
        object.__setattr__(self, "beta", beta)

    def __len__(self) -> int:
        return int(self.cells.shape[0])

    @property
    def centres(self) -> np.ndarray:
        """Cell centres (M, 3), m: (i + 1/2) res."""
        return (self.cells + 0.5) * self.resolution

    @property
    def mean(self) -> np.ndarray:
        """``eq:mean_var``: E[theta_*] = alpha_* / (alpha_* + beta_*)."""
        return self.alpha / (self.alpha + self.beta)

    @property
    def variance(self) -> np.ndarray:
        """``eq:mean_var``: V = alpha beta / ((alpha + beta)^2 (alpha + beta + 1))."""
        s = self.alpha + self.beta
        return self.alpha * self.beta / (s * s * (s + 1.0))

    def select(self, mask) -> OccupancyMap:
        """The map restricted to the cells where ``mask`` is true."""
        mask = np.asarray(mask)
        return dataclasses.replace(
            self, cells=self.cells[mask], alpha=self.alpha[mask], beta=self.beta[mask]
        )

    def occupied(self, threshold: float = OCCUPIED_THRESHOLD) -> OccupancyMap:
        """Cells with mean occupancy > threshold."""
        return self.select(self.mean > threshold)

    def n_occupied(self, threshold: float = OCCUPIED_THRESHOLD) -> int:
        """How many cells have mean occupancy > threshold."""
        return int(np.count_nonzero(self.mean > threshold))

    def points(self, threshold: float = OCCUPIED_THRESHOLD) -> np.ndarray:
        """Occupied cell centres (K, 3): the map's point cloud for evaluation (C2C)."""
        return self.occupied(threshold).centres

    def slice(self, z_min=None, z_max=None, *, axis: int | None = None, index=None):
        """Cells with centre z in [z_min, z_max], or the index plane cells[:, axis] == index."""
        if axis is not None:
            if axis not in (0, 1, 2) or index is None:
                raise DataError("OccupancyMap.slice: axis must be 0, 1 or 2 and index given")
            return self.select(self.cells[:, axis] == int(index))
        z = self.centres[:, 2]
        mask = np.ones(len(self), bool)
        if z_min is not None:
            mask &= z >= z_min
        if z_max is not None:
            mask &= z <= z_max
        return self.select(mask)

    def column_max(self) -> OccupancyMap:
        """Per (x, y) column, the one cell of highest mean occupancy (a seafloor height map)."""
        if len(self) == 0:
            return self
        order = np.lexsort((-self.mean, self.cells[:, 1], self.cells[:, 0]))
        xy = self.cells[order, :2]
        first = np.ones(len(order), bool)
        first[1:] = np.any(xy[1:] != xy[:-1], axis=1)
        return self.select(order[first])

    def save(self, path: str | Path) -> Path:
        """Write the map as ``.npz`` (atomic: temp file then rename)."""
        path = Path(path)
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(
                fh, cells=self.cells, alpha=self.alpha, beta=self.beta,
                resolution=self.resolution, alpha0=self.alpha0, beta0=self.beta0,
                metadata=np.array(json.dumps(self.metadata, default=str)),
                **column_arrays(self.columns),
            )  # fmt: skip
        return path

    @classmethod
    def load(cls, path: str | Path) -> OccupancyMap:
        """Read a map written by :meth:`save` (a folder means FOLDER/map.npz)."""
        path = Path(path)
        if path.is_dir():
            path = path / "map.npz"
        wrong = not_an_npz(path, MAP_FILE)
        if wrong:
            raise ReaderError(wrong)
        try:
            with np.load(path, allow_pickle=False) as d:
                return cls(
                    cells=d["cells"], alpha=d["alpha"], beta=d["beta"],
                    resolution=float(d["resolution"]), alpha0=float(d["alpha0"]),
                    beta0=float(d["beta0"]), metadata=json.loads(str(d["metadata"])),
                    columns=stored_columns(d),
                )  # fmt: skip
        except FileNotFoundError as exc:
            raise ReaderError(f"{path}: no such map file") from exc
        except (KeyError, ValueError, OSError, DataError) as exc:
            raise ReaderError(f"{path}: not an undertow map ({exc})") from exc


def column_arrays(columns: ColumnStats | None) -> dict:
    """The arrays ``map.npz`` stores a map's :class:`ColumnStats` in (none without them)."""
    if columns is None:
        return {}
    carve = {} if columns.carve is None else {"column_carve": columns.carve}
    return {"column_cells": columns.cells, "column_sums": columns.sums, **carve}


def stored_columns(arrays) -> ColumnStats | None:
    """The :class:`ColumnStats` of a map's or a tile's stored arrays (an open ``.npz``), None
    when it has none."""
    if "column_cells" not in arrays:
        return None
    carve = arrays["column_carve"] if "column_carve" in arrays else None
    return ColumnStats(arrays["column_cells"], arrays["column_sums"], carve)


_KINDS = {
    ".ply": "a PLY point cloud", ".tum": "a TUM trajectory", ".txt": "a text file",
    ".yaml": "a YAML file", ".yml": "a YAML file", ".json": "a JSON file", ".bag": "a ROS bag",
    ".mcap": "a ROS 2 bag", ".db3": "a ROS 2 bag",
}  # fmt: skip


def not_an_npz(path: str | Path, expected: str) -> str | None:
    """None if ``path`` is a missing file or a zip archive (what ``.npz`` files are), else a
    one-line message saying what it looks like and what was ``expected`` (instead of numpy's
    "pickled data" error for a text or PLY file)."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
    except FileNotFoundError:
        return None
    except IsADirectoryError:
        return f"{path}: is a folder; expected {expected}"
    except OSError:
        return None  # let the reader report it
    if magic == b"PK\x03\x04":
        return None
    kind = _KINDS.get(path.suffix.lower(), "not an .npz archive")
    if magic == b"ply\n" or magic[:3] == b"ply":
        kind = "a PLY point cloud"
    return f"{path}: {kind}, expected {expected}"
