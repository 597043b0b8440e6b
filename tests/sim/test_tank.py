"""Tank geometry and ray casting against closed forms; A50 beam geometry."""

import numpy as np
import pytest

from undertow.robot import a50_beam_units
from undertow.sim.tank import Tank

TANK = Tank(110.0, 6.7, 3.0, rock_x=50.0, rock_y=0.0, rock_length=1.0, rock_width=0.8,
            rock_height=0.4, rock_edge_radius=0.05)  # fmt: skip


def test_beam_units_geometry():
    B = a50_beam_units()
    np.testing.assert_allclose(np.linalg.norm(B, axis=1), 1.0)
    np.testing.assert_allclose(np.hypot(B[:, 0], B[:, 1]), 0.383, atol=5e-4)
    np.testing.assert_allclose(B[:, 2], 0.924, atol=5e-4)
    # least squares noise gain: sigma_x = sigma_b / (sqrt2 sin 22.5), sigma_z = sigma_b/(2 cos 22.5)
    cov = np.linalg.inv(B.T @ B)
    s = np.deg2rad(22.5)
    np.testing.assert_allclose(
        np.sqrt(np.diag(cov)), [1 / (np.sqrt(2) * np.sin(s))] * 2 + [1 / (2 * np.cos(s))]
    )


def test_vertical_and_slanted_rays_onto_the_flat_floor():
    o = np.array([[20.0, 1.0, 0.5]])
    assert TANK.cast_rays(o, [[0, 0, 1]])[0] == pytest.approx(2.5, abs=1e-5)
    B = a50_beam_units()
    r = TANK.cast_rays(np.repeat(o, 4, 0), B)
    np.testing.assert_allclose(r, 2.5 / B[:, 2], atol=1e-5)


def test_ray_onto_rock_top_and_rounded_edge():
    o = np.array([[50.0, 0.1, 0.6]])
    assert TANK.cast_rays(o, [[0, 0, 1]])[0] == pytest.approx(3.0 - 0.4 - 0.6, abs=1e-5)
    # on the fillet: d_e from the shrunk rectangle edge, r = H - rho + sqrt(rho^2 - d_e^2)
    x = 50.0 + 0.5 - 0.05 + 0.03
    expected_depth = 3.0 - (0.4 - 0.05 + np.sqrt(0.05**2 - 0.03**2))
    assert TANK.floor_depth(x, 0.0) == pytest.approx(expected_depth, abs=1e-12)
    assert TANK.cast_rays([[x, 0.0, 0.5]], [[0, 0, 1]])[0] == pytest.approx(
        expected_depth - 0.5, abs=1e-5
    )
    # beside the rock: the floor
    assert TANK.cast_rays([[50.6, 0.0, 0.5]], [[0, 0, 1]])[0] == pytest.approx(2.5, abs=1e-5)


def test_horizontal_ray_hits_rock_wall_and_tank_wall():
    r = TANK.cast_rays([[48.0, 0.0, 2.8], [20.0, 0.0, 1.0]], [[1, 0, 0], [0, 1, 0]])
    assert r[0] == pytest.approx(2.0 - 0.5, abs=1e-5)  # rock wall at x = 49.5
    assert r[1] == pytest.approx(3.35, abs=1e-5)  # tank wall at y = 3.35


def test_rays_leaving_the_water_or_too_long_are_nan():
    r = TANK.cast_rays([[20.0, 0.0, 0.5], [20.0, 0.0, 0.5]], [[0, 0, -1], [0, 0, 1]], max_range=2.0)
    assert np.all(np.isnan(r))


def test_floor_cloud_lies_on_the_heightfield():
    cloud = TANK.floor_cloud(49.0, 51.0, -1.0, 1.0, 0.05)
    assert cloud.shape == (41 * 41, 3)
    np.testing.assert_allclose(cloud[:, 2], TANK.floor_depth(cloud[:, 0], cloud[:, 1]))
    top = (np.abs(cloud[:, 0] - 50) < 0.4) & (np.abs(cloud[:, 1]) < 0.3)
    np.testing.assert_allclose(cloud[top, 2], 2.6)
    assert cloud[:, 2].max() == pytest.approx(3.0)
