"""Generic sigma-point (unscented) machinery as numba kernels on plain arrays.

Scaled unscented transform (Julier/Uhlmann, Wan/van der Merwe) for a state of dimension n:

    lambda = alpha^2 (n + kappa) - n
    chi_0 = x,  chi_i = x + sqrt(n + lambda) L_i,  chi_{n+i} = x - sqrt(n + lambda) L_i,  L L^T = P
    W^m_0 = lambda / (n + lambda),  W^c_0 = W^m_0 + 1 - alpha^2 + beta,  W_i = 1 / (2 (n + lambda))

The default alpha = 1, beta = 2, kappa = 0 gives lambda = 0, a zero centre mean weight and
sigma points at +-sqrt(n) standard deviations; it is well conditioned for n = 18, where the
often suggested alpha = 1e-3 gives W^m_0 = 1 - n / (alpha^2 (n + kappa)) ~ -1e6 and breaks the
angle means and the positive definiteness of the covariances.

Angles are handled by masks (``True`` = angle, wrapped to [-pi, pi)):

- mean: reference-point mean  mean = wrap(chi_0 + sum_i W_i wrap(chi_i - chi_0));
- residuals: wrap(a - b) for every angle entry, in covariances, cross-covariances and innovations.

Update (additive noise): z_hat = mean(Z), S = sum W^c dz dz^T + R, C = sum W^c dx dz^T,
K = C S^-1, x+ = x + K wrap(z - z_hat), P+ = P - K S K^T, symmetrized.

Sigma points are always drawn from the current (x, P) by the caller, so they are redrawn after
process noise is added and between two updates. Cholesky factorizations repair a matrix that is
not positive definite (symmetrize, floor eigenvalues) and report that they did.

Sigma points are stored as rows: ``chi`` has shape (2n+1, n).
"""

from __future__ import annotations

import numpy as np
from numba import njit

TWO_PI = 2.0 * np.pi
EIG_FLOOR_REL = 1e-12  # eigenvalue floor relative to the largest eigenvalue in a repair
EIG_FLOOR_ABS = 1e-18  # absolute eigenvalue floor in a repair


@njit(cache=True)
def wrap(a):
    """wrap(a) to [-pi, pi) (NaN stays NaN)."""
    if -np.pi <= a < np.pi:
        return a
    r = a - TWO_PI * np.floor((a + np.pi) / TWO_PI)
    return r - TWO_PI if r >= np.pi else r


@njit(cache=True)
def all_finite(a):
    """No NaN or infinity in a (a sum propagates either; a finite overflow to inf also counts
    as not finite, which is what the callers want)."""
    return np.isfinite(a.sum())


@njit(cache=True)
def weights(n, alpha, beta, kappa):
    """Mean and covariance weights (W^m, W^c) and lambda of the scaled unscented transform."""
    lam = alpha * alpha * (n + kappa) - n
    wm = np.full(2 * n + 1, 0.5 / (n + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = wm[0] + 1.0 - alpha * alpha + beta
    return wm, wc, lam


@njit(cache=True)
def _cholesky(A, L):
    """Lower Cholesky factor of A into L; False if A is not (numerically) positive definite."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:  # also catches NaN
            return False
        d = np.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
        for i in range(j):
            L[i, j] = 0.0
    return True


@njit(cache=True)
def symmetrize(P):
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            m = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = m
            P[j, i] = m


@njit(cache=True)
def cholesky_repair(P, L):
    """L L^T = P. If P is not positive definite, repair P in place (symmetrize, floor the
    eigenvalues at EIG_FLOOR_REL * max + EIG_FLOOR_ABS) and factor again.

    Returns 0 (no repair), 1 (repaired) or -1 (P not finite: nothing done).
    """
    if _cholesky(P, L):
        return 0
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            if not np.isfinite(P[i, j]):
                return -1
    symmetrize(P)
    w, V = np.linalg.eigh(P)
    floor = EIG_FLOOR_REL * max(w.max(), 0.0) + EIG_FLOOR_ABS
    for i in range(n):
        w[i] = max(w[i], floor)
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for k in range(n):
                s += V[i, k] * w[k] * V[j, k]
            P[i, j] = s
            P[j, i] = s
    if not _cholesky(P, L):  # pragma: no cover - floored eigenvalues make P PD
        for i in range(n):
            P[i, i] += floor * 10.0
        _cholesky(P, L)
    return 1


@njit(cache=True)
def sigma_points(x, P, lam, angle_mask, L, chi):
    """Sigma points chi (2n+1, n) of N(x, P); angle entries wrapped. Returns the repair flag."""
    status = cholesky_repair(P, L)
    spread(x, L, lam, angle_mask, chi)
    return status


@njit(cache=True)
def spread(x, L, lam, angle_mask, chi):
    """Sigma points chi (2n+1, n) around x from a Cholesky factor L of P; angles wrapped."""
    n = x.size
    c = np.sqrt(n + lam)
    for j in range(n):
        chi[0, j] = x[j]
    for i in range(n):
        for j in range(n):
            d = c * L[j, i]
            chi[1 + i, j] = x[j] + d
            chi[1 + n + i, j] = x[j] - d
    for j in range(n):
        if angle_mask[j]:
            for i in range(2 * n + 1):
                chi[i, j] = wrap(chi[i, j])


@njit(cache=True)
def _mean(chi, wm, angle_mask, out):
    """Weighted mean of the rows of chi; angles by the reference-point mean around chi_0."""
    npts, n = chi.shape
    for j in range(n):
        if angle_mask[j]:
            ref = chi[0, j]
            s = 0.0
            for i in range(npts):
                s += wm[i] * wrap(chi[i, j] - ref)
            out[j] = wrap(ref + s)
        else:
            s = 0.0
            for i in range(npts):
                s += wm[i] * chi[i, j]
            out[j] = s


@njit(cache=True)
def residuals(chi, mean, angle_mask, DT):
    """DT[:, i] = chi_i - mean (wrapped for angles), stored transposed (n, 2n+1)."""
    npts, n = chi.shape
    for j in range(n):
        mj = mean[j]
        if angle_mask[j]:
            for i in range(npts):
                DT[j, i] = wrap(chi[i, j] - mj)
        else:
            for i in range(npts):
                DT[j, i] = chi[i, j] - mj


@njit(cache=True, fastmath={"reassoc", "contract"})
def weighted_outer(AT, BT, wc, out):
    """out = sum_i wc_i A_i B_i^T from transposed residuals AT (na, npts), BT (nb, npts)."""
    na, npts = AT.shape
    nb = BT.shape[0]
    for a in range(na):
        for b in range(nb):
            s = 0.0
            for i in range(npts):
                s += wc[i] * AT[a, i] * BT[b, i]
            out[a, b] = s


@njit(cache=True, fastmath={"reassoc", "contract"})
def _weighted_gram(AT, wc, out):
    """out = sum_i wc_i A_i A_i^T (symmetric) from transposed residuals AT (na, npts)."""
    na, npts = AT.shape
    for a in range(na):
        for b in range(a, na):
            s = 0.0
            for i in range(npts):
                s += wc[i] * AT[a, i] * AT[b, i]
            out[a, b] = s
            out[b, a] = s


@njit(cache=True)
def predict_moments(chi_f, wm, wc, Q, angle_mask, x, P, D):
    """Unscented prediction: x = mean(f(chi)), P = sum W^c dx dx^T + Q (symmetrized);
    D is a workspace (n, 2n+1)."""
    _mean(chi_f, wm, angle_mask, x)
    residuals(chi_f, x, angle_mask, D)
    _weighted_gram(D, wc, P)
    n = x.size
    for i in range(n):
        for j in range(n):
            P[i, j] += Q[i, j]
    symmetrize(P)


@njit(cache=True)
def _solve_lower(L, b):
    """Solve L y = b (L lower triangular) in place of b."""
    m = L.shape[0]
    for i in range(m):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * b[k]
        b[i] = s / L[i, i]


@njit(cache=True)
def _solve_upper_t(L, b):
    """Solve L^T y = b (L lower triangular) in place of b."""
    m = L.shape[0]
    for i in range(m - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, m):
            s -= L[k, i] * b[k]
        b[i] = s / L[i, i]


@njit(cache=True)
def gain(C, L, out, row):
    """out = C A^{-1} for symmetric positive definite A = L L^T (the Kalman gain K = C S^{-1}
    and the RTS gain G = C (P^-)^{-1}), solved row by row: out_i^T = A^{-1} C_i^T."""
    n, m = C.shape
    for i in range(n):
        for a in range(m):
            row[a] = C[i, a]
        _solve_lower(L, row)
        _solve_upper_t(L, row)
        for a in range(m):
            out[i, a] = row[a]


@njit(cache=True)
def update(x, P, chi, Zs, z, R, wm, wc, x_angles, z_angles, gate, w_out=None):
    """Unscented measurement update with additive noise R, in place on (x, P).

    chi: sigma points (2n+1, n) drawn from (x, P); Zs: h(chi_i) as rows (2n+1, m).
    Returns (status, nis): status 0 applied, 1 rejected by the gate (nis > gate), 2 S not
    factorizable. nis = y^T S^-1 y is the normalized innovation squared. ``w_out`` (optional,
    at least m long): receives the whitened innovation w = L_S^-1 y (S = L_S L_S^T), so that
    nis = w^T w (not written when S is not factorizable).
    """
    npts, n = chi.shape
    m = z.size
    zhat = np.empty(m)
    _mean(Zs, wm, z_angles, zhat)
    Dz = np.empty((m, npts))
    residuals(Zs, zhat, z_angles, Dz)
    Dx = np.empty((n, npts))
    residuals(chi, x, x_angles, Dx)
    S = np.empty((m, m))
    _weighted_gram(Dz, wc, S)
    for a in range(m):
        for b in range(m):
            S[a, b] += R[a, b]
    symmetrize(S)
    C = np.empty((n, m))
    weighted_outer(Dx, Dz, wc, C)
    return _correct(x, P, C, S, _innovation(z, zhat, z_angles), x_angles, gate, w_out)


@njit(cache=True)
def update_linear(x, P, H, z, R, x_angles, z_angles, gate, w_out=None):
    """Measurement update for a linear h(x) = H x (angle entries of z wrapped), in place.

    The unscented transform is exact for a linear function: with sigma points of N(x, P),
    mean(H chi) = H x, sum W^c dz dz^T = H P H^T and sum W^c dx dz^T = P H^T. So this equals
    :func:`update` on the same (x, P) (tested) without drawing sigma points:

        z_hat = H x,  S = H P H^T + R,  C = P H^T,  then as :func:`update`.

    Returns (status, nis) as :func:`update`."""
    n = x.size
    m = z.size
    zhat = np.empty(m)
    C = np.empty((n, m))
    for a in range(m):
        s = 0.0
        for j in range(n):
            s += H[a, j] * x[j]
        zhat[a] = wrap(s) if z_angles[a] else s
    for i in range(n):
        for a in range(m):
            s = 0.0
            for j in range(n):
                s += P[i, j] * H[a, j]
            C[i, a] = s
    S = np.empty((m, m))
    for a in range(m):
        for b in range(m):
            s = R[a, b]
            for j in range(n):
                s += H[a, j] * C[j, b]
            S[a, b] = s
    symmetrize(S)
    return _correct(x, P, C, S, _innovation(z, zhat, z_angles), x_angles, gate, w_out)


@njit(cache=True)
def _innovation(z, zhat, z_angles):
    """y = z - z_hat, wrapped for angle entries."""
    m = z.size
    y = np.empty(m)
    for a in range(m):
        d = z[a] - zhat[a]
        y[a] = wrap(d) if z_angles[a] else d
    return y


@njit(cache=True)
def _correct(x, P, C, S, y, x_angles, gate, w_out=None):
    """Kalman correction from the moments: K = C S^-1, x += K y, P -= K S K^T (upper triangle
    mirrored), gated on nis = y^T S^-1 y = w^T w, w = L_S^-1 y. Returns (status, nis) as
    :func:`update`; ``w_out`` receives w."""
    n, m = C.shape
    Ls = np.zeros((m, m))
    if cholesky_repair(S, Ls) < 0:
        return 2, np.inf
    w = y.copy()
    _solve_lower(Ls, w)
    nis = 0.0
    for a in range(m):
        nis += w[a] * w[a]
    if w_out is not None:
        for a in range(m):
            w_out[a] = w[a]
    if not nis <= gate:
        return 1, nis
    _solve_upper_t(Ls, w)  # w = S^-1 y
    K = np.empty((n, m))
    gain(C, Ls, K, np.empty(m))  # K = C S^-1
    for i in range(n):
        s = 0.0
        for a in range(m):
            s += C[i, a] * w[a]
        x[i] += s
        if x_angles[i]:
            x[i] = wrap(x[i])
    KS = np.empty((n, m))
    for i in range(n):
        for b in range(m):
            s = 0.0
            for a in range(m):
                s += K[i, a] * S[a, b]
            KS[i, b] = s
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for a in range(m):
                s += KS[i, a] * K[j, a]
            v = P[i, j] - s
            P[i, j] = v
            P[j, i] = v
    return 0, nis
