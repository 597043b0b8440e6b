"""The factor graph's custom factors (GTSAM ``CustomFactor``, analytic Jacobians) and the IMU
preintegration parameters.

Conventions: undertow's world is z down (x north/along the tank, y east/right) and the body is
forward-right-down, so GTSAM's navigation state needs no conversion: the pose X = (R, p) is
R_B^W = Rz(psi) Ry(theta) Rx(phi) and the world position, the velocity V is world-frame, and the
gravity of :func:`imu_params` is n_g = (0, 0, +g) (``PreintegrationCombinedParams.MakeSharedD``,
the "down" navigation frame); at rest the accelerometer reads f = R^T (a - n_g) = (0, 0, -g).

GTSAM's Pose3 tangent is (d_theta, d_t), both body frame: R' = R Exp(d_theta), p' = p + R d_t to
first order (Pose3::retract). With [w]x the skew matrix of w and e_3 = (0, 0, 1):

- DVL (keys X_k, V_k; :func:`dvl_factor`):
  e = R^T v - u,  u = v_d - (omega - b_0) x r_dvl, the DVL point's body velocity v_d corrected by
  the lever arm with the gyro at the report (its initial bias b_0 removed);
  de/d_theta = [R^T v]x, de/d_t = 0, de/dv = R^T. Noise: the row's covariance (body frame).
- Depth (X_k, V_k; :func:`depth_factor`): the barometer at lever arm r_bar, dt = t_d - t_k after
  the keyframe: e = p_z + v_z dt + e_3^T R r_bar - d;  de/d_theta = -e_3^T R [r_bar]x,
  de/d_t = e_3^T R, de/dv = dt e_3^T. Noise: the depth std.
- DR attitude (X_k [, D_k]; :func:`dr_factor`): with E = Exp((omega - b_0) dt) the rotation from
  the keyframe to the report, e = wrap(rpy(R E) + b - z), b the DR bias D_k (or its held value);
  de/d_theta = T(rpy(R E)) E^T (T the Euler-rate matrix: rpy-rates = T omega_body),
  de/d_t = 0, de/db = I. Noise: the row's covariance.

Each Jacobian is tested against central differences on the manifold
(``tests/peers/test_gtsam_factors.py``).
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError
from ..rotations import matrix_to_rpy, wrap_angle
from .inputs import euler_rate_matrix

E3 = np.array([0.0, 0.0, 1.0])
#: the preintegration's velocity-integration noise std (GTSAM's integrationCovariance): 1e-3;
#: GTSAM's examples' 1e-4 makes the Hessian of a vehicle that stops so ill-conditioned (about
#: 1e10) that gtsam.Marginals refuses it as indeterminate, for estimates equal to the millimetre
INTEGRATION_STD = 1e-3


def require_gtsam():
    """The gtsam module, or one ConfigError line naming the extra that installs it."""
    try:
        import gtsam
    except ImportError:
        raise ConfigError(
            "the factor-graph peers need GTSAM: pip install undertow[peers] (gtsam>=4.3)"
        ) from None
    return gtsam


def skew(w) -> np.ndarray:
    """[w]x, so that [w]x a = w x a."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def so3_exp(w) -> np.ndarray:
    """Exp(w) (Rodrigues)."""
    angle = float(np.linalg.norm(w))
    K = skew(w)
    if angle < 1e-9:
        return np.eye(3) + K
    return np.eye(3) + np.sin(angle) / angle * K + (1 - np.cos(angle)) / angle**2 * K @ K


def imu_params(inputs, integration_std: float = INTEGRATION_STD):
    """PreintegrationCombinedParams of the run: gravity (0, 0, g) (z down), the continuous
    densities of the per-sample stds (sigma_c^2 = sigma_d^2 dt, dt the median IMU step) and the
    bias walks; ``integration_std`` the velocity-integration noise (:data:`INTEGRATION_STD`)."""
    gtsam = require_gtsam()
    from ..log import G0

    dt = float(np.median(np.diff(inputs.imu_t))) if inputs.imu_t.size > 1 else 0.01
    params = gtsam.PreintegrationCombinedParams.MakeSharedD(G0)
    params.setGyroscopeCovariance(np.diag(inputs.gyro_std_rad_s**2 * dt))
    params.setAccelerometerCovariance(np.diag(inputs.accel_std_m_s2**2 * dt))
    params.setIntegrationCovariance(np.eye(3) * integration_std**2)
    params.setBiasOmegaCovariance(np.diag(inputs.gyro_bias_walk_density))
    params.setBiasAccCovariance(np.diag(inputs.accel_bias_walk_density))
    return params


def gaussian(cov):
    """A Gaussian noise model of the covariance ``cov`` (a scalar: its variance)."""
    gtsam = require_gtsam()
    cov = np.atleast_2d(np.asarray(cov, float))
    return gtsam.noiseModel.Gaussian.Covariance(cov)


def dvl_error(R: np.ndarray, v: np.ndarray, u: np.ndarray):
    """(e, de/d(pose) 3x6, de/dv 3x3) of the DVL factor (module doc)."""
    vb = R.T @ v
    return vb - u, np.hstack([skew(vb), np.zeros((3, 3))]), R.T


def depth_error(R, p, v, r_bar, dt: float, d: float):
    """(e (1,), de/d(pose) 1x6, de/dv 1x3) of the depth factor (module doc)."""
    e = p[2] + v[2] * dt + (R @ r_bar)[2] - d
    H_pose = np.hstack([-(R[2] @ skew(r_bar)), R[2]])[None]
    return np.array([e]), H_pose, (dt * E3)[None]


def dr_error(R, E, b, z):
    """(e (3,), de/d(pose) 3x6, de/db) of the DR attitude factor (module doc)."""
    RE = R @ E
    rpy = matrix_to_rpy(RE)
    e = wrap_angle(rpy + b - z)
    T = euler_rate_matrix(rpy)[0]
    return np.asarray(e, float), np.hstack([T @ E.T, np.zeros((3, 3))]), np.eye(3)


def dvl_factor(x_key: int, v_key: int, u: np.ndarray, cov: np.ndarray):
    """The DVL body-velocity factor on (X_k, V_k) with the compensated measurement u."""
    gtsam = require_gtsam()
    u = np.asarray(u, float)

    def error(this, values, H):
        pose = values.atPose3(x_key)
        e, H_pose, H_v = dvl_error(pose.rotation().matrix(), values.atVector(v_key), u)
        if H is not None:
            H[0], H[1] = H_pose, H_v
        return e

    return gtsam.CustomFactor(gaussian(cov), [x_key, v_key], error)


def depth_factor(x_key: int, v_key: int, d: float, std: float, r_bar, dt: float):
    """The barometric depth factor on (X_k, V_k), the report ``dt`` after the keyframe."""
    gtsam = require_gtsam()
    r_bar = np.asarray(r_bar, float)

    def error(this, values, H):
        pose = values.atPose3(x_key)
        R, p = pose.rotation().matrix(), pose.translation()
        e, H_pose, H_v = depth_error(R, p, values.atVector(v_key), r_bar, dt, d)
        if H is not None:
            H[0], H[1] = H_pose, H_v
        return e

    return gtsam.CustomFactor(gaussian(std**2), [x_key, v_key], error)


def dr_factor(x_key: int, d_key: int | None, z, cov, E, held_bias=None):
    """The DR attitude factor on X_k and the DR bias D_k (``d_key`` None: the bias held at
    ``held_bias``, a factor on X_k alone)."""
    gtsam = require_gtsam()
    z, E = np.asarray(z, float), np.asarray(E, float)
    held = np.zeros(3) if held_bias is None else np.asarray(held_bias, float)
    keys = [x_key] if d_key is None else [x_key, d_key]

    def error(this, values, H):
        R = values.atPose3(x_key).rotation().matrix()
        b = held if d_key is None else values.atVector(d_key)
        e, H_pose, H_b = dr_error(R, E, b, z)
        if H is not None:
            H[0] = H_pose
            if d_key is not None:
                H[1] = H_b
        return e

    return gtsam.CustomFactor(gaussian(cov), keys, error)
