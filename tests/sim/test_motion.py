"""The carriage mount shaken by wave loads (Morison, quasi-static) against closed forms.

The wave quantities are recomputed here from Airy theory (wavenumber by scipy's brentq on the
dispersion relation), independently of ``sim/waves.py``.
"""

import numpy as np
import pytest
from scipy.optimize import brentq

from undertow.sim.motion import CarriageMotion
from undertow.sim.scenario.model import CarriageModel, MountLoadModel
from undertow.sim.waves import LinearWave

G, H, RHO = 9.80665, 3.0, 998.0


def _carriage(a, f=1.0, heading_deg=180.0, hold=20.0, **mount) -> CarriageMotion:
    config = CarriageModel(hold_before_s=hold, mount=MountLoadModel(**mount))
    wave = LinearWave(a=a, f=f, h=H, beta=np.deg2rad(heading_deg), rho=RHO, g=G)
    return CarriageMotion(config, wave)


def _airy(a, f, depth):
    """(k, U) with omega^2 = g k tanh(k h), U = a omega cosh(k (h - d)) / sinh(k h)."""
    omega = 2 * np.pi * f
    k = brentq(lambda k: G * k * np.tanh(k * H) - omega**2, 1e-6, 100.0, xtol=1e-14)
    return k, a * omega * np.cosh(k * (H - depth)) / np.sinh(k * H)


def test_no_deflection_in_calm_water_even_while_towed():
    """The steady towing drag is not a wave load: with a vanishing wave the deflection vanishes
    along the whole run, cruise included (with ``- |u_c| u_c`` it would be rho C_D A V^2 / K)."""
    motion = _carriage(a=0.0)
    t = np.linspace(0.0, motion.duration, 2000)
    np.testing.assert_array_equal(motion.mount_deflection(t), 0.0)
    tiny = _carriage(a=1e-9)
    m = tiny.config.mount
    towing = RHO * m.drag_coefficient * m.frontal_area_m2 * 1.0**2 / m.stiffness_n_m
    assert towing > 1e-3  # what a wrong sign would show, metres
    assert np.abs(tiny.mount_deflection(t)).max() < 1e-9


def test_at_rest_deflection_is_the_morison_closed_form_along_the_wave_only():
    """At rest u_c = 0, so delta e_beta with delta = [rho C_M V_b U omega sin(theta)
    + 1/2 rho C_D A_f U^2 |cos theta| cos theta] / K: the wave frequency, along the heading."""
    a, f, beta = 0.1, 1.0, 150.0
    motion = _carriage(a=a, f=f, heading_deg=beta)
    c, m = motion.config, motion.config.mount
    t = np.linspace(0.0, 19.0, 3001)  # inside the 20 s hold before the run
    d = motion.mount_deflection(t)
    e = np.array([np.cos(np.deg2rad(beta)), np.sin(np.deg2rad(beta)), 0.0])
    np.testing.assert_allclose(np.cross(d, e), 0.0, atol=1e-15)  # along e_beta only
    assert np.all(d[:, 2] == 0.0)
    k, U = _airy(a, f, c.depth_m)
    omega = 2 * np.pi * f
    theta = k * (c.start_x_m * e[0] + c.y_m * e[1]) - omega * t
    inertia = RHO * m.inertia_coefficient * m.displaced_volume_m3 * U * omega * np.sin(theta)
    drag = 0.5 * RHO * m.drag_coefficient * m.frontal_area_m2 * U**2 * np.abs(np.cos(theta))
    expected = (inertia + drag * np.cos(theta)) / m.stiffness_n_m
    np.testing.assert_allclose(d @ e, expected, rtol=0, atol=1e-12)
    # zero mean over whole periods: no steady offset at rest
    whole = t < 19.0
    assert abs(np.mean((d @ e)[whole])) < 1e-3 * np.abs(expected).max()


def test_amplitude_scales_linearly_for_inertia_and_quadratically_for_drag_at_rest():
    t = np.linspace(0.0, 10.0, 1001)
    for mount, power in (({"drag_coefficient": 0.0}, 1), ({"inertia_coefficient": 0.0}, 2)):
        small = _carriage(a=0.04, **mount).mount_deflection(t)
        large = _carriage(a=0.08, **mount).mount_deflection(t)  # same k: k depends on f only
        np.testing.assert_allclose(large, 2**power * small, rtol=1e-12, atol=1e-18)


def test_towed_into_oncoming_waves_the_mount_shakes_at_the_encounter_frequency():
    """theta = k (x0 + V t) cos(pi) - omega t: at cruise the load oscillates at the Doppler-shifted
    encounter frequency f_e = f + k V / (2 pi), not at f."""
    f = 1.0
    motion = _carriage(a=0.05, f=f, hold=0.0)
    c = motion.config
    k, _ = _airy(0.05, f, c.depth_m)
    t_acc = c.cruise_speed_m_s / c.acceleration_m_s2
    t_cruise = (c.run_length_m - c.cruise_speed_m_s * t_acc) / c.cruise_speed_m_s
    t = np.arange(t_acc, t_acc + t_cruise, 0.01)
    x = motion.mount_deflection(t)[:, 0]
    spectrum = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(t.size)))
    freqs = np.fft.rfftfreq(t.size, 0.01)
    f_e = f + k * c.cruise_speed_m_s / (2 * np.pi)
    assert f_e == pytest.approx(1.64, abs=0.01)  # omega^2 = g k tanh(k h): k = 4.02 /m
    assert freqs[np.argmax(spectrum)] == pytest.approx(f_e, abs=1.5 / (t[-1] - t[0]))
