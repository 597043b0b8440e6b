"""Ranges -> training samples: hits on a known plane, free-sample spacing, dropped counts,
pose interpolation (position, wrapped yaw, variance)."""

import warnings

import numpy as np
import pytest

from undertow.errors import ConfigError, DataError, MissingStreamError
from undertow.log import Dvl, Log, SonarRange
from undertow.mapping.samples import SENSOR_DVL, SENSOR_SONAR, build_samples
from undertow.robot import Mounting
from undertow.trajectory import Trajectory

TILT = np.deg2rad(22.5)
AZ = np.deg2rad([135.0, -135.0, -45.0, 45.0])


def _trajectory(t, pos, rpy, var=(0.0, 0.0, 0.0)):
    t = np.asarray(t, float)
    x = np.zeros((t.size, 18))
    x[:, :3], x[:, 3:6] = pos, rpy
    P = np.zeros((t.size, 18, 18))
    var = np.broadcast_to(np.asarray(var, float), (t.size, 3))
    for k in range(3):
        P[:, k, k] = var[:, k]
    return Trajectory(t, x, P)


def _log(t, beam_range, beam_valid, sonar_t=None, sonar_range=None):
    t = np.asarray(t, float)
    dvl = Dvl.from_velocity(t, np.zeros((t.size, 3)), beam_range=beam_range, beam_valid=beam_valid)
    sonar = None if sonar_t is None else SonarRange(t=sonar_t, range=sonar_range)
    return Log(dvl=dvl, sonar=sonar, mounting=Mounting())


def test_hits_land_on_known_plane_with_mounting():
    pos, yaw, floor = np.array([1.0, 2.0, 0.5]), 0.3, 2.5
    traj = _trajectory([0.0, 10.0], [pos, pos], [[0, 0, yaw]] * 2)
    m = Mounting()
    o_dvl = pos + np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0],
                            [0, 0, 1]]) @ np.array(m.dvl.translation)  # fmt: skip
    r = (floor - o_dvl[2]) / np.cos(TILT)
    o_sonar_z = pos[2] + m.sonar.translation[2]
    log = _log([5.0], np.full((1, 4), r), np.ones((1, 4), bool), [5.0], [floor - o_sonar_z])
    s = build_samples(log, traj, free_resolution=0.1)
    hits = s.points[s.label == 1]
    assert hits.shape == (5, 3)
    np.testing.assert_allclose(hits[:, 2], floor, atol=1e-12)
    # horizontal: r sin(tilt) along azimuth + DVL mount yaw (0.05) + vehicle yaw
    heading = AZ + m.dvl.rotation[2] + yaw
    dvl_hits = hits[s.sensor[s.label == 1] == SENSOR_DVL]
    expect = o_dvl[:2] + r * np.sin(TILT) * np.column_stack([np.cos(heading), np.sin(heading)])
    np.testing.assert_allclose(dvl_hits[:, :2], expect, atol=1e-12)
    assert np.sum(s.sensor[s.label == 1] == SENSOR_SONAR) == 1
    np.testing.assert_allclose(s.sigma0[s.sensor == SENSOR_DVL], 0.9)
    np.testing.assert_allclose(s.sigma0[s.sensor == SENSOR_SONAR], 0.6)


def test_free_samples_spacing_and_margin():
    traj = _trajectory([0.0, 1.0], [[0, 0, 0]] * 2, [[0, 0, 0]] * 2)
    ranges = np.array([[1.0, 1.234, 0.15, 0.07]])
    s = build_samples(_log([0.5], ranges, np.ones((1, 4), bool)), traj, free_resolution=0.1,
                      use_sonar=False)  # fmt: skip
    for b, (r, count) in enumerate(zip(ranges[0], [10, 12, 1, 0], strict=True)):  # hand counts
        ray = s.ray == b
        origin = s.origins[b]
        dist = np.sort(np.linalg.norm(s.points[ray & (s.label == 0)] - origin, axis=1))
        assert len(dist) == count
        if len(dist):
            assert dist[0] == pytest.approx(0.0)
            np.testing.assert_allclose(np.diff(dist), 0.1)
            assert r - 0.2 < dist[-1] <= r - 0.1 + 1e-9
        hit = s.points[ray & (s.label == 1)]
        assert np.linalg.norm(hit - origin) == pytest.approx(r)


def test_invalid_ranges_dropped_and_counted():
    traj = _trajectory([1.0, 2.0], [[0, 0, 0]] * 2, [[0, 0, 0]] * 2)
    ranges = np.array([[1.0, np.nan, 60.0, 1.0], [0.01, 1.0, 1.0, -1.0], [1.0, 1.0, 1.0, 1.0]])
    valid = np.array([[True, True, True, False], [True, True, True, True], [True] * 4])
    sonar_t, sonar_r = np.array([1.5, 1.6, 3.0]), np.array([0.1, 1.5, 1.5])
    with pytest.warns(UserWarning, match="5 of 9 valid ranges lie outside"):
        s = build_samples(_log([1.5, 1.5, 5.0], ranges, valid, sonar_t, sonar_r), traj)
    assert s.dropped == {
        "dvl_invalid": 1, "dvl_nonfinite": 1, "dvl_out_of_range": 3,
        "dvl_outside_trajectory": 4, "sonar_invalid": 0, "sonar_nonfinite": 0,
        "sonar_out_of_range": 1, "sonar_outside_trajectory": 1,
    }  # fmt: skip
    assert s.n_hits == 4  # 3 DVL beams + 1 sonar range kept


def test_pose_interpolation_position_wrapped_yaw_and_variance():
    traj = _trajectory([0.0, 2.0], [[0, 0, 0], [2.0, 0, 0]], [[0, 0, 3.1], [0, 0, -3.1]],
                       var=[[1.0, 0.0, 0.5], [3.0, 0.0, 0.5]])  # fmt: skip
    log = Log(sonar=SonarRange(t=[1.0], range=[1.0]), mounting=Mounting())
    s = build_samples(log, traj, use_dvl=True)
    # yaw passes through +-pi (not 0): the sonar lever arm (0.164, 0.106) points backwards.
    hit = s.points[s.label == 1][0]
    np.testing.assert_allclose(hit, [1.0 - 0.164, -0.106, 0.306 + 1.0], atol=1e-9)
    np.testing.assert_allclose(s.pose_variance, np.tile([2.0, 0.0, 0.5], (len(s), 1)))


def test_bad_configuration_and_missing_streams():
    traj = _trajectory([0.0, 1.0], [[0, 0, 0]] * 2, [[0, 0, 0]] * 2)
    log = Log(sonar=SonarRange(t=[0.5], range=[1.0]))
    with pytest.raises(ConfigError, match="free_resolution"):
        build_samples(log, traj, free_resolution=0.0)
    with pytest.raises(MissingStreamError, match="range stream"):
        build_samples(log, traj, use_sonar=False)


def test_a_trajectory_that_does_not_overlap_the_log_is_an_error_naming_both_spans():
    """A trajectory shifted by 1e4 s (another log, another clock) would drop every range as
    outside it and give an empty map: an error instead, naming both time spans."""
    ranges, valid = np.ones((3, 4)), np.ones((3, 4), bool)
    log = _log([1.0, 2.0, 3.0], ranges, valid, np.array([1.5]), np.array([1.5]))
    shifted = _trajectory([1e4 + 1.0, 1e4 + 3.0], [[0, 0, 0]] * 2, [[0, 0, 0]] * 2)
    with pytest.raises(DataError, match=r"trajectory 10001.000 .. 10003.000 s, ranges \(dvl, "
                       r"sonar\) 1.000 .. 3.000 s"):  # fmt: skip
        build_samples(log, shifted)
    overlapping = _trajectory([1.0, 3.0], [[0, 0, 0]] * 2, [[0, 0, 0]] * 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a full overlap warns of nothing
        assert build_samples(log, overlapping).n_hits == 13


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [("var", np.nan, "pose_variance"), ("var", -1.0, "pose_variance"), ("sig", 0.0, "sigma0"),
     ("origin", np.inf, "points"), ("r", np.nan, "points")],
)  # fmt: skip
def test_expand_checks_its_rays_as_samples_checks_samples(field, value, message):
    """expand() skips the per-sample checks only for rays that pass them: a bad ray still
    gets the one-line error naming the field, and good rays give the same Samples as the
    checked constructor."""
    from undertow.mapping.samples import Samples, expand

    rays = {"origin": np.zeros((3, 3)), "direction": np.tile([0.0, 0.0, 1.0], (3, 1)),
            "r": np.array([1.0, 0.5, 2.0]), "var": np.full((3, 3), 1e-3),
            "sig": np.full(3, 0.9)}  # fmt: skip
    good = expand(**rays, sensor=np.zeros(3, np.int8), f=0.1, dropped={})
    checked = Samples(good.points, good.label, good.sigma0, good.pose_variance, good.ray,
                      good.sensor, good.origins)  # fmt: skip
    for name in ("points", "label", "sigma0", "pose_variance", "ray", "sensor", "origins"):
        got, want = getattr(good, name), getattr(checked, name)
        assert got.dtype == want.dtype and np.array_equal(got, want), name
    bad = {k: v.copy() for k, v in rays.items()}
    bad[field].flat[1] = value
    with pytest.raises(DataError, match=message):
        expand(**bad, sensor=np.zeros(3, np.int8), f=0.1, dropped={})
