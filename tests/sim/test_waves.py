"""Airy (linear) wave model against closed forms: dispersion omega^2 = g k tanh(k h), orbital
velocities and pressure response (Dean & Dalrymple, "Water Wave Mechanics for Engineers and
Scientists", 1991, ch. 3-4)."""

import numpy as np
import pytest

from undertow.sim.waves import LinearWave, solve_wavenumber

G = 9.80665


def test_dispersion_relation_is_satisfied():
    for f in (0.2, 0.75, 1.0, 3.0):
        for h in (0.5, 3.0, 50.0):
            w = 2 * np.pi * f
            k = solve_wavenumber(w, h, G)
            assert w**2 == pytest.approx(G * k * np.tanh(k * h), rel=1e-10)


def test_deep_and_shallow_limits():
    w = 2 * np.pi * 1.0
    assert solve_wavenumber(w, 1000.0, G) == pytest.approx(w**2 / G, rel=1e-10)
    w = 2 * np.pi * 0.01  # k h ~ 0.04: shallow water
    h = 1.0
    assert solve_wavenumber(w, h, G) == pytest.approx(w / np.sqrt(G * h), rel=1e-3)


@pytest.mark.parametrize(("f", "k", "lam"), [(1.0, 4.02, 1.56), (0.75, 2.26, 2.78)])
def test_paper_wavenumbers_in_3m(f, k, lam):
    wave = LinearWave(a=0.1, f=f, h=3.0, g=G)
    assert wave.k == pytest.approx(k, abs=0.01)
    assert wave.wavelength == pytest.approx(lam, abs=0.01)


@pytest.mark.parametrize(
    ("a", "f", "u"), [(0.1, 1.0, 0.084), (0.1, 0.75, 0.15), (0.05, 0.75, 0.076)]
)
def test_orbital_speed_at_half_metre_matches_notes(a, f, u):
    U, _ = LinearWave(a=a, f=f, h=3.0, g=G).velocity_amplitude(0.5)
    assert U == pytest.approx(u, abs=0.002)


def test_decay_with_depth_matches_closed_form():
    wave = LinearWave(a=0.1, f=1.0, h=3.0, g=G)
    d = np.linspace(0.0, 3.0, 31)
    k, h, w = wave.k, 3.0, wave.omega
    U, W = wave.velocity_amplitude(d)
    np.testing.assert_allclose(U, 0.1 * w * np.cosh(k * (h - d)) / np.sinh(k * h), rtol=1e-12)
    np.testing.assert_allclose(W, 0.1 * w * np.sinh(k * (h - d)) / np.sinh(k * h), rtol=1e-12)
    assert W[-1] == pytest.approx(0.0, abs=1e-15)  # no flow through the floor
    deep = LinearWave(a=0.1, f=2.0, h=50.0, g=G)
    Ud, _ = deep.velocity_amplitude(np.array([0.0, 1.0]))
    assert Ud[1] / Ud[0] == pytest.approx(np.exp(-deep.k), rel=1e-9)


def test_surface_pressure_is_hydrostatic_of_elevation_and_signs_in_z_down():
    wave = LinearWave(a=0.1, f=0.75, h=3.0, g=G, rho=998.0)
    t = np.linspace(0, 4, 101)
    eta = wave.elevation(2.0, 0.0, t)
    np.testing.assert_allclose(wave.dynamic_pressure(2.0, 0.0, 0.0, t), 998.0 * G * eta, atol=1e-9)
    # surface particle vertical displacement (z down) is -eta; velocity is its time derivative
    disp = wave.particle_displacement(2.0, 0.0, 0.0, t)
    np.testing.assert_allclose(disp[:, 2], -eta, atol=1e-12)
    dt = 1e-5
    num = (
        wave.particle_displacement(2.0, 0.0, 0.7, t + dt)
        - wave.particle_displacement(2.0, 0.0, 0.7, t - dt)
    ) / (2 * dt)
    np.testing.assert_allclose(num, wave.orbital_velocity(2.0, 0.0, 0.7, t), atol=1e-8)
    num_a = (
        wave.orbital_velocity(2.0, 0.0, 0.7, t + dt) - wave.orbital_velocity(2.0, 0.0, 0.7, t - dt)
    ) / (2 * dt)
    np.testing.assert_allclose(num_a, wave.orbital_acceleration(2.0, 0.0, 0.7, t), atol=1e-7)


def test_heading_180_propagates_toward_minus_x():
    wave = LinearWave(a=0.1, f=1.0, h=3.0, g=G, beta=np.pi)
    # a crest at x=0, t=0 is found at x = -c dt a moment later
    c = wave.omega / wave.k
    dt = 0.05
    assert wave.elevation(-c * dt, 0.0, dt) == pytest.approx(0.1, rel=1e-9)
    # under a crest the water moves along the propagation direction
    assert wave.orbital_velocity(0.0, 0.0, 0.3, 0.0)[0] < 0


def test_calm_water_is_zero():
    wave = LinearWave(a=0.0, f=1.0, h=3.0)
    assert np.all(wave.orbital_velocity(1.0, 0.0, 0.5, np.arange(3.0)) == 0)
    assert np.all(wave.dynamic_pressure(1.0, 0.0, 0.5, np.arange(3.0)) == 0)
