"""A localization folder written from a store chunk by chunk has the bytes of save_trajectory's
TUM file and config.yaml, and its npz the same arrays."""

from __future__ import annotations

import numpy as np

from undertow.io.results import save_trajectory
from undertow.io.trajectory_stream import save_stored_trajectory, write_tum_chunks
from undertow.io.tum import write_tum
from undertow.trajectory import Trajectory
from undertow.trajectory_chunks import StoredTrajectory, TrajectoryStore


def test_the_folder_from_a_store_is_the_folder_of_the_whole_trajectory(tmp_path):
    rng = np.random.default_rng(7)
    n = 29
    x = rng.normal(size=(n, 18))
    x[:, 3:6] = rng.uniform(-np.pi, np.pi, (n, 3))
    traj = Trajectory(np.arange(n) * 0.01 + 1e4, x, np.tile(np.eye(18), (n, 1, 1)),
                      variant="be", metadata={"counts": {"used_dvl": 3}})  # fmt: skip
    store = TrajectoryStore(tmp_path / "states")
    store.append(traj.t[:10], traj.x[:10], traj.P[:10])
    store.append(traj.t[10:], traj.x[10:], traj.P[10:])
    write_tum(tmp_path / "whole.tum", traj.t, traj.position, traj.orientation)
    write_tum_chunks(tmp_path / "chunks.tum", store, chunk=4)
    assert (tmp_path / "chunks.tum").read_bytes() == (tmp_path / "whole.tum").read_bytes()
    save_trajectory(traj, tmp_path / "a")
    save_stored_trajectory(StoredTrajectory(store, "be", traj.metadata), tmp_path / "b")
    for name in ("trajectory.tum", "config.yaml"):
        assert (tmp_path / "b" / name).read_bytes() == (tmp_path / "a" / name).read_bytes()
    back = Trajectory.load_npz(tmp_path / "b")
    np.testing.assert_array_equal(back.P, traj.P)
    assert back.metadata == traj.metadata
