"""The measurement log: validation, invariants and the stage contract."""

import numpy as np
import pytest

from undertow.errors import DataError, MissingStreamError
from undertow.log import Dvl, Imu, Log, Pressure, SonarRange
from undertow.robot import Mounting, a50_beam_units


def test_a50_beam_geometry_matches_the_datasheet():
    b = a50_beam_units()
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), 1.0)
    np.testing.assert_allclose(np.hypot(b[:, 0], b[:, 1]), np.sin(np.deg2rad(22.5)))
    np.testing.assert_allclose(b[:, 2], 0.9238795, atol=1e-6)
    # azimuths +135, -135, -45, +45 degrees for protocol ids 0..3
    np.testing.assert_allclose(np.rad2deg(np.arctan2(b[:, 1], b[:, 0])), [135, -135, -45, 45])


def test_streams_are_read_only_and_shape_checked():
    imu = Imu(t=[0.0, 0.1], angular_velocity=np.zeros((2, 3)))
    with pytest.raises(ValueError):
        imu.angular_velocity[0, 0] = 1.0
    with pytest.raises(DataError, match="imu.angular_velocity: shape"):
        Imu(t=[0.0, 0.1], angular_velocity=np.zeros((3, 3)))


def test_time_going_backwards_is_named():
    with pytest.raises(DataError, match="pressure.t: time goes backwards at sample 2"):
        Pressure(t=[0.0, 1.0, 0.5], pressure=[1e5, 1e5, 1e5])


def test_depth_is_hydrostatic():
    p = Pressure(t=[0.0], pressure=[101_325.0 + 1025.0 * 9.80665 * 2.5])
    np.testing.assert_allclose(p.depth(water_density=1025.0), [2.5])


def test_require_names_missing_streams_and_what_exists():
    log = Log(dvl=Dvl.from_velocity([0.0, 0.2], np.zeros((2, 3))), source="run.bag")
    log.require("dvl")
    with pytest.raises(
        MissingStreamError, match="localize needs stream.s. imu in run.bag; the log has: dvl"
    ):
        log.require("imu", "dvl", stage="localize")


def test_select_keeps_matching_rows_of_every_field():
    d = Dvl.from_velocity(np.arange(4.0), np.arange(12.0).reshape(4, 3), valid=[1, 0, 1, 1])
    kept = d.select(d.valid)
    assert len(kept) == 3 and kept.beam_unit.shape == (3, 4, 3)
    np.testing.assert_array_equal(kept.velocity[1], [6.0, 7.0, 8.0])
    assert d.invalid_count() == 1


def test_sonar_invalid_counts_out_of_range_and_nan():
    s = SonarRange(t=[0, 1, 2, 3], range=[0.1, 1.0, np.nan, 200.0])
    assert s.invalid_count() == 3


def test_mounting_round_trip_and_rotation():
    m = Mounting()
    assert Mounting.from_dict(m.to_dict()) == m
    R = m.dvl.rotation_matrix()
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.arctan2(R[1, 0], R[0, 0]), 0.05)


def test_time_span_over_streams():
    log = Log(
        imu=Imu(t=[1.0, 5.0], angular_velocity=np.zeros((2, 3))),
        pressure=Pressure(t=[0.5, 2.0], pressure=[1e5, 1e5]),
    )
    assert log.time_span == (0.5, 5.0)
    assert Log().time_span[0] != Log().time_span[0]  # NaN for an empty log


def test_depth_default_density_is_the_simulators_water():
    """One default for both: a simulated barometer (noise off, calm water, at the body origin)
    converted with Pressure.depth()'s defaults gives the true depth (hydrostatics, p = p_atm +
    rho g d). With 997 instead of the simulator's 998 it would be 0.5 mm off at 0.5 m."""
    from undertow.log import FRESH_WATER_DENSITY
    from undertow.sim import Scenario, simulate

    s = Scenario(
        motion={"carriage": {"run_length_m": 1.0, "hold_before_s": 0.5, "hold_after_s": 0.5}},
        barometer={"noise_sigma_pa": 0.0},
        ground_truth={"rate_hz": 100.0},
        floor_cloud={"spacing_m": 0.2},
    )
    assert s.water.density_kg_m3 == FRESH_WATER_DENSITY
    log = simulate(s).log
    assert s.mounting.barometer.translation == (0.0, 0.0, 0.0)
    true_depth = np.interp(log.pressure.t, log.ground_truth.t, log.ground_truth.position[:, 2])
    np.testing.assert_allclose(log.pressure.depth(), true_depth, rtol=0, atol=1e-9)
