"""The filter on any sensor set with DVL velocity and an orientation source, against the
simulator's ground truth; the states no sensor informs are held or left to grow, and named."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
from conftest import REAL_DATA

from undertow.errors import ConfigError, MissingStreamError
from undertow.estimation import Localizer, localize
from undertow.rotations import wrap_angle

SUBSETS = {
    "all": {},
    "no imu": {"imu": None},
    "no dr": {"dead_reckoning": None},
    "no barometer": {"pressure": None},
    "dvl + dr": {"imu": None, "pressure": None},
    "dvl + imu": {"dead_reckoning": None, "pressure": None},
}
NO_DR = ("no dr", "dvl + imu")


@pytest.fixture(scope="module")
def calm(simulation):
    """The calm carriage run and the DVL scale its sound-speed setting implies (what
    `undertow calibrate` estimates): with it the filter's model is right."""
    result = simulation("calm", 1)
    s = result.scenario
    return result.log, s.dvl.sound_speed_setting / s.water.sound_speed_m_s


def _errors(traj, gt):
    """Errors (position, yaw, body velocity) against the ground truth at the filter's times."""
    pos, rpy, _ = gt.interpolate(traj.t)
    vel = gt.body_velocity(traj.t, gt.velocity)
    return (traj.x[:, :3] - pos, wrap_angle(traj.x[:, 5:6] - rpy[:, 2:3]), traj.x[:, 6:9] - vel)


def _nees(err, P):
    return float(np.mean(np.einsum("ni,nij,nj->n", err, np.linalg.inv(P), err)))


@pytest.mark.parametrize("subset", list(SUBSETS))
def test_each_subset_is_consistent_with_the_ground_truth(calm, subset):
    """Mean NEES of yaw (dim 1) and velocity (dim 3) below 3x their dimension; position the same
    where the DR attitude pins the yaw. Without DR the yaw is integrated from the gyro and the
    position error grows with it: there, |position error| within 3 sqrt(trace P_pos) at every
    time (the Gaussian is a poor fit to a banana-shaped position uncertainty)."""
    log, scale = calm
    expect = pytest.warns(RuntimeWarning, match="Localizer: no ")
    with expect if SUBSETS[subset] else contextlib.nullcontext():
        traj = localize(log.replace(**SUBSETS[subset]), "be", dvl_scale_factor=scale)
    assert np.all(np.isfinite(traj.x))
    np.linalg.cholesky(traj.P)  # every covariance positive definite
    e_pos, e_yaw, e_vel = _errors(traj, log.ground_truth)
    assert _nees(e_yaw, traj.P[:, 5:6, 5:6]) < 3.0
    assert _nees(e_vel, traj.P[:, 6:9, 6:9]) < 9.0
    P_pos = traj.P[:, :3, :3]
    if subset in NO_DR:
        spread = np.sqrt(np.trace(P_pos, axis1=1, axis2=2))
        assert np.all(np.linalg.norm(e_pos, axis=1) <= 3.0 * spread)
    else:
        assert _nees(e_pos, P_pos) < 9.0
        assert np.sqrt(np.mean(np.sum(e_pos**2, axis=1))) < 0.5  # m, over 36.6 m of track


def test_the_unobserved_states_are_held_or_named(calm):
    log, scale = calm
    with pytest.warns(RuntimeWarning, match="no IMU: the IMU gyro bias"):
        no_imu = localize(log.replace(imu=None), "be", dvl_scale_factor=scale)
    assert no_imu.metadata["held_bias"] == ["gyro_bias"]
    assert np.all(no_imu.x[:, 15:18] == 0.0) and np.all(no_imu.P[:, 15, 15] == 1e-12)
    assert np.all(no_imu.P[:, 12:15, 12:15][:, [0, 1, 2], [0, 1, 2]] > 1e-9)  # DR bias estimated
    assert np.any(no_imu.x[:, 14] != 0.0)

    with pytest.warns(RuntimeWarning, match="b-bar.g .x.15:18.. is not separable"):
        no_dr = localize(log.replace(dead_reckoning=None), "be", dvl_scale_factor=scale)
    meta = no_dr.metadata
    assert meta["held_bias"] == ["dr_bias"]
    assert np.all(no_dr.x[:, 12:15] == 0.0) and np.all(no_dr.P[:, 12, 12] == 1e-12)
    assert any("initial attitude from the ground truth" in line for line in meta["unobserved"])
    truth0 = log.ground_truth.orientation[0]
    np.testing.assert_allclose(wrap_angle(no_dr.x[0, 3:6] - truth0), 0.0, atol=0.02)
    yaw_var = no_dr.P[:, 5, 5]
    assert yaw_var[-1] > 5 * yaw_var[len(yaw_var) // 10]  # integrated from the gyro: grows

    with pytest.warns(RuntimeWarning, match="no barometer"):
        without = localize(log.replace(pressure=None), "be", dvl_scale_factor=scale)
    with_baro = localize(log, "be", dvl_scale_factor=scale)
    assert without.metadata["unobserved"] == [
        "no barometer: depth from DVL integration only, its variance grows"
    ]
    assert with_baro.metadata["unobserved"] == [] and with_baro.metadata["held_bias"] == []
    z_var = without.P[:, 2, 2]
    assert z_var[-1] > z_var[len(z_var) // 10] and z_var[-1] > 10 * with_baro.P[-1, 2, 2]


def test_no_dr_and_no_ground_truth_start_from_the_imu_orientation_else_zeros(calm):
    from undertow.log import Imu
    from undertow.rotations import rpy_to_quaternion

    log, _ = calm
    imu = log.imu
    rpy = np.array([0.05, -0.02, 1.2])
    q = np.tile(rpy_to_quaternion(rpy), (len(imu), 1))
    bare = log.replace(dead_reckoning=None, ground_truth=None)
    with pytest.warns(RuntimeWarning, match="orientation report"):
        traj = Localizer("baseline").run(bare.replace(imu=Imu(imu.t, imu.angular_velocity,
                                                              orientation=q)))  # fmt: skip
    np.testing.assert_allclose(traj.x[0, 3:6], rpy, atol=0.02)
    with pytest.warns(RuntimeWarning, match="initial attitude zeros"):
        traj = Localizer("baseline").run(bare)
    assert any("initial attitude zeros" in line for line in traj.metadata["unobserved"])


def test_smoothing_holds_what_the_filter_held(calm):
    log, scale = calm
    with pytest.warns(RuntimeWarning):
        smoothed = localize(log.replace(imu=None), "be", dvl_scale_factor=scale, smooth=True)
    assert np.all(smoothed.x[:, 15:18] == 0.0) and np.all(smoothed.P[:, 15, 15] == 1e-12)


def test_missing_dvl_or_orientation_is_one_line(calm):
    log, _ = calm
    with pytest.raises(ConfigError, match="no DVL velocity") as err:
        Localizer().run(log.replace(dvl=None))
    assert "\n" not in str(err.value)
    needs = r"no orientation source: needs an IMU gyro \(stream imu\) or the DVL.s dead reckoning"
    with pytest.raises(ConfigError, match="has DVL velocity but " + needs) as err:
        Localizer().run(log.replace(imu=None, dead_reckoning=None))
    assert "\n" not in str(err.value)
    assert isinstance(err.value, MissingStreamError)  # as before, for callers catching that


@pytest.mark.realdata
def test_the_real_dvl_only_recording_is_refused_in_one_line():
    from undertow.io import read_log

    bag = REAL_DATA / "a50_ros1_circle.bag"
    log = read_log(bag)
    with pytest.raises(ConfigError, match="DVL velocity but no orientation source") as err:
        localize(log)
    assert "\n" not in str(err.value) and str(bag) in str(err.value)
