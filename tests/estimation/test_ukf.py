"""Sigma-point kernels against the Kalman filter (linear model) and FilterPy (the filter's model,
the swell states included)."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy_reference import FilterPyModel

from undertow.estimation import filter_loop, model, ukf
from undertow.rotations import rpy_to_matrix, wrap_angle

NO_ANGLES = np.zeros(4, dtype=np.bool_)


def test_weights_well_conditioned_for_18_states():
    wm, wc, lam = ukf.weights(18, 1.0, 2.0, 0.0)
    assert lam == 0.0 and wm[0] == 0.0 and abs(wm.sum() - 1.0) < 1e-12 and np.all(wc >= 0)


def test_linear_gaussian_equals_kalman_filter():
    rng = np.random.default_rng(1)
    dt = 0.1
    F = np.eye(4) + np.diag([dt, dt], 2)
    Q = np.diag([1e-4, 1e-4, 1e-2, 1e-2])
    H = rng.normal(size=(3, 4))
    R = np.diag([0.1, 0.2, 0.05])
    x_kf, P_kf = np.array([1.0, -1, 0.5, 0.2]), np.diag([1.0, 2.0, 0.5, 0.5])
    x, P = x_kf.copy(), P_kf.copy()
    wm, wc, lam = ukf.weights(4, 0.7, 2.0, 0.0)
    L, chi = np.zeros((4, 4)), np.empty((9, 4))
    D = np.empty((4, 9))
    for _ in range(20):
        z = H @ rng.normal(size=4) + rng.normal(size=3)
        x_kf, P_kf = F @ x_kf, F @ P_kf @ F.T + Q
        S = H @ P_kf @ H.T + R
        K = P_kf @ H.T @ np.linalg.inv(S)
        x_kf, P_kf = x_kf + K @ (z - H @ x_kf), P_kf - K @ S @ K.T
        ukf.sigma_points(x, P, lam, NO_ANGLES, L, chi)
        ukf.predict_moments(np.ascontiguousarray(chi @ F.T), wm, wc, Q, NO_ANGLES, x, P, D)
        ukf.sigma_points(x, P, lam, NO_ANGLES, L, chi)
        Zs = np.ascontiguousarray(chi @ H.T)
        status, _ = ukf.update(x, P, chi, Zs, z, R, wm, wc, NO_ANGLES, NO_ANGLES[:3], np.inf)
        assert status == 0
        np.testing.assert_allclose(x, x_kf, rtol=0, atol=1e-9)
        np.testing.assert_allclose(P, P_kf, rtol=0, atol=1e-9)


def test_linear_update_equals_the_sigma_point_update_on_the_filter_models():
    """The IMU, DVL and DR models are linear: the closed-form update the filter uses for them
    must equal the full unscented update (sigma points through _h), angles and wrap included."""
    rng = np.random.default_rng(7)
    n = model.N_STATE
    A = rng.normal(size=(n, n)) * 0.05
    P0 = A @ A.T + np.eye(n) * 1e-3
    x0 = rng.normal(size=n) * 0.3
    x0[5] = np.pi - 0.01  # yaw next to the wrap
    imu_Rt = np.ascontiguousarray(rpy_to_matrix([np.pi, 0.0, 0.02]).T)
    dvl_Rt = np.ascontiguousarray(rpy_to_matrix([0.0, 0.0, 0.05]).T)
    arm, baro = np.array([0.164, 0.004, 0.284]), np.zeros(3)
    sensors = model.SensorModel(imu_Rt, dvl_Rt, arm, baro, np.full(4, np.inf))
    H = model.jacobians(sensors)
    wm, wc, lam = ukf.weights(n, 1.0, 2.0, 0.0)
    R = np.diag([1e-3, 2e-3, 5e-4])
    for kind in (model.IMU, model.DVL, model.DR):
        angles = np.full(3, kind == model.DR)
        z = rng.normal(size=3) * 0.1
        if kind == model.DR:
            z[2] = -np.pi + 0.02  # across +-pi from the state's yaw + bias
        x, P = x0.copy(), P0.copy()
        chi, L = np.empty((2 * n + 1, n)), np.zeros((n, n))
        ukf.sigma_points(x, P, lam, model.STATE_ANGLES, L, chi)
        Zs, col, Rw = np.empty((2 * n + 1, 3)), np.empty(3), np.empty((3, 3))
        for i in range(2 * n + 1):
            model.h(kind, chi[i], sensors, col, Rw)
            Zs[i] = col
        ukf.update(x, P, chi, Zs, z, R, wm, wc, model.STATE_ANGLES, angles, np.inf)
        x_lin, P_lin = x0.copy(), P0.copy()
        ukf.update_linear(x_lin, P_lin, H[kind], z, R, model.STATE_ANGLES, angles, np.inf)
        np.testing.assert_allclose(wrap_angle(x_lin - x), 0.0, atol=1e-10)
        np.testing.assert_allclose(P_lin, P, atol=1e-12)


def test_cholesky_repair_makes_pd():
    P = np.diag([1.0, 1e-3, -1e-6])
    L = np.zeros((3, 3))
    assert ukf.cholesky_repair(P, L) == 1
    np.testing.assert_allclose(L @ L.T, P, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(P) > 0)


# --- the filter loop against FilterPy running an independent numpy statement of the model -----
R_IMU = rpy_to_matrix([np.pi, 0.0, 0.02])  # a REP-103 IMU, slightly turned
R_DVL = rpy_to_matrix([0.0, 0.0, 0.05])
R_DVL_ARM = np.array([0.164, 0.004, 0.284])
BARO_ARM = np.array([0.0, 0.1, -0.05])
Q_ACC, Q_B, MU = np.full(6, 0.02), np.full(6, 1e-6), np.array([0, 0, 1e-3, 0, 0, 0])


@pytest.mark.parametrize(
    "swell", [None, (2 * np.pi * 0.8, 0.03**2, 0.1, None), (2 * np.pi * 0.8, 0.03**2, 0.1, 2.0)]
)
def test_full_model_agrees_with_filterpy(swell):
    """All four measurement kinds through their mounting, angles near +-pi, equal times
    (updates without predict), one gap longer than dt_max (capped), with and without a swell
    (its transition and noise in the reference by expm and Van Loan's method, at the encounter
    frequency of waves from a known direction or widened for an unknown one): every recorded
    mean and covariance equal to FilterPy's on the numpy model of tests/filterpy_reference.py."""
    rng = np.random.default_rng(7)
    n, N = model.N_STATE, 80
    kinds = rng.integers(0, 4, N)
    t = np.sort(np.round(rng.uniform(0, 4, N), 2))  # some equal times: updates without predict
    t[N // 2 :] += 1.5  # a gap longer than dt_max
    dt_max = 1.0
    x0 = np.r_[0, 0, 1, 0.05, -0.03, np.pi - 0.05, 0.3, 0, 0, 0, 0, 0.05, np.zeros(6)]
    P0 = np.diag(np.r_[[0.01] * 3, [0.02] * 3, [0.05] * 6, [0.005] * 3, [0.002] * 3] ** 2)
    alpha, beta, kappa = 0.8, 2.0, 0.0
    # the filter starts the swell pair held (variance 1e-12), at P_inf once a row sets a swell
    pair = [1e-12, 1e-12] if swell is None else [swell[1] / swell[0] ** 2, swell[1]]
    ref = FilterPyModel(np.r_[x0, 0.0, 0.0], np.diag(np.r_[np.diag(P0), pair]), 0.0,
                        alpha=alpha, beta=beta, kappa=kappa, q_acc=Q_ACC, q_bias=Q_B, mu_bias=MU,
                        imu_rotation=R_IMU, dvl_rotation=R_DVL, dvl_translation=R_DVL_ARM,
                        baro_translation=BARO_ARM, dt_max=dt_max, swell=swell)  # fmt: skip
    z = np.zeros((N, 3))
    Rm = np.zeros((N, 3, 3))
    for k in range(N):
        m = 1 if kinds[k] == 3 else 3
        z[k, :m] = ref.hx(np.r_[x0, 0.0, 0.0], kinds[k]) + rng.normal(0, 0.02, m)
        Rm[k, :m, :m] = np.diag(rng.uniform(1e-4, 1e-3, m))
    wm, wc, lam = ukf.weights(n, alpha, beta, kappa)
    damping = 0.1 if swell is None else swell[2]
    process = model.ProcessModel(wm, wc, lam, Q_ACC, Q_B, MU, dt_max, False, swell_damping=damping)
    sensors = model.SensorModel(np.ascontiguousarray(R_IMU.T), np.ascontiguousarray(R_DVL.T),
                                R_DVL_ARM, BARO_ARM, np.full(4, np.inf))  # fmt: skip
    if swell is not None:
        beta = np.nan if swell[3] is None else swell[3]
        sw = np.tile([swell[0], swell[1], np.cos(beta), np.sin(beta)], (N, 1))
    meas = filter_loop.pack_measurements(t, kinds, z, Rm, None if swell is None else sw)
    out_t, out_x, out_P, counts, _ = filter_loop.run_filter(
        meas, 0.0, x0, P0, process, sensors, None
    )
    rows = []
    for k in range(N):
        x, P = ref.step(t[k], kinds[k], z[k], Rm[k])
        if k == N - 1 or t[k + 1] != t[k]:
            rows.append((t[k], x.copy(), P.copy()))
    used = [filter_loop.USED + kind for kind in range(4)]
    assert counts[used].sum() == N and counts[filter_loop.DT_CAPPED] == 1  # all used, one dt capped
    np.testing.assert_allclose(out_t, [r[0] for r in rows])
    for (_, xr, Pr), xk, Pk in zip(rows, out_x, out_P, strict=True):
        np.testing.assert_allclose(wrap_angle(xk - xr[:18]), 0, atol=1e-9)
        np.testing.assert_allclose(Pk, Pr[:18, :18], rtol=1e-7, atol=1e-12)
