"""The DVL, depth and GPS messages of the field, written with rosbags from their public
definitions and read back by meaning (undertow.io.ros_dvl, undertow.io.rosbag_streams); their
malformed variants keep the good data with one warning line each."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from io_fixtures import header, write_raw_bag
from rosbags.rosbag2 import StoragePlugin

from undertow.io import read_log
from undertow.io.msgdefs import (
    COLA2_DVL,
    DS_DVL,
    UUV_DVL,
    WL_DVL,
    WL_DVLDR,
    dvl_typestore,
)
from undertow.io.ros_dvl import TWIST, TWIST_COV
from undertow.io.topics import TopicMap

T = dvl_typestore().types
T0 = 1_700_000_000.0
N = 12


def vec(x, y, z):
    return T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))


def velocity(i: int) -> tuple[float, float, float]:
    return (0.1 * i, -0.05 * i, 0.01 * i)


def _read(path, **topics):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_log(path, TopicMap(**topics) if topics else None)
    return log, [str(w.message) for w in caught]


def wl_dvl(i: int, t: float, cov=None):
    beams = [T["dvl_msgs/msg/DVLBeam"](id=k, velocity=0.1 * k, distance=1.0 + 0.1 * k,
                                        rssi=-30.0, nsd=-80.0, valid=k != 2)
             for k in range(4)]  # fmt: skip
    c = np.full(9, 1e-4) if cov is None else cov
    return T[WL_DVL](header=header(t, "dvl_link"), time=float(i), velocity=vec(*velocity(i)),
                     fom=0.01, covariance=np.asarray(c, float), altitude=1.5, beams=beams,
                     velocity_valid=i != 3, status=0, form="json_v3.1")  # fmt: skip


def uuv_dvl(msgtype: str, i: int, t: float):
    beam_t = msgtype.replace("/DVL", "/DVLBeam")
    pose = T["geometry_msgs/msg/PoseStamped"](
        header=header(t),
        pose=T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        ),
    )
    beams = [T[beam_t](range=-1.0 if k == 1 else 2.0, range_covariance=0.0, velocity=0.2,
                       velocity_covariance=0.0, pose=pose) for k in range(4)]  # fmt: skip
    cov = np.full(9, -1.0) if i == 5 else np.eye(3).ravel() * 4e-4
    return T[msgtype](header=header(t), velocity=vec(*velocity(i)), velocity_covariance=cov,
                      altitude=2.0, beams=beams)  # fmt: skip


def ds_dvl(i: int, t: float):
    ds_header = T["ds_core_msgs/msg/DsHeader"](
        io_time=T["builtin_interfaces/msg/Time"](sec=int(t), nanosec=0),
        source_uuid=np.zeros(2, np.uint64),
    )
    units = [vec(*u) for u in ((0.5, 0.0, 0.866), (-0.5, 0.0, 0.866), (0.0, 0.5, 0.866),
                               (0.0, -0.5, 0.866))]  # fmt: skip
    return T[DS_DVL](header=header(t), ds_header=ds_header, dvl_time=t,
                     velocity=vec(*velocity(i)), velocity_covar=np.full(9, -1.0), altitude=3.0,
                     course_gnd=0.0, speed_gnd=0.0, num_good_beams=4, speed_sound=1500.0,
                     beam_unit_vec=units, range=np.array([3.4, 3.5, 3.6, 0.0]),
                     range_covar=np.zeros(4, np.float32),
                     raw_velocity=np.array([0.1, 0.2, 0.3, 0.4], np.float32),
                     raw_velocity_covar=np.zeros(4, np.float32),
                     velocity_mode=0 if i == 4 else 1, coordinate_mode=0)  # fmt: skip


def twist(msgtype: str, i: int, t: float, frame: str = "dvl_link"):
    tw = T["geometry_msgs/msg/Twist"](linear=vec(*velocity(i)), angular=vec(0, 0, 0))
    if msgtype == TWIST:
        return T[TWIST](header=header(t, frame), twist=tw)
    cov = np.zeros(36)
    cov[[0, 7, 14]] = 9e-4
    wc = T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=cov)
    return T[TWIST_COV](header=header(t, frame), twist=wc)


BUILDERS = {
    WL_DVL: wl_dvl,
    UUV_DVL: lambda i, t: uuv_dvl(UUV_DVL, i, t),
    COLA2_DVL: lambda i, t: uuv_dvl(COLA2_DVL, i, t),
    DS_DVL: ds_dvl,
    TWIST_COV: lambda i, t: twist(TWIST_COV, i, t),
    TWIST: lambda i, t: twist(TWIST, i, t),
}


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
@pytest.mark.parametrize("msgtype", list(BUILDERS))
def test_every_dvl_type_reads_its_velocity_validity_and_covariance(tmp_path, msgtype, storage):
    """Velocity as written, in order; validity and covariance by each source's convention
    (sqlite3 bags carry no definitions: the shipped ones decode them)."""
    times = T0 + 0.2 * np.arange(N)
    msgs = [("/robot/dvl", msgtype, int(t * 1e9), BUILDERS[msgtype](i, t))
            for i, t in enumerate(times)]  # fmt: skip
    write_raw_bag(tmp_path / "bag", msgs, storage)
    log, _ = _read(tmp_path / "bag", dvl=["/robot/dvl"])
    dvl = log.dvl
    assert len(dvl) == N
    np.testing.assert_allclose(dvl.t, times, atol=1e-6)
    np.testing.assert_allclose(dvl.velocity, [velocity(i) for i in range(N)], atol=1e-12)
    valid = np.asarray(dvl.valid)
    if msgtype == WL_DVL:  # velocity_valid false on report 3
        assert not valid[3] and valid[np.arange(N) != 3].all()
        np.testing.assert_allclose(dvl.covariance[0], np.full((3, 3), 1e-4))
        assert not dvl.beam_valid[0, 2] and np.isnan(dvl.beam_range[0, 2])
        np.testing.assert_allclose(dvl.beam_range[0, [0, 1, 3]], [1.0, 1.1, 1.3])
    elif msgtype in (UUV_DVL, COLA2_DVL):  # covariance all -1 on report 5: invalid
        assert not valid[5] and valid[np.arange(N) != 5].all()
        np.testing.assert_allclose(dvl.covariance[0], np.eye(3) * 4e-4)
        assert np.isnan(dvl.covariance[5]).all()
        assert not dvl.beam_valid[0, 1] and dvl.beam_valid[0, [0, 2, 3]].all()
    elif msgtype == DS_DVL:  # velocity_mode 0 on report 4; covariance -1: unknown
        assert not valid[4] and valid[np.arange(N) != 4].all()
        assert np.isnan(dvl.covariance).all()
        np.testing.assert_allclose(dvl.beam_unit[0, 0], [0.5, 0.0, 0.866])
        assert not dvl.beam_valid[0, 3]  # range 0
    elif msgtype == TWIST_COV:
        assert valid.all()
        np.testing.assert_allclose(dvl.covariance[2], np.eye(3) * 9e-4)
    else:
        assert valid.all() and np.isnan(dvl.covariance).all()


def test_a_twist_in_the_base_frame_is_rotated_to_the_dvl_frame(tmp_path):
    """header.frame_id base_link: v_DVL = R^T v_body with the DVL's mounting rotation."""
    times = T0 + 0.2 * np.arange(N)
    msgs = [("/dvl/twist", TWIST, int(t * 1e9), twist(TWIST, i, t, "base_link"))
            for i, t in enumerate(times)]  # fmt: skip
    write_raw_bag(tmp_path / "bag", msgs)
    log, lines = _read(tmp_path / "bag", dvl=["/dvl/twist"])
    R = log.mounting.dvl.rotation_matrix()
    body = np.array([velocity(i) for i in range(N)])
    np.testing.assert_allclose(log.dvl.velocity, body @ R, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,nj->ni", R, log.dvl.velocity), body, atol=1e-12)
    assert any("body frame base_link" in line for line in lines)


def dvldr(i: int, t: float):
    return T[WL_DVLDR](header=header(t), time=t, position=vec(i, 2 * i, 0.5),
                       pos_std=0.1 * i, roll=1.0, pitch=-2.0, yaw=90.0 + i, type="position_local",
                       status=0, format="json_v3.1")  # fmt: skip


def test_dvldr_dead_reckoning_in_radians(tmp_path):
    times = T0 + 0.2 * np.arange(N)
    msgs = [("/dvl/position", WL_DVLDR, int(t * 1e9), dvldr(i, t)) for i, t in enumerate(times)]
    msgs += [("/dvl/data", WL_DVL, int(t * 1e9), wl_dvl(i, t)) for i, t in enumerate(times)]
    write_raw_bag(tmp_path / "bag", msgs, StoragePlugin.SQLITE3)
    log, _ = _read(tmp_path / "bag", dead_reckoning=["/dvl/position"])
    dr = log.dead_reckoning
    np.testing.assert_allclose(dr.position[:, :2], [(i, 2 * i) for i in range(N)])
    np.testing.assert_allclose(dr.std, 0.1 * np.arange(N))
    np.testing.assert_allclose(np.degrees(dr.orientation[:, 2]), 90.0 + np.arange(N))
    np.testing.assert_allclose(np.degrees(dr.orientation[0, :2]), [1.0, -2.0])


def _pose_cov(t: float, z: float):
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=float(z)),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    pc = T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36))
    return T["geometry_msgs/msg/PoseWithCovarianceStamped"](header=header(t), pose=pc)


def _pressure(t: float, p: float):
    return T["sensor_msgs/msg/FluidPressure"](header=header(t), fluid_pressure=float(p),
                                              variance=0.0)  # fmt: skip


@pytest.mark.parametrize("z_sign", [1.0, -1.0])
def test_a_pose_depth_sign_detected_from_the_pressure(tmp_path, z_sign):
    """z down or up: the sign of its correlation with the pressure makes it depth (+ down)."""
    times = T0 + 0.1 * np.arange(40)
    depth = 0.5 + 0.5 * np.sin(np.arange(40) / 6)
    msgs = [("/depth_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", int(t * 1e9),
             _pose_cov(t, z_sign * d)) for t, d in zip(times, depth, strict=True)]  # fmt: skip
    msgs += [
        (
            "/pressure",
            "sensor_msgs/msg/FluidPressure",
            int(t * 1e9),
            _pressure(t, 90_000 + 9_787 * d),
        )
        for t, d in zip(times, depth, strict=True)
    ]
    write_raw_bag(tmp_path / "bag", msgs)
    log, _ = _read(tmp_path / "bag", depth=["/depth_pose"])
    np.testing.assert_allclose(log.depth.depth, depth, atol=1e-12)
    assert log.metadata["depth_z"].startswith("down" if z_sign > 0 else "up")


def test_a_float_depth_is_positive_down_and_a_lone_pose_is_up(tmp_path):
    times = T0 + 0.1 * np.arange(10)
    msgs = [("/depth", "std_msgs/msg/Float64", int(t * 1e9), T["std_msgs/msg/Float64"](data=2.0))
            for t in times]  # fmt: skip
    msgs += [("/pose_z", "geometry_msgs/msg/PoseWithCovarianceStamped", int(t * 1e9),
              _pose_cov(t, -3.0)) for t in times]  # fmt: skip
    write_raw_bag(tmp_path / "a", msgs[:10])
    log, _ = _read(tmp_path / "a")
    assert (log.depth.depth == 2.0).all()  # no header: record time
    np.testing.assert_allclose(log.depth.t, times, atol=1e-6)
    write_raw_bag(tmp_path / "b", msgs[10:])
    log, lines = _read(tmp_path / "b", depth=["/pose_z"])
    assert (log.depth.depth == 3.0).all()
    assert any("read as up (REP-103)" in line for line in lines)


def _fix(t: float, lat: float, lon: float, status: int = 0):
    st = T["sensor_msgs/msg/NavSatStatus"](status=status, service=1)
    return T["sensor_msgs/msg/NavSatFix"](header=header(t, "gps"), status=st, latitude=lat,
                                          longitude=lon, altitude=10.0,
                                          position_covariance=np.diag([4.0, 9.0, 16.0]).ravel(),
                                          position_covariance_type=2)  # fmt: skip


def test_navsatfix_projected_to_metres_bad_fixes_dropped_and_counted(tmp_path):
    """Local north-east metres against pyproj's geodesic (independent of the projection)."""
    from pyproj import Geod

    lat0, lon0 = 40.0717, -111.6002
    geod = Geod(ellps="WGS84")
    rows = []
    for k, (az, dist) in enumerate([(0, 0), (0, 100), (90, 100), (45, 300), (200, 50)]):
        lon, lat, _ = geod.fwd(lon0, lat0, az, dist)
        rows.append((T0 + k, lat, lon, az, dist))
    msgs = [("/fix", "sensor_msgs/msg/NavSatFix", int(t * 1e9), _fix(t, la, lo))
            for t, la, lo, _, _ in rows]  # fmt: skip
    msgs.insert(2, ("/fix", "sensor_msgs/msg/NavSatFix", int((T0 + 1.5) * 1e9),
                    _fix(T0 + 1.5, lat0, lon0, status=-1)))  # fmt: skip
    msgs.insert(3, ("/fix", "sensor_msgs/msg/NavSatFix", int((T0 + 1.6) * 1e9),
                    _fix(T0 + 1.6, math.nan, math.nan)))  # fmt: skip
    write_raw_bag(tmp_path / "bag", msgs)
    log, lines = _read(tmp_path / "bag")
    gps = log.gps
    assert len(gps) == 5 and gps.origin[:2] == (lat0, lon0)
    for (_, _, _, az, dist), p in zip(rows, gps.position, strict=True):
        assert math.hypot(p[0], p[1]) == pytest.approx(dist, abs=1e-3 + 1e-5 * dist)
        if dist:
            assert math.degrees(math.atan2(p[1], p[0])) % 360 == pytest.approx(az, abs=0.01)
    np.testing.assert_allclose(gps.horizontal_std, math.sqrt(13.0))
    assert any("status NO_FIX" in line and ": 1" in line for line in lines)
    assert any("non-finite or out-of-range" in line and ": 1" in line for line in lines)


def test_a_dvl_definition_without_covariance_keeps_the_rest(tmp_path):
    """An older dvl_msgs/DVL (no covariance field), as a bag that carries its own definition
    would hold it: the covariance is unknown (NaN), velocity and beams read."""
    from rosbags.typesys import get_types_from_msg, get_typestore
    from rosbags.typesys.stores import Stores

    from undertow.io.msgdefs import WL_BEAM, WL_DVL_MSG

    store = get_typestore(Stores.ROS2_HUMBLE)
    old = WL_DVL_MSG.replace("float64[] covariance\n", "")
    types = get_types_from_msg(old, WL_DVL)
    types.update(
        get_types_from_msg(
            "int64 id\nfloat64 velocity\nfloat64 distance\nfloat64 rssi\nfloat64 nsd\nbool valid\n",
            WL_BEAM,
        )
    )
    store.register(types)
    from rosbags.rosbag2 import Writer

    Old = store.types
    with Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/dvl/data", WL_DVL, typestore=store)
        for i in range(5):
            t = T0 + 0.2 * i
            stamp = Old["builtin_interfaces/msg/Time"](sec=int(t), nanosec=int((t % 1) * 1e9))
            msg = Old[WL_DVL](
                header=Old["std_msgs/msg/Header"](stamp=stamp, frame_id="dvl"),
                time=t,
                velocity=Old["geometry_msgs/msg/Vector3"](x=0.3, y=0.0, z=0.0),
                fom=0.01,
                altitude=1.0,
                beams=[],
                velocity_valid=True,
                status=0,
                form="json_v3",
            )
            writer.write(conn, int(t * 1e9), store.serialize_cdr(msg, WL_DVL))
    log, _ = _read(tmp_path / "bag")
    assert len(log.dvl) == 5 and np.isnan(log.dvl.covariance).all()
    assert (log.dvl.velocity[:, 0] == 0.3).all()


def _odom(t: float, east: float, north: float, up: float):
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=east, y=north, z=up),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    cov = np.zeros(36)
    cov[0] = 4.0
    twist = T["geometry_msgs/msg/Twist"](linear=vec(0, 0, 0), angular=vec(0, 0, 0))
    return T["nav_msgs/msg/Odometry"](
        header=header(t, "map"),
        child_frame_id="odom",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


def test_an_odometry_gps_in_east_north_up_is_north_east_down_about_its_first_fix(tmp_path):
    """REP-103 east-north-up (e.g. UTM metres) to undertow's north-east-down; NaN fixes (a
    receiver with no fix) dropped and counted."""
    enu = [(12086.3, -18568.7, 189.3), (12096.3, -18563.7, 189.0), (math.nan, math.nan, 0.0)]
    msgs = [("/gps_odom", "nav_msgs/msg/Odometry", int((T0 + i) * 1e9), _odom(T0 + i, *p))
            for i, p in enumerate(enu)]  # fmt: skip
    write_raw_bag(tmp_path / "bag", msgs)
    log, lines = _read(tmp_path / "bag", gps=["/gps_odom"])
    np.testing.assert_allclose(log.gps.position, [[0, 0, 0], [5.0, 10.0, 0.3]], atol=1e-9)
    np.testing.assert_allclose(log.gps.horizontal_std, 2.0)
    assert any("non-finite positions" in line and ": 1" in line for line in lines)
