"""The study's mapping helpers: the pose covariance made consistent with the error."""

import numpy as np

from undertow.log import GroundTruth
from undertow.study.maps import consistent_covariance
from undertow.trajectory import STATE_NAMES, Trajectory


def test_a_consistent_covariance_has_each_axis_mean_variance_equal_to_its_mean_squared_error():
    """S P S with S = diag(k_x, k_y, k_z, 1, ...): over the poses inside the ground truth's span
    each position axis's mean variance is its mean squared error (the poses outside do not
    count), the covariance stays positive semidefinite with the same correlations, and the
    other states keep theirs."""
    rng = np.random.default_rng(3)
    n, m = 201, len(STATE_NAMES)
    t = np.linspace(0.0, 20.0, n)
    truth = np.stack([0.5 * t, np.sin(t), 2.0 + 0.01 * t], axis=1)
    x = np.zeros((n, m))
    x[:, :3] = truth + rng.normal(0.0, [0.3, 0.05, 0.004], (n, 3))
    a = rng.normal(0.0, 0.1, (n, m, m))
    P = a @ np.transpose(a, (0, 2, 1)) + 1e-4 * np.eye(m)
    gt = GroundTruth(t=t[20:180], position=truth[20:180], orientation=np.zeros((160, 3)))
    out = consistent_covariance(Trajectory(t, x, P, variant="proposed"), gt)
    inside = slice(20, 180)
    for j in range(3):
        error = x[inside, j] - truth[inside, j]
        np.testing.assert_allclose(np.mean(out.P[inside, j, j]), np.mean(error**2), rtol=1e-12)
    np.testing.assert_array_equal(out.P[:, 3:, 3:], P[:, 3:, 3:])
    assert np.linalg.eigvalsh(out.P).min() > 0
    np.testing.assert_allclose(_correlation(out.P), _correlation(P), rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(out.x, x)


def _correlation(c):
    d = np.sqrt(np.einsum("nii->ni", c))
    return c / (d[:, :, None] * d[:, None, :])
