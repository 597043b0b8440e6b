"""Cross-checks of a real log's sensors against each other, before the filter runs.

Two disagreements a new robot's log shows and the filter cannot fix by itself:

- **The IMU's axes.** The filter's body frame is forward-right-down; ROS drivers often publish
  in REP-103's forward-left-up. A yaw that turns against the DVL's yaw (the DVL's attitude is
  north-east-down) is the sign: the correlation of the IMU's yaw change (its own orientation,
  else its integrated gyro z) with the DVL's over windows of :data:`WINDOW_S` s, below
  :data:`FLIP_CORRELATION`, says the IMU's z axis points up, i.e. a rotation of pi about x
  (``mounting: {imu: {rotation: [pi, 0, 0]}}``).
- **The DVL's pitch against the depth.** Moving at speed u along its x axis with pitch theta
  (nose up positive), a vehicle's depth changes at d' = -u sin(theta) (small angle of attack),
  so the flight-path pitch theta_fp = -asin(d' / u) follows from the pressure's depth and the
  DVL's speed. The DVL's reported pitch minus theta_fp, over the samples moving faster than
  :data:`MIN_SPEED_M_S`, has a mean (an offset of the DVL's attitude: the DR bias b^g of
  eq:dr_meas_model, ``localizer.dr_bias_rad``) and a scatter (the attitude's accuracy on this
  vehicle, ``localizer.dr_orientation_std_rad``), both proposed when the mean exceeds
  :data:`PITCH_OFFSET_RAD`.
"""

from __future__ import annotations

import math

import numpy as np

from ..log import G0, Log
from ..rotations import quaternion_to_rpy

WINDOW_S = 2.0
FLIP_CORRELATION = -0.6
MIN_SPEED_M_S = 0.3
PITCH_OFFSET_RAD = math.radians(3.0)
DEPTH_RATE_WINDOW_S = 1.0


def _yaw_changes(t_a, yaw_a, t_b, yaw_b, window_s: float):
    start, end = max(t_a[0], t_b[0]), min(t_a[-1], t_b[-1]) - window_s
    if end <= start:
        return None, None
    ts = np.arange(start, end, window_s / 2)
    da = np.interp(ts + window_s, t_a, yaw_a) - np.interp(ts, t_a, yaw_a)
    db = np.interp(ts + window_s, t_b, yaw_b) - np.interp(ts, t_b, yaw_b)
    return da, db


def imu_axes(log: Log) -> dict | None:
    """Whether the IMU's z axis points up against the DVL's attitude (see the module
    docstring): ``{"z_up", "correlation", "windows", "evidence"}``, None without an IMU and the
    DVL's dead reckoning or with too little turning."""
    imu, dr = log.imu, log.dead_reckoning
    if imu is None or dr is None or len(imu) < 10 or len(dr) < 10:
        return None
    yaw_dr = np.unwrap(np.asarray(dr.orientation, float)[:, 2])
    if imu.orientation is not None:
        yaw_imu, source = np.unwrap(quaternion_to_rpy(imu.orientation)[:, 2]), "its orientation"
    else:
        dt = np.diff(imu.t, prepend=imu.t[0])
        yaw_imu, source = np.cumsum(np.asarray(imu.angular_velocity)[:, 2] * dt), "its gyro z"
    ok = np.isfinite(yaw_imu)
    da, db = _yaw_changes(imu.t[ok], yaw_imu[ok], dr.t, yaw_dr, WINDOW_S)
    if da is None or da.size < 5 or np.std(da) == 0 or np.std(db) == 0:
        return None
    r = float(np.corrcoef(da, db)[0, 1])
    z_up = r < FLIP_CORRELATION
    evidence = (
        f"the IMU's yaw ({source}) turns {'against' if r < 0 else 'with'} the DVL's over "
        f"{da.size} windows of {WINDOW_S:g} s (correlation {r:+.2f})"
        + (": its z axis points up (ROS forward-left-up)" if z_up else "")
    )
    return {"z_up": z_up, "correlation": r, "windows": int(da.size), "evidence": evidence}


def dvl_pitch_offset(log: Log, water_density: float, surface_pressure: float) -> dict | None:
    """The DVL's pitch against the flight path from the pressure (see the module docstring):
    ``{"offset_rad", "scatter_rad", "samples", "evidence"}``, None without a DVL, its dead
    reckoning and a pressure, or with fewer than 10 samples at speed."""
    dvl, dr, p = log.dvl, log.dead_reckoning, log.pressure
    if dvl is None or dr is None or p is None or len(p) < 3 or len(dr) < 3:
        return None
    depth = (np.asarray(p.pressure, float) - surface_pressure) / (water_density * G0)
    ok = np.isfinite(depth)
    tp, depth = np.asarray(p.t)[ok], depth[ok]
    t = np.asarray(dvl.t)
    h = DEPTH_RATE_WINDOW_S / 2
    rate = (np.interp(t + h, tp, depth) - np.interp(t - h, tp, depth)) / (2 * h)
    u = np.linalg.norm(np.asarray(dvl.velocity, float), axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        theta_fp = -np.arcsin(np.clip(rate / u, -1.0, 1.0))
    theta_dr = np.interp(t, dr.t, np.asarray(dr.orientation, float)[:, 1])
    inside = (t - h >= tp[0]) & (t + h <= tp[-1]) & (t >= dr.t[0]) & (t <= dr.t[-1])
    use = inside & np.asarray(dvl.valid) & (u > MIN_SPEED_M_S) & np.isfinite(theta_fp)
    if use.sum() < 10:
        return None
    e = theta_dr[use] - theta_fp[use]
    offset, scatter = float(np.mean(e)), float(np.std(e, ddof=1))
    evidence = (
        f"the DVL's pitch is {math.degrees(offset):+.1f} deg (scatter "
        f"{math.degrees(scatter):.1f} deg) off the flight path the pressure's depth rate and "
        f"the DVL's speed give, over {int(use.sum())} samples faster than {MIN_SPEED_M_S} m/s"
    )
    return {"offset_rad": offset, "scatter_rad": scatter, "samples": int(use.sum()),
            "evidence": evidence}  # fmt: skip
