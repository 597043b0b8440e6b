"""A trajectory too long for memory: the filter's states on disk in chunks, read back lazily.

Three pieces, for a log of any length (a day-long log at 100 states/s has 8.6 million states;
their 18x18 covariances alone are 22 GB):

- :class:`TrajectoryStore`: the working store the filter appends to and the smoother rewrites
  backward, a folder of three raw float64 files (``t.f8`` (N,), ``x.f8`` (N, 18), ``P.f8``
  (N, 18, 18), C order, little-endian): appending is a write at the end, a chunk anywhere is
  a read at its offset (plain reads: a memory map would count every page it touched in the
  process's resident set), and only the chunks in use are in memory;
- :func:`write_npz`: the user's ``trajectory.npz`` streamed from such chunks, the same archive
  :meth:`~undertow.trajectory.Trajectory.save_npz` writes (the same members, dtypes and
  ``.npy`` headers; each member deflated as a stream), so
  :meth:`~undertow.trajectory.Trajectory.load_npz` reads either;
- :func:`npz_rows` and :class:`PoseTrack`: a ``trajectory.npz`` read chunk by chunk (each
  member decompressed as a stream), keeping only what a consumer needs: the mapper takes the
  times, poses and position variances (10 of the 342 numbers of a state).

Why raw files and not zarr: the store is a scratch space for one forward and one backward
pass (uncompressed, so that a chunk is a slice with no codec), and the published format stays
the ``trajectory.npz`` every reader of undertow already takes; no new dependency.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._util.atomic import atomic_path
from ._util.plain import to_plain
from .errors import ReaderError
from .trajectory import (
    ORIENTATION,
    POSITION,
    STATE_NAMES,
    Trajectory,
    check_npz,
    wave_arrays,
)

N_STATE = len(STATE_NAMES)
#: the shape of one state's row in each stored array
ROW_SHAPES = {"t": (), "x": (N_STATE,), "P": (N_STATE, N_STATE)}
#: states per chunk read or written at once (about 26 MB of covariances)
CHUNK_STATES = 10_000


class TrajectoryStore:
    """States (t, x, P) in a folder of raw float64 files (module doc), appended in time order.

    ``TrajectoryStore(folder)`` starts an empty store (the folder is created; files left there
    are replaced). :meth:`read` reads a chunk, :meth:`rewrite` overwrites one (the smoother),
    :meth:`chunks` gives the chunk bounds."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.n = 0
        for name in ROW_SHAPES:
            self._path(name).write_bytes(b"")

    def _path(self, name: str) -> Path:
        return self.folder / f"{name}.f8"

    def __len__(self) -> int:
        return self.n

    def append(self, t: np.ndarray, x: np.ndarray, P: np.ndarray) -> None:
        """Append states (k,), (k, 18), (k, 18, 18) at the end."""
        k = len(t)
        for name, value in (("t", t), ("x", x), ("P", P)):
            a = np.ascontiguousarray(value, dtype="<f8")
            if a.shape != (k, *ROW_SHAPES[name]):
                raise ValueError(f"TrajectoryStore: {name} {a.shape} for {k} states")
            with open(self._path(name), "ab") as fh:
                fh.write(a.tobytes())
        self.n += k

    def read(self, k0: int = 0, k1: int | None = None) -> tuple[np.ndarray, ...]:
        """(t, x, P) of states k0..k1-1 (default: to the end), read from the files (plain
        reads, not a memory map: the pages read stay in the page cache, not in this process)."""
        return tuple(self.read_array(name, k0, k1) for name in ROW_SHAPES)

    def read_array(self, name: str, k0: int = 0, k1: int | None = None) -> np.ndarray:
        """Rows k0..k1-1 of the array ``name`` (t, x or P)."""
        k1 = self.n if k1 is None else min(k1, self.n)
        m, shape = max(k1 - k0, 0), ROW_SHAPES[name]
        row = int(np.prod(shape, dtype=np.int64))
        a = np.fromfile(self._path(name), dtype="<f8", count=m * row, offset=k0 * row * 8)
        return a.reshape((m, *shape))

    def rewrite(self, k0: int, x: np.ndarray, P: np.ndarray) -> None:
        """Overwrite the states x and P from row k0 on (the smoother's backward pass)."""
        for name, value in (("x", x), ("P", P)):
            a = np.ascontiguousarray(value, dtype="<f8")
            if k0 < 0 or k0 + len(a) > self.n or a.shape[1:] != ROW_SHAPES[name]:
                raise ValueError(f"TrajectoryStore: {name} rows {k0}..{k0 + len(a)} of {self.n}")
            with open(self._path(name), "r+b") as fh:
                fh.seek(k0 * a[0].size * 8 if len(a) else 0)
                fh.write(a.tobytes())

    def chunks(self, size: int = CHUNK_STATES, reverse: bool = False) -> list[tuple[int, int]]:
        """The bounds [k0, k1) of consecutive chunks of at most ``size`` states."""
        bounds = [(k, min(k + size, self.n)) for k in range(0, self.n, size)]
        return bounds[::-1] if reverse else bounds

    def trajectory(self, variant: str = "", metadata: dict | None = None) -> Trajectory:
        """The whole store as an in-memory Trajectory (for a store that fits)."""
        t, x, P = self.read()
        return Trajectory(t, x, P, variant=variant, metadata=metadata or {})

    def remove(self) -> None:
        """Delete the folder and its files."""
        shutil.rmtree(self.folder, ignore_errors=True)


def write_npz(path: str | Path, store: TrajectoryStore, variant: str, metadata: dict,
              chunk: int = CHUNK_STATES) -> Path:  # fmt: skip
    """``trajectory.npz`` of the states in ``store`` (module doc), written chunk by chunk:
    the members of :meth:`Trajectory.save_npz` in its order, t, x and P streamed (their
    ``.npy`` header first, from the store's length, then the chunks' bytes); atomic."""
    path = Path(path)
    small = {
        "state_names": np.array(STATE_NAMES),
        "variant": np.array(variant),
        "metadata_json": np.array(json.dumps(to_plain(metadata), default=str)),
        **wave_arrays(metadata),
    }
    with (
        atomic_path(path) as tmp,
        zipfile.ZipFile(tmp, mode="w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as zf,
    ):
        for name, shape in ROW_SHAPES.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as fid:
                header = {"descr": "<f8", "fortran_order": False, "shape": (len(store), *shape)}
                np.lib.format.write_array_header_1_0(fid, header)
                for k0, k1 in store.chunks(chunk):
                    fid.write(store.read_array(name, k0, k1).tobytes())
        for name, value in small.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as fid:
                np.lib.format.write_array(fid, value, allow_pickle=False)
    return path


def npz_path(path: str | Path) -> Path:
    """``path``, or ``path/trajectory.npz`` for a folder, checked to be a zip archive."""
    path = Path(path)
    if path.is_dir():
        path = path / "trajectory.npz"
    check_npz(path)
    return path


def npz_rows(path: str | Path, name: str, chunk: int = CHUNK_STATES) -> Iterator[np.ndarray]:
    """The rows of member ``name`` (t, x or P) of a trajectory.npz, ``chunk`` at a time,
    decompressed as a stream (never the whole array in memory)."""
    path = npz_path(path)
    try:
        with zipfile.ZipFile(path) as zf, zf.open(f"{name}.npy") as fp:
            version = np.lib.format.read_magic(fp)
            read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                    else np.lib.format.read_array_header_2_0)  # fmt: skip
            shape, fortran, dtype = read(fp)
            if fortran or len(shape) == 0:
                raise ValueError(f"{name} is not a C-order array of rows")
            row = int(np.prod(shape[1:], dtype=np.int64))
            for k0 in range(0, shape[0], chunk):
                m = min(chunk, shape[0] - k0)
                data = fp.read(m * row * dtype.itemsize)
                yield np.frombuffer(data, dtype=dtype).reshape((m, *shape[1:]))
    except (KeyError, ValueError, OSError, zipfile.BadZipFile) as exc:
        raise ReaderError(f"{path}: cannot read {name} ({exc})") from exc


def npz_header(path: str | Path) -> tuple[str, dict]:
    """(variant, metadata) of a trajectory.npz, without reading its arrays."""
    path = npz_path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            metadata = json.loads(str(data["metadata_json"])) if "metadata_json" in data else {}
            return str(data["variant"]), metadata if isinstance(metadata, dict) else {}
    except (KeyError, ValueError, OSError, zipfile.BadZipFile) as exc:
        raise ReaderError(f"{path}: cannot read the trajectory's metadata ({exc})") from exc


@dataclass(frozen=True, eq=False)
class PoseTrack:
    """What the mapper reads of a trajectory: times (N,), positions and roll-pitch-yaw (N, 3)
    and the per-axis position variance (N, 3) (the diagonal of P's position block), with the
    variant and metadata; the same values as the Trajectory's properties of those names."""

    t: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    position_variance: np.ndarray
    variant: str = ""
    metadata: dict = field(default_factory=dict)

    #: roll-pitch-yaw unwrapped along the whole track (numpy.unwrap), when known: a window of
    #: the track carries its part, so that its angles are those of the whole, not re-unwrapped
    unwrapped_orientation: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.size)

    def window(self, t0: float, t1: float) -> PoseTrack:
        """The states from the last one at or before ``t0`` to the first at or after ``t1``
        (the whole track's ends where these fall outside it): interpolation at any time in
        [t0, t1] gives the whole track's values, and a time outside the track is outside the
        window too. Its angles are the whole track's unwrapped ones (computed once)."""
        if self.unwrapped_orientation is None:  # column by column: a day's temporaries a third
            ang = np.empty_like(self.orientation)
            for j in range(ang.shape[1]):
                ang[:, j] = np.unwrap(self.orientation[:, j])
            object.__setattr__(self, "unwrapped_orientation", ang)
        i0 = max(int(np.searchsorted(self.t, t0, side="right")) - 1, 0)
        i1 = min(int(np.searchsorted(self.t, t1, side="left")) + 1, len(self))
        part = slice(i0, max(i1, i0 + 1))
        return PoseTrack(self.t[part], self.position[part], self.orientation[part],
                         self.position_variance[part], self.variant, self.metadata,
                         self.unwrapped_orientation[part])  # fmt: skip

    @classmethod
    def from_npz(cls, path: str | Path, chunk: int = CHUNK_STATES) -> PoseTrack:
        """The pose track of a trajectory.npz, its P read chunk by chunk (module doc)."""
        variant, metadata = npz_header(path)
        # each chunk's columns copied into arrays of the track's length (10 floats a state):
        # neither a list of chunks joined at the end nor a view (a slice, einsum's diagonal)
        # that would keep its whole chunk (18 x 18 floats a state for P) alive
        t = np.concatenate([*npz_rows(path, "t", chunk), np.empty(0)])
        n = len(t)
        position, orientation, var = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
        k = 0
        for x in npz_rows(path, "x", chunk):
            if k + len(x) > n:
                break
            position[k : k + len(x)] = x[:, POSITION]
            orientation[k : k + len(x)] = x[:, ORIENTATION]
            k += len(x)
        j = 0
        for P in npz_rows(path, "P", chunk):
            if j + len(P) > n:
                break
            var[j : j + len(P)] = np.einsum("nii->ni", P[:, POSITION, POSITION])
            j += len(P)
        if not (k == j == n):
            raise ReaderError(f"{npz_path(path)}: t, x and P differ in length")
        return cls(t, position, orientation, var, variant, metadata)


@dataclass(frozen=True, eq=False)
class StoredTrajectory:
    """A trajectory whose states are in a :class:`TrajectoryStore` (what the filter and the
    smoother give for a log too long for memory): its variant and metadata, its times, and
    :meth:`load` for the whole Trajectory of one that fits."""

    store: TrajectoryStore
    variant: str = ""
    metadata: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.store)

    @property
    def t(self) -> np.ndarray:
        return self.store.read_array("t")

    def load(self) -> Trajectory:
        return self.store.trajectory(self.variant, self.metadata)

    def replace(self, **changes) -> StoredTrajectory:
        return dataclasses.replace(self, **changes)

    def save_npz(self, path: str | Path, chunk: int = CHUNK_STATES) -> Path:
        """The trajectory.npz of :meth:`Trajectory.save_npz`, streamed (:func:`write_npz`)."""
        return write_npz(path, self.store, self.variant, self.metadata, chunk)


@dataclass(frozen=True, eq=False)
class NpzTrajectory:
    """A trajectory.npz on disk, read lazily: its variant and metadata at once, the rest when
    asked (:meth:`pose_track` chunk by chunk, :meth:`load` whole)."""

    path: Path
    variant: str = ""
    metadata: dict = field(default_factory=dict)

    @classmethod
    def open(cls, path: str | Path) -> NpzTrajectory:
        path = npz_path(path)
        return cls(path, *npz_header(path))

    @property
    def t(self) -> np.ndarray:
        return np.concatenate([*npz_rows(self.path, "t"), np.empty(0)])

    def __len__(self) -> int:
        return int(self.t.size)

    def pose_track(self, chunk: int = CHUNK_STATES) -> PoseTrack:
        return PoseTrack.from_npz(self.path, chunk)

    def load(self) -> Trajectory:
        return Trajectory.load_npz(self.path)
