"""The factor-graph peers on synthesized sensors with a closed-form truth: a static vehicle stays
put while its horizontal variance grows as a velocity known from the DVL's samples, and a
constant-velocity straight line ends at p0 + v T within the estimated uncertainty."""

import numpy as np
import pytest

pytest.importorskip("gtsam")

from undertow.errors import ConfigError  # noqa: E402
from undertow.log import G0, P_ATM, DeadReckoning, Dvl, Imu, Log, Pressure  # noqa: E402
from undertow.peers.factor_graph import factor_graph, isam2  # noqa: E402
from undertow.robot import Mounting  # noqa: E402
from undertow.rotations import rpy_to_matrix  # noqa: E402

RHO = 998.0
DEPTH = 2.0
DVL_STD = 0.01  # the LocalizerConfig default the log without a DVL covariance gets


def _line_log(duration, speed, yaw, seed=0, accel=True):
    """Level, constant heading ``yaw``, constant body velocity (speed, 0, 0) at DEPTH: IMU
    100 Hz (gyro 0, specific force (0, 0, -g) in FRD), DVL 8 Hz in the DVL frame, barometer
    10 Hz, DR attitude 5 Hz; white noise at the filter's default stds."""
    rng = np.random.default_rng(seed)
    mounting = Mounting()

    def times(rate):
        return np.arange(0.0, duration + 1e-9, 1.0 / rate)

    ti, td, tp, tr = times(100), times(8), times(10), times(5)
    f = np.tile([0.0, 0.0, -G0], (ti.size, 1)) + rng.normal(0, 0.03, (ti.size, 3))
    imu = Imu(ti, rng.normal(0, 0.005, (ti.size, 3)), f if accel else None)
    v_dvl = mounting.dvl.rotation_matrix().T @ np.array([speed, 0.0, 0.0])
    dvl = Dvl.from_velocity(td, v_dvl + rng.normal(0, DVL_STD, (td.size, 3)))
    depth = DEPTH + rng.normal(0, 0.01, tp.size)
    rpy = np.array([0.0, 0.0, yaw]) + rng.normal(0, [0.005, 0.005, 0.01], (tr.size, 3))
    return Log(
        imu=imu,
        dvl=dvl,
        pressure=Pressure(tp, P_ATM + RHO * G0 * depth),
        dead_reckoning=DeadReckoning(tr, np.zeros((tr.size, 3)), rpy),
        mounting=mounting,
        metadata={"water_density_kg_m3": RHO},
    )


# the DVL covariance is absent from these logs (the config's std is used): no warning matters here
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")
ESTIMATORS = [pytest.param(factor_graph, id="batch"), pytest.param(isam2, id="isam2")]


@pytest.mark.parametrize("run", ESTIMATORS)
def test_a_static_vehicle_stays_put_and_its_horizontal_variance_grows(run):
    duration = 20.0
    traj = run(_line_log(duration, 0.0, 0.0), initial_position=(1.0, 2.0, DEPTH))
    var = traj.position_variance
    err = traj.position[-1] - [1.0, 2.0, DEPTH]
    assert np.all(np.abs(err) < 4 * np.sqrt(var[-1])), (err, np.sqrt(var[-1]))
    # x, y are observed only through the start: their variance grows from P0's (0.01 m)^2 ...
    if traj.metadata["online"]:
        assert np.all(np.diff(var[:, :2], axis=0) > -1e-9)
    # ... linearly, at the rate of a constant velocity known from N DVL samples (closed form:
    # var = T^2 sigma^2 / N = sigma^2 dt T, the least possible: the IMU's noise adds a little)
    closed_form = 1e-4 + DVL_STD**2 * 0.125 * duration
    assert np.all(var[-1, :2] > 0.98 * closed_form), (var[-1], closed_form)
    assert np.all(var[-1, :2] < 1.3 * closed_form), (var[-1], closed_form)
    assert np.sqrt(var[-1, 2]) < 0.01  # the barometer holds z


@pytest.mark.parametrize("run", ESTIMATORS)
def test_a_constant_velocity_line_ends_at_p0_plus_v_t(run):
    duration, speed, yaw = 30.0, 0.5, 0.7
    traj = run(_line_log(duration, speed, yaw, seed=1), initial_position=(0.0, 0.0, DEPTH))
    truth = np.array([speed * np.cos(yaw), speed * np.sin(yaw), 0.0]) * traj.t[-1]
    truth[2] = DEPTH
    err = traj.position[-1] - truth
    std = np.sqrt(traj.position_variance[-1])
    assert np.all(np.abs(err) < 4 * std + 1e-3), (err, std)
    assert np.all(std < 0.1)
    np.testing.assert_allclose(traj.velocity_body[-20:].mean(axis=0), [speed, 0, 0], atol=0.01)
    R = rpy_to_matrix(traj.orientation[-1])
    np.testing.assert_allclose(R, rpy_to_matrix([0, 0, yaw]), atol=0.02)
    assert np.all(np.isfinite(traj.P)) and np.all(np.linalg.eigvalsh(traj.P[:, :6, :6]) > 0)


def test_a_log_without_an_accelerometer_is_one_line():
    with pytest.raises(ConfigError, match="accelerometer"):
        factor_graph(_line_log(2.0, 0.0, 0.0, accel=False))
