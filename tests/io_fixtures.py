"""Shared builders for the io tests: a Log with every stream, and a raw bag writer."""

from __future__ import annotations

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer

from undertow.io.msgdefs import dvl_typestore
from undertow.log import DeadReckoning, Dvl, GroundTruth, Imu, Log, Pressure, SonarRange, WaveProbe
from undertow.robot import Mounting, SensorMount, a50_beam_units

T0 = 1_700_000_000.0


def full_log(n: int = 40, seed: int = 0) -> Log:
    """A Log with every stream, invalid beams, NaN altitude, an invalid velocity, float32-exact
    values where the message type is float32 (sonar range, standard-flavor beam velocity)."""
    rng = np.random.default_rng(seed)
    t = T0 + np.arange(n) * 0.1 + rng.uniform(0, 0.01, n)
    beam_valid = rng.random((n, 4)) > 0.2
    beam_range = np.where(beam_valid, rng.uniform(1, 3, (n, 4)), np.nan)
    altitude = rng.uniform(1, 2, n)
    altitude[::7] = np.nan
    valid = np.ones(n, bool)
    valid[3] = False
    cov = np.tile(np.diag([1e-6, 2e-6, 3e-7]), (n, 1, 1)) + rng.normal(0, 1e-9, (n, 3, 3))
    cov[n // 2] = np.nan
    dvl = Dvl(
        t=t,
        velocity=rng.normal(0, 0.3, (n, 3)),
        valid=valid,
        fom=rng.uniform(0, 0.01, n),
        covariance=cov,
        altitude=altitude,
        beam_id=np.tile(np.arange(4), (n, 1)),
        beam_unit=np.tile(a50_beam_units(), (n, 1, 1)),
        beam_range=beam_range,
        beam_valid=beam_valid,
        beam_velocity=rng.normal(0, 0.2, (n, 4)).astype(np.float32).astype(np.float64),
    )
    m = 4 * n
    ti = T0 + np.arange(m) * 0.025
    imu = Imu(
        t=ti,
        angular_velocity=rng.normal(0, 0.1, (m, 3)),
        linear_acceleration=rng.normal(0, 1, (m, 3)) + [0, 0, -9.81],
        orientation=np.tile([0.0, 0.0, np.sin(0.2), np.cos(0.2)], (m, 1)),
    )
    rpy = np.column_stack([rng.uniform(-0.2, 0.2, (n, 2)), rng.uniform(-3, 3, n)])
    dr = DeadReckoning(
        t=t + 0.003, position=rng.normal(0, 2, (n, 3)), orientation=rpy, std=rng.uniform(0, 1, n)
    )
    pressure = Pressure(t=t + 0.001, pressure=101325.0 + rng.uniform(0, 30000, n))
    sonar = SonarRange(
        t=t + 0.002,
        range=rng.uniform(1, 3, n).astype(np.float32).astype(np.float64),
        # the Ping's confidence (% / 100, NaN unknown); its own generator: the draws above stay
        confidence=_confidence(np.random.default_rng(seed + 1), n),
        field_of_view=float(np.float32(0.5)),
        min_range=0.5,
        max_range=50.0,
    )
    probe = WaveProbe(t=ti, elevation=rng.normal(0, 0.05, m), x=12.5)
    gt = GroundTruth(
        t=t + 0.004,
        position=rng.normal(0, 5, (n, 3)),
        orientation=rpy,
        velocity=rng.normal(0, 0.5, (n, 3)),
    )
    mounting = Mounting(dvl=SensorMount((0.1, 0.2, 0.3), (0.0, 0.0, 0.1)))
    return Log(
        imu=imu,
        dvl=dvl,
        dead_reckoning=dr,
        pressure=pressure,
        sonar=sonar,
        wave_probe=probe,
        ground_truth=gt,
        mounting=mounting,
        source="unit-test",
        metadata={"scenario": "roundtrip", "seed": seed},
    )


def _confidence(rng, n: int) -> np.ndarray:
    return np.where(rng.random(n) < 0.1, np.nan, rng.integers(0, 101, n) / 100.0)


def write_raw_bag(path, messages, storage=StoragePlugin.MCAP) -> None:
    """Write (topic, msgtype, time_ns, message) tuples as a ROS 2 bag, mcap or sqlite3 (no
    undertow code besides the registered message definitions)."""
    store = dvl_typestore()
    with Writer(path, version=9, storage_plugin=storage) as writer:
        conns = {}
        for topic, msgtype, ns, msg in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], ns, store.serialize_cdr(msg, msgtype))


def header(t: float, frame: str = "base"):
    T = dvl_typestore().types
    sec = int(t)
    stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((t - sec) * 1e9)))
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)
