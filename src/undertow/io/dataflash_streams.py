"""The streams of an ArduPilot dataflash log, from its records' rows (see
:mod:`undertow.io.dataflash` for what each stream is made of, with its sources)."""

from __future__ import annotations

import math

import numpy as np

from ..log import AutopilotPose, DeadReckoning, Dvl, GpsFix, Imu, Pressure, SonarRange
from ..rotations import quaternion_to_rpy, rpy_to_quaternion, world_to_body, wrap_angle
from .collect import Notes, count_nan_rows, time_order
from .geo import local_ned

#: VISO confidence (%) below which a DVL velocity is flagged invalid (the tlog reader's default)
MIN_CONFIDENCE = 1.0
#: an IMU time further than this from the nearest ATT sample gets no orientation (s)
ATTITUDE_MAX_GAP_S = 1.0
MAV_SENSOR_ROTATION_PITCH_270 = 25  # a downward rangefinder
RANGEFINDER_GOOD = 4  # AP_RangeFinder Status::Good
GPS_3D_FIX = 3  # AP_GPS GPS_OK_FIX_3D


class StreamBuilder:
    """Builds the Log streams from the message tables (:meth:`build`); what it chose and why
    goes to :attr:`info` (for ``metadata['dataflash']``), the surface pressure it found to
    :attr:`surface` ((Pa, source) or None), counted problems to ``notes``."""

    def __init__(self, notes: Notes, params: dict[str, float], gps_origin=None) -> None:
        self.notes = notes
        self.params = params
        self.gps_origin = gps_origin
        self.gps_origin_used: tuple | None = None
        self.info: dict = {}
        self.surface: tuple[float, str] | None = None

    def build(self, tables: dict) -> dict:
        """The streams of ``tables`` (message name -> rows in the order and units of
        :data:`undertow.io.dataflash.FIELDS`,
        None when absent), by Log field name; empty streams left out."""
        attitude = _attitude(tables["ATT"], self.notes)
        builders = {
            "imu": lambda: self.imu(tables, attitude),
            "pressure": lambda: self.pressure(tables["BARO"]),
            "sonar": lambda: self.sonar(tables["RFND"]),
            "dvl": lambda: self.dvl(tables, attitude),
            "dead_reckoning": lambda: self.dead_reckoning(tables["VISP"]),
            "gps": lambda: self.gps(tables["GPS"], tables["GPA"]),
            "autopilot": lambda: self.autopilot(tables),
        }
        streams = {}
        for name, build in builders.items():
            stream = build()
            if stream is not None and len(stream):
                streams[name] = stream
        return streams

    def _ordered(self, table: np.ndarray, stream: str, t: np.ndarray | None = None):
        t = table[:, 0] if t is None else t
        order = time_order(t, stream, self.notes)
        return t[order], table[order]

    def imu(self, tables, attitude) -> Imu | None:
        imu, source = tables["IMU"], "IMU"
        if imu is None and tables["GYR"] is not None:
            imu, source = tables["GYR"], "GYR"
        if imu is None:
            return None
        imu, k = _instance(imu, 1)
        t = imu[:, 2] if source == "GYR" and np.isfinite(imu[:, 2]).all() else imu[:, 0]
        t, imu = self._ordered(imu, "imu", t)
        gyro = imu[:, 3:6] if source == "GYR" else imu[:, 2:5]
        acc = None if source == "GYR" else imu[:, 5:8]
        count_nan_rows(self.notes, "imu", gyro)
        orientation = None
        if attitude is not None:
            orientation = interpolate_orientation(*attitude, t, ATTITUDE_MAX_GAP_S)
            self.notes.add("imu: rows without an ATT attitude within 1 s (orientation NaN)",
                           int(np.isnan(orientation[:, 3]).sum()))  # fmt: skip
        self.info["imu"] = f"{source} instance {k}" + (
            ", orientation: ATT interpolated (slerp) to the IMU times" if attitude else ""
        )
        return Imu(t, gyro, acc, orientation)

    def pressure(self, baro) -> Pressure | None:
        if baro is None:
            return None
        k, why = _depth_sensor(baro, self.params)
        baro, _ = _instance(baro, 1, k)
        t, baro = self._ordered(baro, "pressure")
        count_nan_rows(self.notes, "pressure", baro[:, 2])
        self.info["pressure"] = f"BARO instance {k} ({why})"
        name = f"BARO{k + 1}_GND_PRESS"
        ground = self.params.get(name, math.nan)
        if 30_000.0 < ground < 200_000.0:
            self.surface = (ground, f"{name} parameter of the dataflash log")
        elif name in self.params:
            self.notes.add(f"{name} = {ground} Pa is not a surface pressure (not used)", 1)
        return Pressure(t, baro[:, 2])

    def sonar(self, rfnd) -> SonarRange | None:
        if rfnd is None:
            return None
        orient = rfnd[:, 4]
        down = rfnd[np.isnan(orient) | (orient == MAV_SENSOR_ROTATION_PITCH_270)]
        self.notes.add("RFND records of rangefinders not looking down ignored",
                       int(len(rfnd) - len(down)))  # fmt: skip
        if not len(down):
            return None
        down, k = _instance(down, 1)
        t, down = self._ordered(down, "sonar")
        status, quality = down[:, 3], down[:, 5]
        rng = np.where(np.isnan(status) | (status == RANGEFINDER_GOOD), down[:, 2], np.nan)
        conf = np.where((quality > 0) & (quality <= 100), quality / 100.0, np.nan)
        self.info["sonar"] = f"RFND instance {k} (downward)"
        return SonarRange(t, rng, conf, **self._range_limits(k))

    def _range_limits(self, k: int) -> dict:
        """min_range/max_range (m) of rangefinder ``k`` from RNGFND{n}_MIN_CM/MAX_CM (cm), or
        RNGFND{n}_MIN/MAX (m, ArduPilot 4.6 on); the SonarRange defaults unless 0 <= min < max."""
        for suffix, scale in (("_CM", 0.01), ("", 1.0)):
            low = self.params.get(f"RNGFND{k + 1}_MIN{suffix}", math.nan) * scale
            high = self.params.get(f"RNGFND{k + 1}_MAX{suffix}", math.nan) * scale
            if 0.0 <= low < high < math.inf:
                return {"min_range": low, "max_range": high}
        return {}

    def dvl(self, tables, attitude) -> Dvl | None:
        viso, visv = tables["VISO"], tables["VISV"]
        if viso is not None:
            dt = viso[:, 1]
            good = np.isfinite(dt) & (dt > 0)
            self.notes.add("VISO records with dt <= 0 dropped", int((~good).sum()))
            t, viso = self._ordered(viso[good], "dvl")
            self.info["dvl"] = "VISO: v = PosD / dt (body frame)"
            velocity = viso[:, 2:5] / viso[:, 1:2]
            count_nan_rows(self.notes, "dvl", velocity)
            return Dvl.from_velocity(t, velocity, valid=viso[:, 5] >= MIN_CONFIDENCE)
        if visv is None:
            return None
        if attitude is None:
            self.notes.add("VISV velocities (NED) not used: no ATT attitude to rotate them", 1)
            return None
        t, visv = self._ordered(visv, "dvl")
        q = interpolate_orientation(*attitude, t, ATTITUDE_MAX_GAP_S)
        velocity = world_to_body(quaternion_to_rpy(q), visv[:, 1:4])
        count_nan_rows(self.notes, "dvl", velocity)
        err = visv[:, 4]
        cov = np.where((err > 0)[:, None, None], (err**2)[:, None, None] * np.eye(3), np.nan)
        self.info["dvl"] = "VISV: NED velocity rotated into the body by the ATT attitude"
        return Dvl.from_velocity(t, velocity, valid=~(visv[:, 5] > 0), covariance=cov)

    def dead_reckoning(self, visp) -> DeadReckoning | None:
        if visp is None:
            return None
        t, visp = self._ordered(visp, "dead_reckoning")
        rpy = np.deg2rad(visp[:, 4:7])
        rpy[:, 2] = wrap_angle(rpy[:, 2])
        std = np.where(visp[:, 7] > 0, visp[:, 7], np.nan)
        resets = np.diff(np.nan_to_num(visp[:, 8]))
        self.info["dead_reckoning"] = {"source": "VISP", "resets": int(np.sum(resets != 0))}
        return DeadReckoning(t, visp[:, 1:4], rpy, std)

    def gps(self, gps, gpa) -> GpsFix | None:
        if gps is None:
            return None
        gps, k = _instance(gps, 1)
        t, gps = self._ordered(gps, "gps")
        lat, lon, alt = gps[:, 3], gps[:, 4], gps[:, 5]
        fixed = gps[:, 2] >= GPS_3D_FIX
        sane = (np.isfinite(gps[:, 3:6]).all(axis=1) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
                & ~((lat == 0) & (lon == 0)))  # fmt: skip
        self.notes.add("gps: records without a 3D fix dropped", int((~fixed).sum()))
        self.notes.add("gps: fixes with non-finite or impossible coordinates dropped",
                       int((fixed & ~sane).sum()))  # fmt: skip
        keep = fixed & sane
        if not keep.any():
            return None
        first = (float(lat[keep][0]), float(lon[keep][0]), float(alt[keep][0]))
        origin = first if self.gps_origin is None else tuple(self.gps_origin)
        try:
            position = local_ned(lat[keep], lon[keep], alt[keep], origin)
        except ImportError:
            self.notes.add("gps: fixes not used (projecting them needs pyproj: pip install "
                           "pyproj)", 1)  # fmt: skip
            return None
        self.gps_origin_used = origin
        hacc = _matched(gpa, k, gps[keep, 0])
        about = "the first 3D fix" if self.gps_origin is None else "the settings' gps_origin"
        self.info["gps"] = f"GPS instance {k}, local north-east-down about {about}"
        return GpsFix(t[keep], position, lat[keep], lon[keep], alt[keep],
                      np.where(hacc > 0, hacc, np.nan), origin=origin)  # fmt: skip

    def autopilot(self, tables) -> AutopilotPose | None:
        name = "XKF1" if tables["XKF1"] is not None else "NKF1"
        ekf = tables[name]
        if ekf is None:
            return None
        ekf, core = _instance(ekf, 1)
        t, ekf = self._ordered(ekf, "autopilot")
        rpy = np.deg2rad(ekf[:, 2:5])
        rpy[:, 2] = wrap_angle(rpy[:, 2])
        self.info["autopilot"] = f"{name} core {core} ({'EKF3' if name == 'XKF1' else 'EKF2'})"
        return AutopilotPose(t, ekf[:, 8:11], rpy, ekf[:, 5:8])


def _instance(table: np.ndarray, column: int, k: float | None = None):
    """(rows of instance ``k`` (default: the lowest present), k); a NaN instance (the column
    absent) counts as 0."""
    inst = np.nan_to_num(table[:, column], nan=0.0)
    k = float(np.min(inst)) if k is None else k
    return table[inst == k], int(k)


def _depth_sensor(baro: np.ndarray, params: dict) -> tuple[int, str]:
    """The BARO instance of the depth sensor, and why."""
    instances = np.unique(np.nan_to_num(baro[:, 1], nan=0.0))
    primary = params.get("BARO_PRIMARY", math.nan)
    if primary in instances:
        return int(primary), f"BARO_PRIMARY = {int(primary)}: ArduSub's depth sensor"
    for k in instances:
        rows, _ = _instance(baro, 1, k)
        p, alt = rows[:, 2], rows[:, 3]
        ok = np.isfinite(p) & np.isfinite(alt)
        if ok.sum() >= 3 and np.ptp(p[ok]) > 1.0:
            slope = np.polyfit(p[ok], alt[ok], 1)[0]  # water: -1 / (9800 SG) m/Pa
            if -2e-4 < slope < -5e-5:
                return int(k), "its Alt follows Press as a water-type barometer's"
    return int(instances[0]), "the lowest instance"


def _attitude(att: np.ndarray | None, notes: Notes):
    """(times, quaternions x y z w) of the ATT records with finite angles, in time order."""
    if att is None:
        return None
    att = att[np.isfinite(att).all(axis=1)]
    if not len(att):
        return None
    order = time_order(att[:, 0], "ATT", notes)
    att = att[order]
    return att[:, 0], rpy_to_quaternion(np.deg2rad(att[:, 1:4]))


def interpolate_orientation(t_src, q_src, t, max_gap_s: float = ATTITUDE_MAX_GAP_S):
    """Quaternions (x, y, z, w) at times ``t`` by spherical linear interpolation of ``q_src``
    (at sorted times ``t_src``): q(t) = [sin((1 - u) a) q_k + sin(u a) q_k+1] / sin(a), u =
    (t - t_k) / (t_k+1 - t_k), cos a = |q_k . q_k+1| (Shoemake, "Animating rotation with
    quaternion curves", SIGGRAPH 1985; the shorter arc). Before the first and after the last
    sample the end sample is held up to ``max_gap_s`` away; rows between samples more than
    ``max_gap_s`` apart, or further from the ends, are NaN. Returned with w >= 0."""
    t_src, q_src, t = np.asarray(t_src, float), np.asarray(q_src, float), np.asarray(t, float)
    n = t_src.size
    k = np.clip(np.searchsorted(t_src, t, side="right") - 1, 0, max(n - 2, 0))
    k1 = np.minimum(k + 1, n - 1)
    span = t_src[k1] - t_src[k]
    u = np.where(span > 0, (t - t_src[k]) / np.where(span > 0, span, 1.0), 0.0)
    u = np.clip(u, 0.0, 1.0)
    q0, q1 = q_src[k], q_src[k1]
    dot = np.sum(q0 * q1, axis=1)
    q1 = np.where(dot[:, None] < 0, -q1, q1)
    angle = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    s = np.sin(angle)
    small = s < 1e-9
    w0 = np.where(small, 1.0 - u, np.sin((1.0 - u) * angle) / np.where(small, 1.0, s))
    w1 = np.where(small, u, np.sin(u * angle) / np.where(small, 1.0, s))
    q = w0[:, None] * q0 + w1[:, None] * q1
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(q[:, 3:4] < 0, -q, q)
    nearest = np.minimum(np.abs(t - t_src[k]), np.abs(t - t_src[k1]))
    inside = (t >= t_src[0]) & (t <= t_src[-1])
    q[np.where(inside, span > max_gap_s, nearest > max_gap_s)] = np.nan
    return q


def _matched(table: np.ndarray | None, k: int, t: np.ndarray) -> np.ndarray:
    """Column 2 of ``table``'s instance-``k`` rows at the same times as ``t`` (NaN elsewhere):
    ArduPilot writes GPS and GPA with one time_us."""
    out = np.full(t.size, np.nan)
    if table is None:
        return out
    rows, _ = _instance(table, 1, k)
    lookup = dict(zip(rows[:, 0].tolist(), rows[:, 2].tolist(), strict=True))
    return np.array([lookup.get(v, math.nan) for v in t.tolist()])
