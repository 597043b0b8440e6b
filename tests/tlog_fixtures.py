"""MAVLink telemetry logs (.tlog) written with pymavlink's own encoder from a simulated run's
streams (known values): shared by the tlog reader's tests and the MAVLink link's."""

from __future__ import annotations

import struct

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from scipy.spatial.transform import Rotation

from undertow.rotations import rpy_to_matrix

EPOCH = 1_700_000_000.0  # the simulated run starts at 0; a tlog stamps Unix time


def new_mav():
    return mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)


def record(encoder, t: float, msg) -> bytes:
    """One tlog record: 8-byte big-endian receive time (us since the epoch) + the packed frame."""
    return struct.pack(">Q", int(round((EPOCH + t) * 1e6))) + msg.pack(encoder)


def attitude_rows(log):
    gt, imu = log.ground_truth, log.imu
    _, rpy, _ = gt.interpolate(imu.t)
    return [
        (t, mavlink2.MAVLink_attitude_message(int(t * 1000), *a, *w))
        for t, a, w in zip(imu.t, rpy, imu.angular_velocity, strict=True)
    ]


def imu2_rows(log):
    imu = log.imu
    gyro = np.round(imu.angular_velocity * 1000.0).astype(int)
    acc = np.round(imu.linear_acceleration / 9.80665 * 1000.0).astype(int)
    return [
        (t, mavlink2.MAVLink_scaled_imu2_message(int(t * 1000), *a, *g, 0, 0, 0, 2000))
        for t, g, a in zip(imu.t, gyro, acc, strict=True)
    ]


def pressure_rows(log, msg_class=mavlink2.MAVLink_scaled_pressure2_message):
    p = log.pressure
    return [
        (t, msg_class(int(t * 1000), pa / 100.0, 0.0, 1500))
        for t, pa in zip(p.t, p.pressure, strict=True)
    ]


def vision_rows(log):
    """VISION_POSITION_DELTA for DVL samples 1..N-1: d_k = v_k dt_k (current body frame), a_k the
    rotation vector of R(t_{k-1})^T R(t_k) from the ground-truth attitude."""
    dvl = log.dvl
    _, rpy, _ = log.ground_truth.interpolate(dvl.t)
    R = rpy_to_matrix(rpy)
    rows = []
    for k in range(1, len(dvl)):
        dt = dvl.t[k] - dvl.t[k - 1]
        a = Rotation.from_matrix(R[k - 1].T @ R[k]).as_rotvec()
        d = dvl.velocity[k] * dt
        usec = int(round(dt * 1e6))
        rows.append(
            (
                dvl.t[k],
                mavlink2.MAVLink_vision_position_delta_message(
                    int(dvl.t[k] * 1e6), usec, a, d, 90.0
                ),
            )
        )
    return rows, R


def sonar_rows(log, sensor_id=3):
    s = log.sonar
    return [
        (
            t,
            mavlink2.MAVLink_distance_sensor_message(
                int(t * 1000),
                30,
                10000,
                int(round(r * 100)),
                1,
                sensor_id,
                25,
                0,
                signal_quality=int(round(c * 100)),
            ),
        )
        for t, r, c in zip(s.t, s.range, s.confidence, strict=True)
    ]


def write_tlog(path, rows) -> None:
    encoder = new_mav()
    rows = sorted(rows, key=lambda r: r[0])
    path.write_bytes(b"".join(record(encoder, t, m) for t, m in rows))
