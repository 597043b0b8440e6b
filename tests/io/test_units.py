"""True units and references (undertow.io.units): the gyro's unit against a known rotation,
the surface pressure of a dive that starts at the surface, statements and overrides."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from undertow.estimation.config import LocalizerConfig
from undertow.estimation.localizer import MissingSensorError, sensor_coverage
from undertow.io import LogOptions
from undertow.io.units import gyro_orientation_ratio, resolve_units, surface_pressure
from undertow.log import G0, DeadReckoning, Dvl, Imu, Log, Pressure

RATE_HZ = 50.0
AMPLITUDE = math.radians(40.0)
OMEGA = 2 * math.pi / 8.0  # yaw swings of +-40 deg over 8 s: peak 31 deg/s


def _turning_imu(scale: float, seed: int = 0, orientation: bool = True) -> Imu:
    """yaw(t) = A sin(w t), roll = pitch = 0: the body rate is r = A w cos(w t) (closed form);
    the gyro reads it times ``scale`` (1: rad/s, 180/pi: deg/s) plus white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 60, 1 / RATE_HZ)
    yaw = AMPLITUDE * np.sin(OMEGA * t)
    rate = np.zeros((t.size, 3))
    rate[:, 2] = AMPLITUDE * OMEGA * np.cos(OMEGA * t)
    gyro = (rate + rng.normal(0, 0.002, rate.shape)) * scale
    q = np.column_stack([np.zeros((t.size, 2)), np.sin(yaw / 2), np.cos(yaw / 2)])
    return Imu(t=t, angular_velocity=gyro, orientation=q if orientation else None)


def _resolve(log: Log, **options):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = resolve_units(log, LogOptions(**options))
    return out, [str(w.message) for w in caught]


def test_the_ratio_to_the_orientation_is_the_unit_factor():
    for scale in (1.0, 180 / math.pi):
        imu = _turning_imu(scale)
        rpy = np.column_stack([np.zeros((len(imu), 2)), AMPLITUDE * np.sin(OMEGA * imu.t)])
        s, r, n = gyro_orientation_ratio(imu.t, imu.angular_velocity, rpy)
        assert s == pytest.approx(scale, rel=0.05) and r > 0.95 and n >= 5


def test_a_gyro_in_rad_s_is_kept():
    log, lines = _resolve(Log(imu=_turning_imu(1.0)))
    assert log.metadata["imu_units"]["unit"] == "rad/s"
    assert log.metadata["imu_units"]["how"] == "orientation" and not lines


def test_a_gyro_in_deg_s_is_converted_with_its_evidence():
    raw = _turning_imu(180 / math.pi)
    log, lines = _resolve(Log(imu=raw))
    np.testing.assert_allclose(log.imu.angular_velocity, np.radians(raw.angular_velocity))
    verdict = log.metadata["imu_units"]
    assert verdict["unit"] == "deg/s" and verdict["converted"]
    assert verdict["ratio_to_orientation"] == pytest.approx(180 / math.pi, rel=0.05)
    assert len(lines) == 1 and "converted from deg/s" in lines[0] and "imu_units" in lines[0]


def test_the_dvl_attitude_serves_when_the_imu_has_no_orientation():
    raw = _turning_imu(180 / math.pi, orientation=False)
    t = raw.t[::10]
    rpy = np.column_stack([np.zeros((t.size, 2)), AMPLITUDE * np.sin(OMEGA * t)])
    dr = DeadReckoning(t=t, position=np.zeros((t.size, 3)), orientation=rpy)
    log, _ = _resolve(Log(imu=raw, dead_reckoning=dr))
    assert log.metadata["imu_units"]["unit"] == "deg/s"
    assert "dead-reckoning" in log.metadata["imu_units"]["evidence"]


def _dvl_for(t):
    return Dvl.from_velocity(t, np.tile([0.5, 0.0, 0.0], (t.size, 1)))


def test_without_an_orientation_a_gyro_beyond_the_envelope_is_refused_until_set():
    raw = _turning_imu(180 / math.pi, orientation=False)
    log, lines = _resolve(Log(imu=raw, dvl=_dvl_for(raw.t[::10])))
    assert log.metadata["imu_units"]["unit"] == "ambiguous"
    assert any("imu_units: deg/s" in line for line in lines)
    with pytest.raises(MissingSensorError, match=r"imu_units: deg/s"):
        sensor_coverage(log, LocalizerConfig())
    set_log, _ = _resolve(Log(imu=raw, dvl=_dvl_for(raw.t[::10])), imu_units="deg/s")
    np.testing.assert_allclose(set_log.imu.angular_velocity, np.radians(raw.angular_velocity))
    sensor_coverage(set_log, LocalizerConfig())  # no error


def _dive(p_surface: float, start_depth: float = 0.0, hold_s: float = 10.0) -> Pressure:
    """``hold_s`` at ``start_depth``, then down to 5 m over 40 s (from the surface: 0)."""
    t = np.arange(0, 40 + hold_s, 0.1)
    depth = start_depth + np.clip((t - hold_s) / 40, 0, 1) * (5 - start_depth)
    noise = np.random.default_rng(1).normal(0, 20.0, t.size)
    return Pressure(t=t, pressure=p_surface + 998.0 * G0 * depth + noise)


def test_the_surface_pressure_of_a_lake_at_altitude_is_found_at_the_start():
    p_surface = 86_000.0  # about 1,300 m above sea level
    log, lines = _resolve(Log(pressure=_dive(p_surface)))
    assert log.metadata["surface_pressure_pa"] == pytest.approx(p_surface, abs=15.0)
    assert "first pressures at the surface" in log.metadata["surface_pressure_source"]
    assert any("surface pressure 86,0" in line for line in lines)
    depth = log.pressure.depth(998.0, log.metadata["surface_pressure_pa"])
    assert depth.min() > -0.1


def test_a_log_that_starts_diving_gets_the_shallowest_bound_or_the_atmosphere():
    """No rest at the start: the surface is not in the log."""
    log, _ = _resolve(Log(pressure=_dive(80_000.0, start_depth=1.0, hold_s=0.0)))
    assert log.metadata["surface_pressure_pa"] == pytest.approx(80_000 + 998 * G0, abs=80)
    assert "minimum pressure" in log.metadata["surface_pressure_source"]
    sea, _ = _resolve(Log(pressure=_dive(101_000.0, start_depth=2.0, hold_s=0.0)))
    assert sea.metadata["surface_pressure_pa"] == 101_325.0


def test_a_wrong_surface_pressure_warns_depths_above_the_water_and_settings_win():
    log, lines = _resolve(Log(pressure=_dive(86_000.0)), surface_pressure_pa=101_325.0)
    assert log.metadata["surface_pressure_pa"] == 101_325.0
    assert any("above the water" in line and "surface_pressure_pa" in line for line in lines)


def test_salt_water_is_stated_and_used():
    log, _ = _resolve(Log(pressure=_dive(101_325.0)), water="salt")
    assert log.metadata["water_density_kg_m3"] == 1025.0 and log.metadata["water"] == "salt"
    found, _ = surface_pressure(log, "auto", 1025.0)
    assert found == log.metadata["surface_pressure_pa"]
