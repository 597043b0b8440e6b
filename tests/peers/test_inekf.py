"""inekf(log): the error conversions (and the DR-bias states' to the UKF's rpy offset) against
numerical derivatives, a synthetic straight run
through the Log adapter, and the refusal of a log without an accelerometer."""

import numpy as np
import pytest
from conftest import numeric_jacobian

from undertow.errors import MissingStreamError
from undertow.log import G0, Dvl, Imu, Log, Pressure
from undertow.peers.inekf import dr_bias_rpy, from_ordinary_jacobian, inekf, ordinary_jacobian
from undertow.peers.lie import se23_exp, se23_inverse, se23_log, so3_exp
from undertow.rotations import matrix_to_rpy, rpy_to_matrix


def _numeric(fun, n=15, h=1e-6):
    return numeric_jacobian(fun, n, h)


def test_conversions_to_and_from_the_ordinary_errors_match_numerical_derivatives():
    rng = np.random.default_rng(0)
    rpy = np.r_[0.1, -0.2, 2.0]
    R, v, p = rpy_to_matrix(rpy), rng.normal(size=3), rng.normal(size=3) * 5

    def ordinary(e):  # true state exp(e) X_hat -> (d_theta world, dv, dp, db)
        dR, dv, dp = se23_exp(e[:9])
        Rt = dR @ R
        th = se23_log(Rt @ R.T, np.zeros(3), np.zeros(3))[:3]
        return np.r_[th, dR @ v + dv - v, dR @ p + dp - p, e[9:]]

    assert np.allclose(_numeric(ordinary), ordinary_jacobian(v[None], p[None])[0], atol=1e-7)

    def invariant(d):  # (dp, d rpy, d nu body, db) -> e
        Rt = rpy_to_matrix(rpy + d[3:6])
        vt, pt = Rt @ (R.T @ v + d[6:9]), p + d[0:3]
        Ri, vi, pi = se23_inverse(R, v, p)
        return np.r_[se23_log(Rt @ Ri, Rt @ vi + vt, Rt @ pi + pt), d[9:]]

    assert np.allclose(_numeric(invariant), from_ordinary_jacobian(R, p, rpy), atol=1e-7)


def _straight_log(accel=True, T=30.0):
    """A level vehicle heading 0.3 rad at a constant 0.4 m/s, 2 m deep, exact readings."""
    rpy = np.r_[0.0, 0.0, 0.3]
    R = rpy_to_matrix(rpy)
    v_body = np.r_[0.4, 0.0, 0.0]
    ti = np.arange(0.0, T, 0.01)
    f = np.tile(R.T @ np.r_[0.0, 0.0, -G0], (ti.size, 1))
    imu = Imu(t=ti, angular_velocity=np.zeros((ti.size, 3)),
              linear_acceleration=f if accel else None)  # fmt: skip
    td = np.arange(0.05, T, 0.125)
    log0 = Log()
    R_dvl = log0.mounting.dvl.rotation_matrix()
    dvl = Dvl.from_velocity(td, np.tile(R_dvl.T @ v_body, (td.size, 1)))
    tp = np.arange(0.02, T, 0.1)
    d = 2.0 + (R @ np.asarray(log0.mounting.barometer.translation))[2]
    pressure = Pressure(t=tp, pressure=np.full(tp.size, 101_325.0 + d * 998.0 * G0))
    return Log(imu=imu, dvl=dvl, pressure=pressure), R, v_body


@pytest.mark.filterwarnings("ignore:Localizer. no DVL dead reckoning")
def test_inekf_on_a_synthetic_straight_run_follows_the_line():
    log, R, v_body = _straight_log()
    traj = inekf(log, initial_state=[0, 0, 2.0, 0, 0, 0.3] + [0.4, 0, 0] + [0] * 9)
    assert traj.variant == "inekf" and traj.x.shape[1] == 18
    T = traj.t[-1] - traj.t[0]
    expected = np.r_[0.0, 0.0, 2.0] + R @ v_body * traj.t[-1]
    assert np.allclose(traj.position[-1], expected, atol=1e-3 * max(T, 1.0))
    assert np.allclose(traj.orientation[-1], matrix_to_rpy(R), atol=1e-4)
    assert np.allclose(traj.velocity_body[-1], v_body, atol=1e-4)
    assert np.all(np.isfinite(traj.P)) and np.all(np.linalg.eigvalsh(traj.P) > -1e-12)
    summary = traj.metadata["inekf"]
    assert summary["dvl_updates"] > 0 and summary["depth_updates"] > 0
    assert summary["dvl_gated"] == 0


@pytest.mark.filterwarnings("ignore:Localizer. no DVL dead reckoning")
def test_inekf_refuses_a_log_without_accelerometer_in_one_line():
    log, _, _ = _straight_log(accel=False, T=2.0)
    with pytest.raises(MissingStreamError, match="accelerometer") as info:
        inekf(log)
    assert "\n" not in str(info.value)


def test_dr_bias_states_map_to_the_rpy_offset_by_its_numerical_derivative():
    """A world rotation b_d between the DR attitude and the vehicle's, R_m = Exp(b_d) R, is the
    rpy offset rpy(Exp(b_d) R) - rpy(R) = T R^T b_d to first order: against central
    differences of that offset, at a pitched and rolled attitude."""
    rpy = np.array([0.2, -0.3, 2.5])
    R = rpy_to_matrix(rpy)

    class _Inputs:
        x0 = np.zeros(18)

    C = np.zeros((1, 18, 18))
    C[0, 15:18, 15:18] = np.diag([1.0, 2.0, 3.0])
    J = _numeric(lambda b: matrix_to_rpy(so3_exp(b) @ R) - rpy, n=3)
    for k in range(3):
        b = np.zeros((1, 9))
        b[0, 6 + k] = 1e-7
        out = dr_bias_rpy(_Inputs(), R[None], b, C)
        assert np.allclose(out["dr_bias"][0] / 1e-7, J[:, k], rtol=1e-5, atol=1e-6)
    assert np.allclose(out["dr_bias_cov"][0], J @ C[0, 15:18, 15:18] @ J.T, rtol=1e-5)
