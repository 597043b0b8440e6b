"""ArduPilot dataflash logs (.BIN, text .log): the real ArduSub log and logs the test writes.

The synthetic logs are written by :class:`DataflashWriter` in ArduPilot's binary format (FMT
records, then UNIT/MULT/FMTU, then data records with ArduPilot 4.1's layouts from
``LogStructure.h``) from known motion; pymavlink's own ``DFReader`` reads them back as a peer.
The real log (``ardusub_small.BIN``, a vehicle resting at the surface) is checked against
physics and against its own other records, never against numbers this reader printed.
"""

from __future__ import annotations

import contextlib
import io
import math
import random
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import REAL_DATA

from undertow.errors import ReaderError, UndertowError
from undertow.io import detect_format, read_log, summarize
from undertow.io.dataflash import read_dataflash
from undertow.io.dataflash_streams import interpolate_orientation
from undertow.log import G0
from undertow.rotations import quaternion_to_rpy, rpy_to_matrix, rpy_to_quaternion, wrap_angle

BIN = REAL_DATA / "ardusub_small.BIN"
SEED = Path(__file__).resolve().parents[2] / "fuzz" / "corpus" / "ardusub_head.BIN"


def realdata(test):
    """Marks a test of the real log (a missing shared folder fails it: conftest.py)."""
    return pytest.mark.realdata(test)


# -- a dataflash writer (the binary format pymavlink's DFReader reads) ---------------------------

HEAD = b"\xa3\x95"
STRUCT = {"b": "b", "B": "B", "h": "h", "H": "H", "i": "i", "I": "I", "f": "f", "d": "d",
          "n": "4s", "N": "16s", "Z": "64s", "c": "h", "C": "H", "e": "i", "E": "I", "L": "i",
          "M": "b", "q": "q", "Q": "Q"}  # fmt: skip
SCALE = {"c": 100, "C": 100, "e": 100, "E": 100, "L": 1e7}
UNITS = {"-": "", "#": "instance", "s": "s", "m": "m", "n": "m/s", "o": "m/s/s", "E": "rad/s",
         "k": "deg/s", "d": "deg", "h": "degheading", "r": "rad", "P": "Pa", "D": "deglatitude",
         "U": "deglongitude", "O": "degC", "S": "satellites", "z": "Hz", "%": "%"}  # fmt: skip
MULTS = {"-": 0.0, "?": 1.0, "0": 1.0, "B": 1e-2, "C": 1e-3, "F": 1e-6, "G": 1e-7}
#: ArduSub 4.1's layouts (name: type id, format, columns, unit ids, multiplier ids)
FORMATS = {
    "IMU": (130, "QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz",
            "s#EEEooo--O--zz", "F-000000-----00"),
    "ATT": (131, "QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF",
            "sddddhhdh-", "FBBBBBBBB-"),
    "BARO": (132, "QBffcfIffB", "TimeUS,I,Alt,Press,Temp,CRt,SMS,Offset,GndTemp,Health",
             "s#mPOnsmO-", "F-00B0C?0-"),
    "RFND": (133, "QBCBB", "TimeUS,Instance,Dist,Stat,Orient", "s#m--", "F-B--"),
    "VISO": (134, "Qffffffff", "TimeUS,dt,AngDX,AngDY,AngDZ,PosDX,PosDY,PosDZ,conf",
             "ssrrrmmm-", "FF000000-"),
    "VISP": (135, "QQIffffffffBB",
             "TimeUS,RTimeUS,CTimeMS,PX,PY,PZ,Roll,Pitch,Yaw,PErr,AErr,Rst,Ign",
             "sssmmmddhmd--", "FFC00000000--"),
    "VISV": (136, "QQIffffBB", "TimeUS,RTimeUS,CTimeMS,VX,VY,VZ,VErr,Rst,Ign", "sssnnnn--",
             "FFC0000--"),
    "GPS": (137, "QBBIHBcLLeffffB",
            "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
            "s#---SmDUmnhnh-", "F----0BGGB000--"),
    "GPA": (138, "QBCCCCfBIH", "TimeUS,I,VDop,HAcc,VAcc,SAcc,YAcc,VV,SMS,Delta", "s#mmmnd-ss",
            "F-BBBB0-CC"),
    "XKF1": (139, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH",
             "s#ddhnnnnmmmkkkm", "F-BBB0000000BBBB"),
    "PARM": (140, "QNf", "TimeUS,Name,Value", "s--", "F--"),
    "MSG": (141, "QZ", "TimeUS,Message", "s-", "F-"),
}  # fmt: skip


class DataflashWriter:
    """Writes ArduPilot dataflash records: FMT (type 0x80: Type, Length, Name[4], Format[16],
    Columns[64]), UNIT/MULT/FMTU, then data records [0xA3 0x95 type][packed little-endian body],
    fields of format c/C/e/E stored x100 and L x1e7 (pymavlink's FORMAT_TO_STRUCT); ``text``
    writes the same records as a text log (``NAME, v1, v2, ...``, values scaled)."""

    def __init__(self, text: bool = False, formats=FORMATS) -> None:
        self.text, self.out, self.layout = text, [], {}
        self._define(0x80, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")
        self._define(0xB1, "UNIT", "QbZ", "TimeUS,Id,Label")
        self._define(0xB2, "MULT", "Qbd", "TimeUS,Id,Mult")
        self._define(0xB3, "FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds")
        for key, label in UNITS.items():
            self.write("UNIT", 0, ord(key), label)
        for key, mult in MULTS.items():
            self.write("MULT", 0, ord(key), mult)
        for name, (type_id, form, columns, units, mults) in formats.items():
            self._define(type_id, name, form, columns)
            self.write("FMTU", 0, type_id, units, mults)

    def _define(self, type_id: int, name: str, form: str, columns: str) -> None:
        length = 3 + struct.calcsize("<" + "".join(STRUCT[c] for c in form))
        self.layout[name] = (type_id, form, columns.split(","))
        self.write("FMT", type_id, length, name, form, columns)

    def write(self, name: str, *values) -> None:
        type_id, form, _ = self.layout[name]
        if self.text:
            self.out.append(", ".join([name, *(str(v) for v in values)]) + "\n")
            return
        packed = []
        for char, value in zip(form, values, strict=True):
            if char in SCALE:
                value = int(round(value * SCALE[char]))
            elif char in "nNZ":
                value = value.encode()
            packed.append(value)
        body = struct.pack("<" + "".join(STRUCT[c] for c in form), *packed)
        self.out.append(HEAD + bytes([type_id]) + body)

    def record(self, name: str, **fields) -> None:
        """A record of ``name`` with the given columns (the others 0)."""
        _, form, columns = self.layout[name]
        values = [
            fields.pop(c, "" if f in "nNZ" else 0) for c, f in zip(columns, form, strict=True)
        ]
        assert not fields, fields
        self.write(name, *values)

    def bytes(self) -> bytes:
        return "".join(self.out).encode() if self.text else b"".join(self.out)


# -- the synthetic dive --------------------------------------------------------------------------

T0 = 10.0  # s since boot
ROLL, PITCH = 5.0, -3.0  # deg
YAW0, YAW_RATE = 350.0, 30.0  # deg, deg/s: the heading crosses north
V_BODY = np.array([0.5, -0.2, 0.1])  # m/s, body FRD
ORIGIN = (47.3769, 8.5417, 408.0)
P_SURFACE, P_WATER_GND = 101_000.0, 101_050.0


def yaw_at(t):
    return (YAW0 + YAW_RATE * (np.asarray(t) - T0)) % 360.0


def rotation_at(t) -> np.ndarray:
    return rpy_to_matrix(np.deg2rad([ROLL, PITCH, float(yaw_at(t))]))


def gps_fix(t):
    """(lat, lon, alt) of a fix 1 m/s north of ORIGIN and 0.1 m/s up (pyproj's geodesic)."""
    from pyproj import Geod

    lon, lat, _ = Geod(ellps="WGS84").fwd(ORIGIN[1], ORIGIN[0], 0.0, 1.0 * (t - T0))
    return lat, lon, ORIGIN[2] + 0.1 * (t - T0)


def dive(dvl: str = "viso", text: bool = False, formats=FORMATS, imu_deg: bool = False,
         primary: bool = True) -> bytes:  # fmt: skip
    """Three seconds of a vehicle turning at 30 deg/s, descending 0.5 m/s."""
    w = DataflashWriter(text, formats)
    w.record("MSG", TimeUS=int(T0 * 1e6) - 1000, Message="ArduSub V4.5.0 (abcdef12)")
    params = {"BARO_PRIMARY": 1, "BARO2_GND_PRESS": P_SURFACE, "BARO_SPEC_GRAV": 1.0,
              "RNGFND1_MIN_CM": 20, "RNGFND1_MAX_CM": 5000, "VISO_POS_X": 0.1, "VISO_POS_Y": 0.0,
              "VISO_POS_Z": 0.2}  # fmt: skip
    if not primary:
        del params["BARO_PRIMARY"]
    for name, value in params.items():
        w.record("PARM", TimeUS=int(T0 * 1e6) - 500, Name=name, Value=value)
    events = []
    for i in range(150):  # IMU 50 Hz, between the ATT samples
        events.append((T0 + 0.01 + 0.02 * i, "imu", i))
    for i in range(31):
        events.append((T0 + 0.1 * i, "att", i))
    for i in range(15):  # 5 Hz sensors
        events.append((T0 + 0.05 + 0.2 * i, "slow", i))
    for t, kind, i in sorted(events):
        us = int(round(t * 1e6))
        if kind == "imu":
            gyro = (0.0, 0.0, YAW_RATE if imu_deg else math.radians(YAW_RATE))
            w.record("IMU", TimeUS=us, I=0, GyrX=gyro[0], GyrY=gyro[1], GyrZ=gyro[2], AccX=0.0,
                     AccY=0.0, AccZ=-G0, GH=1, AH=1)  # fmt: skip
        elif kind == "att":
            w.record("ATT", TimeUS=us, Roll=ROLL, Pitch=PITCH, Yaw=float(yaw_at(t)))
        else:
            _slow_records(w, t, us, i, dvl)
    return w.bytes()


def _slow_records(w: DataflashWriter, t: float, us: int, i: int, dvl: str) -> None:
    depth = 0.5 * (t - T0)
    p_water = P_SURFACE + 9800.0 * depth
    w.record("BARO", TimeUS=us, I=0, Press=99_000.0, Alt=0.0, Health=1)  # the air baro
    w.record("BARO", TimeUS=us, I=1, Press=p_water, Alt=(P_WATER_GND - p_water) / 9800.0)
    w.record("RFND", TimeUS=us, Instance=0, Dist=2.5, Stat=1 if i == 3 else 4, Orient=25)
    w.record("RFND", TimeUS=us, Instance=1, Dist=7.0, Stat=4, Orient=0)  # looking forward
    if dvl == "viso":
        d = V_BODY * 0.2
        w.record("VISO", TimeUS=us, dt=0.2, PosDX=d[0], PosDY=d[1], PosDZ=d[2],
                 conf=0.0 if i == 5 else 80.0)  # fmt: skip
    else:
        v = rotation_at(t) @ V_BODY  # NED, as ArduPilot logs VISV
        w.record("VISV", TimeUS=us, VX=v[0], VY=v[1], VZ=v[2], VErr=0.05, Ign=int(i == 5))
    w.record("VISP", TimeUS=us, PX=1.0 + t, PY=2.0, PZ=depth, Roll=ROLL, Pitch=PITCH,
             Yaw=float(yaw_at(t)), PErr=0.05, Rst=int(i >= 10))  # fmt: skip
    lat, lon, alt = gps_fix(t)
    status = 1 if i == 2 else 6  # one record without a fix
    if i == 4:
        lat = lon = 0.0  # ArduPilot's "no position" with a fix status: impossible
    w.record("GPS", TimeUS=us, I=0, Status=status, Lat=lat, Lng=lon, Alt=alt, NSats=12)
    w.record("GPA", TimeUS=us, I=0, HAcc=0.02)
    for core in (0, 1):
        w.record("XKF1", TimeUS=us, C=core, Roll=ROLL, Pitch=PITCH, Yaw=float(yaw_at(t)),
                 VN=1.0, VE=2.0 + core, VD=0.5, PN=1.0 * (t - T0), PE=0.0, PD=depth)  # fmt: skip


def _read(path, data: bytes):
    path.write_bytes(data)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_log(path)
    return log, [str(w.message) for w in caught]


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    path = tmp_path_factory.mktemp("df") / "dive.BIN"
    return _read(path, dive())


def test_writer_is_read_by_pymavlink_as_written(tmp_path):
    """The writer follows pymavlink's DFReader format: its reader sees the values written."""
    from pymavlink import DFReader

    path = tmp_path / "dive.BIN"
    path.write_bytes(dive())
    reader = DFReader.DFReader_binary(str(path))
    imu, att = [], []
    while (m := reader.recv_match(type=["IMU", "ATT"])) is not None:
        (imu if m.get_type() == "IMU" else att).append(m)
    reader.close()
    assert len(imu) == 150 and len(att) == 31
    assert imu[0].AccZ == pytest.approx(-G0, rel=1e-6)
    assert att[3].Yaw == pytest.approx(float(yaw_at(T0 + 0.3)), abs=0.01)
    log = read_dataflash(path)
    np.testing.assert_allclose(log.imu.angular_velocity[:, 2], [m.GyrZ for m in imu])
    np.testing.assert_allclose(log.imu.t, [m.TimeUS * 1e-6 for m in imu])


def test_imu_and_its_attitude_interpolated(synthetic):
    log, _ = synthetic
    imu = log.imu
    assert len(imu) == 150 and np.all(np.diff(imu.t) > 0)
    np.testing.assert_allclose(imu.angular_velocity[:, 2], math.radians(YAW_RATE), rtol=1e-6)
    np.testing.assert_allclose(imu.linear_acceleration[:, 2], -G0, rtol=1e-6)
    rpy = quaternion_to_rpy(imu.orientation)  # slerp between ATT samples 0.1 s apart
    expect = np.deg2rad(np.column_stack([np.full(150, ROLL), np.full(150, PITCH), yaw_at(imu.t)]))
    err = wrap_angle(rpy - expect)
    assert np.abs(err).max() < 2e-4  # the ATT's centidegree resolution
    assert "ATT interpolated" in log.metadata["dataflash"]["imu"]


def test_pressure_is_the_depth_sensor_with_its_ground_pressure(synthetic):
    log, _ = synthetic
    p = log.pressure
    depth = 0.5 * (p.t - T0)
    np.testing.assert_allclose(p.pressure, P_SURFACE + 9800.0 * depth, rtol=1e-7)
    assert log.metadata["surface_pressure_pa"] == P_SURFACE
    assert "BARO2_GND_PRESS" in log.metadata["surface_pressure_source"]
    assert "BARO_PRIMARY" in log.metadata["dataflash"]["pressure"]


def test_depth_sensor_found_by_its_water_formula(tmp_path):
    """Without BARO_PRIMARY, the barometer whose Alt follows Press at -1 / 9800 m/Pa (AP_Baro's
    water-type formula) is the depth sensor."""
    log, _ = _read(tmp_path / "noprimary.BIN", dive(primary=False))
    np.testing.assert_allclose(log.pressure.pressure[0], P_SURFACE + 9800.0 * 0.025, rtol=1e-7)
    assert "water-type" in log.metadata["dataflash"]["pressure"]


def test_gyr_only_when_no_imu(tmp_path):
    """GYR (raw samples, timed by SampleUS) stands in for a log without IMU records."""
    w = DataflashWriter(formats={"ATT": FORMATS["ATT"]})
    w._define(150, "GYR", "QBQfff", "TimeUS,I,SampleUS,GyrX,GyrY,GyrZ")
    w.write("FMTU", 0, 150, "s#sEEE", "F-F000")
    for i in range(20):
        us = 10_000_000 + 1000 * i
        w.record("GYR", TimeUS=us + 500, I=0, SampleUS=us, GyrX=0.1, GyrY=0.0, GyrZ=-0.2)
        w.record("ATT", TimeUS=us, Roll=1.0, Pitch=2.0, Yaw=3.0)
    log, _ = _read(tmp_path / "gyr.BIN", w.bytes())
    np.testing.assert_allclose(log.imu.t, 10.0 + 0.001 * np.arange(20))
    np.testing.assert_allclose(log.imu.angular_velocity[:, [0, 2]], [[0.1, -0.2]] * 20, rtol=1e-6)
    assert log.imu.linear_acceleration is None and log.metadata["dataflash"]["imu"][:3] == "GYR"


def test_rangefinder_downward_status_and_limits(synthetic):
    log, notes = synthetic
    s = log.sonar
    assert len(s) == 15 and s.min_range == pytest.approx(0.2) and s.max_range == pytest.approx(50)
    assert np.isnan(s.range[3]) and np.allclose(np.delete(s.range, 3), 2.5)
    assert any("not looking down ignored: 15" in n for n in notes)


def test_viso_is_a_body_velocity(synthetic):
    log, _ = synthetic
    dvl = log.dvl
    np.testing.assert_allclose(dvl.velocity, np.tile(V_BODY, (15, 1)), atol=1e-6)
    assert dvl.valid.tolist() == [i != 5 for i in range(15)]
    np.testing.assert_allclose(log.mounting.dvl.translation, (0.1, 0.0, 0.2), rtol=1e-6)
    assert log.mounting.dvl.rotation == (0.0, 0.0, 0.0)


def test_visv_ned_velocity_is_rotated_into_the_body(tmp_path):
    log, _ = _read(tmp_path / "visv.BIN", dive(dvl="visv"))
    dvl = log.dvl
    # (the ATT attitude is interpolated to the VISV times; centidegree angles)
    np.testing.assert_allclose(dvl.velocity, np.tile(V_BODY, (15, 1)), atol=2e-4)
    assert dvl.valid.tolist() == [i != 5 for i in range(15)]
    np.testing.assert_allclose(np.sqrt(dvl.covariance[:, 0, 0]), 0.05, rtol=1e-6)
    assert log.metadata["dataflash"]["dvl"].startswith("VISV")


def test_visp_dead_reckoning(synthetic):
    log, _ = synthetic
    dr = log.dead_reckoning
    np.testing.assert_allclose(dr.position[:, 0], 1.0 + dr.t, rtol=1e-6)
    np.testing.assert_allclose(dr.position[:, 2], 0.5 * (dr.t - T0), atol=1e-6)
    np.testing.assert_allclose(np.rad2deg(dr.orientation[:, 0]), ROLL, atol=1e-5)
    yaw = np.deg2rad(yaw_at(dr.t))
    assert np.abs(wrap_angle(dr.orientation[:, 2] - yaw)).max() < 1e-6
    np.testing.assert_allclose(dr.std, 0.05, rtol=1e-6)
    assert log.metadata["dataflash"]["dead_reckoning"]["resets"] == 1


def test_gps_local_metres_and_dropped_fixes(synthetic):
    log, notes = synthetic
    gps = log.gps
    assert len(gps) == 13  # 15 records, one without a fix, one at (0, 0)
    north = 1.0 * (gps.t - T0)  # the geodesic distance the fixes were made at, due north
    np.testing.assert_allclose(
        gps.position[:, 0] - gps.position[0, 0], north - north[0], atol=0.02
    )  # fmt: skip  (1e-7 deg quantization: 1 cm)
    assert np.abs(gps.position[:, 1]).max() < 0.02
    np.testing.assert_allclose(gps.position[:, 2], -0.1 * (gps.t - gps.t[0]), atol=0.011)
    assert gps.origin[0] == pytest.approx(gps.latitude[0]) and gps.origin[2] == gps.altitude[0]
    np.testing.assert_allclose(gps.horizontal_std, 0.02)
    assert any("without a 3D fix dropped: 1" in n for n in notes)
    assert any("impossible coordinates dropped: 1" in n for n in notes)


def test_gps_about_a_given_origin(tmp_path):
    from undertow.io.read_options import LogOptions

    path = tmp_path / "dive.BIN"
    path.write_bytes(dive())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = read_log(path, options=LogOptions(gps_origin=list(ORIGIN)))
    gps = log.gps
    np.testing.assert_allclose(gps.position[:, 0], 1.0 * (gps.t - T0), atol=0.02)
    np.testing.assert_allclose(gps.position[:, 2], -0.1 * (gps.t - T0), atol=0.011)
    assert gps.origin == ORIGIN and log.metadata["gps_origin"] == list(ORIGIN)


def test_autopilot_is_ekf_core_zero(synthetic):
    log, _ = synthetic
    ap = log.autopilot
    assert len(ap) == 15
    np.testing.assert_allclose(ap.velocity, np.tile([1.0, 2.0, 0.5], (15, 1)), rtol=1e-6)
    np.testing.assert_allclose(ap.position[:, 0], ap.t - T0, atol=1e-5)
    assert log.metadata["vehicle"] == "ArduSub"
    assert log.metadata["firmware"] == "ArduSub V4.5.0 (abcdef12)"
    assert log.metadata["format"] == "dataflash"


def test_text_log_reads_like_the_binary(tmp_path, synthetic):
    binary, _ = synthetic
    text = dive(text=True)
    lines = text.decode().splitlines()
    # a fix whose latitude is NaN (a text log can hold one): dropped and counted
    i = next(k for k, ln in enumerate(lines) if ln.startswith("GPS,") and ", 6, " in ln)
    parts = lines[i].split(", ")
    parts[8] = "nan"  # Lat
    lines[i] = ", ".join(parts)
    path = tmp_path / "dive.log"
    log, notes = _read(path, ("\n".join(lines) + "\n").encode())
    assert detect_format(path) == "dataflash"
    for name in ("imu", "pressure", "sonar", "dvl", "dead_reckoning", "autopilot"):
        a, b = getattr(log, name), getattr(binary, name)
        np.testing.assert_allclose(a.t, b.t)
    np.testing.assert_allclose(log.imu.orientation, binary.imu.orientation, atol=1e-6)
    assert len(log.gps) == len(binary.gps) - 1
    assert any("impossible coordinates dropped: 2" in n for n in notes)


def test_declared_units_are_converted_or_refused(tmp_path):
    formats = dict(FORMATS)
    formats["IMU"] = (*FORMATS["IMU"][:3], "s#kkkooo--O--zz", FORMATS["IMU"][4])  # deg/s gyro
    formats["BARO"] = (*FORMATS["BARO"][:3], "s#mmOnsmO-", FORMATS["BARO"][4])  # Press in "m"
    log, notes = _read(tmp_path / "units.BIN", dive(formats=formats, imu_deg=True))
    np.testing.assert_allclose(log.imu.angular_velocity[:, 2], math.radians(YAW_RATE), rtol=1e-6)
    assert any("IMU.GyrX: unit 'deg/s' in the log, converted to rad/s" in n for n in notes)
    assert log.pressure is None
    assert any("BARO.Press: unit 'm' in the log, expected Pa" in n for n in notes)


def test_truncated_and_garbage_keep_the_good_records(tmp_path, synthetic):
    good, _ = synthetic
    data = dive()
    log, notes = _read(tmp_path / "cut.BIN", data[:-7])  # the last record (EKF core 1's) cut
    assert {n: len(s) for n, s in log.streams().items()} == {
        n: len(s) for n, s in good.streams().items()
    }
    assert any("truncated last record dropped: 1" in n for n in notes)
    rng = random.Random(1)
    junk = bytes(rng.randrange(256) for _ in range(3000))
    middle = len(data) // 2
    log, notes = _read(tmp_path / "junk.BIN", data[:middle] + junk + data[middle:])
    for name, stream in good.streams().items():
        assert len(getattr(log, name)) >= len(stream) - 1, name  # (a record cut by the junk)
    assert any("damaged regions skipped: 1" in n for n in notes)


def test_fmt_redefining_a_type_is_refused(tmp_path, synthetic):
    """A damaged FMT giving IMU's type another layout mid-log is skipped and counted; the IMU
    records after it keep their layout."""
    good, _ = synthetic
    data = dive()
    type_id = FORMATS["IMU"][0]
    body = struct.pack("<BB4s16s64s", type_id, 3 + 12, b"IMU", b"Qf", b"TimeUS,GyrX")
    middle = data.find(HEAD + bytes([type_id]), len(data) // 2)
    log, notes = _read(tmp_path / "fmt.BIN", data[:middle] + HEAD + b"\x80" + body + data[middle:])
    np.testing.assert_array_equal(log.imu.angular_velocity, good.imu.angular_velocity)
    assert any("FMT records with unknown format characters or lengths skipped: 1" in n
               for n in notes)  # fmt: skip


def test_time_outlier_is_dropped(tmp_path):
    data = bytearray(dive())
    marker = HEAD + bytes([FORMATS["IMU"][0]])
    at = data.find(marker, len(data) // 2)
    struct.pack_into("<Q", data, at + 3, struct.unpack_from("<Q", data, at + 3)[0] + 10**11)
    log, notes = _read(tmp_path / "outlier.BIN", bytes(data))
    assert len(log.imu) == 149 and log.imu.t[-1] - log.imu.t[0] < 4
    assert any("IMU: records with a time an hour off" in n for n in notes)


@pytest.mark.parametrize(
    "content",
    [b"", b"\x00" * 5000, bytes(random.Random(2).randrange(256) for _ in range(20000)),
     b"\xa3\x95\x80" + b"\x00" * 86],
    ids=["empty", "zeros", "garbage", "fmt-only"],
)  # fmt: skip
def test_not_a_usable_dataflash_log_is_one_line(tmp_path, content):
    path = tmp_path / "bad.BIN"
    path.write_bytes(content)
    with pytest.raises(ReaderError) as err:
        read_log(path)
    assert str(err.value).startswith(str(path)) and "\n" not in str(err.value)


def test_detection_by_suffix_and_content(tmp_path):
    data = dive()
    for name in ("a.BIN", "a.bin", "a.log", "renamed.dat"):
        (tmp_path / name).write_bytes(data)
        assert detect_format(tmp_path / name) == "dataflash", name
    (tmp_path / "dvl.log").write_text('{"type": "velocity", "vx": 0.1}\n')
    assert detect_format(tmp_path / "dvl.log") == "a50_json"


def test_interpolate_orientation_gaps_and_ends():
    q = rpy_to_quaternion(np.deg2rad([[0, 0, 0], [0, 0, 90], [0, 0, 100]]))
    t_src = np.array([0.0, 1.0, 5.0])
    out = interpolate_orientation(t_src, q, np.array([-0.5, 0.5, 3.0, 5.5, 7.0]), max_gap_s=1.0)
    yaw = np.rad2deg(quaternion_to_rpy(out[[0, 1, 3]])[:, 2])
    np.testing.assert_allclose(yaw, [0.0, 45.0, 100.0], atol=1e-9)  # ends held within 1 s
    assert np.isnan(out[2]).all() and np.isnan(out[4]).all()  # in a 4 s gap; 2 s past the end


def _mutate(rng: random.Random, data: bytes) -> bytes:
    out = bytearray(data)
    kind = rng.choice(("flip", "flip", "fill", "truncate", "splice"))
    if kind == "truncate":
        return bytes(out[: rng.randrange(len(out))])
    if kind == "splice":
        i, n = rng.randrange(len(out)), rng.choice((1, 7, 89, 1000))
        return bytes(out[:i] + out[i : i + n] * 2 + out[i + n :] if rng.random() < 0.5
                     else out[:i] + out[i + n :])  # fmt: skip
    for _ in range(rng.choice((1, 4, 16))):
        i = rng.randrange(len(out))
        if kind == "flip":
            out[i] ^= 1 << rng.randrange(8)
        else:
            out[i : i + 64] = rng.choice((b"\x00", b"\xff", b"\xa3")) * len(out[i : i + 64])
    return bytes(out)


def test_fuzzed_bin_bytes_never_escape(tmp_path):
    """Mutations of the fuzzing seed (the head of the real log, fuzz/corpus/) read to a Log or
    one UndertowError line; no other exception, no numpy warning, nothing printed."""
    seed = SEED.read_bytes()
    rng = random.Random(23)
    outcomes = {"log": 0, "error": 0}
    for k in range(60):
        path = tmp_path / f"in{k}.BIN"
        path.write_bytes(_mutate(rng, seed))
        printed = io.StringIO()
        with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(printed):
            warnings.simplefilter("always")
            try:
                read_log(path)
                outcomes["log"] += 1
            except UndertowError as exc:
                assert str(exc) and "\n" not in str(exc), str(exc)
                outcomes["error"] += 1
        leaked = [str(w.message) for w in caught if not issubclass(w.category, UserWarning)]
        assert not leaked and not printed.getvalue(), (k, leaked, printed.getvalue()[:200])
    assert outcomes["log"] > 30  # most damage keeps the good records


# -- the real ArduSub log ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def real():
    """(Log, {message: list of pymavlink records}) of ardusub_small.BIN, the records read by
    pymavlink's own DFReader (a peer reader, for the checks that need other fields)."""
    from pymavlink import DFReader

    log = read_log(BIN)
    reader = DFReader.DFReader_binary(str(BIN))
    records: dict[str, list] = {}
    while (m := reader.recv_match(type=["IMU", "ATT", "BARO", "XKF1"])) is not None:
        records.setdefault(m.get_type(), []).append(m)
    reader.close()
    return log, records, reader.params


@realdata
@pytest.mark.parametrize("name", ["imu", "pressure", "autopilot"])
def test_real_streams_present_on_one_clock(real, name):
    log, _, _ = real
    stream = getattr(log, name)
    assert stream is not None and len(stream) > 100
    assert np.all(np.diff(stream.t) > 0)
    start, end = log.time_span
    assert stream.t[0] - start < 1.0 and end - stream.t[-1] < 1.0  # one boot clock, ~24 s
    assert 20 < end - start < 30


@realdata
def test_real_imu_matches_pymavlink_and_is_si(real):
    log, records, _ = real
    imu0 = [m for m in records["IMU"] if m.I == 0]
    assert len(log.imu) == len(imu0)
    np.testing.assert_allclose(log.imu.angular_velocity[:, 0], [m.GyrX for m in imu0])
    # at rest the accelerometer reads gravity (m/s^2, not g or mg)
    f = np.linalg.norm(log.imu.linear_acceleration.mean(axis=0))
    assert abs(f - G0) < 0.1


@realdata
def test_real_gyro_integrates_to_the_attitude_change(real):
    """The EKF's gyro bias (XKF1 GX/GY/GZ, deg/s) is what the resting gyro reads (rad/s), and
    the bias-corrected gyro integrates to the ATT attitude change: units and frames agree."""
    log, records, _ = real
    bias = np.deg2rad([[m.GX, m.GY, m.GZ] for m in records["XKF1"] if m.C == 0]).mean(axis=0)
    gyro = log.imu.angular_velocity
    np.testing.assert_allclose(gyro.mean(axis=0), bias, atol=np.deg2rad(0.05))
    t = log.imu.t
    turned = np.sum(0.5 * (gyro[1:] - bias + gyro[:-1] - bias) * np.diff(t)[:, None], axis=0)
    att = np.array([[m.TimeUS * 1e-6, m.Roll, m.Pitch, m.Yaw] for m in records["ATT"]])
    inside = (att[:, 0] >= t[0]) & (att[:, 0] <= t[-1])
    change = np.deg2rad(att[inside][-1, 1:] - att[inside][0, 1:])
    np.testing.assert_allclose(turned, change, atol=np.deg2rad(0.5))
    raw = np.sum(0.5 * (gyro[1:] + gyro[:-1]) * np.diff(t)[:, None], axis=0)
    assert np.abs(raw - change).max() > np.deg2rad(5)  # the bias is real: ~0.45 deg/s x 24 s


@realdata
def test_real_attitude_agrees_with_the_ekf(real):
    log, _, _ = real
    ap = log.autopilot
    rpy = quaternion_to_rpy(log.imu.orientation)
    yaw_imu = np.interp(ap.t, log.imu.t, np.unwrap(rpy[:, 2]))
    assert np.abs(wrap_angle(yaw_imu - ap.orientation[:, 2])).max() < np.deg2rad(1.0)
    assert np.abs(np.interp(ap.t, log.imu.t, rpy[:, 0]) - ap.orientation[:, 0]).max() < 0.02


@realdata
def test_real_pressure_is_the_water_depth_sensor(real):
    """ArduSub's depth sensor: its logged Alt is (p_gnd - p) / (9800 SG) (AP_Baro), so Alt and
    the pressure read here change together at -1 / (9800 SG) m/Pa; the EKF's down position
    follows the same depth; the ground pressure parameter is the pressure at the start."""
    log, records, params = real
    p = log.pressure
    k = int(params["BARO_PRIMARY"])
    alt = np.array([m.Alt for m in records["BARO"] if m.I == k])
    sg = params["BARO_SPEC_GRAV"]
    np.testing.assert_allclose(alt - alt[0], -(p.pressure - p.pressure[0]) / (9800.0 * sg),
                               atol=1e-6)  # fmt: skip
    p0 = log.metadata["surface_pressure_pa"]
    assert abs(np.median(p.pressure[p.t < p.t[0] + 2.0]) - p0) < 100.0  # 1 cm of water
    depth = (p.pressure - p0) / (9800.0 * sg)
    pd = np.interp(p.t, log.autopilot.t, log.autopilot.position[:, 2])
    assert np.abs(pd - depth).max() < 0.05
    assert 90_000 < p.pressure.min() and p.pressure.max() < 110_000  # Pa at the surface


@realdata
def test_real_detection_info_and_metadata(tmp_path, real):
    log, _, _ = real
    assert detect_format(BIN) == "dataflash"
    renamed = tmp_path / "ardusub.log"
    renamed.write_bytes(BIN.read_bytes())
    assert detect_format(renamed) == "dataflash"
    summary = summarize(log)
    names = {s.name: s for s in summary.streams}
    assert set(names) == {"imu", "pressure", "autopilot"}
    assert all(s.invalid == 0 and s.missing_values == 0 for s in names.values())
    assert log.metadata["vehicle"] == "ArduSub" and "V4.1" in log.metadata["firmware"]
    assert log.metadata["dataflash"]["units"].startswith("checked against")
