"""MAVLink telemetry logs (.tlog): written here with pymavlink's own encoder from the streams of a
simulated run (known values), read back through ``read_log`` and compared, units converted."""

from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from tlog_fixtures import (
    EPOCH,
    attitude_rows,
    imu2_rows,
    new_mav,
    pressure_rows,
    record,
    sonar_rows,
    vision_rows,
    write_tlog,
)

from undertow.errors import ConfigError, ReaderError
from undertow.io import detect_format, read_log, summarize
from undertow.io.mavlink import MavlinkConfig
from undertow.rotations import quaternion_to_rpy, rpy_to_matrix


@pytest.fixture(scope="module")
def sim_log(simulation):
    log = simulation("calm")
    log = log.log if hasattr(log, "log") else log
    return log.replace(**{n: s.select(s.t < 10.0) for n, s in log.streams().items()})


@pytest.fixture(scope="module")
def tlog_file(tmp_path_factory, sim_log):
    vision, R = vision_rows(sim_log)
    rows = (
        attitude_rows(sim_log)
        + imu2_rows(sim_log)
        + pressure_rows(sim_log)
        + vision
        + sonar_rows(sim_log)
    )
    path = tmp_path_factory.mktemp("tlog") / "dive.tlog"
    write_tlog(path, rows)
    return path, R


def test_attitude_imu_pressure_sonar_units(tlog_file, sim_log):
    path, _ = tlog_file
    assert detect_format(path) == "tlog"
    log = read_log(path)
    imu = log.imu
    np.testing.assert_allclose(imu.t, EPOCH + sim_log.imu.t, rtol=0, atol=2e-6)
    np.testing.assert_allclose(imu.angular_velocity, sim_log.imu.angular_velocity, atol=1e-6)
    _, rpy, _ = sim_log.ground_truth.interpolate(sim_log.imu.t)
    np.testing.assert_allclose(quaternion_to_rpy(imu.orientation), rpy, atol=1e-6)
    assert imu.linear_acceleration is None  # ATTITUDE has none
    np.testing.assert_allclose(log.pressure.pressure, sim_log.pressure.pressure, rtol=1e-7)
    np.testing.assert_allclose(log.sonar.range, sim_log.sonar.range, rtol=0, atol=0.005 + 1e-9)
    np.testing.assert_allclose(log.sonar.confidence, sim_log.sonar.confidence, atol=0.005 + 1e-9)
    assert log.sonar.min_range == 0.3 and log.sonar.max_range == 100.0
    assert log.metadata["time_base"].startswith("tlog receive time")
    offsets = log.metadata["tlog"]["clock_offsets_s"]["ATTITUDE"]
    assert abs(offsets["median"] - EPOCH) < 1e-3  # receive time minus time_boot_ms


def test_scaled_imu2_gyro_is_mrad_per_s(tlog_file, sim_log):
    path, _ = tlog_file
    log = read_log(path, mavlink=MavlinkConfig(gyro="scaled_imu2"))
    np.testing.assert_allclose(
        log.imu.angular_velocity, sim_log.imu.angular_velocity, rtol=0, atol=0.5e-3 + 1e-12
    )
    np.testing.assert_allclose(
        log.imu.linear_acceleration, sim_log.imu.linear_acceleration, rtol=0, atol=0.5e-2
    )
    assert np.all(np.isfinite(log.imu.orientation[1:]))  # the latest ATTITUDE before each row


def test_vision_position_delta_velocity_and_dead_reckoning(tlog_file, sim_log):
    path, R = tlog_file
    log = read_log(path)
    dvl = sim_log.dvl
    np.testing.assert_allclose(log.dvl.t, EPOCH + dvl.t[1:], atol=2e-6)
    np.testing.assert_allclose(log.dvl.velocity, dvl.velocity[1:], rtol=1e-5, atol=1e-6)
    assert log.dvl.valid.all()
    # independent integral: R_k relative to the first sample's frame, p_k = sum R_j d_j
    R_rel = np.einsum("ji,njk->nik", R[0], R[1:])
    d = dvl.velocity[1:] * np.diff(dvl.t)[:, None]
    p = np.cumsum(np.einsum("nij,nj->ni", R_rel, d), axis=0)
    np.testing.assert_allclose(log.dead_reckoning.position, p, atol=1e-5)
    np.testing.assert_allclose(rpy_to_matrix(log.dead_reckoning.orientation), R_rel, atol=1e-5)
    assert log.mounting.dvl.rotation == (0.0, 0.0, 0.0)


def test_pressure_sensor_is_configurable(tmp_path, sim_log):
    path = tmp_path / "p.tlog"
    write_tlog(path, pressure_rows(sim_log, mavlink2.MAVLink_scaled_pressure3_message))
    with pytest.raises(ReaderError, match="no usable measurement .*SCALED_PRESSURE3 x"):
        read_log(path)
    log = read_log(path, mavlink=MavlinkConfig(pressure="SCALED_PRESSURE3"))
    assert len(log.pressure) == len(sim_log.pressure)
    with pytest.raises(ConfigError, match="mavlink.pressure"):
        MavlinkConfig(pressure="SCALED_PRESSURE9")


def test_distance_sensor_choice_and_rangefinder(tmp_path, sim_log):
    rows = sonar_rows(sim_log, sensor_id=3) + sonar_rows(sim_log, sensor_id=0)
    path = tmp_path / "r.tlog"
    write_tlog(path, rows)
    with pytest.warns(UserWarning, match="ids other than 3 ignored"):
        assert len(read_log(path).sonar) == len(sim_log.sonar)
    log = read_log(path, mavlink=MavlinkConfig(range_sensor_id=0))
    assert len(log.sonar) == len(sim_log.sonar)
    rf = [
        (t, mavlink2.MAVLink_rangefinder_message(r, 0.0))
        for t, r in zip(sim_log.sonar.t, sim_log.sonar.range, strict=True)
    ]
    write_tlog(path, rf)
    np.testing.assert_allclose(read_log(path).sonar.range, sim_log.sonar.range, rtol=1e-6)


def test_damage_is_skipped_and_counted(tmp_path, tlog_file):
    path, _ = tlog_file
    raw = bytearray(path.read_bytes())
    good = read_log(path)
    damaged = raw[:5000] + b"garbage bytes \xfd\xfe\x00" + raw[5000:]
    damaged[20_000] ^= 0xFF  # a CRC failure (or a broken header) later on
    damaged = damaged[:-7]  # a truncated last record
    out = tmp_path / "damaged.tlog"
    out.write_bytes(bytes(damaged))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_log(out)
    text = "\n".join(str(w.message) for w in caught)
    assert "damaged records skipped" in text and "truncated last record dropped: 1" in text
    n_good = sum(len(s) for s in good.streams().values())
    n_read = sum(len(s) for s in log.streams().values())
    assert n_good - 6 <= n_read < n_good  # at most the hit records are lost
    assert summarize(log).streams


def test_not_a_tlog_is_one_line(tmp_path):
    path = tmp_path / "x.tlog"
    path.write_bytes(b"hello world, this is not a tlog" * 10)
    with pytest.raises(ReaderError, match=r"x\.tlog: not a MAVLink telemetry log"):
        read_log(path)
    (tmp_path / "e.tlog").write_bytes(b"")
    with pytest.raises(ReaderError, match="empty"):
        read_log(tmp_path / "e.tlog")


def test_sniffed_without_suffix(tmp_path, tlog_file):
    path, _ = tlog_file
    other = tmp_path / "telemetry.bin2"
    other.write_bytes(path.read_bytes()[:20_000])
    assert detect_format(other) == "tlog"
    (tmp_path / "junk.bin2").write_bytes(b"\x00" * 100)
    with pytest.raises(ReaderError, match="unknown log format"):
        detect_format(tmp_path / "junk.bin2")


def test_a_damaged_timestamp_drops_one_message(tmp_path, sim_log):
    rows = pressure_rows(sim_log)[:20]
    encoder = new_mav()
    chunks = [record(encoder, t, m) for t, m in rows]
    stamp = struct.unpack(">Q", chunks[7][:8])[0] + 2 * 86_400 * 10**6  # two days off
    chunks[7] = struct.pack(">Q", stamp) + chunks[7][8:]  # the frame itself is intact
    path = tmp_path / "stamp.tlog"
    path.write_bytes(b"".join(chunks))
    with pytest.warns(UserWarning, match="an hour off their neighbours' dropped: 1"):
        log = read_log(path)
    expected = np.delete(sim_log.pressure.pressure[:20], 7)
    np.testing.assert_allclose(log.pressure.pressure, expected, rtol=1e-7)


def test_undertow_info_on_a_tlog(tlog_file):
    import json

    from typer.testing import CliRunner

    from undertow.cli import app

    path, _ = tlog_file
    result = CliRunner().invoke(app, ["info", str(path), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    counts = {s["name"]: s["messages"] for s in info["streams"]}
    log = read_log(path)
    assert counts == {name: len(s) for name, s in log.streams().items()}
    bad = path.parent / "bad.tlog"
    bad.write_bytes(b"not a tlog" * 30)
    result = CliRunner().invoke(app, ["info", str(bad)])
    assert result.exit_code == 1 and "not a MAVLink telemetry log" in result.output
    assert "Traceback" not in result.output


def test_the_autopilots_ground_pressure_parameter_is_the_surface_pressure(tmp_path, sim_log):
    """ArduSub's BARO2_GND_PRESS (the Bar30 of SCALED_PRESSURE2, calibrated at boot) in a
    PARAM_VALUE: the surface pressure, stated; BARO1_GND_PRESS (another barometer) is not."""
    rows = attitude_rows(sim_log) + pressure_rows(sim_log)
    t0 = rows[0][0]
    for name, value in ((b"BARO1_GND_PRESS", 99_800.0), (b"BARO2_GND_PRESS", 97_770.0)):
        rows.append((t0, mavlink2.MAVLink_param_value_message(name, value, 9, 300, 1)))
    path = tmp_path / "params.tlog"
    write_tlog(path, sorted(rows, key=lambda r: r[0]))
    log = read_log(path)
    assert log.metadata["surface_pressure_pa"] == 97_770.0
    assert "BARO2_GND_PRESS" in log.metadata["surface_pressure_source"]
