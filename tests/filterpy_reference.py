"""The filter's model restated in plain numpy, run by FilterPy's UnscentedKalmanFilter.

An independent statement of :mod:`undertow.estimation.model` for cross-checks: written from the
equations (eq:dynamics_model, eq:imu_meas_model .. eq:bar_meas_model and the conventions in
model.py's docstring), not from the numba kernels, and run by a peer library. It is what
``tests/test_estimation_ukf.py`` compares the filter with and what ``benchmarks/bench_ukf.py``
times against ours, so that both use the same model:

- process f: eta += J(eta) nu dt with J = diag(R_B^W, T(phi, theta)) (Euler-rate transform),
  angles wrapped, biases += mu_b dt;
- process noise Q = G diag(q_acc / dt) G^T (G = [J dt^2/2; I dt]) plus diag(q_bias dt), with J
  at the current mean;
- the swell states x[18:20] = (y, xi) (``swell`` = (omega_0, sigma^2, lambda, beta or None)):
  moved by scipy's expm(A dt), A = [[0, 1], [-omega^2, -2 lambda omega]], with the noise of Van
  Loan's method ("Computing integrals involving the matrix exponential", IEEE TAC 1978) for a
  white input of intensity q = 4 lambda omega sigma^2 (var(y') = q / (4 lambda omega)), where
  omega is the encounter frequency of the mean's velocity over ground v = R_B^W nu,
  |omega_0 - k_0 (v_x cos beta + v_y sin beta)| (k_0 = omega_0^2 / g, at least 0.1 omega_0),
  or omega_0 with lambda widened to k_0 |v_h| / omega_0 (at most 0.9) when beta is None; none
  (held: identity, no noise) without ``swell``;
- measurements: IMU R_imu^T omega + b-bar^g, DVL R_dvl^T (v + omega x r_dvl) (mounting),
  DR wrap(eta_2 + b^g), barometer z + e_3^T R_B^W r_bar + xi;
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

N = 20
STATE_ANGLES = np.zeros(N, bool)
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
    """FilterPy's UKF on the 20-state model; ``step(t, kind, z, R)`` as one measurement of the
    filter loop (predict to t when t advances, redraw sigma points, update). ``kind`` 0 IMU,
    1 DVL, 2 DR, 3 barometer (z and R then use their first entry)."""

    def __init__(self, x0, P0, t0=0.0, *, alpha=1.0, beta=2.0, kappa=0.0, q_acc, q_bias,
                 mu_bias, imu_rotation=np.eye(3), dvl_rotation=np.eye(3),
                 dvl_translation=(0.0, 0.0, 0.0), baro_translation=(0.0, 0.0, 0.0),
                 dt_max=1.0, swell=None):  # fmt: skip
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
        self.swell = swell
        self.points = MerweScaledSigmaPoints(N, alpha, beta, kappa)
        self.ukf = UnscentedKalmanFilter(
            N, 3, 1.0, hx=None, fx=self.fx, points=self.points,
            x_mean_fn=lambda s, w: angle_mean(s, w, STATE_ANGLES),
            residual_x=lambda a, b: residual(a, b, STATE_ANGLES),
        )  # fmt: skip
        self.ukf.x = np.array(x0, float)
        self.ukf.P = np.array(P0, float)

    def _J(self, x):
        J = np.zeros((6, 6))
        J[:3, :3], J[3:, 3:] = rpy_to_matrix(x[3:6]), euler_rate(x[3], x[4])
        return J

    def _band(self, x):
        """(omega, lambda) of the swell at the mean x: the encounter frequency, or omega_0 with
        the band widened to the Doppler range when the direction is unknown."""
        omega0, _, lam, beta = self.swell
        v = rpy_to_matrix(x[3:6]) @ x[6:9]
        k0 = omega0**2 / 9.80665
        if beta is None:
            return omega0, min(max(lam, k0 * np.hypot(v[0], v[1]) / omega0), 0.9)
        return max(
            abs(omega0 - k0 * (v[0] * np.cos(beta) + v[1] * np.sin(beta))), 0.1 * omega0
        ), lam

    def _swell(self, dt):
        """(Phi, Q) of the swell states over dt at the band of the mean when predicting: expm
        and Van Loan's method."""
        from scipy.linalg import expm

        if self.swell is None:
            return np.eye(2), np.zeros((2, 2))
        var = self.swell[1]
        omega, lam = self.band
        A = np.array([[0.0, 1.0], [-(omega**2), -2.0 * lam * omega]])
        q = 4.0 * lam * omega * var
        M = np.zeros((4, 4))
        M[:2, :2], M[:2, 2:], M[2:, 2:] = -A, np.array([[0, 0], [0, q]]), A.T
        E = expm(M * dt)
        Phi = E[2:, 2:].T
        return Phi, Phi @ E[:2, 2:]

    def fx(self, x, dt):
        out = x.copy()
        out[:6] = x[:6] + self._J(x) @ x[6:12] * dt
        out[3:6] = wrap_angle(out[3:6])
        out[12:18] += self.mu * dt
        out[18:20] = self._swell(dt)[0] @ x[18:20]
        return out

    def Q(self, x, dt):
        G = np.vstack([self._J(x) * dt**2 / 2, np.eye(6) * dt])
        Q = np.zeros((N, N))
        Q[:12, :12] = G @ np.diag(self.q_acc / dt) @ G.T
        Q[12:18, 12:18] = np.diag(self.q_bias * dt)
        Q[18:20, 18:20] = self._swell(dt)[1]
        return Q

    def hx(self, x, kind):
        if kind == 0:
            return self.imu_R.T @ x[9:12] + x[15:18]
        if kind == 1:
            return self.dvl_R.T @ (x[6:9] + np.cross(x[9:12], self.dvl_r))
        if kind == 2:
            return wrap_angle(x[3:6] + x[12:15])
        return np.array([x[2] + (rpy_to_matrix(x[3:6]) @ self.baro_r)[2] + x[19]])

    def step(self, t, kind, z, R):
        f = self.ukf
        if t > self.t:
            dt = min(t - self.t, self.dt_max)
            if self.swell is not None:
                self.band = self._band(f.x)
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
