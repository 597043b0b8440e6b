"""SO(3) and SE_2(3) in closed form: hat, exponential, logarithm, left Jacobian, adjoint.

SE_2(3) (Barrau and Bonnabel, "The invariant extended Kalman filter as a stable observer",
IEEE TAC 62(4), 2017, section V) holds an attitude R, a velocity v and a position p as the 5x5
matrix

    X = [[R, v, p], [0, 1, 0], [0, 0, 1]],   X^-1 = (R^T, -R^T v, -R^T p).

Its Lie algebra vector is xi = (phi, nu, rho) (rotation, velocity, position parts, 9 entries):

    exp(xi) = (Exp(phi), J(phi) nu, J(phi) rho),      log(X) = (Log R, J^-1 v, J^-1 p)

with Exp the Rodrigues formula, J the left Jacobian of SO(3) (theta = |phi|, W = [phi]x):

    Exp(phi) = I + sin(theta)/theta W + (1 - cos(theta))/theta^2 W^2
    J(phi)   = I + (1 - cos(theta))/theta^2 W + (theta - sin(theta))/theta^3 W^2
    J^-1     = I - W/2 + (1/theta^2 - (1 + cos(theta)) / (2 theta sin(theta))) W^2

(Barfoot, "State Estimation for Robotics", 2017, eqs. 7.37, 7.86, 7.94) and the adjoint

    Ad_X = [[R, 0, 0], [[v]x R, R, 0], [[p]x R, 0, R]],   X exp(xi) X^-1 = exp(Ad_X xi).

Small angles use the Taylor series of each coefficient. The functions are numba-compiled so
that the filter's loop (:mod:`undertow.peers.inekf_core`) calls them without leaving machine
code; they take and return plain float64 arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_SMALL = 1e-6  # |phi| below which the Taylor series of the coefficients are used


@njit(cache=True)
def hat(w):
    """[w]x, the 3x3 skew matrix with [w]x u = w x u."""
    W = np.zeros((3, 3))
    W[0, 1], W[0, 2] = -w[2], w[1]
    W[1, 0], W[1, 2] = w[2], -w[0]
    W[2, 0], W[2, 1] = -w[1], w[0]
    return W


@njit(cache=True)
def so3_exp(phi):
    """Exp(phi) by the Rodrigues formula."""
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    th = np.sqrt(th2)
    W = hat(phi)
    if th < _SMALL:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        a, b = np.sin(th) / th, (1.0 - np.cos(th)) / th2
    return np.eye(3) + a * W + b * (W @ W)


@njit(cache=True)
def so3_log(R):
    """Log(R), the rotation vector phi with Exp(phi) = R (|phi| <= pi)."""
    c = min(max(0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0), -1.0), 1.0)
    th = np.arccos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if th < _SMALL:
        return 0.5 * (1.0 + th * th / 6.0) * w
    if np.pi - th < 1e-4:  # near pi: the axis from the symmetric part (R + R^T)/2 + I ~ 2 a a^T
        B = 0.25 * (R + R.T) + 0.5 * np.eye(3)
        k = np.argmax(np.array([B[0, 0], B[1, 1], B[2, 2]]))
        a = B[:, k] / np.sqrt(max(B[k, k], 1e-300))
        if a[0] * w[0] + a[1] * w[1] + a[2] * w[2] < 0.0:
            a = -a
        return th * a / np.sqrt(a @ a)
    return th / (2.0 * np.sin(th)) * w


@njit(cache=True)
def so3_left_jacobian(phi):
    """J(phi), the left Jacobian of SO(3)."""
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    th = np.sqrt(th2)
    W = hat(phi)
    if th < _SMALL:
        a, b = 0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0
    else:
        a, b = (1.0 - np.cos(th)) / th2, (th - np.sin(th)) / (th2 * th)
    return np.eye(3) + a * W + b * (W @ W)


@njit(cache=True)
def so3_left_jacobian_inv(phi):
    """J(phi)^-1."""
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    th = np.sqrt(th2)
    W = hat(phi)
    if th < _SMALL:
        c = 1.0 / 12.0 + th2 / 720.0
    else:
        c = 1.0 / th2 - (1.0 + np.cos(th)) / (2.0 * th * np.sin(th))
    return np.eye(3) - 0.5 * W + c * (W @ W)


@njit(cache=True)
def se23_exp(xi):
    """exp(xi) of xi = (phi, nu, rho) (9,): the triple (R, v, p)."""
    phi = xi[0:3].copy()
    J = so3_left_jacobian(phi)
    return so3_exp(phi), J @ xi[3:6].copy(), J @ xi[6:9].copy()


@njit(cache=True)
def se23_log(R, v, p):
    """log(X) (9,) of X = (R, v, p)."""
    phi = so3_log(R)
    Ji = so3_left_jacobian_inv(phi)
    out = np.empty(9)
    out[0:3] = phi
    out[3:6] = Ji @ v
    out[6:9] = Ji @ p
    return out


@njit(cache=True)
def se23_adjoint(R, v, p):
    """Ad_X (9, 9) of X = (R, v, p), for xi ordered (phi, nu, rho)."""
    A = np.zeros((9, 9))
    A[0:3, 0:3] = R
    A[3:6, 3:6] = R
    A[6:9, 6:9] = R
    A[3:6, 0:3] = hat(v) @ R
    A[6:9, 0:3] = hat(p) @ R
    return A


@njit(cache=True)
def se23_inverse(R, v, p):
    """X^-1 = (R^T, -R^T v, -R^T p)."""
    Rt = R.T.copy()
    return Rt, -(Rt @ v), -(Rt @ p)


@njit(cache=True)
def se23_compose(R1, v1, p1, R2, v2, p2):
    """X1 X2 = (R1 R2, R1 v2 + v1, R1 p2 + p1)."""
    return R1 @ R2, R1 @ v2 + v1, R1 @ p2 + p1


def se23_matrix(R, v, p) -> np.ndarray:
    """The 5x5 matrix of X = (R, v, p) (for tests and printing)."""
    X = np.eye(5)
    X[:3, :3] = R
    X[:3, 3] = v
    X[:3, 4] = p
    return X
