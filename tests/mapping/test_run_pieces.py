"""A log mapped in pieces (:func:`undertow.mapping.run.map_pieces`) against the whole log's
map (:func:`undertow.mapping.run.map_log`): the same cells; CSM's counts exactly, BKI's float32
sums within 2e-6."""

import warnings

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.estimation.localizer import localize
from undertow.io import iter_log_pieces, read_log
from undertow.mapping.config import MappingConfig
from undertow.mapping.run import map_log, map_pieces


def _by_cell(occupancy):
    order = np.lexsort(np.asarray(occupancy.cells).T[::-1])
    return np.asarray(occupancy.cells)[order], occupancy.alpha[order], occupancy.beta[order]


@pytest.mark.parametrize(
    "method, rtol",
    [("csm", 0.0), ("tpu", 2e-6), pytest.param("bki", 2e-6, marks=pytest.mark.slow)],
)
def test_pieces_give_the_whole_logs_map(simulated_run, method, rtol):
    log = simulated_run("calm") / "log"
    config = MappingConfig(method=method, resolution=0.2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        truth = localize(read_log(log))  # the trajectory: the same for both
        whole = map_log(read_log(log), truth, config)
        pieces = map_pieces(iter_log_pieces(log, 1.0), truth, config)
    cells, alpha, beta = _by_cell(whole.map)
    got = _by_cell(pieces.map)
    np.testing.assert_array_equal(got[0], cells)
    np.testing.assert_allclose(got[1], alpha, rtol=rtol, atol=0)
    np.testing.assert_allclose(got[2], beta, rtol=rtol, atol=0)
    assert pieces.metadata["samples"] == whole.metadata["samples"]
    assert pieces.metadata["mapper"]["n_integrations"] > 40  # 48 s in 1 s pieces


def test_adaptive_kernels_need_the_whole_log():
    with pytest.raises(ConfigError, match="whole log"):
        map_pieces([], None, MappingConfig(method="adaptive", variance_bounds=None))


def test_a_pose_track_is_read_per_piece_through_its_window(simulated_run, tmp_path):
    """map_pieces interpolates each piece in its window of a lazy PoseTrack (not the day's
    track): the same map bit for bit as with the whole trajectory; the window's angles are the
    whole track's unwrapped ones (a heading that wraps across pieces)."""
    from undertow.trajectory_chunks import PoseTrack

    log = simulated_run("calm") / "log"
    config = MappingConfig(method="tpu", resolution=0.2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        truth = localize(read_log(log))
        truth.x[:, 8] += np.linspace(0.0, 9.0, len(truth))  # yaw turning through +-pi
        truth.save_npz(tmp_path / "trajectory.npz")
        track = PoseTrack.from_npz(tmp_path / "trajectory.npz")
        whole = map_pieces(iter_log_pieces(log, 4.0), truth, config)
        windows = map_pieces(iter_log_pieces(log, 4.0), track, config)
    for name in ("cells", "alpha", "beta"):
        np.testing.assert_array_equal(getattr(whole.map, name), getattr(windows.map, name))
    part = track.window(track.t[10] + 1e-3, track.t[20])
    assert part.t[0] == track.t[10] and part.t[-1] == track.t[20]
    np.testing.assert_array_equal(
        part.unwrapped_orientation, np.unwrap(track.orientation, axis=0)[10:21]
    )
