"""The trajectory on disk (undertow.trajectory_chunks): a store appended in pieces holds what
was appended; the streamed trajectory.npz holds the arrays Trajectory.save_npz writes (member by
member, the same deflated bytes) and reads back with load_npz; the lazy readers give the
values of the whole arrays."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from undertow.errors import ReaderError
from undertow.trajectory import Trajectory
from undertow.trajectory_chunks import (
    NpzTrajectory,
    PoseTrack,
    StoredTrajectory,
    TrajectoryStore,
    npz_rows,
    write_npz,
)


def _random(n: int, seed: int = 0) -> Trajectory:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, 18, 18))
    meta = {"config": {"variant": "proposed"}, "wave_track": {"t": [0.0, 1.0],
            "amplitude_m": [0.1, 0.2], "frequency_hz": [None, 0.5]}}  # fmt: skip
    return Trajectory(np.cumsum(rng.uniform(0.001, 0.02, n)), rng.normal(size=(n, 18)),
                      A @ np.swapaxes(A, 1, 2), variant="proposed", metadata=meta)  # fmt: skip


def _stored(tmp_path, traj: Trajectory, pieces) -> TrajectoryStore:
    store = TrajectoryStore(tmp_path / "states")
    for k0, k1 in zip(pieces[:-1], pieces[1:], strict=True):
        store.append(traj.t[k0:k1], traj.x[k0:k1], traj.P[k0:k1])
    return store


def test_a_store_filled_in_pieces_holds_the_states_and_its_chunks_cover_them(tmp_path):
    traj = _random(23)
    store = _stored(tmp_path, traj, [0, 1, 1, 10, 23])  # an empty piece too
    back = store.trajectory()
    for name in "txP":
        np.testing.assert_array_equal(getattr(back, name), getattr(traj, name))
    assert store.chunks(5) == [(0, 5), (5, 10), (10, 15), (15, 20), (20, 23)]
    assert store.chunks(5, reverse=True)[0] == (20, 23)
    with pytest.raises(ValueError, match="P"):
        store.append(traj.t[:2], traj.x[:2], traj.P[:1])
    store.remove()
    assert not (tmp_path / "states").exists()


def test_the_streamed_npz_is_the_one_save_npz_writes(tmp_path):
    traj = _random(37)
    traj.save_npz(tmp_path / "whole.npz")
    stored = StoredTrajectory(_stored(tmp_path, traj, [0, 20, 37]), traj.variant, traj.metadata)
    stored.save_npz(tmp_path / "chunks.npz", chunk=4)  # chunks that do not divide N
    members = []
    for name in ("whole.npz", "chunks.npz"):
        with zipfile.ZipFile(tmp_path / name) as z:
            members.append([(i.filename, i.CRC, i.file_size, i.compress_size)
                            for i in z.infolist()])  # fmt: skip
    assert members[0] == members[1] and "wave_t.npy" in [m[0] for m in members[0]]
    back = Trajectory.load_npz(tmp_path / "chunks.npz")
    for name in "txP":
        np.testing.assert_array_equal(getattr(back, name), getattr(traj, name))
    assert back.metadata == traj.metadata and back.variant == traj.variant


def test_the_lazy_readers_give_the_whole_arrays_values(tmp_path):
    traj = _random(41, seed=3)
    traj.save_npz(tmp_path / "trajectory.npz")
    rows = list(npz_rows(tmp_path, "P", chunk=8))
    assert [len(r) for r in rows] == [8, 8, 8, 8, 8, 1]
    np.testing.assert_array_equal(np.concatenate(rows), traj.P)
    track = PoseTrack.from_npz(tmp_path / "trajectory.npz", chunk=6)
    for name in ("t", "position", "orientation", "position_variance"):
        np.testing.assert_array_equal(getattr(track, name), getattr(traj, name))
    assert track.variant == "proposed" and track.metadata == traj.metadata and len(track) == 41
    lazy = NpzTrajectory.open(tmp_path)
    assert len(lazy) == 41 and lazy.metadata == traj.metadata
    np.testing.assert_array_equal(lazy.load().x, traj.x)


def test_an_empty_store_writes_an_empty_trajectory(tmp_path):
    store = TrajectoryStore(tmp_path / "s")
    write_npz(tmp_path / "e.npz", store, "", {})
    assert len(Trajectory.load_npz(tmp_path / "e.npz")) == 0
    assert len(PoseTrack.from_npz(tmp_path / "e.npz")) == 0


def test_a_file_that_is_not_a_trajectory_is_one_reader_error(tmp_path):
    (tmp_path / "t.tum").write_text("0 0 0 0 0 0 0 1\n")
    with pytest.raises(ReaderError, match="TUM file has poses only"):
        PoseTrack.from_npz(tmp_path / "t.tum")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(ReaderError, match="cannot read"):
        PoseTrack.from_npz(tmp_path / "other.npz")


def test_the_pose_track_holds_one_chunk_of_covariances_at_a_time(tmp_path):
    """P is 18 x 18 floats a state: reading the track must not keep every chunk alive (a
    diagonal taken by einsum, or a column slice, is a view of its whole chunk). Measured with
    tracemalloc, which numpy's allocations report to."""
    import tracemalloc

    traj = _random(20_000, seed=4)
    traj.save_npz(tmp_path / "trajectory.npz")
    p_bytes = traj.P.nbytes
    del traj
    tracemalloc.start()
    try:
        track = PoseTrack.from_npz(tmp_path / "trajectory.npz", chunk=500)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(track) == 20_000
    assert peak < p_bytes / 4, (peak, p_bytes)  # about 3 % of P: the track and one chunk
