"""adaptive-r: innovation-based adaptive R of the DVL and DR (Akhlaghi, Zhou and Huang 2017),
a peer baseline with be's bias estimation and no wave noise."""

from __future__ import annotations

import numpy as np
import pytest
from test_localize import make_log

from undertow.estimation import Localizer, localize
from undertow.estimation.config import VARIANTS, LocalizerConfig
from undertow.estimation.model import N_STATE, STATE_ANGLES, Z_LINEAR, adapt_r
from undertow.estimation.ukf import update_linear
from undertow.robot import Mounting


def test_the_variant_is_listed_and_defined():
    assert "adaptive-r" in VARIANTS
    cfg = LocalizerConfig(variant="adaptive-r")
    assert cfg.estimates_bias and not cfg.adds_wave_noise and cfg.adapts_r
    assert cfg.sensor_model(Mounting()).adapt_r
    for other in ("baseline", "be", "an", "proposed"):
        assert not LocalizerConfig(variant=other).adapts_r


def test_the_update_is_unbiased_when_r_is_right():
    """E[eps eps^T + H P+ H^T] = R for eps = z - H x+ (closed form, model.adapt_r's doc): with
    alpha = 0 the adapted R is that sum, averaged here over innovations drawn from N(0, S)."""
    rng = np.random.default_rng(0)
    H = np.zeros((3, N_STATE))
    H[:, 6:9] = np.eye(3)  # a velocity sensor
    A = rng.normal(size=(N_STATE, N_STATE))
    P0 = A @ A.T * 1e-3 + np.eye(N_STATE) * 1e-4
    R = np.array([[4e-4, 1e-4, 0.0], [1e-4, 2e-4, 0.0], [0.0, 0.0, 1e-4]])
    S = H @ P0 @ H.T + R
    Ls = np.linalg.cholesky(S)
    total = np.zeros((3, 3))
    n = 4000
    for _ in range(n):
        x, P = np.zeros(N_STATE), P0.copy()
        z = Ls @ rng.normal(size=3)  # innovation nu = z - H x with x = 0
        status, _ = update_linear(x, P, H, z, R, STATE_ANGLES, Z_LINEAR, np.inf)
        assert status == 0
        Ra = np.zeros((3, 3))
        adapt_r(Ra, 0.0, z, x, P, H, False)
        total += Ra
    np.testing.assert_allclose(total / n, R, atol=4 * np.sqrt(2.0 / n) * R.max())


@pytest.mark.parametrize("nominal", [0.05, 0.0005])
def test_r_converges_to_the_true_noise_from_a_wrong_nominal(nominal):
    """make_log's DVL noise is 0.005 m/s, its DR noise 0.003 rad per axis; nominal R 10x too large
    or too small. With the motion model right (constant velocity: small acceleration density),
    the adapted std devs end within 30 % (40 % for DR) of the truth."""
    log = make_log(duration=60.0, u=0.2, seed=3)
    run = Localizer("adaptive-r", dvl_velocity_std_m_s=(nominal,) * 3,
                    dr_orientation_std_rad=(0.6 * nominal,) * 3,
                    accel_density=(1e-6,) * 3).run(log)  # fmt: skip
    adapted = run.metadata["adaptive_r"]
    assert adapted["alpha"] == 0.98
    dvl = np.sqrt(np.diag(adapted["dvl"]["final_R"]))
    dr = np.sqrt(np.diag(adapted["dead_reckoning"]["final_R"]))
    np.testing.assert_allclose(dvl, 0.005, rtol=0.3)
    np.testing.assert_allclose(dr, 0.003, rtol=0.4)
    fixed = Localizer("be", dvl_velocity_std_m_s=(nominal,) * 3,
                      dr_orientation_std_rad=(0.6 * nominal,) * 3,
                      accel_density=(1e-6,) * 3).run(log)  # fmt: skip
    # the fixed-R filter's NIS is off by the factor (true / nominal)^2; the adaptive one is not
    nis_adaptive = run.metadata["nis"]["dvl"]["mean"]
    nis_fixed = fixed.metadata["nis"]["dvl"]["mean"]
    assert abs(np.log(nis_adaptive / 3)) < abs(np.log(nis_fixed / 3))


def test_alpha_near_one_is_be_and_other_variants_ignore_alpha():
    """R frozen at the nominal (alpha -> 1) is be; alpha does not touch the other variants."""
    log = make_log(duration=10.0, u=0.2, seed=1)
    be = localize(log, "be")
    frozen = localize(log, "adaptive-r", adaptive_r_alpha=1.0 - 1e-12)
    np.testing.assert_allclose(frozen.x, be.x, atol=1e-9)
    for variant in ("baseline", "be", "an", "proposed"):
        a = localize(log, variant)
        b = localize(log, variant, adaptive_r_alpha=0.5)
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert "adaptive_r" not in a.metadata
    adaptive = localize(log, "adaptive-r", wave="wave-a0.10-f1.00")
    assert adaptive.metadata["wave_noise"] is None  # no wave noise
    assert not np.array_equal(adaptive.x, be.x)
