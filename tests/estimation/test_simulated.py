"""The filter on the simulator's calm carriage run: hidden biases recovered within the filter's
own 3-sigma, and the smoother never worse than the filter."""

import numpy as np
import pytest

from undertow.estimation import calibrate, localize, smooth
from undertow.evaluation.trajectory import trajectory_rmse
from undertow.sim import load_scenario, simulate


@pytest.fixture(scope="module")
def run():
    calm = simulate(load_scenario("calm"), seed=11)
    calibration = calibrate(simulate(load_scenario("calm"), seed=12).log)
    trajectory = localize(calm.log, "proposed", calibration=calibration)
    return calm, calibration, trajectory


def test_gyro_bias_recovered_within_three_sigma(run):
    calm, _, trajectory = run
    imu_t = calm.log.imu.t
    truth = np.column_stack(
        [np.interp(trajectory.t, imu_t, calm.gyro_bias[:, i]) for i in range(3)]
    )
    last = -1
    error = trajectory.x[last, 15:18] - truth[last]
    sigma = np.sqrt(np.diag(trajectory.P[last])[15:18])
    assert np.all(np.abs(error) < 3 * sigma), (error, sigma)
    assert np.all(sigma < 0.002)  # and it learned something: the prior sigma was 0.01 rad/s


def test_dead_reckoning_yaw_bias_tracks_the_drift(run):
    """DR yaw = true yaw + drift t: the DR bias state estimates the accumulated drift."""
    calm, _, trajectory = run
    drift = calm.scenario.dead_reckoning.yaw_drift_rate
    truth = drift * (trajectory.t - calm.log.dead_reckoning.t[0])
    sigma = np.sqrt(trajectory.P[:, 14, 14])
    late = trajectory.t > trajectory.t[-1] / 2
    assert np.all(np.abs(trajectory.x[late, 14] - truth[late]) < 3 * sigma[late])


def test_smoother_is_no_worse_than_the_filter(run):
    calm, _, trajectory = run
    gt = calm.log.ground_truth
    filtered = trajectory_rmse(trajectory, gt).rmse
    smoothed = trajectory_rmse(smooth(trajectory), gt).rmse
    # yaw is left out: it hinges on the DR drift mu_b calibrated on another run, a model
    # mismatch under which RTS is not optimal (both are below 0.5 mrad here)
    for axis in ("z_m", "roll_rad", "pitch_rad", "vx_m_s", "vy_m_s", "vz_m_s"):
        assert smoothed[axis] <= filtered[axis] * 1.01, axis
    assert smoothed["vx_m_s"] < 0.9 * filtered["vx_m_s"]
