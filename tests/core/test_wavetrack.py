"""WaveTrack: the wave condition over time (nodes, linear in between, held outside)."""

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.trajectory import Trajectory
from undertow.wavetrack import WaveTrack


def _ramp():
    # calm until 10 s, ramp to a = 0.1 m, f = 1 Hz at 20 s, then to 0.05 m, 0.75 Hz at 40 s
    return WaveTrack(
        np.array([0.0, 10.0, 20.0, 30.0, 40.0]),
        np.array([0.0, 0.0, 0.1, 0.1, 0.05]),
        np.array([np.nan, np.nan, 1.0, 1.0, 0.75]),
        "scenario",
    )


def test_linear_between_nodes_and_held_outside():
    track = _ramp()
    a, f = track.at(np.array([-5.0, 5.0, 15.0, 25.0, 35.0, 100.0]))
    np.testing.assert_allclose(a, [0.0, 0.0, 0.05, 0.1, 0.075, 0.05])
    # calm has no frequency; a ramp out of calm keeps the wave's frequency
    assert np.isnan(f[0]) and np.isnan(f[1])
    np.testing.assert_allclose(f[2:], [1.0, 1.0, 0.875, 0.75])


def test_round_trip_through_a_plain_dict_and_the_constant_form():
    track = _ramp()
    back = WaveTrack.from_dict(track.to_dict())
    t = np.linspace(-1, 50, 77)
    for x, y in zip(track.at(t), back.at(t), strict=True):
        np.testing.assert_array_equal(x, y)
    const = WaveTrack.from_dict({"amplitude_m": 0.1, "frequency_hz": 1.0}, source="probe")
    assert const.is_constant and const.source == "probe" and not track.is_constant
    assert const.at(123.0)[0] == 0.1


@pytest.mark.parametrize(
    "t, a, f, match",
    [
        ([0.0, 1.0], [0.1], [1.0], "same length"),
        ([1.0, 0.0], [0.1, 0.1], [1.0, 1.0], "non-decreasing"),
        ([0.0], [-0.1], [1.0], ">= 0"),
        ([0.0], [0.1], [np.nan], "needs a frequency"),
    ],
)
def test_bad_tracks_are_one_line(t, a, f, match):
    with pytest.raises(ConfigError, match=match) as info:
        WaveTrack(np.array(t), np.array(a), np.array(f))
    assert "\n" not in str(info.value)


def test_trajectory_npz_records_the_followed_condition(tmp_path):
    track = _ramp()
    n = 5
    traj = Trajectory(
        t=np.arange(n, dtype=float),
        x=np.zeros((n, 18)),
        P=np.tile(np.eye(18), (n, 1, 1)),
        variant="proposed",
        metadata={"wave_track": track.to_dict()},
    )
    path = traj.save_npz(tmp_path / "trajectory.npz")
    with np.load(path) as data:
        np.testing.assert_array_equal(data["wave_t"], track.t)
        np.testing.assert_array_equal(data["wave_amplitude_m"], track.amplitude_m)
        np.testing.assert_array_equal(
            np.isnan(data["wave_frequency_hz"]), np.isnan(track.frequency_hz)
        )
    assert Trajectory.load_npz(path).metadata["wave_track"]["t"] == list(track.t)
