"""The live view: a Foxglove WebSocket server (Foxglove SDK, ``pip install foxglove-sdk``).

Open Foxglove (app or https://app.foxglove.dev), "Open connection", Foxglove WebSocket,
``ws://HOST:PORT`` (default ``ws://127.0.0.1:8765``), and add a 3D panel with ``world`` as its
display frame. The server speaks the SDK's WebSocket protocol (subprotocol
``foxglove.sdk.v1``). Messages are stamped with the estimate's time t (s); frames are undertow's:
``world`` north-east-down, ``base_link`` forward-right-down (the 3D panel shows z down as
"up" is +z: turn the view over, or read depth as -z).

Topics (:data:`TOPICS`, topic -> schema name):

- ``/undertow/pose`` (``foxglove.Odometry``): the filter's pose, frame ``world``, body
  ``base_link``: position x[0:3], orientation the quaternion of (phi, theta, psi) = x[3:6],
  ``pose_covariance`` P[0:6, 0:6] row-major (the Euler-angle block as is, see
  :mod:`undertow.live.recorder`); body velocity x[6:9] and angular rate x[9:12] with
  ``velocity_covariance`` P[6:12, 6:12] (the state layout of :mod:`undertow.estimation.model`);
- ``/undertow/pose/uncertainty`` (``foxglove.SceneUpdate``): the 3-sigma ellipsoid of the
  position, axes 2 * 3 sqrt(lambda_i) along the eigenvectors of P[0:3, 0:3];
- ``/tf`` (``foxglove.FrameTransform``): ``world`` -> ``base_link`` (the same pose), so panels
  can follow the robot;
- ``/undertow/path`` (``foxglove.PosesInFrame``): the positions so far (orientation identity),
  at most :data:`MAX_PATH_POSES` of them, evenly spaced over the whole path, the newest last
  (:func:`path_points`: an hour's path stays a message the app draws at once);
- ``/undertow/rays/dvl``, ``/undertow/rays/sonar`` (``foxglove.SceneUpdate``): one line
  segment per beam from its origin to its end point (world frame, m), DVL green, sonar orange;
- ``/undertow/map`` (``foxglove.PointCloud``): the occupied cells' centres (mean occupancy above
  the threshold, 0.5 by default), fields x, y, z (float32) and red, green, blue, alpha (uint8),
  coloured by the cell's mean E[theta] or variance V[theta] (eq:mean_var) from blue (lowest of the
  cloud) to red (highest); the live session sends the cloud it keeps chunk by chunk
  (:mod:`undertow.live.map_cloud`: colours on a fixed scale, at most about 200 000 points);
- ``/undertow/wave`` (JSON, schema ``undertow.Wave``): ``{"t": s, "amplitude_m": a,
  "frequency_hz": f}``;
With ``autopilot`` (``undertow live --autopilot``; :data:`AUTOPILOT_TOPICS`):

- ``/autopilot/pose`` (``foxglove.PoseInFrame``): where the
  autopilot's EKF puts the vehicle (its LOCAL_POSITION_NED and ATTITUDE turned into ``world``,
  :mod:`undertow.live.autopilot`), next to undertow's pose;
- ``/autopilot/ekf`` (JSON, schema ``undertow.AutopilotEkf``): its EKF_STATUS_REPORT decoded
  (flag names, whether it has a horizontal position, test ratios) and whether undertow sends.
"""

from __future__ import annotations

import json
import math
import threading

import numpy as np

from ..errors import ConfigError
from ..occupancy import OCCUPIED_THRESHOLD, OccupancyMap
from ..rotations import matrix_to_quaternion_scalar, rpy_to_quaternion_scalar

POSE = "/undertow/pose"
UNCERTAINTY = "/undertow/pose/uncertainty"
TF = "/tf"
PATH = "/undertow/path"
RAYS = {"dvl": "/undertow/rays/dvl", "sonar": "/undertow/rays/sonar"}
MAP = "/undertow/map"
WAVE = "/undertow/wave"
AUTOPILOT_POSE = "/autopilot/pose"
AUTOPILOT_EKF = "/autopilot/ekf"

#: topic -> schema name of every channel the view advertises (module docstring)
TOPICS: dict[str, str] = {
    POSE: "foxglove.Odometry",
    UNCERTAINTY: "foxglove.SceneUpdate",
    TF: "foxglove.FrameTransform",
    PATH: "foxglove.PosesInFrame",
    RAYS["dvl"]: "foxglove.SceneUpdate",
    RAYS["sonar"]: "foxglove.SceneUpdate",
    MAP: "foxglove.PointCloud",
    WAVE: "undertow.Wave",
}
#: the channels added for ``undertow live --autopilot`` (module docstring)
AUTOPILOT_TOPICS: dict[str, str] = {
    AUTOPILOT_POSE: "foxglove.PoseInFrame",
    AUTOPILOT_EKF: "undertow.AutopilotEkf",
}
WAVE_SCHEMA = {
    "type": "object",
    "title": "undertow.Wave",
    "properties": {
        "t": {"type": "number", "description": "time (s)"},
        "amplitude_m": {"type": "number", "description": "wave amplitude a (m)"},
        "frequency_hz": {"type": "number", "description": "wave frequency f (Hz)"},
    },
}
EKF_SCHEMA = {
    "type": "object",
    "title": "undertow.AutopilotEkf",
    "properties": {
        "flags": {"type": "integer", "description": "EKF_STATUS_REPORT flags"},
        "names": {"type": "array", "items": {"type": "string"}, "description": "flags set"},
        "horizontal_position": {"type": "boolean", "description": "EKF3 has a position"},
        "sending": {"type": "boolean", "description": "undertow sends to the autopilot"},
        "reason": {"type": "string", "description": "why undertow does not send"},
    },
}
RAY_COLORS = {"dvl": (0.2, 0.9, 0.3, 1.0), "sonar": (1.0, 0.6, 0.1, 1.0)}
#: the most positions ``/undertow/path`` carries (:func:`path_points`)
MAX_PATH_POSES = 2000


def _foxglove():
    try:
        import foxglove
        from foxglove import channels, messages
    except ImportError:
        raise ConfigError(
            "live view: the Foxglove SDK is not installed (pip install foxglove-sdk)"
        ) from None
    return foxglove, channels, messages


def _stamp(fm, t: float):
    sec = math.floor(t)
    nsec = min(int(round((t - sec) * 1e9)), 999_999_999)
    return fm.Timestamp(int(sec), nsec), int(sec) * 1_000_000_000 + nsec


def _colors(values: np.ndarray) -> np.ndarray:
    """RGBA uint8 (N, 4): blue (lowest value) to red (highest), linear in the value."""
    v = np.asarray(values, dtype=np.float64)
    lo, hi = (float(np.nanmin(v)), float(np.nanmax(v))) if v.size else (0.0, 1.0)
    return scale_colors((v - lo) / (hi - lo) if hi > lo else np.full(v.shape, 0.5))


def scale_colors(s: np.ndarray) -> np.ndarray:
    """RGBA uint8 (N, 4) of s in [0, 1]: blue (0) to red (1), linear; NaN as the middle."""
    s = np.nan_to_num(np.clip(np.asarray(s, dtype=np.float64), 0.0, 1.0), nan=0.5)
    rgba = np.empty((s.size, 4), np.uint8)
    rgba[:, 0] = np.round(255 * s)
    rgba[:, 1] = np.round(255 * (1 - np.abs(2 * s - 1)) * 0.6)
    rgba[:, 2] = np.round(255 * (1 - s))
    rgba[:, 3] = 255
    return rgba


def path_points(positions, max_poses: int = MAX_PATH_POSES) -> np.ndarray:
    """At most ``max_poses`` (>= 2) of the positions (N, 3): all of them, or every k-th from the
    first with k = ceil(N / (max_poses - 1)), and the newest last."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p) <= max_poses:
        return p
    step = -(-len(p) // (max_poses - 1))
    return np.concatenate([p[: len(p) - 1 : step], p[-1:]])


class PathTrail:
    """The positions behind ``/undertow/path`` in bounded memory: of the positions offered
    (numbered 0, 1, ... in order), those whose number is a multiple of ``step`` are kept; when
    more than ``limit`` are kept, every other one is dropped and ``step`` doubles (the kept
    ones stay evenly spaced over the whole path), so a day's path holds at most ``limit``
    positions. :meth:`positions` adds the newest offered."""

    def __init__(self, limit: int = 2 * MAX_PATH_POSES) -> None:
        self.limit = max(int(limit), 2)
        self.step = 1
        self.offered = 0
        self._kept = np.empty((0, 3))
        self._newest: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self._kept)

    def extend(self, positions) -> None:
        p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        if not len(p):
            return
        first = (-self.offered) % self.step  # the first offered number that is a multiple
        self._kept = np.concatenate([self._kept, p[first :: self.step]])
        self.offered += len(p)
        self._newest = p[-1].copy()
        while len(self._kept) > self.limit:
            self._kept, self.step = self._kept[::2], 2 * self.step

    def positions(self) -> np.ndarray:
        """The kept positions and the newest offered (N, 3)."""
        if self._newest is None:
            return self._kept
        if (self.offered - 1) % self.step == 0:  # the newest is kept already
            return self._kept
        return np.concatenate([self._kept, self._newest[None]])


def ellipsoid_axes(cov) -> tuple[list[float], tuple[float, float, float, float]]:
    """(diameters, orientation quaternion (x, y, z, w)) of the 3-sigma ellipsoid of the 3x3
    covariance ``cov``: 2 * 3 sqrt(lambda_i) along the eigenvectors (as a rotation: the third
    flipped when they form a left-handed basis), so cov = R diag((d / 6)^2) R^T."""
    cov = np.asarray(cov, dtype=np.float64)
    lam, vec = np.linalg.eigh(0.5 * (cov + cov.T))
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = rows = vec.tolist()
    if a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0) < 0:
        rows = [[a0, a1, -a2], [b0, b1, -b2], [c0, c1, -c2]]
    return [6.0 * math.sqrt(v) if v > 0 else 0.0 for v in lam.tolist()], (
        matrix_to_quaternion_scalar(rows)
    )


def newest_ranges(chunk):
    """(kind, units (n, 3) in the sensor frame, ranges (n,), mount) of the valid beams of a
    chunk's newest DVL report and of its newest sonar range (the rays the session shows)."""
    out = []
    if chunk.dvl is not None and len(chunk.dvl):
        d = chunk.dvl
        r, u = d.beam_range[-1], d.beam_unit[-1]
        ok = d.beam_valid[-1] & np.isfinite(r) & np.all(np.isfinite(u), axis=1)
        out.append(("dvl", u[ok], r[ok], chunk.mounting.dvl))
    if chunk.sonar is not None and len(chunk.sonar):
        r = chunk.sonar.range[-1:]
        ok = np.isfinite(r)
        unit = np.zeros((int(ok.sum()), 3))
        unit[:, 2] = 1.0  # the sonar frame's +z axis
        out.append(("sonar", unit, r[ok], chunk.mounting.sonar))
    return out


class _Listener:
    """Keeps the topics some client is subscribed to (callbacks from the server's thread)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.subscribers: dict[str, int] = {}

    def on_subscribe(self, client, channel) -> None:
        with self.lock:
            self.subscribers[channel.topic] = self.subscribers.get(channel.topic, 0) + 1

    def on_unsubscribe(self, client, channel) -> None:
        with self.lock:
            self.subscribers[channel.topic] = max(self.subscribers.get(channel.topic, 0) - 1, 0)


class LiveView:
    """The Foxglove WebSocket server and its channels (:data:`TOPICS`).

    ``port`` 0 binds an ephemeral port; :attr:`port` is the bound one. A topic nobody is
    subscribed to costs nothing: its message is not even built (a caller may also skip work,
    e.g. building the occupancy map, when :meth:`subscribed` says no one looks)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, *, name: str = "undertow",
                 autopilot: bool = False):  # fmt: skip
        foxglove, ch, self._m = _foxglove()
        self._listener = _Listener()
        self._context = foxglove.Context()
        try:
            self._server = foxglove.start_server(
                name=name, host=host, port=int(port), context=self._context,
                server_listener=self._listener,
            )  # fmt: skip
        except Exception as exc:  # the SDK raises its own error types for a busy port
            raise ConfigError(f"live view: cannot serve on {host}:{port} ({exc})") from None
        self.host = host
        ctx = self._context
        self._channels = {
            POSE: ch.OdometryChannel(POSE, context=ctx),
            UNCERTAINTY: ch.SceneUpdateChannel(UNCERTAINTY, context=ctx),
            TF: ch.FrameTransformChannel(TF, context=ctx),
            PATH: ch.PosesInFrameChannel(PATH, context=ctx),
            MAP: ch.PointCloudChannel(MAP, context=ctx),
            WAVE: foxglove.Channel(
                WAVE, message_encoding="json", context=ctx,
                schema=foxglove.Schema(name="undertow.Wave", encoding="jsonschema",
                                       data=json.dumps(WAVE_SCHEMA).encode()),
            ),
            **{topic: ch.SceneUpdateChannel(topic, context=ctx) for topic in RAYS.values()},
        }  # fmt: skip
        if autopilot:
            self._channels[AUTOPILOT_POSE] = ch.PoseInFrameChannel(AUTOPILOT_POSE, context=ctx)
            self._channels[AUTOPILOT_EKF] = foxglove.Channel(
                AUTOPILOT_EKF, message_encoding="json", context=ctx,
                schema=foxglove.Schema(name="undertow.AutopilotEkf", encoding="jsonschema",
                                       data=json.dumps(EKF_SCHEMA).encode()),
            )  # fmt: skip
        self._closed = False

    @property
    def port(self) -> int:
        """The bound TCP port."""
        return int(self._server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def subscribed(self, topic: str) -> bool:
        """Whether a client is subscribed to ``topic`` now."""
        with self._listener.lock:
            return self._listener.subscribers.get(topic, 0) > 0

    def _log(self, topic: str, msg, ns: int) -> None:
        if not self._closed:
            self._channels[topic].log(msg, log_time=ns)

    # -- publishers ---------------------------------------------------------------------------
    def publish_pose(self, t: float, x, P) -> None:
        """Odometry, uncertainty ellipsoid and the world -> base_link transform of (x, P)."""
        wanted = [topic for topic in (POSE, TF, UNCERTAINTY) if self.subscribed(topic)]
        if not wanted:
            return
        m = self._m
        x = np.asarray(x, dtype=np.float64).reshape(-1)
        P = np.asarray(P, dtype=np.float64)
        stamp, ns = _stamp(m, t)
        q = rpy_to_quaternion_scalar(float(x[3]), float(x[4]), float(x[5]))
        quat = m.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])
        pos = m.Vector3(x=float(x[0]), y=float(x[1]), z=float(x[2]))
        vel = x[6:12] if x.size >= 12 else np.zeros(6)
        vcov = P[6:12, 6:12] if x.size >= 12 else np.zeros((6, 6))
        odom = m.Odometry(
            timestamp=stamp, frame_id="world", body_frame_id="base_link",
            pose=m.Pose(position=pos, orientation=quat),
            linear_velocity=m.Vector3(x=float(vel[0]), y=float(vel[1]), z=float(vel[2])),
            angular_velocity=m.Vector3(x=float(vel[3]), y=float(vel[4]), z=float(vel[5])),
            pose_covariance=P[:6, :6].ravel().tolist(),
            velocity_covariance=np.asarray(vcov, dtype=np.float64).ravel().tolist(),
        )  # fmt: skip
        tf = m.FrameTransform(
            timestamp=stamp, parent_frame_id="world", child_frame_id="base_link",
            translation=pos, rotation=quat,
        )  # fmt: skip
        ellipsoid = self._ellipsoid(stamp, x[:3], P[:3, :3]) if UNCERTAINTY in wanted else None
        # built first, then handed to the server back to back: its sender wakes once for the
        # three rather than once for each
        self._log(POSE, odom, ns)
        self._log(TF, tf, ns)
        if ellipsoid is not None:
            self._log(UNCERTAINTY, ellipsoid, ns)

    def _ellipsoid(self, stamp, centre, cov):
        """3-sigma ellipsoid: diameters 2 * 3 sqrt(lambda_i) along the eigenvectors of cov."""
        m = self._m
        size, q = ellipsoid_axes(cov)
        sphere = m.SpherePrimitive(
            pose=m.Pose(
                position=m.Vector3(x=float(centre[0]), y=float(centre[1]), z=float(centre[2])),
                orientation=m.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]),
            ),
            size=m.Vector3(x=float(size[0]), y=float(size[1]), z=float(size[2])),
            color=m.Color(r=0.3, g=0.6, b=1.0, a=0.35),
        )
        entity = m.SceneEntity(timestamp=stamp, frame_id="world", id="pose", spheres=[sphere])
        return m.SceneUpdate(entities=[entity])

    def publish_path(self, t: float, positions) -> None:
        """The path: positions (N, 3) in ``world`` (at most MAX_PATH_POSES, :func:`path_points`)."""
        if not self.subscribed(PATH):
            return
        m = self._m
        stamp, ns = _stamp(m, t)
        p = path_points(positions)
        identity = m.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
        poses = [
            m.Pose(position=m.Vector3(x=float(a), y=float(b), z=float(c)), orientation=identity)
            for a, b, c in p
        ]
        self._log(PATH, m.PosesInFrame(timestamp=stamp, frame_id="world", poses=poses), ns)

    def publish_rays(self, t: float, origins, ends, kind: str) -> None:
        """Rays of ``kind`` ("dvl" or "sonar"): segments origins[i] -> ends[i] (N, 3) in world."""
        if kind not in RAYS:
            raise ConfigError(f"live view: ray kind '{kind}' is not one of {list(RAYS)}")
        if not self.subscribed(RAYS[kind]):
            return
        m = self._m
        stamp, ns = _stamp(m, t)
        a = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(ends, dtype=np.float64).reshape(-1, 3)
        pairs = np.stack([a, b], axis=1).reshape(-1, 3)
        ok = np.isfinite(pairs).all(axis=1).reshape(-1, 2).all(axis=1).repeat(2)
        points = [m.Point3(x=float(u), y=float(v), z=float(w)) for u, v, w in pairs[ok]]
        r, g, bl, al = RAY_COLORS[kind]
        line = m.LinePrimitive(
            type=m.LinePrimitiveLineType.LineList, thickness=0.01, points=points,
            color=m.Color(r=r, g=g, b=bl, a=al),
        )  # fmt: skip
        entity = m.SceneEntity(timestamp=stamp, frame_id="world", id=kind, lines=[line])
        self._log(RAYS[kind], m.SceneUpdate(entities=[entity]), ns)

    def publish_map(
        self,
        t: float,
        occupancy: OccupancyMap,
        color_by: str = "mean",
        threshold: float = OCCUPIED_THRESHOLD,
    ) -> None:
        """The occupied cells (mean > ``threshold``) as a point cloud coloured by ``color_by``
        ("mean" or "variance")."""
        if color_by not in ("mean", "variance"):
            raise ConfigError(f"live view: color_by '{color_by}' is not 'mean' or 'variance'")
        if not self.subscribed(MAP):
            return
        cells = occupancy.occupied(threshold)
        value = cells.mean if color_by == "mean" else cells.variance
        data = np.zeros(len(cells), dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
        data["xyz"] = cells.centres
        data["rgba"] = _colors(value)
        self.publish_cloud(t, data)

    def publish_cloud(self, t: float, data: np.ndarray) -> None:
        """Points already packed (x, y, z float32, red, green, blue, alpha uint8: 16 bytes
        each, e.g. :meth:`~undertow.live.map_cloud.MapCloud.points`) on ``/undertow/map``."""
        if not self.subscribed(MAP):
            return
        m = self._m
        stamp, ns = _stamp(m, t)
        f32, u8 = m.PackedElementFieldNumericType.Float32, m.PackedElementFieldNumericType.Uint8
        fields = [m.PackedElementField(name=n, offset=4 * i, type=f32) for i, n in enumerate("xyz")]
        fields += [
            m.PackedElementField(name=n, offset=12 + i, type=u8)
            for i, n in enumerate(("red", "green", "blue", "alpha"))
        ]
        cloud = m.PointCloud(
            timestamp=stamp, frame_id="world", point_stride=16, fields=fields,
            data=data.tobytes(),
            pose=m.Pose(position=m.Vector3(), orientation=m.Quaternion(w=1.0)),
        )  # fmt: skip
        self._log(MAP, cloud, ns)

    def publish_wave(self, t: float, amplitude_m: float, frequency_hz: float) -> None:
        """The wave estimate as JSON ``{"t", "amplitude_m", "frequency_hz"}`` (NaN as null)."""
        if not self.subscribed(WAVE):
            return
        _, ns = _stamp(self._m, t)

        def num(v):
            v = float(v)
            return v if math.isfinite(v) else None

        msg = {"t": float(t), "amplitude_m": num(amplitude_m), "frequency_hz": num(frequency_hz)}
        self._log(WAVE, json.dumps(msg), ns)

    def publish_autopilot_pose(self, t: float, position, rpy) -> None:
        """The autopilot's pose in ``world`` (module docstring)."""
        if not self.subscribed(AUTOPILOT_POSE):
            return
        m = self._m
        stamp, ns = _stamp(m, t)
        q = rpy_to_quaternion_scalar(*(float(a) for a in rpy))
        p = [float(v) for v in position]
        pose = m.Pose(position=m.Vector3(x=p[0], y=p[1], z=p[2]),
                      orientation=m.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]))  # fmt: skip
        self._log(AUTOPILOT_POSE, m.PoseInFrame(timestamp=stamp, frame_id="world", pose=pose), ns)

    def publish_autopilot_ekf(self, t: float, report: dict) -> None:
        """The autopilot's EKF status as JSON (module docstring; NaN as null)."""
        if not self.subscribed(AUTOPILOT_EKF):
            return
        _, ns = _stamp(self._m, t)
        clean = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                 for k, v in report.items()}  # fmt: skip
        self._log(AUTOPILOT_EKF, json.dumps(clean, default=str), ns)

    def close(self) -> None:
        """Stop the server (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for channel in self._channels.values():
            channel.close()
        self._server.stop()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
