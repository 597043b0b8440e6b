"""The InEKF's kernels: Jacobians against numerical derivatives, a static vehicle against the
closed form of a pure-noise propagation, and a constant-velocity line in closed form with a
Monte Carlo NEES."""

import numpy as np
from conftest import numeric_jacobian
from scipy.stats import chi2

from undertow.peers.inekf_core import (
    InekfModel,
    depth_innovation,
    dvl_innovation,
    propagate,
    run_inekf,
    transition,
    update_attitude,
)
from undertow.peers.lie import se23_exp, se23_inverse, se23_log, so3_exp

G = 9.80665
RATE = 100.0


def _model(**kw):
    base = dict(
        gyro_density=np.full(3, 1e-7), accel_density=np.full(3, 1e-5),
        gyro_bias_walk=np.full(3, 1e-14), accel_bias_walk=np.full(3, 1e-14),
        gyro_sample_var=np.full(3, 1e-5), dvl_R=so3_exp(np.array([0.0, 0.0, 0.05])),
        dvl_r=np.array([0.164, 0.004, 0.284]), baro_r=np.array([-0.1, 0.05, 0.2]),
        gravity=G, gate_dvl=np.inf, gate_depth=np.inf, gate_attitude=np.inf, max_dt=1.0,
    )  # fmt: skip
    base.update(kw)
    return InekfModel(**base)


def _state(rng):
    R, v, p = se23_exp(rng.normal(size=9) * np.r_[0.4, 0.4, 0.4, 0.5, 0.5, 0.5, 3, 3, 3])
    return (R, v, p), rng.normal(size=6) * 0.01


def _perturb_right(X, b, e):
    """X = exp(e[:9]) X_hat, b = b_hat + e[9:]."""
    dR, dv, dp = se23_exp(e[:9])
    R, v, p = X
    return (dR @ R, dR @ v + dv, dR @ p + dp), b + e[9:]


def _numeric(fun, n=15, h=1e-6):
    return numeric_jacobian(fun, n, h)


def test_dvl_jacobian_matches_numerical_derivative_of_the_measurement_model():
    """The innovation of the noise-free reading of a perturbed true state, y = R_d^T (R^T v +
    (omega_m - b_g) x r), is H e to first order."""
    rng = np.random.default_rng(0)
    model = _model()
    X, b = _state(rng)
    omega_m = rng.normal(size=3) * 0.5

    def z_of(e):
        (R, v, _), bt = _perturb_right(X, b, e)
        y = model.dvl_R.T @ (R.T @ v + np.cross(omega_m - bt[:3], model.dvl_r))
        return dvl_innovation(X[0], X[1], b, y, np.eye(3), omega_m, model)[0]

    H = dvl_innovation(X[0], X[1], b, np.zeros(3), np.eye(3), omega_m, model)[1]
    assert np.allclose(z_of(np.zeros(15)), 0.0, atol=1e-12)
    assert np.allclose(_numeric(z_of), H, atol=1e-7)


def test_depth_jacobian_matches_numerical_derivative_in_the_left_invariant_error():
    rng = np.random.default_rng(1)
    model = _model()
    X, b = _state(rng)

    def z_of(e):  # true state X_hat exp(e): the left-invariant error
        dR, dv, dp = se23_exp(e[:9])
        R, p = X[0] @ dR, X[0] @ dp + X[2]
        d = p[2] + (R @ model.baro_r)[2]
        return depth_innovation(X[0], X[2], d, model)[0]

    H = depth_innovation(X[0], X[2], 0.0, model)[1]
    assert np.allclose(_numeric(z_of), H, atol=1e-7)


def test_attitude_update_jacobian_is_the_identity_on_the_attitude_error():
    rng = np.random.default_rng(2)
    X, b = _state(rng)
    P = np.eye(15) * 1e-2
    model = _model()
    xi = np.r_[0.01, -0.02, 0.015]
    Rm = so3_exp(xi) @ X[0]
    # with a tiny noise, the update moves the attitude onto the reading
    R, *_ = update_attitude(*X, b, P, Rm, np.eye(3) * 1e-14, model)
    assert np.allclose(R, Rm, atol=1e-9)


def test_transition_matches_numerical_derivative_of_the_propagation():
    """exp(A dt) against the error of the propagated mean of a perturbed state (dt small: the
    mean's Euler step and the held-estimate transition agree to O(dt^2))."""
    rng = np.random.default_rng(3)
    model = _model()
    X, b = _state(rng)
    w, f, dt = rng.normal(size=3), rng.normal(size=3) + np.r_[0, 0, -G], 1e-4
    Xp = propagate(*X, b, np.eye(15), w, f, dt, model)[:3]

    def e_of(e):
        Xt, bt = _perturb_right(X, b, e)
        Rt, vt, pt = propagate(*Xt, bt, np.eye(15), w, f, dt, model)[:3]
        Ri, vi, pi = se23_inverse(*Xp)
        return np.r_[se23_log(Rt @ Ri, Rt @ vi + vt, Rt @ pi + pt), bt - b]

    Phi = transition(*X, dt, G)
    assert np.allclose(_numeric(e_of), Phi, atol=1e-6)


def test_static_vehicle_covariance_follows_the_pure_noise_closed_form():
    """At rest at the origin (R = I, v = p = 0, known biases), with no update:
    xi_R = xi_R0 + W_g, xi_v = [g]x int xi_R + W_a, xi_p = int xi_v, so
    P_vv = s_a t + G (P_RR0 t^2 + s_g t^3 / 3) G^T,
    P_pp = P_pp0 + s_a t^3 / 3 + G (P_RR0 t^4 / 4 + s_g t^5 / 20) G^T, and the mean stays put."""
    model = _model(gyro_bias_walk=np.zeros(3), accel_bias_walk=np.zeros(3))
    R, v, p, b = np.eye(3), np.zeros(3), np.zeros(3), np.zeros(6)
    P = np.zeros((15, 15))
    P[0:3, 0:3] = np.diag([1e-4, 2e-4, 3e-4])
    P[6:9, 6:9] = np.eye(3) * 0.01
    P0 = P.copy()
    n, dt = 1000, 1.0 / RATE
    for _ in range(n):
        R, v, p, P = propagate(R, v, p, b, P, np.zeros(3), np.r_[0.0, 0.0, -G], dt, model)
    t = n * dt
    assert np.allclose(R, np.eye(3)) and np.allclose(v, 0) and np.allclose(p, 0)
    Gx = np.array([[0, -G, 0], [G, 0, 0], [0, 0, 0.0]])
    sg, sa, PRR = model.gyro_density[0], model.accel_density[0], P0[0:3, 0:3]
    assert np.allclose(P[0:3, 0:3], PRR + sg * t * np.eye(3), rtol=1e-9)
    Pvv = sa * t * np.eye(3) + Gx @ (PRR * t**2 + sg * t**3 / 3 * np.eye(3)) @ Gx.T
    Ppp = P0[6:9, 6:9] + sa * t**3 / 3 * np.eye(3)
    Ppp = Ppp + Gx @ (PRR * t**4 / 4 + sg * t**5 / 20 * np.eye(3)) @ Gx.T
    assert np.allclose(P[3:6, 3:6], Pvv, rtol=0.02)
    assert np.allclose(P[6:9, 6:9], Ppp, rtol=0.02)


def _line(rng, model, T=20.0, v_world=(0.5, 0.2, 0.05), noise=True, P0=None):
    """A constant-velocity line (closed form: p = p0 + v t, R constant) and its readings."""
    R = so3_exp(np.r_[0.02, -0.03, 0.7])
    v = np.asarray(v_world)
    p0 = np.r_[1.0, -2.0, 3.0]
    b = np.r_[0.002, -0.001, 0.003, 0.02, -0.03, 0.01]
    if P0 is not None:  # truth drawn around the estimate with the filter's P0
        e = rng.multivariate_normal(np.zeros(15), P0) if noise else np.zeros(15)
    else:
        e = np.zeros(15)
    ti = np.arange(int(T * RATE) + 1) / RATE
    s = (lambda var, n: rng.normal(size=(n, 3)) * np.sqrt(var)) if noise else (
        lambda var, n: np.zeros((n, 3)))  # fmt: skip
    Rt, vt, pt, _ = _perturb_right((R, v, p0), b, e)[0] + (None,)
    bt = b + e[9:]
    gyro = bt[:3] + s(model.gyro_density * RATE, ti.size)
    accel = Rt.T @ np.r_[0, 0, -G] + bt[3:] + s(model.accel_density * RATE, ti.size)
    td = np.arange(0.1, T, 0.125)
    Cd = np.eye(3) * 1e-4
    vd = (model.dvl_R.T @ Rt.T @ vt)[None]  # the true angular velocity is 0: no lever-arm term
    y = vd + s(np.diag(Cd), td.size)
    tp = np.arange(0.05, T, 0.1)
    d = pt[2] + vt[2] * tp + (Rt @ model.baro_r)[2] + s(np.full(3, 1e-4), tp.size)[:, 0]
    truth = (Rt, vt, pt, bt)
    est = (R, v, p0, b)
    return truth, est, (ti, gyro, accel, td, y, np.tile(Cd, (td.size, 1, 1)), tp, d,
                        np.full(tp.size, 1e-4))  # fmt: skip


P0_LINE = np.diag(np.r_[[1e-4] * 3, [1e-2] * 3, [1e-2] * 3, [1e-6] * 3, [1e-4] * 3])


def _run(streams, est, model, P0=P0_LINE):
    R, v, p, b = est
    return run_inekf(*streams, t0=0.0, R0=R, v0=v, p0=p, b0=b, P0=P0, model=model)


def test_noise_free_constant_velocity_line_is_followed_exactly():
    """Exact readings from the exact start: p(T) = p0 + v T, v and R unchanged."""
    model = _model()
    rng = np.random.default_rng(5)
    (Rt, vt, pt, bt), est, streams = _line(rng, model, noise=False)
    out = _run(streams, est, model)
    T = out.t[-1]
    assert np.allclose(out.p[-1], pt + vt * T, atol=1e-9)
    assert np.allclose(out.v[-1], vt, atol=1e-10) and np.allclose(out.R[-1], Rt, atol=1e-10)
    assert np.allclose(out.b[-1], bt, atol=1e-10)
    assert np.all(out.applied)


def test_constant_velocity_line_monte_carlo_position_and_nees_are_consistent():
    """20 runs, truth drawn from P0 around the estimate: the final position lies within 4 sigma of
    p0 + v T per axis in every run, and 20 * mean NEES is inside chi2(20 * 15)'s 0.1-99.9 %
    interval at four times; the observed states' variances stay bounded (depth, velocity,
    roll and pitch) while x, y and yaw grow."""
    model = _model()
    rng = np.random.default_rng(6)
    runs, checks = 20, (2.0, 8.0, 14.0, 19.8)
    nees = np.zeros((runs, len(checks)))
    for k in range(runs):
        (Rt, vt, pt, bt), est, streams = _line(rng, model, P0=P0_LINE)
        out = _run(streams, est, model)
        sd = np.sqrt(out.P[-1].diagonal())
        T = out.t[-1]
        dp = pt + vt * T - out.p[-1]  # a world-position error (xi_p + [p]x xi_R to 1st order)
        sd_p = np.sqrt(np.diag(_position_cov(out, -1)))
        assert np.all(np.abs(dp) < 4 * sd_p), (dp, sd_p)
        for c, tc in enumerate(checks):
            i = int(np.searchsorted(out.t, tc))
            Ri, vi, pi = se23_inverse(out.R[i], out.v[i], out.p[i])
            ptc = pt + vt * out.t[i]
            e = np.r_[se23_log(Rt @ Ri, Rt @ vi + vt, Rt @ pi + ptc), bt - out.b[i]]
            nees[k, c] = e @ np.linalg.solve(out.P[i], e)
    lo, hi = chi2.ppf([0.001, 0.999], runs * 15)
    total = nees.sum(axis=0)
    assert np.all((total > lo) & (total < hi)), (total, lo, hi)
    sd0 = np.sqrt(P0_LINE.diagonal())
    assert np.all(sd[[0, 1, 3, 4, 5]] < sd0[[0, 1, 3, 4, 5]])  # roll, pitch, velocity observed
    assert np.sqrt(_position_cov(out, -1)[2, 2]) < 0.02  # depth observed
    assert np.all(sd_p[:2] > sd0[6]) and sd[2] > 0.5 * sd0[2]  # x, y grow; yaw is kept


def _position_cov(out, i):
    """Cov(dp) of the world position error dp = xi_p - [p]x xi_R."""
    from undertow.peers.inekf import ordinary_covariance

    return ordinary_covariance(out.P[i : i + 1 or None], out.v[i : i + 1 or None],
                               out.p[i : i + 1 or None])[0, 6:9, 6:9]  # fmt: skip


def test_dr_bias_states_split_a_heading_offset_as_the_two_state_closed_form():
    """At rest, level, exact IMU, m attitude readings R_m = Rz(c) with variance s_n: the heading
    error xi and the DR-bias b_d (about z) see z = xi + b_d + n, the rest of the state nothing,
    so their posterior is the linear Kalman filter's in closed form,
    P+ = (P0^-1 + m / s_n [[1, 1], [1, 1]])^-1, mean = P+ (m c / s_n) (1, 1)."""
    model = _model(gyro_density=np.zeros(3), gyro_bias_walk=np.zeros(3),
                   accel_bias_walk=np.zeros(3), dr_bias_walk=np.zeros(3))  # fmt: skip
    s_r, s_b, s_n, c, m = 4e-4, 1e-3, 2.5e-5, 0.02, 10
    P0 = np.zeros((18, 18))
    P0[0:3, 0:3], P0[15:18, 15:18] = np.eye(3) * s_r, np.eye(3) * s_b
    P0[6:9, 6:9] = np.eye(3) * 1e-2
    ti = np.arange(0, 101) / RATE
    ta = np.arange(1, m + 1) / m
    no_dvl = (np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)))
    no_depth = (np.zeros(0), np.zeros(0), np.zeros(0))
    out = run_inekf(ti, np.zeros((ti.size, 3)), np.tile([0.0, 0.0, -G], (ti.size, 1)),
                    *no_dvl, *no_depth, t0=0.0, R0=np.eye(3), v0=np.zeros(3),
                    p0=np.zeros(3), b0=np.zeros(9), P0=P0, model=model,
                    attitude=(ta, np.tile(so3_exp(np.r_[0.0, 0.0, c]), (m, 1, 1)),
                              np.tile(np.eye(3) * s_n, (m, 1, 1))))  # fmt: skip
    post = np.linalg.inv(np.diag([1 / s_r, 1 / s_b]) + m / s_n * np.ones((2, 2)))
    mean = post @ np.full(2, m * c / s_n)
    yaw = np.arctan2(out.R[-1][1, 0], out.R[-1][0, 0])
    assert out.b.shape == (m, 9) and out.P.shape == (m, 18, 18) and np.all(out.applied)
    assert np.allclose([yaw, out.b[-1, 8]], mean, rtol=1e-6, atol=1e-12)
    assert np.allclose(out.P[-1][np.ix_([2, 17], [2, 17])], post, rtol=1e-6)
    assert np.allclose(out.b[-1, 6:8], 0.0, atol=1e-12)
