"""Sigma-point kernels against the Kalman filter (linear model) and FilterPy (18-state model)."""

from __future__ import annotations

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from undertow.estimation import model, ukf
from undertow.rotations import rpy_to_matrix, wrap_angle

NO_ANGLES = np.zeros(4, dtype=np.bool_)


def test_weights_well_conditioned_for_18_states():
    wm, wc, lam = ukf._weights(18, 1.0, 2.0, 0.0)
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
    wm, wc, lam = ukf._weights(4, 0.7, 2.0, 0.0)
    L, chi = np.zeros((4, 4)), np.empty((9, 4))
    D = np.empty((4, 9))
    for _ in range(20):
        z = H @ rng.normal(size=4) + rng.normal(size=3)
        x_kf, P_kf = F @ x_kf, F @ P_kf @ F.T + Q
        S = H @ P_kf @ H.T + R
        K = P_kf @ H.T @ np.linalg.inv(S)
        x_kf, P_kf = x_kf + K @ (z - H @ x_kf), P_kf - K @ S @ K.T
        ukf._sigma_points(x, P, lam, NO_ANGLES, L, chi)
        ukf._predict_moments(np.ascontiguousarray(chi @ F.T), wm, wc, Q, NO_ANGLES, x, P, D)
        ukf._sigma_points(x, P, lam, NO_ANGLES, L, chi)
        Zs = np.ascontiguousarray(chi @ H.T)
        status, _ = ukf._update(x, P, chi, Zs, z, R, wm, wc, NO_ANGLES, NO_ANGLES[:3], np.inf)
        assert status == 0
        np.testing.assert_allclose(x, x_kf, rtol=0, atol=1e-9)
        np.testing.assert_allclose(P, P_kf, rtol=0, atol=1e-9)


def test_cholesky_repair_makes_pd():
    P = np.diag([1.0, 1e-3, -1e-6])
    L = np.zeros((3, 3))
    assert ukf._cholesky_repair(P, L) == 1
    np.testing.assert_allclose(L @ L.T, P, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(P) > 0)


# --- an independent numpy version of the 18-state model for FilterPy --------------------------
R_DVL = rpy_to_matrix([0.0, 0.0, 0.05])
R_DVL_ARM = np.array([0.164, 0.004, 0.284])
BARO_ARM = np.array([0.0, 0.1, -0.05])
Q_ACC, Q_B, MU = np.full(6, 0.02), np.full(6, 1e-6), np.array([0, 0, 1e-3, 0, 0, 0])


def euler_rate(phi, theta):
    return np.array([
        [1, np.sin(phi) * np.tan(theta), np.cos(phi) * np.tan(theta)],
        [0, np.cos(phi), -np.sin(phi)],
        [0, np.sin(phi) / np.cos(theta), np.cos(phi) / np.cos(theta)],
    ])  # fmt: skip


def fx(x, dt):
    J = np.zeros((6, 6))
    J[:3, :3], J[3:, 3:] = rpy_to_matrix(x[3:6]), euler_rate(x[3], x[4])
    out = x.copy()
    out[:6] = x[:6] + J @ x[6:12] * dt
    out[3:6] = wrap_angle(out[3:6])
    out[12:] += MU * dt
    return out


def q_matrix(x, dt):
    J = np.zeros((6, 6))
    J[:3, :3], J[3:, 3:] = rpy_to_matrix(x[3:6]), euler_rate(x[3], x[4])
    G = np.vstack([J * dt**2 / 2, np.eye(6) * dt])
    Q = np.zeros((18, 18))
    Q[:12, :12] = G @ np.diag(Q_ACC / dt) @ G.T
    Q[12:, 12:] = np.diag(Q_B * dt)
    return Q


def hx(x, kind):
    if kind == 0:
        return x[9:12] + x[15:18]
    if kind == 1:
        return R_DVL.T @ (x[6:9] + np.cross(x[9:12], R_DVL_ARM))
    if kind == 2:
        return wrap_angle(x[3:6] + x[12:15])
    return np.array([x[2] + (rpy_to_matrix(x[3:6]) @ BARO_ARM)[2]])


def angle_mean(sigmas, wm, mask):
    ref = sigmas[0]
    d = sigmas - ref
    d[:, mask] = wrap_angle(d[:, mask])
    m = ref + wm @ d
    m[mask] = wrap_angle(m[mask])
    return m


def residual(a, b, mask):
    d = a - b
    d[mask] = wrap_angle(d[mask])
    return d


def test_full_model_agrees_with_filterpy():
    rng = np.random.default_rng(7)
    n, N = 18, 80
    kinds = rng.integers(0, 4, N)
    t = np.sort(np.round(rng.uniform(0, 4, N), 2))  # some equal times: updates without predict
    x0 = np.r_[0, 0, 1, 0.05, -0.03, np.pi - 0.05, 0.3, 0, 0, 0, 0, 0.05, np.zeros(6)]
    P0 = np.diag(np.r_[[0.01] * 3, [0.02] * 3, [0.05] * 6, [0.005] * 3, [0.002] * 3] ** 2)
    z = np.zeros((N, 3))
    Rm = np.zeros((N, 3, 3))
    for k in range(N):
        m = 1 if kinds[k] == 3 else 3
        z[k, :m] = hx(x0, kinds[k]) + rng.normal(0, 0.02, m)
        Rm[k, :m, :m] = np.diag(rng.uniform(1e-4, 1e-3, m))
    alpha, beta, kappa = 0.8, 2.0, 0.0
    wm, wc, lam = ukf._weights(n, alpha, beta, kappa)
    out_t, out_x, out_P, counts = model._run_filter(
        t, kinds, z, Rm, x0, P0, 0.0, wm, wc, lam, Q_ACC, Q_B, MU, np.eye(3),
        np.ascontiguousarray(R_DVL.T), R_DVL_ARM, BARO_ARM, 10.0, np.full(4, np.inf), False,
        np.empty(0), True, N,
    )  # fmt: skip

    smask = np.zeros(n, bool)
    smask[3:6] = True
    pts = MerweScaledSigmaPoints(n, alpha, beta, kappa)
    f = UnscentedKalmanFilter(n, 3, 1.0, hx=None, fx=fx, points=pts,
                              x_mean_fn=lambda s, w: angle_mean(s, w, smask),
                              residual_x=lambda a, b: residual(a, b, smask))  # fmt: skip
    f.x, f.P = x0.copy(), P0.copy()
    t_cur, rows = 0.0, []
    for k in range(N):
        if t[k] > t_cur:
            f.Q = q_matrix(f.x, t[k] - t_cur)
            f.predict(dt=t[k] - t_cur)
            t_cur = t[k]
        m = 1 if kinds[k] == 3 else 3
        zmask = np.full(m, kinds[k] == 2)
        f.sigmas_f = pts.sigma_points(f.x, f.P)  # redraw between updates (as the kernel does)
        f.z_mean = lambda s, w, zm=zmask: angle_mean(s, w, zm)
        f.residual_z = lambda a, b, zm=zmask: residual(a, b, zm)
        f.update(z[k, :m], R=Rm[k, :m, :m], hx=lambda x, kd=kinds[k]: hx(x, kd))
        f.x[3:6] = wrap_angle(f.x[3:6])
        if k == N - 1 or t[k + 1] != t[k]:
            rows.append((t[k], f.x.copy(), f.P.copy()))
    assert counts[:4].sum() == N
    np.testing.assert_allclose(out_t, [r[0] for r in rows])
    for (_, xr, Pr), xk, Pk in zip(rows, out_x, out_P, strict=True):
        np.testing.assert_allclose(wrap_angle(xk - xr), 0, atol=1e-9)
        np.testing.assert_allclose(Pk, Pr, rtol=1e-7, atol=1e-12)
