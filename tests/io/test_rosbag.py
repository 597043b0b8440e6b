"""ROS bag reading and writing: real ROS 1 recording, round trips, and bad input."""

from __future__ import annotations

import json
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import REAL_DATA
from io_fixtures import T0, full_log, header, write_raw_bag
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from undertow.errors import ReaderError, UndertowError
from undertow.io import TopicMap, read_log, write_log
from undertow.io.msgdefs import dvl_typestore
from undertow.log import Log, Pressure
from undertow.robot import Mounting, SensorMount

#: reads the shared real recordings (conftest.py: a missing folder fails)
pytestmark = pytest.mark.realdata

REAL = REAL_DATA
BAG = REAL / "a50_ros1_circle.bag"
T = dvl_typestore().types


def _plain_messages(path, topic):
    """(record ns, message) of ``topic`` read with plain rosbags, no undertow code."""
    with AnyReader([Path(path)]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [(t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages(conns)]


def test_real_ros1_bag_matches_plain_rosbags():
    log = read_log(BAG)
    msgs = [m for _, m in _plain_messages(BAG, "/dvl/data")]
    raw_json = [json.loads(m.data) for _, m in _plain_messages(BAG, "/dvl/json_data")]
    assert len(log.dvl) == len(msgs) == 378
    stamps = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs])
    np.testing.assert_array_equal(log.dvl.t, np.sort(stamps))
    assert np.isnan(log.dvl.altitude).sum() == sum(m.altitude < 0 for m in msgs)
    assert (~log.dvl.beam_valid).sum() == sum(not b.valid for m in msgs for b in m.beams)
    assert (~log.dvl.valid).sum() == sum(not m.velocity_valid for m in msgs)
    # covariance and time_of_validity come from the raw JSON topic
    by_time = {r["time"]: r for r in raw_json}
    first = msgs[0]
    np.testing.assert_array_equal(log.dvl.covariance[0], by_time[first.time]["covariance"])
    tov = log.metadata["dvl_time_of_validity_s"]
    assert tov[0] == by_time[first.time]["time_of_validity"] * 1e-6
    assert log.ground_truth is None and log.imu is None


def _assert_logs_equal(a: Log, b: Log, flavor: str) -> None:
    for name, s in a.streams().items():
        r = getattr(b, name)
        assert r is not None, name
        assert np.max(np.abs(r.t - s.t)) <= 1e-9, name
    d, e = a.dvl, b.dvl
    np.testing.assert_array_equal(e.velocity, d.velocity)
    np.testing.assert_array_equal(e.valid, d.valid)
    np.testing.assert_array_equal(e.covariance, d.covariance)
    np.testing.assert_array_equal(e.altitude, d.altitude)
    np.testing.assert_array_equal(e.beam_valid, d.beam_valid)
    np.testing.assert_array_equal(e.beam_range, d.beam_range)
    np.testing.assert_array_equal(e.beam_velocity, d.beam_velocity)
    np.testing.assert_array_equal(e.beam_unit, d.beam_unit)
    if flavor == "driver":
        np.testing.assert_array_equal(e.fom, d.fom)
    else:  # marine_acoustic_msgs/Dvl has no figure of merit
        assert np.isnan(e.fom).all()
    np.testing.assert_array_equal(b.imu.angular_velocity, a.imu.angular_velocity)
    np.testing.assert_array_equal(b.imu.linear_acceleration, a.imu.linear_acceleration)
    np.testing.assert_array_equal(b.imu.orientation, a.imu.orientation)
    np.testing.assert_array_equal(b.pressure.pressure, a.pressure.pressure)
    np.testing.assert_array_equal(b.sonar.range, a.sonar.range)
    np.testing.assert_array_equal(b.sonar.confidence, a.sonar.confidence)  # NaN where unknown
    assert b.sonar.field_of_view == a.sonar.field_of_view
    assert (b.sonar.min_range, b.sonar.max_range) == (a.sonar.min_range, a.sonar.max_range)
    np.testing.assert_array_equal(b.wave_probe.elevation, a.wave_probe.elevation)
    assert b.wave_probe.x == a.wave_probe.x
    for name in ("dead_reckoning", "ground_truth"):
        s, r = getattr(a, name), getattr(b, name)
        np.testing.assert_array_equal(r.position, s.position)
        np.testing.assert_allclose(r.orientation, s.orientation, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(b.dead_reckoning.std, a.dead_reckoning.std)
    np.testing.assert_allclose(b.ground_truth.velocity, a.ground_truth.velocity, atol=1e-12)
    assert b.mounting == a.mounting
    assert {k: b.metadata[k] for k in a.metadata} == a.metadata  # writer's metadata restored
    assert b.metadata["recorded"]["source"] == a.source


@pytest.mark.parametrize("flavor", ["driver", "standard"])
def test_round_trip_every_stream(tmp_path, flavor):
    log = full_log()
    path = write_log(log, tmp_path / "bag", flavor=flavor)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]  # no temp dir left behind
    _assert_logs_equal(log, read_log(path), flavor)


def test_standard_flavor_is_readable_by_plain_rosbags(tmp_path):
    log = full_log(n=10)
    path = write_log(log, tmp_path / "bag", flavor="standard")
    humble = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([path], default_typestore=humble) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types["/dvl/data"] == "marine_acoustic_msgs/msg/Dvl"
        assert types["/imu/data"] == "sensor_msgs/msg/Imu"
        assert types["/ground_truth/odom"] == "nav_msgs/msg/Odometry"
        conns = [c for c in reader.connections if c.topic == "/dvl/data"]
        msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(conns)]
    assert len(msgs) == 10
    np.testing.assert_array_equal([m.velocity.x for m in msgs], log.dvl.velocity[:, 0])
    unit = msgs[0].beam_unit_vec[3]
    np.testing.assert_allclose([unit.x, unit.y, unit.z], log.dvl.beam_unit[0, 3])


def test_write_refuses_overwrite_and_decimates_ground_truth(tmp_path):
    log = full_log(n=10)
    path = write_log(log, tmp_path / "bag")
    with pytest.raises(UndertowError, match="already exists"):
        write_log(log, path)
    t = T0 + np.arange(2000) / 1000.0  # 1 kHz for 2 s
    gt = log.ground_truth.__class__(
        t=t, position=np.zeros((2000, 3)), orientation=np.zeros((2000, 3))
    )
    write_log(log.replace(ground_truth=gt), path, overwrite=True, ground_truth_rate_hz=100.0)
    back = read_log(path)
    assert len(back.ground_truth) == 200
    assert back.ground_truth.rate_hz == pytest.approx(100.0)


def test_missing_empty_unknown_and_truncated(tmp_path):
    with pytest.raises(ReaderError, match="no such file"):
        read_log(tmp_path / "missing.bag")
    (tmp_path / "empty.bag").write_bytes(b"")
    with pytest.raises(ReaderError, match="empty"):
        read_log(tmp_path / "empty.bag")
    (tmp_path / "x.csv").write_text("1,2\n")
    with pytest.raises(ReaderError, match="unknown log format"):
        read_log(tmp_path / "x.csv")
    cut1 = tmp_path / "cut.bag"
    cut1.write_bytes(BAG.read_bytes()[: BAG.stat().st_size // 2])
    with pytest.raises(ReaderError, match=r"cut\.bag"):
        read_log(cut1)
    bag = write_log(full_log(n=50), tmp_path / "ros2")
    mcap = next(bag.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    with pytest.raises(ReaderError, match="ros2"):
        read_log(bag)


def _pressure_msgs(times, values, topic="/fluid_pressure"):
    fp = T["sensor_msgs/msg/FluidPressure"]
    return [
        (
            topic,
            "sensor_msgs/msg/FluidPressure",
            int(i * 1e6),
            fp(header=header(t), fluid_pressure=float(v), variance=0.0),
        )
        for i, (t, v) in enumerate(zip(times, values, strict=True))
    ]


def test_sonar_confidence_is_matched_to_its_range_by_stamp(tmp_path):
    """Two ranges of one stamp take that stamp's confidences in order, whatever the order of the
    topics in the file; a range without one gets NaN (counted); the time base ignores them."""
    rng_t, conf_t = T["sensor_msgs/msg/Range"], T["undertow_msgs/msg/RangeConfidence"]
    stamps = [T0 + 0.5, T0 + 0.5, T0 + 1.25, T0 + 2.0]

    def sonar(t, r):
        return rng_t(header=header(t), radiation_type=0, field_of_view=0.4, min_range=0.3,
                     max_range=30.0, range=r)  # fmt: skip

    msgs = [
        (
            "/ping_sonar/confidence",
            "undertow_msgs/msg/RangeConfidence",
            i,
            conf_t(header=header(t), confidence=c),
        )
        for i, (t, c) in enumerate([(stamps[2], 0.25), (stamps[0], 0.5), (stamps[1], 0.75)])
    ]
    msgs += [("/ping_sonar/range", "sensor_msgs/msg/Range", 10 + i, sonar(t, 1.0 + i))
             for i, t in enumerate(stamps)]  # fmt: skip
    write_raw_bag(tmp_path / "bag", msgs)
    with pytest.warns(UserWarning, match="sonar_confidence: ranges without a confidence.*: 1"):
        log = read_log(tmp_path / "bag")
    np.testing.assert_array_equal(log.sonar.range, [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(log.sonar.confidence, [0.5, 0.75, 0.25, np.nan])
    assert log.metadata["topics"]["sonar_confidence"] == "/ping_sonar/confidence"


def test_unknown_type_on_mapped_topic_and_missing_topics(tmp_path):
    string = T["std_msgs/msg/String"]
    msgs = [("/imu/data", "std_msgs/msg/String", 1, string(data="hello"))]
    write_raw_bag(tmp_path / "only_unknown", msgs)
    with pytest.raises(ReaderError, match=r"no known measurement stream.*/imu/data"):
        read_log(tmp_path / "only_unknown")
    write_raw_bag(tmp_path / "mixed", msgs + _pressure_msgs([1.0, 2.0], [101325.0, 101400.0]))
    with pytest.warns(UserWarning, match="unsupported type std_msgs/msg/String"):
        log = read_log(tmp_path / "mixed")
    assert log.imu is None and log.dvl is None
    np.testing.assert_array_equal(log.pressure.pressure, [101325.0, 101400.0])


def test_time_backwards_nan_and_hpa(tmp_path):
    write_raw_bag(
        tmp_path / "b",
        _pressure_msgs([3.0, 1.0, 2.0], [1013.0, np.nan, 1020.0], topic="/BlueROV/pressure2_fluid"),
    )
    with pytest.warns(UserWarning) as record:
        log = read_log(tmp_path / "b")
    text = " ".join(str(w.message) for w in record)
    assert "backwards" in text and "NaN" in text and "hPa" in text
    np.testing.assert_array_equal(log.pressure.t, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(log.pressure.pressure, [np.nan, 102000.0, 101300.0])
    assert len(log.metadata["warnings"]) == 3


def test_json_topic_alone_gives_dvl_and_custom_topic_map(tmp_path):
    string = T["std_msgs/msg/String"]
    lines = [m.data for _, m in _plain_messages(BAG, "/dvl/json_data")][:20]
    msgs = [
        ("/a50/raw", "std_msgs/msg/String", (10 + i) * 10**9, string(data=s))
        for i, s in enumerate(lines)
    ]
    write_raw_bag(tmp_path / "j", msgs)
    cfg = tmp_path / "topics.yaml"
    cfg.write_text("dvl_json: /a50/raw\npressure: [/baro]\n")
    with pytest.warns(UserWarning, match=r"j: pressure: no topic of the topic map \(/baro\)"):
        log = read_log(tmp_path / "j", TopicMap.from_yaml(cfg))
    assert len(log.dvl) == 20
    np.testing.assert_array_equal(log.dvl.t, 10.0 + np.arange(20))
    assert log.dvl.velocity[0, 0] == json.loads(lines[0])["vx"]
    assert np.isfinite(log.dvl.covariance).all()


def test_nan_values_are_kept_with_a_warning(tmp_path):
    log = full_log(n=10)
    p = log.pressure.pressure.copy()
    p[4] = np.nan
    path = write_log(log.replace(pressure=Pressure(t=log.pressure.t, pressure=p)), tmp_path / "b")
    with pytest.warns(UserWarning, match="pressure: messages with NaN"):
        back = read_log(path)
    assert np.isnan(back.pressure.pressure[4]) and np.isfinite(back.pressure.pressure).sum() == 9


def test_ros2_bag_read_from_mcap_file_and_copy(tmp_path):
    path = write_log(full_log(n=5), tmp_path / "bag")
    assert len(read_log(next(path.glob("*.mcap"))).dvl) == 5
    shutil.copytree(path, tmp_path / "copy")
    assert read_log(tmp_path / "copy").mounting == full_log(n=5).mounting


def test_ros2_sqlite3_bag_as_ros2_bag_record_writes_it(tmp_path):
    """`ros2 bag record` defaults to sqlite3 (.db3) before Iron: read it like mcap."""
    from rosbags.rosbag2 import StoragePlugin

    T = dvl_typestore().types
    messages = []
    for i in range(20):
        t = T0 + 0.1 * i
        msg = T["sensor_msgs/msg/FluidPressure"](
            header=header(t, "baro"),
            fluid_pressure=101_325.0 + 1000.0 * 9.81 * i / 10,
            variance=0.0,
        )
        messages.append(("/fluid_pressure", "sensor_msgs/msg/FluidPressure", int(t * 1e9), msg))
    write_raw_bag(tmp_path / "db3bag", messages, storage=StoragePlugin.SQLITE3)
    assert list((tmp_path / "db3bag").glob("*.db3"))
    log = read_log(tmp_path / "db3bag")
    assert len(log.pressure) == 20
    np.testing.assert_allclose(log.pressure.t - log.pressure.t[0], 0.1 * np.arange(20), atol=1e-6)
    np.testing.assert_allclose(log.pressure.depth(1000.0, g=9.81), np.arange(20) / 10, atol=1e-9)


# -- user-given topics that are not in the bag -----------------------------------------------


def test_user_topic_missing_from_the_real_bag_warns_once_naming_stream_topics_and_file(tmp_path):
    cfg = tmp_path / "topics.yaml"
    cfg.write_text("imu: [/mavros/imu/data, /my_imu]\ndvl: /dvl/data\n")
    with pytest.warns(UserWarning) as record:
        log = read_log(BAG, TopicMap.from_yaml(cfg))
    lines = [str(w.message) for w in record if "topic map" in str(w.message)]
    assert len(lines) == 1 and "\n" not in lines[0]
    assert re.search(r"a50_ros1_circle\.bag: imu: .*/mavros/imu/data, /my_imu", lines[0])
    assert "/dvl/data" in lines[0]  # the topics the bag does have
    assert len(log.dvl) == 378 and lines[0] in log.metadata["warnings"]


def test_a_user_dvl_topic_not_in_the_bag_says_the_raw_json_was_read_instead():
    """The real bag also carries the A50's raw JSON: the DVL is still read, and the warning says
    so instead of claiming the stream was not read."""
    with pytest.warns(UserWarning) as record:
        log = read_log(BAG, TopicMap(dvl=["/nope/dvl"]))
    (line,) = [str(w.message) for w in record if "topic map" in str(w.message)]
    assert "dvl: no topic of the topic map (/nope/dvl)" in line
    assert "read from dvl_json" in line and "stream not read" not in line
    assert log.dvl is not None and len(log.dvl) > 0


def test_absent_default_topics_stay_silent():
    """The real bag has no IMU, pressure or sonar: with the defaults (also written out in full,
    as config.yaml does) that is a legal DVL-only log, no warning about topics."""
    for topics in (None, TopicMap.model_validate(TopicMap().model_dump())):
        with warnings.catch_warnings(record=True) as record:
            warnings.simplefilter("always")
            log = read_log(BAG, topics)
        assert not [w for w in record if "topic map" in str(w.message)]
        assert log.imu is None and len(log.dvl) == 378


# -- the mounting inside the bag: /tf_static ---------------------------------------------------

MOUNTING = Mounting(
    imu=SensorMount((0.01, -0.02, 0.03), (np.pi, 0.0, 0.0)),  # a REP-103 IMU, roll pi
    dvl=SensorMount((0.2, 0.01, 0.3), (0.02, -0.03, 0.785)),
    sonar=SensorMount((0.15, 0.1, 0.31), (0.0, 0.4, 0.0)),
    barometer=SensorMount((-0.1, 0.0, 0.05), (0.0, 0.0, 0.0)),
)


def _same_rotation(a, b):
    from scipy.spatial.transform import Rotation

    ra = Rotation.from_euler("ZYX", np.asarray(a)[::-1])
    rb = Rotation.from_euler("ZYX", np.asarray(b)[::-1])
    return (ra.inv() * rb).magnitude() < 1e-12


def test_mounting_survives_a_bare_copy_of_the_bag_through_tf_static(tmp_path):
    log = full_log(n=10).replace(mounting=MOUNTING)
    path = write_log(log, tmp_path / "bag")
    (path / "undertow.yaml").unlink()  # what a copy of the bag without the sidecar loses
    back = read_log(path)
    assert back.metadata["mounting_source"] == "/tf_static"
    for sensor in ("imu", "dvl", "sonar", "barometer"):
        got, want = getattr(back.mounting, sensor), getattr(MOUNTING, sensor)
        np.testing.assert_allclose(got.translation, want.translation, rtol=0, atol=1e-15)
        assert _same_rotation(got.rotation, want.rotation), sensor
    np.testing.assert_allclose(back.mounting.dvl.rotation, MOUNTING.dvl.rotation, atol=1e-12)
    # a lone .mcap in a folder without metadata.yaml: read as that file, mounting kept
    lone = tmp_path / "lone"
    lone.mkdir()
    shutil.copy(next(path.glob("*.mcap")), lone / "log.mcap")
    again = read_log(lone)
    assert (
        len(again.dvl) == 10 and again.mounting.sonar.translation == back.mounting.sonar.translation
    )


def test_tf_static_is_standard_ros_seen_by_plain_rosbags(tmp_path):
    """Parent base_link, one child per sensor, translation = lever arm, rotation = the
    quaternion of R_sensor^body (scipy's intrinsic Z-Y-X Euler angles, yaw-pitch-roll), child
    frame = the frame_id of that sensor's messages; latched (transient local) QoS."""
    from scipy.spatial.transform import Rotation

    log = full_log(n=5).replace(mounting=MOUNTING)
    path = write_log(log, tmp_path / "bag", flavor="standard")
    humble = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([path], default_typestore=humble) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert conns["/tf_static"].msgtype == "tf2_msgs/msg/TFMessage"
        qos = conns["/tf_static"].ext.offered_qos_profiles[0]
        assert qos.durability.name == "TRANSIENT_LOCAL"
        msgs = [
            reader.deserialize(r, c.msgtype) for c, _, r in reader.messages([conns["/tf_static"]])
        ]
        frames = {}
        for topic in ("/dvl/data", "/imu/data", "/ping_sonar/range", "/fluid_pressure"):
            c, _, raw = next(reader.messages([conns[topic]]))
            frames[topic] = reader.deserialize(raw, c.msgtype).header.frame_id
    assert len(msgs) == 1
    tfs = {tf.child_frame_id: tf for tf in msgs[0].transforms}
    assert set(tfs) == {"imu_link", "dvl_link", "sonar_link", "pressure_link"}
    assert {tf.header.frame_id for tf in tfs.values()} == {"base_link"}
    assert frames == {
        "/dvl/data": "dvl_link", "/imu/data": "imu_link",
        "/ping_sonar/range": "sonar_link", "/fluid_pressure": "pressure_link",
    }  # fmt: skip
    for child, sensor in (("imu_link", "imu"), ("dvl_link", "dvl"), ("sonar_link", "sonar")):
        tf, want = tfs[child].transform, getattr(MOUNTING, sensor)
        got = [tf.translation.x, tf.translation.y, tf.translation.z]
        np.testing.assert_allclose(got, want.translation, rtol=0, atol=0)
        q = np.array([tf.rotation.x, tf.rotation.y, tf.rotation.z, tf.rotation.w])
        ref = Rotation.from_euler("ZYX", want.rotation[::-1]).as_quat()  # x y z w
        assert min(np.abs(q - ref).max(), np.abs(q + ref).max()) < 1e-12, child
        # the rotation takes sensor-frame vectors to the body frame: the sonar's axis (+z)
        if sensor == "sonar":
            axis = Rotation.from_quat(q).apply([0.0, 0.0, 1.0])
            np.testing.assert_allclose(axis, [np.sin(0.4), 0.0, np.cos(0.4)], atol=1e-12)


def test_sidecar_wins_over_tf_static_and_frame_names_come_from_the_topic_map(tmp_path):
    import yaml

    topics = TopicMap(base_frame="base_frd", frames={"dvl": ["a50"], "sonar": "ping"})
    path = write_log(full_log(n=5).replace(mounting=MOUNTING), tmp_path / "bag", topics=topics)
    side = path / "undertow.yaml"
    data = yaml.safe_load(side.read_text())
    data["mounting"]["dvl"]["translation"] = [9.0, 9.0, 9.0]
    side.write_text(yaml.safe_dump(data))
    back = read_log(path, topics)
    assert back.metadata["mounting_source"] == "undertow.yaml"
    assert back.mounting.dvl.translation == (9.0, 9.0, 9.0)
    side.unlink()
    back = read_log(path, topics)
    assert back.mounting.dvl.translation == MOUNTING.dvl.translation
    assert back.mounting.sonar.translation == MOUNTING.sonar.translation
    # with the default map a50 / ping mean nothing and imu_link hangs off base_frd, not
    # base_link: said in a warning, defaults kept
    with pytest.warns(UserWarning, match=r"parent is not base_link .*: 2 \(first: base_frd"):
        assert read_log(path).mounting.dvl == Mounting().dvl


def test_folder_of_storage_files_without_metadata(tmp_path):
    path = write_log(full_log(n=5), tmp_path / "bag")
    two = tmp_path / "two"
    two.mkdir()
    for name in ("a.mcap", "b.mcap"):
        shutil.copy(next(path.glob("*.mcap")), two / name)
    with pytest.raises(ReaderError, match=r"two: no metadata\.yaml and 2 storage files"):
        read_log(two)


def test_an_empty_topic_list_turns_a_stream_off_without_a_warning():
    """dvl_json: [] with the DVL topic hidden: no DVL at all, and no warning for the empty list."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        with pytest.raises(ReaderError, match="no known measurement stream"):
            read_log(BAG, TopicMap(dvl=["/nope/dvl"], dvl_json=[]))
    lines = [str(w.message) for w in record]
    assert any("dvl: no topic" in line for line in lines)
    assert not any("dvl_json" in line for line in lines)
