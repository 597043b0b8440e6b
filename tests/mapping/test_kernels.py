"""Sparse kernel of eq:kernel and its product form (eq:decom_kernel) against closed forms."""

import numpy as np
import pytest
from scipy.integrate import quad

from undertow.mapping.kernels import product_kernel, sparse_kernel


def test_kernel_value_at_zero_is_sigma0():
    assert sparse_kernel(0.0, 0.15, sigma0=0.9) == pytest.approx(0.9)


def test_kernel_zero_at_and_beyond_length_scale():
    l = 0.15
    assert np.all(sparse_kernel(np.array([l, 1.0001 * l, 2 * l, 10.0]), l, 0.9) == 0.0)


def test_kernel_symmetric_and_monotone_on_support():
    l = 0.2
    d = np.linspace(0, l, 2001)[:-1]
    k = sparse_kernel(d, l)
    np.testing.assert_array_equal(k, sparse_kernel(-d, l))
    assert np.all(np.diff(k) < 0)
    assert np.all(k > 0)


def test_kernel_continuous_and_flat_at_length_scale():
    # Near d = l the kernel vanishes like (1 - d/l)^5: continuous with zero slope at the edge.
    l = 0.15
    for e in (1e-2, 1e-3):
        assert sparse_kernel(l * (1 - e), l) < 10 * e**5


def test_kernel_integral_closed_form():
    # int_{-l}^{l} k(d) dd = 2 l sigma0 / 3 (the cos and sin terms integrate to zero on [0, 1]).
    l, s0 = 0.17, 0.6
    val, _ = quad(lambda d: float(sparse_kernel(d, l, s0)), -l, l, points=[0.0])
    assert val == pytest.approx(2 * l * s0 / 3, rel=1e-9)


def test_product_kernel_factorizes_and_matches_1d_on_axes():
    rng = np.random.default_rng(1)
    lengths = np.array([0.18, 0.12, 0.06])
    delta = rng.uniform(-0.2, 0.2, (500, 3))
    expected = 0.9 * np.prod([sparse_kernel(np.abs(delta[:, j]), lengths[j]) for j in range(3)], 0)
    np.testing.assert_allclose(product_kernel(delta, lengths, 0.9), expected)
    for j in range(3):
        on_axis = np.zeros((50, 3))
        on_axis[:, j] = np.linspace(-0.2, 0.2, 50)
        np.testing.assert_allclose(
            product_kernel(on_axis, lengths, 0.9), sparse_kernel(on_axis[:, j], lengths[j], 0.9)
        )


def test_product_kernel_box_support_differs_from_radial():
    # Off the axes the product kernel is not the radial one: at (a, a, 0) with a < l < a sqrt(2)
    # the radial kernel is 0 but the box-support product is positive.
    l, a = 0.15, 0.12
    assert sparse_kernel(np.hypot(a, a), l) == 0.0
    assert product_kernel([a, a, 0.0], [l, l, l]) > 0.0


def test_sincos_matches_libm_over_the_kernel_range():
    """The scatter's sin/cos (fdlibm's kernels) agree with numpy's to about an ulp where the
    adaptive kernel uses them (2 pi d / l for |d| < l + res), and far beyond."""
    from undertow.mapping.kernels import sincos

    x = np.concatenate([np.linspace(-40.0, 40.0, 200_001), np.pi / 2 * np.arange(-64, 65)])
    got = np.array([sincos(v) for v in x])
    assert np.max(np.abs(got[:, 0] - np.sin(x))) < 4e-16
    assert np.max(np.abs(got[:, 1] - np.cos(x))) < 4e-16
