"""The covariance sent to the autopilot: MAVLink's 21-term layout, the frame turn and inflation,
ArduPilot's reduction and the confidence mapping, against closed forms and independent
enumerations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from undertow.live.autopilot import covariance as cov


def _spd(seed: int, n: int = 18) -> np.ndarray:
    A = np.random.default_rng(seed).normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def test_layout_is_the_row_major_upper_triangle():
    C = np.arange(36, dtype=float).reshape(6, 6)
    C = C + C.T  # symmetric, every pair distinct
    rows, cols = np.triu_indices(6)  # numpy's own row-major enumeration of i <= j
    assert cov.upper_triangle(C) == C[rows, cols].tolist()
    assert [k for k, (i, j) in enumerate(cov.UPPER) if i == j] == list(cov.DIAGONAL)
    # "the first six entries are the first ROW, the next five the second ROW" (common.xml)
    assert (
        cov.upper_triangle(C)[:6] == C[0].tolist()
        and cov.upper_triangle(C)[6:11] == C[1, 1:].tolist()
    )
    np.testing.assert_array_equal(cov.from_upper_triangle(cov.upper_triangle(C)), C)


def test_ardupilot_reductions_of_each_block():
    sx, sy, sz, sr, sp, sw = 0.3, 0.4, 0.05, 0.01, 0.02, 0.1
    P = np.diag([sx, sy, sz, sr, sp, sw, *([1.0] * 12)]) ** 2
    c = cov.upper_triangle(cov.pose_covariance(P, 0.7, 2.0))
    pos, ang = cov.ardupilot_errors(c, "sqrt")
    assert pos == pytest.approx(math.sqrt(2.0 * (sx**2 + sy**2 + sz**2)))
    assert ang == pytest.approx(math.sqrt(2.0 * (sr**2 + sp**2 + sw**2)))
    # ArduSub 4.x: the cube root of the squared variances (of the axes as sent: no turn here)
    pos, ang = cov.ardupilot_errors(cov.upper_triangle(cov.pose_covariance(P, 0.0, 2.0)))
    assert pos == pytest.approx(math.cbrt(4.0 * (sx**4 + sy**4 + sz**4)))
    assert ang == pytest.approx(math.cbrt(4.0 * (sr**4 + sp**4 + sw**4)))
    assert cov.ardupilot_errors([math.nan] + [1.0] * 20) == (0.0, 0.0)
    with pytest.raises(ValueError, match="cube"):
        cov.ardupilot_errors(c, "cube")
    # the clamps: [VISO_POS_M_NSE, 100] and [VISO_YAW_M_NSE, 1.5]
    assert cov.clamped_errors([0.0] * 21, 0.2, 0.3) == (0.2, 0.3)
    assert cov.clamped_errors([1e6] * 21, 0.2, 0.3) == (100.0, 1.5)


def test_turning_the_frame_rotates_the_position_block_only():
    P = np.diag([0.09, 0.01, 0.04, 0.001, 0.002, 0.003] + [1.0] * 12)
    C = cov.pose_covariance(P, math.pi / 2)  # x -> y, y -> -x
    np.testing.assert_allclose(np.diag(C)[:3], [0.01, 0.09, 0.04], atol=1e-15)
    np.testing.assert_array_equal(C[3:, 3:], P[3:6, 3:6])
    P = _spd(1)
    for dpsi in (0.3, -2.0):
        C = cov.pose_covariance(P, dpsi, 3.0)
        assert np.trace(C[:2, :2]) == pytest.approx(3.0 * np.trace(P[:2, :2]))
        assert np.all(np.linalg.eigvalsh(C) > 0)
        R = cov.rotate_z(dpsi)
        np.testing.assert_allclose(C[:3, 3:], 3.0 * R @ P[:3, 3:6], rtol=1e-12)
    assert cov.horizontal_std(P, 2.0) == pytest.approx(math.sqrt(2.0 * (P[0, 0] + P[1, 1])))
    np.testing.assert_allclose(cov.velocity_covariance(P, 2.0), 2.0 * P[6:12, 6:12])


@settings(max_examples=200, deadline=None)
@given(st.floats(0.1, 0.9), st.floats(0.01, 0.1), st.floats(0.5, 5.0))
def test_confidence_inverts_ekf3_velocity_error(std, vmin, vmax):
    c = cov.confidence_from_std(std, vmin, vmax)
    assert 0.0 <= c <= 100.0
    if vmin <= std <= vmax:
        assert cov.ekf_velocity_error(c, vmin, vmax) == pytest.approx(std)


def test_confidence_clamps_and_quality_scale():
    assert cov.confidence_from_std(0.01) == 100.0  # better than VIS_VERR_MIN: the best
    assert cov.confidence_from_std(5.0) == 0.0
    assert cov.confidence_from_std(math.nan) == 0.0
    assert cov.ekf_velocity_error(100.0) == cov.VIS_VERR_MIN_DEFAULT
    q = [cov.quality_from_std(s, 2.0) for s in np.linspace(0.0, 2.0, 21)]
    assert q[0] == 100 and q[-1] == 1 and all(a >= b for a, b in zip(q, q[1:], strict=False))
    assert cov.quality_from_std(math.nan, 2.0) == 1
