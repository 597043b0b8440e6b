"""One time base per log (undertow.io.clock): chosen from the stamps and record times, stated,
overridable; a log of mixed clocks never spans days."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from conftest import REAL_DATA
from io_fixtures import header, write_raw_bag

from undertow.errors import ConfigError
from undertow.io import LogOptions, read_log
from undertow.io.clock import ClockTable, check_policy, choose_time_base
from undertow.io.msgdefs import dvl_typestore

T = dvl_typestore().types
COUG = REAL_DATA / "coug_a50_imu_ros2"


def _table(streams: dict[str, tuple[np.ndarray, np.ndarray]]) -> ClockTable:
    table = ClockTable()
    for name, (stamps, records) in streams.items():
        for h, r in zip(stamps, records, strict=True):
            table.add(name, h, r)
    return table


def test_stamps_on_one_clock_are_the_base():
    r = 1000.0 + np.arange(10) * 0.1
    table = _table({"imu": (r - 0.01, r), "dvl": (r - 0.2, r + 0.05)})
    base = choose_time_base(table)
    assert base.base == "header" and not base.mixed
    np.testing.assert_array_equal(base.times[:10], r - 0.01)
    assert base.offsets_s["dvl"] == pytest.approx(0.25)


def test_a_stream_without_stamps_puts_every_stream_on_the_record_time():
    r = 1000.0 + np.arange(10) * 0.1
    table = _table({"imu": (np.full(10, np.nan), r), "dvl": (r - 515_000.0, r)})
    base = choose_time_base(table, names={"imu": "/imu"})
    assert base.base == "record" and base.mixed
    np.testing.assert_array_equal(base.times, np.r_[r, r])
    assert "/imu (10 of 10)" in base.reason and "515,000 s" in base.reason
    assert "--time header|record" in base.line()


def test_stamps_on_two_clocks_put_every_stream_on_the_record_time():
    r = 1000.0 + np.arange(10) * 0.1
    table = _table({"imu": (r, r), "dvl": (r - 3600.0, r)})
    base = choose_time_base(table)
    assert base.base == "record" and base.mixed and "3,600 s off" in base.reason


def test_header_asked_puts_unstamped_messages_on_the_stamps_clock():
    r = 1000.0 + np.arange(10) * 0.1
    table = _table({"imu": (np.full(10, np.nan), r), "dvl": (r - 500.0, r)})
    base = choose_time_base(table, "header")
    assert base.base == "header" and base.shift_s == {"imu": 500.0}
    np.testing.assert_allclose(base.times, np.r_[r - 500.0, r - 500.0])


def test_record_asked_and_a_bad_policy():
    r = np.arange(5.0)
    base = choose_time_base(_table({"a": (r + 1, r)}), "record")
    np.testing.assert_array_equal(base.times, r)
    with pytest.raises(ConfigError, match="auto, header or record"):
        check_policy("gps")


def test_a_log_without_any_stamp_is_not_mixed():
    r = np.arange(5.0)
    base = choose_time_base(_table({"json": (np.full(5, np.nan), r)}))
    assert base.base == "record" and not base.mixed


def _imu(t: float, stamp: bool):
    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    v = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.01)
    return T["sensor_msgs/msg/Imu"](
        header=header(t if stamp else 0.0),
        orientation=q,
        orientation_covariance=np.zeros(9),
        angular_velocity=v,
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=v,
        linear_acceleration_covariance=np.zeros(9),
    )


def _pressure(t: float):
    return T["sensor_msgs/msg/FluidPressure"](header=header(t), fluid_pressure=101_325.0,
                                              variance=0.0)  # fmt: skip


def _bag(tmp_path, offset_s: float):
    """IMU with zero stamps and a pressure stamped ``offset_s`` before its record time."""
    record = 1_744_320_600.0 + 0.1 * np.arange(30)
    msgs = [("/imu/data", "sensor_msgs/msg/Imu", int(t * 1e9), _imu(t, False)) for t in record]
    msgs += [("/pressure", "sensor_msgs/msg/FluidPressure", int((t + 0.05) * 1e9),
              _pressure(t + 0.05 - offset_s)) for t in record]  # fmt: skip
    write_raw_bag(tmp_path / "bag", msgs)
    return tmp_path / "bag", record


def _read(path, **options):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_log(path, options=LogOptions(**options))
    return log, [str(w.message) for w in caught]


def test_a_replayed_bag_is_put_on_one_clock_and_says_so(tmp_path):
    path, record = _bag(tmp_path, 515_220.0)
    log, lines = _read(path)
    start, end = log.time_span
    assert end - start < 4.0  # not 515,000 s of interleaved clocks
    np.testing.assert_allclose(log.imu.t, record, atol=1e-6)
    np.testing.assert_allclose(log.pressure.t, record + 0.05, atol=1e-6)
    tb = log.metadata["time_base"]
    assert tb["base"] == "record" and tb["mixed_clocks"] and tb["missing_stamps"]["imu"] == 30
    assert sum("time base: record" in line for line in lines) == 1
    forced, lines = _read(path, time="header")
    np.testing.assert_allclose(forced.pressure.t, record + 0.05 - 515_220.0, atol=1e-6)
    np.testing.assert_allclose(forced.imu.t, record + 0.05 - 515_220.0 - 0.05, atol=1e-3)
    assert any("as asked" in line for line in lines)


@pytest.mark.realdata
def test_the_real_auv_bag_reads_on_one_clock():
    """The shared AUV recording: IMU stamps all zero, DVL and pressure about 515,000 s before
    the record time: the record time for all, its span the bag's own (about 20 s)."""
    log, lines = _read(COUG)
    start, end = log.time_span
    assert 10.0 < end - start < 25.0
    tb = log.metadata["time_base"]
    assert tb["base"] == "record" and tb["missing_stamps"]["imu"] == len(log.imu)
    assert math.isclose(tb["offsets_s"]["dvl"], tb["offsets_s"]["pressure"], abs_tol=1.0)
    assert tb["offsets_s"]["dvl"] > 500_000
    assert any("/coug2/modem_imu" in line and "time base" in line for line in lines)
