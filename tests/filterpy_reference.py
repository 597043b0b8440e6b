"""The 18-state model restated in plain numpy, run by FilterPy's UnscentedKalmanFilter.

An independent statement of :mod:`undertow.estimation.model` for cross-checks: written from the
equations (eq:dynamics_model, eq:imu_meas_model .. eq:bar_meas_model and the conventions in
model.py's docstring), not from the numba kernels, and run by a peer library. It is what
``tests/test_estimation_ukf.py`` compares the filter with and what ``benchmarks/bench_ukf.py``
times against ours, so that both use the same model:

- process f: eta += J(eta) nu dt with J = diag(R_B^W, T(phi, theta)) (Euler-rate transform),
  angles wrapped, biases += mu_b dt;
- process noise Q = G diag(q_acc / dt) G^T (G = [J dt^2/2; I dt]) plus diag(q_bias dt), with J
  at the current mean;
- measurements: IMU R_imu^T omega + b-bar^g, DVL R_dvl^T (v + omega x r_dvl) (mounting),
  DR wrap(eta_2 + b^g), barometer z + e_3^T R_B^W r_bar;
- angle-aware sigma-point means (reference-point mean) and wrapped residuals for the state and
  for DR measurements (FilterPy's x_mean_fn, z_mean_fn, residual_x, residual_z);
- sigma points redrawn from (x, P) before every update, dt capped at ``dt_max``, the scaled
  sigma points of van der Merwe with the same alpha, beta, kappa.

Not modelled here: the Mahalanobis gate, the frozen bias states of the variants without bias
estimation, and the covariance repair. FilterPy is a test dependency, imported on use.
"""

from __future__ import annotations

import numpy as np

from undertow.rotations import rpy_to_matrix, wrap_angle

STATE_ANGLES = np.zeros(18, bool)
STATE_ANGLES[3:6] = True


def euler_rate(phi: float, theta: float) -> np.ndarray:
    """T(phi, theta): Euler-angle rates = T omega (Fossen)."""
    return np.array([
        [1, np.sin(phi) * np.tan(theta), np.cos(phi) * np.tan(theta)],
        [0, np.cos(phi), -np.sin(phi)],
        [0, np.sin(phi) / np.cos(theta), np.cos(phi) / np.cos(theta)],
    ])  # fmt: skip


def angle_mean(sigmas: np.ndarray, wm: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Weighted mean of the rows; angles (mask) as wrap(chi_0 + sum W_i wrap(chi_i - chi_0))."""
    ref = sigmas[0]
    d = sigmas - ref
    d[:, mask] = wrap_angle(d[:, mask])
    m = ref + wm @ d
    m[mask] = wrap_angle(m[mask])
    return m


def residual(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> np.ndarray:
    d = a - b
    d[mask] = wrap_angle(d[mask])
    return d


class FilterPyModel:
    """FilterPy's UKF on the 18-state model; ``step(t, kind, z, R)`` as one measurement of the
    filter loop (predict to t when t advances, redraw sigma points, update). ``kind`` 0 IMU,
    1 DVL, 2 DR, 3 barometer (z and R then use their first entry)."""

    def __init__(self, x0, P0, t0=0.0, *, alpha=1.0, beta=2.0, kappa=0.0, q_acc, q_bias,
                 mu_bias, imu_rotation=np.eye(3), dvl_rotation=np.eye(3),
                 dvl_translation=(0.0, 0.0, 0.0), baro_translation=(0.0, 0.0, 0.0),
                 dt_max=1.0):  # fmt: skip
        from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

        self.q_acc = np.asarray(q_acc, float)
        self.q_bias = np.asarray(q_bias, float)
        self.mu = np.asarray(mu_bias, float)
        self.imu_R = np.asarray(imu_rotation, float)
        self.dvl_R = np.asarray(dvl_rotation, float)
        self.dvl_r = np.asarray(dvl_translation, float)
        self.baro_r = np.asarray(baro_translation, float)
        self.dt_max = float(dt_max)
        self.t = float(t0)
        self.points = MerweScaledSigmaPoints(18, alpha, beta, kappa)
        self.ukf = UnscentedKalmanFilter(
            18, 3, 1.0, hx=None, fx=self.fx, points=self.points,
            x_mean_fn=lambda s, w: angle_mean(s, w, STATE_ANGLES),
            residual_x=lambda a, b: residual(a, b, STATE_ANGLES),
        )  # fmt: skip
        self.ukf.x = np.array(x0, float)
        self.ukf.P = np.array(P0, float)

    def _J(self, x):
        J = np.zeros((6, 6))
        J[:3, :3], J[3:, 3:] = rpy_to_matrix(x[3:6]), euler_rate(x[3], x[4])
        return J

    def fx(self, x, dt):
        out = x.copy()
        out[:6] = x[:6] + self._J(x) @ x[6:12] * dt
        out[3:6] = wrap_angle(out[3:6])
        out[12:] += self.mu * dt
        return out

    def Q(self, x, dt):
        G = np.vstack([self._J(x) * dt**2 / 2, np.eye(6) * dt])
        Q = np.zeros((18, 18))
        Q[:12, :12] = G @ np.diag(self.q_acc / dt) @ G.T
        Q[12:, 12:] = np.diag(self.q_bias * dt)
        return Q

    def hx(self, x, kind):
        if kind == 0:
            return self.imu_R.T @ x[9:12] + x[15:18]
        if kind == 1:
            return self.dvl_R.T @ (x[6:9] + np.cross(x[9:12], self.dvl_r))
        if kind == 2:
            return wrap_angle(x[3:6] + x[12:15])
        return np.array([x[2] + (rpy_to_matrix(x[3:6]) @ self.baro_r)[2]])

    def step(self, t, kind, z, R):
        f = self.ukf
        if t > self.t:
            dt = min(t - self.t, self.dt_max)
            f.Q = self.Q(f.x, dt)
            f.predict(dt=dt)
            self.t = t
        m = 1 if kind == 3 else 3
        zmask = np.full(m, kind == 2)
        f.sigmas_f = self.points.sigma_points(f.x, f.P)  # redraw after Q, between updates
        f.z_mean = lambda s, w: angle_mean(s, w, zmask)
        f.residual_z = lambda a, b: residual(a, b, zmask)
        f.update(np.asarray(z, float)[:m], R=np.asarray(R, float)[:m, :m],
                 hx=lambda x: self.hx(x, kind))  # fmt: skip
        f.x[3:6] = wrap_angle(f.x[3:6])
        return f.x, f.P
