"""Robust by default: physical envelopes, the default gate, per-sensor health (issue 10).

The reference is always the same run without the injected fault (the clean trajectory), and
each guard is shown to matter: without it the fault moves the track by far more.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from undertow.cli import app
from undertow.errors import DataError
from undertow.estimation.localizer import localize
from undertow.log import Dvl, Imu, Pressure
from undertow.robot import Mounting, SensorMount
from undertow.rotations import quaternion_to_rpy

WAVE = "wave-a0.10-f0.75"
NO_ENVELOPE = {
    "dvl_max_speed_m_s": None,
    "gyro_max_rate_rad_s": None,
    "max_depth_m": None,
    "min_depth_m": None,
    "max_vertical_speed_m_s": None,
}


def _run(log, **params):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        trajectory = localize(log, variant="proposed", **params)
    return trajectory, [str(w.message) for w in caught]


def _faulty(log):
    """One DVL report at 1e6 m/s, three pressure samples at 1e9 Pa, one IMU sample at 1e4
    rad/s, each in the middle of the run."""
    dvl, p, imu = log.dvl, log.pressure, log.imu
    v = np.array(dvl.velocity)
    v[len(v) // 2] = (1e6, 0.0, 0.0)
    pressure = np.array(p.pressure)
    pressure[[len(pressure) // 3, len(pressure) // 2, 2 * len(pressure) // 3]] = 1e9
    w = np.array(imu.angular_velocity)
    w[len(w) // 2] = (0.0, 0.0, 1e4)
    return log.replace(
        dvl=dataclasses.replace(dvl, velocity=v),
        pressure=Pressure(p.t, pressure),
        imu=Imu(imu.t, w),
    )


def _gap(a, b) -> float:
    """Largest position difference at the times both have (a rejected sample removes one)."""
    common, ia, ib = np.intersect1d(a.t, b.t, return_indices=True)
    assert common.size >= 0.99 * max(len(a.t), len(b.t))
    return float(np.max(np.linalg.norm(a.position[ia] - b.position[ib], axis=1)))


@pytest.fixture(scope="module")
def wave_log(simulation):
    return simulation(WAVE, 0).log


@pytest.fixture(scope="module")
def clean(wave_log):
    trajectory, caught = _run(wave_log)
    assert caught == []  # a clean run rejects, gates and warns of nothing
    counts = trajectory.metadata["counts"]
    assert all(v == 0 for k, v in counts.items() if k.startswith(("rejected", "gated")))
    return trajectory


@pytest.mark.slow
def test_default_keeps_the_track_under_injected_outliers(wave_log, clean):
    faulty = _faulty(wave_log)
    robust, caught = _run(faulty)
    assert _gap(robust, clean) < 0.3  # a few decimetres at most
    c = robust.metadata["counts"]
    assert c["rejected_dvl_speed"] == 1 and c["rejected_imu_range"] == 1
    assert c["rejected_pressure_depth"] == 3
    for sensor in ("dvl", "imu", "pressure"):  # one warning line per sensor
        mine = [m for m in caught if m.startswith(f"{sensor}: ")]
        assert len(mine) == 1 and "rejected" in mine[0] and "\n" not in mine[0], caught
    # the envelopes matter: without them and without the gate the track goes far away
    naive, _ = _run(faulty, gate_probability=None, **NO_ENVELOPE)
    assert _gap(naive, clean) > 10.0
    # and the default gate alone (no envelopes) catches the DVL and pressure outliers
    gated, _ = _run(_faulty(wave_log).replace(imu=wave_log.imu), **NO_ENVELOPE)
    assert _gap(gated, clean) < 0.3
    assert gated.metadata["counts"]["gated_dvl"] >= 1
    assert gated.metadata["counts"]["gated_pressure"] >= 3


@pytest.mark.slow
def test_default_gate_changes_nothing_on_clean_runs(wave_log, clean):
    """The default gate (20 sigma on DVL, DR, barometer) gates nothing on a clean wave run, in
    every variant: the trajectory is the ungated one, bit for bit."""
    for variant in ("baseline", "proposed"):
        default = localize(wave_log, variant=variant)
        off = localize(wave_log, variant=variant, gate_probability=None)
        assert np.array_equal(default.x, off.x)
        assert default.metadata["config"]["gate_probability"] == "default"
        assert off.metadata["config"]["gate_probability"] is None


def _dvl_mounting(rotation):
    return Mounting(dvl=SensorMount((0.164, 0.004, 0.284), tuple(rotation)))


@pytest.mark.parametrize("rotation", [(np.nan, 0.0, 0.0), "zero quaternion"])
def test_non_finite_mounting_is_one_line(simulation, rotation):
    if rotation == "zero quaternion":  # what /tf_static's (0, 0, 0, 0) becomes
        with np.errstate(invalid="ignore"):
            rotation = quaternion_to_rpy(np.zeros(4))
    log = simulation("calm", 0).log.replace(mounting=_dvl_mounting(rotation))
    with pytest.raises(DataError, match="dvl rotation .* not finite") as info:
        localize(log)
    assert "\n" not in str(info.value)


def test_all_invalid_dvl_reports_warn_per_sensor(simulation):
    log = simulation("calm", 0).log
    dvl = dataclasses.replace(log.dvl, valid=np.zeros(len(log.dvl), bool))
    _, caught = _run(log.replace(dvl=dvl))
    mine = [m for m in caught if m.startswith("dvl: ")]
    assert len(mine) == 1 and "100 %" in mine[0] and "invalid" in mine[0], caught


def test_health_is_judged_per_sensor(simulation):
    """IMU samples outnumber DVL reports ten to one: a DVL whose every report is rejected is
    a small share of all measurements, yet it is reported, and only it."""
    log = simulation("calm", 0).log
    dvl = Dvl.from_velocity(log.dvl.t, np.full((len(log.dvl), 3), 50.0))
    trajectory, caught = _run(log.replace(dvl=dvl))
    assert len(log.imu) > 5 * len(log.dvl)
    health = [m for m in caught if "barely uses" in m]
    assert len(health) == 1 and health[0].startswith("dvl: 100 %"), caught
    s = trajectory.metadata["sensors"]["dvl"]
    assert s["used"] == 0 and s["rejected"] == {"rejected_dvl_speed": len(log.dvl)}


@pytest.mark.slow
def test_gate_off_reaches_the_filter(simulated_run, tmp_path):
    runner = CliRunner()
    log = str(simulated_run("calm", 0) / "log")
    settings = tmp_path / "settings.yaml"
    settings.write_text("localizer: {gate_probability: null}\n")
    cases = {
        "off": (["--gate", "off"], None),
        "settings": (["--config", str(settings)], None),
        "default": ([], "default"),
        "number": (["--gate", "0.999"], 0.999),
    }
    for name, (args, expected) in cases.items():
        out = tmp_path / name
        r = runner.invoke(app, ["localize", log, "--out", str(out), "-q", *args])
        assert r.exit_code == 0, r.output
        used = yaml.safe_load((out / "config.yaml").read_text())
        assert used["config"]["gate_probability"] == expected, name
    r = runner.invoke(app, ["localize", log, "--out", str(tmp_path / "bad"), "--gate", "x"])
    assert r.exit_code == 1 and "--gate" in r.output and "Traceback" not in r.output


def test_map_blames_the_trajectory_not_the_origin(simulation):
    from undertow.mapping.run import map_log
    from undertow.trajectory import Trajectory

    log = simulation("calm", 0).log
    good = localize(log)
    x = np.array(good.x)
    x[len(x) // 2 :, 0] += 1e7  # a localization that jumped 10 000 km
    bad = Trajectory(good.t, x, good.P, variant=good.variant)
    with pytest.raises(DataError, match="localization is wrong, not the map origin"):
        map_log(log, bad)
