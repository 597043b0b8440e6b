"""A log localized in pieces (:mod:`undertow.estimation.localizer_pieces`) against the whole
log's run (:func:`undertow.estimation.localizer.localize`): the same states bit for bit, the
same metadata (counts, NIS, consistency report), filtered and smoothed."""

import warnings

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.estimation.localizer import localize
from undertow.estimation.localizer_pieces import localize_pieces
from undertow.estimation.noise_physics import sensor_site
from undertow.io import iter_log_pieces, read_log
from undertow.trajectory_chunks import TrajectoryStore


def test_tiny_pieces_give_the_whole_logs_states_and_metadata(simulated_run, tmp_path):
    smooth = True  # the smoothed states are the filtered ones smoothed: both are checked
    log = simulated_run("wave-a0.10-f1.00") / "log"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = localize(read_log(log), variant="proposed", smooth=smooth)
        store = TrajectoryStore(tmp_path / "store")
        # 0.7 s pieces: 70 of them, each holding about 7 barometer rows (the depth-rate check's
        # window reaches into the neighbours)
        pieces = localize_pieces(iter_log_pieces(log, 0.7), store, variant="proposed",
                                 smooth=smooth)  # fmt: skip
    t, x, P = store.read()
    np.testing.assert_array_equal(t, whole.t)
    np.testing.assert_array_equal(x, whole.x)
    np.testing.assert_array_equal(P, whole.P)
    assert pieces.metadata == whole.metadata
    assert list(pieces.metadata) == list(whole.metadata)
    assert sorted(p.name for p in (tmp_path / "store").iterdir()) == ["P.f8", "t.f8", "x.f8"]


def test_a_wave_estimated_from_the_log_is_refused(simulated_run, tmp_path):
    log = simulated_run("calm") / "log"
    with pytest.raises(ConfigError, match="whole log"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        localize_pieces(iter_log_pieces(log, 5.0), TrajectoryStore(tmp_path / "s"), wave="auto")


def test_an_extrapolated_wave_takes_the_whole_logs_site_from_a_first_pass(simulated_run, tmp_path):
    """A condition outside the profile (physics extrapolation: the noise depends on the DVL's
    median depth over the log): with ``site_pieces`` (a first pass over the depth and DVL
    streams alone) the pieces give the whole log's wave noise, states and metadata, where the
    first piece's site (what they took before) is another."""
    log = simulated_run("wave-a0.10-f1.00") / "log"
    site_streams = ("pressure", "depth", "ground_truth", "dvl", "dvl_json")
    options = {"variant": "proposed", "wave": (0.15, 0.33)}  # outside: scaled from a node
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = localize(read_log(log), **options)
        store = TrajectoryStore(tmp_path / "store")
        pieces = localize_pieces(
            iter_log_pieces(log, 10.0), store,
            site_pieces=lambda: iter_log_pieces(log, 10.0, streams=site_streams), **options,
        )  # fmt: skip
        first_piece = sensor_site(next(iter_log_pieces(log, 10.0)))
    assert whole.metadata["wave_noise"]["how"] == "extrapolated"
    assert pieces.metadata == whole.metadata
    t, x, P = store.read()
    np.testing.assert_array_equal(t, whole.t)
    np.testing.assert_array_equal(x, whole.x)
    np.testing.assert_array_equal(P, whole.P)
    site = whole.metadata["wave_noise"]["extrapolation"]["site"]
    assert first_piece.sensor_depth_m != site["sensor_depth_m"]
