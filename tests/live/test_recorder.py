"""The live recorder: what write_record returns is what read_log reads back, bit for bit."""

from __future__ import annotations

import math
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from rosbags.highlevel import AnyReader

from undertow.errors import ConfigError, DataError
from undertow.io import read_log
from undertow.io.msgdefs import dvl_typestore
from undertow.live.recorder import POSE_TOPIC, STATUS_TOPIC, WAVE_TOPIC, Recorder
from undertow.records import RECORD_FIELDS, Record, records_to_log
from undertow.robot import Mounting
from undertow.rotations import quaternion_to_rpy

T0 = 1_700_000_000.0


def _maybe(rng, value, p_missing=0.1):
    return None if rng.random() < p_missing else value


def _dvl_data(rng) -> dict:
    valid = rng.random(4) < 0.7
    v = rng.normal(0, 0.5, 3)
    if rng.random() < 0.05:
        v[rng.integers(3)] = np.nan
    return {
        "velocity": tuple(v),
        "valid": bool(rng.random() < 0.8),
        "fom": _maybe(rng, float(rng.exponential(0.01))),
        "covariance": _maybe(rng, rng.normal(0, 1e-4, (3, 3))),
        "altitude": float(rng.choice([rng.uniform(0.3, 5), -1.0, np.nan, np.inf])),
        "beam_range": tuple(np.where(rng.random(4) < 0.1, np.nan, rng.uniform(0.3, 6, 4))),
        "beam_valid": tuple(bool(k) for k in valid),
        "beam_velocity": tuple(rng.normal(0, 0.3, 4)),
    }


def _imu_data(rng, first: bool, parts: tuple[bool, bool]) -> dict:
    acc, q = parts if first else (rng.random() < 0.8, rng.random() < 0.8)
    quat = rng.normal(size=4)
    return {
        "angular_velocity": tuple(rng.normal(0, 0.2, 3)),
        "linear_acceleration": tuple(rng.normal(0, 1, 3)) if acc else None,
        "orientation": tuple(quat / np.linalg.norm(quat)) if q else None,
    }


def _data(rng, stream: str, first: bool, imu_parts) -> dict:
    if stream == "dvl":
        return _dvl_data(rng)
    if stream == "imu":
        return _imu_data(rng, first, imu_parts)
    if stream == "dead_reckoning":
        return {
            "position": tuple(rng.normal(0, 10, 3)),
            "orientation": tuple(rng.uniform(-math.pi, math.pi, 3) * [0.5, 0.45, 1]),
            "std": _maybe(rng, float(rng.exponential(0.1))),
        }
    if stream == "pressure":
        return {"pressure": float(rng.uniform(101_000, 140_000))}
    extra = {"field_of_view": 0.4, "min_range": 0.5, "max_range": 30.0} if first else {}
    r = float(rng.choice([rng.uniform(0.1, 40), np.nan, 1e39]))
    return {"range": r, "confidence": float(rng.uniform()), **extra}


def _records(seed: int, t0: float, n: int = 40) -> list[Record]:
    """n records per stream from t0, times random (off the ns grid) and distinct, streams
    interleaved."""
    rng = np.random.default_rng(seed)
    imu_parts = (bool(rng.random() < 0.5), bool(rng.random() < 0.5))
    out = []
    for stream in RECORD_FIELDS:
        times = np.sort(t0 + rng.uniform(0, 60, n))
        for i, t in enumerate(times):
            data = _data(rng, stream, i == 0, imu_parts)
            out.append(Record(stream, float(t), data, t + 0.01, t - 0.002, "test"))
    order = np.argsort([r.t + rng.uniform(-0.5, 0.5) for r in out])  # arrival roughly in time
    return [out[i] for i in order]


def _bits(a) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype == np.bool_:
        return a
    a = a.astype(np.float64)
    return np.where(np.isnan(a), np.float64(np.nan), a).view(np.uint64)  # one NaN, signed zeros


def _assert_same_stream(name: str, read, expected) -> None:
    assert read is not None and expected is not None, name
    assert np.array_equal(_bits(read.t), _bits(expected.t)), f"{name}: t"
    for field in RECORD_FIELDS[name]:
        a, b = getattr(read, field), getattr(expected, field)
        assert (a is None) == (b is None), f"{name}.{field}: {a is None} vs {b is None}"
        if a is not None:
            assert np.array_equal(_bits(a), _bits(b)), f"{name}.{field} differs"
    if name == "sonar":
        for key in ("field_of_view", "min_range", "max_range"):
            assert getattr(read, key) == getattr(expected, key) == np.float32(getattr(read, key))


@pytest.mark.parametrize(("seed", "t0"), [(0, T0), (1, T0), (2, 10.0), (3, 10.0)])
def test_read_log_gives_back_exactly_what_write_record_returned(tmp_path, seed, t0):
    mounting = Mounting().updated({"dvl": {"translation": [0.1, 0.2, 0.3]}})
    rec = Recorder(tmp_path / "rec", mounting, {"water_density_kg_m3": 1025.0})
    records = _records(seed, t0)
    returned = [rec.write_record(r) for r in records]
    assert not (tmp_path / "rec").exists()  # nothing at the target before close
    assert rec.close() == tmp_path / "rec"
    assert [p.name for p in tmp_path.iterdir()] == ["rec"]  # the partial folder is gone
    log = read_log(tmp_path / "rec")
    expected = records_to_log(returned)
    assert sorted(log.streams()) == sorted(RECORD_FIELDS)
    for name in RECORD_FIELDS:
        _assert_same_stream(name, getattr(log, name), getattr(expected, name))
    assert log.mounting == mounting and log.metadata["water_density_kg_m3"] == 1025.0
    # the quantization is real: sonar ranges to float32, times near 0 s to the ns grid (float64
    # at Unix times is coarser than a ns: there the stamp gives the same float back)
    pairs = list(zip(records, returned, strict=True))
    assert any(a.data["range"] != b.data["range"] for a, b in pairs if a.stream == "sonar")
    assert any(a.t != b.t for a, b in pairs) == (t0 < 1e6)


_ANY = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)
_TIME = st.floats(0.0, 2.0**31 - 2, allow_subnormal=True)


def _vec(n):
    return st.tuples(*[_ANY] * n)


_DATA = {
    "imu": st.fixed_dictionaries(
        {"angular_velocity": _vec(3)},
        optional={"linear_acceleration": _vec(3), "orientation": _vec(4)},
    ),
    "dvl": st.fixed_dictionaries(
        {"velocity": _vec(3)},
        optional={
            "valid": st.booleans(),
            "fom": _ANY,
            "altitude": _ANY,
            "covariance": st.lists(_ANY, min_size=9, max_size=9),
            "beam_range": _vec(4),
            "beam_valid": st.tuples(*[st.booleans()] * 4),
            "beam_velocity": _vec(4),
        },
    ),  # fmt: skip
    "dead_reckoning": st.fixed_dictionaries(
        {"position": _vec(3), "orientation": _vec(3)}, optional={"std": _ANY}
    ),
    # the reader takes a pressure stream with a median under 20 kPa for hPa (module docstring)
    "pressure": st.fixed_dictionaries({"pressure": st.floats(2e4, 1e300) | st.just(math.nan)}),
    "sonar": st.fixed_dictionaries({"range": _ANY}, optional={"confidence": _ANY}),
}
_RECORDS = st.lists(
    st.sampled_from(sorted(_DATA)).flatmap(
        lambda s: st.builds(Record, st.just(s), _TIME, _DATA[s])
    ),
    min_size=1,
    max_size=25,
)


@hsettings(max_examples=25, deadline=None, database=None)
@given(_RECORDS)
def test_round_trip_is_exact_for_any_values(records):
    """Extreme values (NaN, inf, subnormals, -0.0, huge), equal times, missing fields."""
    with tempfile.TemporaryDirectory() as tmp:
        rec = Recorder(Path(tmp) / "r")
        returned = [rec.write_record(r) for r in records]
        rec.close()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # NaN rows are noted by the reader
            log = read_log(Path(tmp) / "r")
    expected = records_to_log(returned)
    for name in RECORD_FIELDS:
        assert (getattr(log, name) is None) == (getattr(expected, name) is None), name
        if getattr(log, name) is not None:
            _assert_same_stream(name, getattr(log, name), getattr(expected, name))


def test_equal_reports_a_day_apart_keep_their_covariance(tmp_path):
    """Found by the property test: two equal velocity reports more than a day after the last
    one both get the maximal `time` interval; the second's key must stay inside the interval
    the reader accepts ([0, a day]) or its JSON line, and with it the covariance, is lost."""
    day = 86_400.0
    cov = np.diag([1e-4, 2e-4, 3e-4])
    records = []
    for k in range(3):  # each late report follows an early one: each gets the maximal interval
        records.append(Record("dvl", 0.0, {"velocity": (0.1 * k, 0.0, 0.0)}))
        records.append(Record("dvl", 2 * day, {"velocity": (0.5, 0.1, 0.0), "covariance": cov}))
    with Recorder(tmp_path / "r") as rec:
        returned = [rec.write_record(r) for r in records]
    log = read_log(tmp_path / "r")
    assert np.array_equal(log.dvl.covariance[log.dvl.t > day], np.stack([cov] * 3))
    _assert_same_stream("dvl", log.dvl, records_to_log(returned).dvl)


def test_quantization_rules_on_single_records(tmp_path):
    with Recorder(tmp_path / "q") as rec:
        sonar = rec.write_record(Record("sonar", 10.0, {"range": 0.1, "confidence": 0.5}))
        assert sonar.data["range"] == float(np.float32(0.1)) != 0.1
        assert sonar.data["confidence"] == 0.5  # float64 beside the Range: as given
        missing = rec.write_record(Record("sonar", 10.1, {"range": 0.1}))
        assert math.isnan(missing.data["confidence"])  # a record without one: NaN
        dvl = rec.write_record(
            Record("dvl", 10.5, {"velocity": (0.1, np.nan, 0.0), "covariance": np.eye(3),
                                 "altitude": -1.0, "beam_range": (1, 2, 3, 4),
                                 "beam_valid": (True, False, True, True)})
        )  # fmt: skip
        assert math.isnan(dvl.data["altitude"]) and math.isnan(dvl.data["beam_range"][1])
        assert np.isnan(dvl.data["covariance"]).all()  # no JSON match with a NaN velocity
        assert dvl.data["beam_range"][2] == 3.0 and math.isnan(dvl.data["fom"])
        dr = rec.write_record(
            Record("dead_reckoning", 11.0, {"position": (1, 2, 3), "orientation": (0.1, 0.2, 0.3)})
        )
        assert math.isnan(dr.data["std"])
        np.testing.assert_allclose(dr.data["orientation"], (0.1, 0.2, 0.3), atol=1e-12)
        imu = rec.write_record(Record("imu", 12.0, {"angular_velocity": (0, 0, 1)}))
        assert set(imu.data) == {"angular_velocity"}  # the first IMU record fixes the parts
        later = rec.write_record(
            Record("imu", 12.1, {"angular_velocity": (0, 0, 1), "orientation": (0, 0, 0, 1)})
        )
        assert set(later.data) == {"angular_velocity"}
    log = read_log(tmp_path / "q")
    assert log.imu.orientation is None and log.imu.linear_acceleration is None


def test_estimates_and_late_records_have_their_own_topics(tmp_path):
    rng = np.random.default_rng(5)
    x = rng.normal(size=18)
    x[3:6] = (0.1, -0.2, 2.5)
    A = rng.normal(size=(18, 18))
    P = A @ A.T
    with Recorder(tmp_path / "est") as rec:
        rec.write_record(Record("pressure", 100.0, {"pressure": 110_000.0}))
        rec.write_late(Record("pressure", 99.0, {"pressure": 120_000.0}))
        rec.write_late(Record("dvl", 99.5, {"velocity": (1.0, 0.0, 0.0)}))
        rec.write_pose(100.25, x, P)
        rec.write_wave(100.5, 0.05, 0.75)
        rec.write_status(100.75, {"rates": {"dvl": 4.0, "imu": math.nan}, "late": np.int64(2)})
    log = read_log(tmp_path / "est")
    assert list(log.pressure.pressure) == [110_000.0] and log.dvl is None  # late ones not read
    got = {}
    with AnyReader([tmp_path / "est"], default_typestore=dvl_typestore()) as reader:
        for conn, ns, raw in reader.messages():
            got.setdefault(conn.topic, []).append((ns, reader.deserialize(raw, conn.msgtype)))
    assert {"/undertow/late/pressure", "/undertow/late/dvl", "/undertow/late/dvl_json"} <= set(got)
    ns, pose = got[POSE_TOPIC][0]
    assert ns == 100_250_000_000 and pose.header.frame_id == "world"
    p, q = pose.pose.pose.position, pose.pose.pose.orientation
    assert (p.x, p.y, p.z) == tuple(x[:3])
    np.testing.assert_allclose(quaternion_to_rpy([q.x, q.y, q.z, q.w]), x[3:6], atol=1e-12)
    assert np.array_equal(pose.pose.covariance, P[:6, :6].ravel())
    wave = got[WAVE_TOPIC][0][1].vector
    assert (wave.x, wave.y) == (0.05, 0.75)
    assert got[STATUS_TOPIC][0][1].data == '{"rates": {"dvl": 4.0, "imu": null}, "late": 2}'


def test_declared_topics_exist_before_their_first_message(tmp_path):
    """declare() adds the topics up front: a stream that never sends is an empty topic the
    reader skips, the mounting still goes first (at the first message's time), and the bag
    reads back as one recorded without the declaration."""
    mounting = Mounting.from_dict({"dvl": {"translation": [0.1, 0.0, 0.2]}})
    records = [Record("imu", 50.0 + 0.01 * k, {"angular_velocity": (0.01 * k, 0.0, 0.0)})
               for k in range(5)]  # fmt: skip
    for name, declare in (("declared", True), ("plain", False)):
        with Recorder(tmp_path / name, mounting) as rec:
            if declare:
                rec.declare(["imu", "dvl", "sonar"], wave=True)
                with pytest.raises(DataError, match="stream 'gps'"):
                    rec.declare(["gps"])
            for r in records:
                rec.write_record(r)
    with AnyReader([tmp_path / "declared"], default_typestore=dvl_typestore()) as reader:
        topics = {c.topic: c.msgcount for c in reader.connections}
        first = next(iter(reader.messages()))[0].topic
    assert {"/dvl/data", "/dvl/json_data", POSE_TOPIC, STATUS_TOPIC, WAVE_TOPIC} <= set(topics)
    assert topics["/dvl/data"] == 0 and first == "/tf_static"
    declared, plain = read_log(tmp_path / "declared"), read_log(tmp_path / "plain")
    assert declared.dvl is None and declared.sonar is None
    assert np.array_equal(declared.imu.angular_velocity, plain.imu.angular_velocity)
    assert declared.mounting.to_dict() == plain.mounting.to_dict()
    assert declared.mounting.dvl.translation == mounting.dvl.translation


def test_abort_crash_and_misuse(tmp_path, monkeypatch):
    monkeypatch.setenv("UNDERTOW_CACHE_DIR", str(tmp_path / "cache"))
    rec = Recorder(tmp_path / "a")
    rec.write_record(Record("pressure", 1.0, {"pressure": 1e5}))
    rec.abort()
    assert list(tmp_path.iterdir()) == []  # nothing at the target, nothing next to it
    with pytest.raises(DataError, match="aborted"):
        rec.write_record(Record("pressure", 2.0, {"pressure": 1e5}))
    crashed = Recorder(tmp_path / "c", flush_every_s=0.5)
    for i in range(5):
        crashed.write_record(Record("pressure", 1.0 + i, {"pressure": 1e5}))
    # a crash (never closed): only the partial folder exists, holding the flushed chunks (a
    # chunk closes at the first record 0.5 s or more after the last flush: here each record
    # from the second on), without the mcap footer; read_log reads them through a copy
    (partial,) = (p for p in tmp_path.iterdir() if p.name != "cache")
    assert partial.name.startswith("c.partial-") and not (tmp_path / "c").exists()
    mcap = partial / "c" / "c.mcap"
    before = mcap.read_bytes()
    with pytest.warns(UserWarning, match="incomplete recording"):
        back = read_log(mcap)
    assert back.pressure.t.tolist() == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert mcap.read_bytes() == before
    crashed.abort()
    with pytest.raises(DataError, match="'gps'"):
        Recorder(tmp_path / "m").write_record(Record("gps", 1.0, {}))
    with pytest.raises(DataError, match="imu record: malformed"):
        Recorder(tmp_path / "f").write_record(Record("imu", 1.0, {"angular_velocity": "fast"}))
    with pytest.raises(DataError, match="dvl record: malformed"):
        Recorder(tmp_path / "g").write_record(Record("dvl", 1.0, {"velocity": (1, 2)}))
    with pytest.raises(DataError, match="not in"):
        Recorder(tmp_path / "n").write_record(Record("pressure", -1.0, {"pressure": 1e5}))
    Recorder(tmp_path / "ok").close()
    with pytest.raises(ConfigError, match="already exists"):
        Recorder(tmp_path / "ok")


def test_wave_conditions_are_read_back_as_the_filter_took_them(tmp_path):
    """/undertow/wave_condition: JSON floats keep their digits, null for 'every row'."""
    a, f = 0.1 + 1e-17 * 3, 1.0 / 3.0
    with Recorder(tmp_path / "w") as rec:
        rec.declare(["pressure"], wave=True)
        rec.write_record(Record("pressure", 1.0, {"pressure": 101325.0}))
        rec.write_wave_condition(1.5, None, (a, f))
        rec.write_wave_condition(2.5, 2.25, "calm")
    log = read_log(tmp_path / "w")
    assert log.metadata["live_wave"] == [
        {"t": 1.5, "from_t": None, "condition": [a, f]},
        {"t": 2.5, "from_t": 2.25, "condition": "calm"},
    ]
