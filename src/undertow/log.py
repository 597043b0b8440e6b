"""The measurement log: typed, time-ordered streams of numpy arrays.

Conventions (used by every stage):

- Time ``t`` is float64 seconds (any epoch; readers keep the log's own, the simulator starts at 0),
  non-decreasing within a stream.
- World frame: x along the tank / north, y to the right / east, z DOWN (depth positive), origin at
  the still water surface. Body frame: forward-right-down (FRD). Angles in radians,
  roll-pitch-yaw (phi, theta, psi) with R = Rz(psi) Ry(theta) Rx(phi) mapping body to world.
- DVL frame: x forward, y right, z down, origin where the four beam axes meet (Water Linked A50).
- Missing optional values are NaN (never 0 or -1); validity flags say what the sensor reported.

Every stream is a frozen dataclass whose arrays are made read-only, so a Log can be shared by
stages without copies or surprises. The robot's description (DVL beam geometry, where each
sensor sits on the body) is :mod:`undertow.robot`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .errors import DataError, MissingStreamError
from .robot import A50_UNITS, DvlGeometry, Mounting
from .rotations import world_to_body, wrap_angle

G0 = 9.80665  # standard gravity, m/s^2
P_ATM = 101_325.0  # standard atmosphere, Pa
#: Default water density (kg/m^3) of every depth conversion and of the simulator: fresh water at
#: the basin's temperature, about 20 C (pure water: 998.2 kg/m^3 at 20 C, 999.1 at 15 C, CRC
#: Handbook of Chemistry and Physics; sea water is about 1025). Pass 1025 for a sea-water log.
FRESH_WATER_DENSITY = 998.0
_BEAM_IDS = np.arange(4)[None]  # (1, 4): beam ids 0..3
_BEAM_IDS.setflags(write=False)


def _as_array(value, dtype, name: str, stream: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=dtype, copy=True)
    except (TypeError, ValueError, OverflowError) as exc:  # (an int too large for a float)
        raise DataError(
            f"{stream}.{name}: cannot convert to {np.dtype(dtype).name}: {exc}"
        ) from exc
    arr.setflags(write=False)
    return arr


@functools.cache
def _field_defaults(cls) -> tuple[tuple[str, object], ...]:
    return tuple((f.name, f.default) for f in dataclasses.fields(cls))


class _Stream:
    """Shared validation: every array field has the length of ``t`` along axis 0."""

    kind: ClassVar[str] = "stream"
    _shapes: ClassVar[dict[str, tuple]] = {}
    _dtypes: ClassVar[dict[str, type]] = {}

    def __post_init__(self) -> None:
        t = _as_array(self.t, np.float64, "t", self.kind).reshape(-1)
        object.__setattr__(self, "t", t)
        if not np.all(np.isfinite(t)):
            raise DataError(f"{self.kind}.t: non-finite timestamps")
        if t.size > 1 and np.any(np.diff(t) < 0):
            i = int(np.argmax(np.diff(t) < 0))
            raise DataError(
                f"{self.kind}.t: time goes backwards at sample {i + 1} "
                f"({t[i]:.6f} -> {t[i + 1]:.6f})"
            )
        n = t.size
        for name, tail in self._tails().items():
            value = getattr(self, name)
            if value is None:
                continue
            arr = _as_array(value, self._dtypes.get(name, np.float64), name, self.kind)
            if arr.shape != (n, *tail):
                raise DataError(
                    f"{self.kind}.{name}: shape {arr.shape}, expected {(n, *tail)} "
                    "(one row per time)"
                )
            object.__setattr__(self, name, arr)

    def _tails(self) -> dict[str, tuple]:
        """Expected shape after the time axis, per array field (``_shapes`` unless a stream
        sizes a dimension from its data)."""
        return self._shapes

    @classmethod
    def trusted(cls, **fields):
        """The stream of ``fields`` without the constructor's checks and copies, for a builder
        that made every array itself in this class's dtypes and shapes, with finite times in
        order (:func:`undertow.records.records_to_log`, called for every few records
        live); the arrays are made read-only, as the constructor makes its copies."""
        obj = object.__new__(cls)
        for name, default in _field_defaults(cls):
            value = fields.pop(name, default)
            if value is dataclasses.MISSING:
                raise TypeError(f"{cls.__name__}.trusted: missing field {name}")
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(obj, name, value)
        if fields:
            raise TypeError(f"{cls.__name__}.trusted: unknown fields {sorted(fields)}")
        return obj

    def __len__(self) -> int:
        return int(self.t.size)

    @classmethod
    def array_fields(cls) -> tuple[str, ...]:  # per-row array fields besides t
        return tuple(cls._shapes)

    @property
    def rate_hz(self) -> float:
        """Median sample rate (NaN with fewer than two samples)."""
        if self.t.size < 2:
            return float("nan")
        dt = np.median(np.diff(self.t))
        return float(1.0 / dt) if dt > 0 else float("nan")

    def select(self, mask: np.ndarray):
        """A stream of the same type holding only the rows where ``mask`` is true."""
        mask = np.asarray(mask)
        changes = {"t": self.t[mask]}
        for name in self._shapes:
            value = getattr(self, name)
            if value is not None:
                changes[name] = value[mask]
        return dataclasses.replace(self, **changes)

    def invalid_count(self) -> int:
        """Rows with a non-finite value in the main measurement (see each stream)."""
        return 0


@dataclass(frozen=True, eq=False)
class Imu(_Stream):
    """IMU: angular rate (rad/s, body), optional linear acceleration (m/s^2) and orientation
    (quaternion x, y, z, w, world from body)."""

    kind: ClassVar[str] = "imu"
    _shapes: ClassVar[dict[str, tuple]] = {
        "angular_velocity": (3,),
        "linear_acceleration": (3,),
        "orientation": (4,),
    }
    t: np.ndarray
    angular_velocity: np.ndarray
    linear_acceleration: np.ndarray | None = None
    orientation: np.ndarray | None = None

    def invalid_count(self) -> int:
        return int(np.sum(~np.all(np.isfinite(self.angular_velocity), axis=1)))


@dataclass(frozen=True, eq=False)
class Dvl(_Stream):
    """DVL bottom-track velocity report, with its four beams.

    ``velocity`` is the body velocity in the DVL frame (m/s); ``valid`` the sensor's velocity
    validity flag; ``fom`` the figure of merit (m/s, NaN if absent); ``covariance`` 3x3 (m/s)^2
    (NaN if unknown); ``altitude`` (m, NaN when the sensor reported it invalid, e.g. -1).
    Per beam (shape (N, 4)): ``beam_id``, ``beam_unit`` (N, 4, 3) unit vector in the DVL frame,
    ``beam_range`` (m, slant range along the beam), ``beam_valid``, ``beam_velocity`` (m/s, radial).
    """

    kind: ClassVar[str] = "dvl"
    _shapes: ClassVar[dict[str, tuple]] = {
        "velocity": (3,),
        "valid": (),
        "fom": (),
        "covariance": (3, 3),
        "altitude": (),
        "beam_id": (4,),
        "beam_unit": (4, 3),
        "beam_range": (4,),
        "beam_valid": (4,),
        "beam_velocity": (4,),
    }
    _dtypes: ClassVar[dict[str, type]] = {
        "valid": np.bool_,
        "beam_valid": np.bool_,
        "beam_id": np.int64,
    }
    t: np.ndarray
    velocity: np.ndarray
    valid: np.ndarray
    fom: np.ndarray
    covariance: np.ndarray
    altitude: np.ndarray
    beam_id: np.ndarray
    beam_unit: np.ndarray
    beam_range: np.ndarray
    beam_valid: np.ndarray
    beam_velocity: np.ndarray

    def invalid_count(self) -> int:
        finite = np.all(np.isfinite(self.velocity), axis=1)
        return int(np.sum(~(self.valid & finite)))

    def with_geometry(self, geometry: DvlGeometry) -> Dvl:
        """A copy whose beam vectors are ``geometry.units()`` in every row (for logs whose
        messages carry none, e.g. a Nortek or Teledyne head recorded through A50-style
        messages); DataError when the beam counts differ."""
        units = geometry.units()
        if units.shape != self.beam_unit.shape[1:]:
            raise DataError(
                f"dvl: geometry {geometry.name} has {geometry.beams} beams, the stream "
                f"{self.beam_unit.shape[1]}"
            )
        return dataclasses.replace(self, beam_unit=np.broadcast_to(units, self.beam_unit.shape))

    @classmethod
    def from_velocity(
        cls,
        t,
        velocity,
        valid=None,
        fom=None,
        covariance=None,
        altitude=None,
        beam_range=None,
        beam_valid=None,
        beam_velocity=None,
    ) -> Dvl:
        """Build a Dvl stream with A50 beam geometry and NaN/False for what is not given."""
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        return cls(**cls.velocity_fields(t, velocity, valid, fom, covariance, altitude,
                                          beam_range, beam_valid, beam_velocity))  # fmt: skip

    @staticmethod
    def velocity_fields(t, velocity, valid, fom, covariance, altitude, beam_range, beam_valid,
                         beam_velocity) -> dict:  # fmt: skip
        """The fields of :meth:`from_velocity` (t a float64 array)."""
        n = t.size
        nan = np.full(n, np.nan)
        return dict(
            t=t,
            velocity=velocity,
            valid=np.ones(n, bool) if valid is None else valid,
            fom=nan if fom is None else fom,
            covariance=np.full((n, 3, 3), np.nan) if covariance is None else covariance,
            altitude=nan if altitude is None else altitude,
            beam_id=np.repeat(_BEAM_IDS, n, axis=0),  # (np.tile, without its set-up)
            beam_unit=np.repeat(A50_UNITS[None], n, axis=0),
            beam_range=np.full((n, 4), np.nan) if beam_range is None else beam_range,
            beam_valid=np.zeros((n, 4), bool) if beam_valid is None else beam_valid,
            beam_velocity=np.full((n, 4), np.nan) if beam_velocity is None else beam_velocity,
        )


@dataclass(frozen=True, eq=False)
class DeadReckoning(_Stream):
    """The DVL's own dead-reckoning report (Water Linked ``position_local``).

    ``position`` (m, x y z with z down, in the DVL's reset frame), ``orientation`` roll, pitch,
    yaw (rad), ``std`` (m, the sensor's position standard deviation, NaN if absent).
    """

    kind: ClassVar[str] = "dead_reckoning"
    _shapes: ClassVar[dict[str, tuple]] = {"position": (3,), "orientation": (3,), "std": ()}
    t: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    std: np.ndarray | None = None

    def invalid_count(self) -> int:
        return int(np.sum(~np.all(np.isfinite(self.orientation), axis=1)))


@dataclass(frozen=True, eq=False)
class Pressure(_Stream):
    """Absolute pressure (Pa) from the barometer."""

    kind: ClassVar[str] = "pressure"
    _shapes: ClassVar[dict[str, tuple]] = {"pressure": ()}
    t: np.ndarray
    pressure: np.ndarray

    def depth(
        self,
        water_density: float = FRESH_WATER_DENSITY,
        surface_pressure: float = P_ATM,
        g: float = G0,
    ) -> np.ndarray:
        """Depth below the surface (m, positive down): d = (p - p_atm) / (rho g); the default
        density is :data:`FRESH_WATER_DENSITY` (the simulator's too), use 1025 for sea water."""
        return (self.pressure - surface_pressure) / (water_density * g)

    def invalid_count(self) -> int:
        return int(np.sum(~np.isfinite(self.pressure)))


@dataclass(frozen=True, eq=False)
class SonarRange(_Stream):
    """Single-beam echo sounder (Ping sonar): ``range`` (m), ``confidence`` (0-1, NaN if absent).

    ``field_of_view`` is the full cone angle (rad); ``min_range``/``max_range`` the sensor limits.
    """

    kind: ClassVar[str] = "sonar"
    _shapes: ClassVar[dict[str, tuple]] = {"range": (), "confidence": ()}
    t: np.ndarray
    range: np.ndarray
    confidence: np.ndarray | None = None
    field_of_view: float = float(np.deg2rad(25.0))
    min_range: float = 0.3
    max_range: float = 100.0

    def invalid_count(self) -> int:
        r = self.range
        return int(np.sum(~(np.isfinite(r) & (r >= self.min_range) & (r <= self.max_range))))


@dataclass(frozen=True, eq=False)
class Multibeam(_Stream):
    """Multibeam echosounder: per ping, B beam detections in the sensor frame.

    ``points`` (N, B, 3) m: the detection of beam j of ping n in the sensor frame (x forward
    along track, y starboard, z down: the acoustic axis at nadir), NaN where the beam has no
    detection; every ping has the same B (pings with fewer detections are padded with NaN).
    ``intensity`` (N, B) backscatter (NaN if absent). Derived: slant range r = |p|, unit
    u = p / r, across-track angle theta = atan2(p_y, p_z) (0 at nadir, positive to starboard).
    ``min_range``/``max_range``: the sensor's limits (m).
    """

    kind: ClassVar[str] = "multibeam"
    _shapes: ClassVar[dict[str, tuple]] = {"points": (None, 3), "intensity": (None,)}
    t: np.ndarray
    points: np.ndarray
    intensity: np.ndarray | None = None
    min_range: float = 0.1
    max_range: float = 200.0

    def __post_init__(self) -> None:
        pts = _as_array(self.points, np.float64, "points", self.kind)
        if pts.ndim == 2 and pts.shape[0] == 0:
            pts = pts.reshape(0, 0, 3)
        if pts.ndim != 3 or pts.shape[2] != 3:
            raise DataError(f"{self.kind}.points: shape {pts.shape}, expected (N, B, 3)")
        object.__setattr__(self, "points", pts)
        super().__post_init__()

    def _tails(self) -> dict[str, tuple]:
        beams = self.points.shape[1]  # the beam count of this log
        return {"points": (beams, 3), "intensity": (beams,)}

    @property
    def beams(self) -> int:
        """B, the beams per ping."""
        return int(self.points.shape[1])

    @property
    def range(self) -> np.ndarray:
        """Slant range r = |p| (N, B), NaN without a detection."""
        return np.linalg.norm(self.points, axis=2)

    @property
    def beam_unit(self) -> np.ndarray:
        """Unit vectors u = p / |p| (N, B, 3) in the sensor frame, NaN without a detection."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.points / self.range[..., None]

    @property
    def across_angle(self) -> np.ndarray:
        """Across-track beam angle theta = atan2(p_y, p_z) (rad, N x B)."""
        return np.arctan2(self.points[..., 1], self.points[..., 2])

    @property
    def valid(self) -> np.ndarray:
        """(N, B): the beam has a finite detection inside [min_range, max_range]."""
        r = self.range
        with np.errstate(invalid="ignore"):
            return np.isfinite(r) & (r >= self.min_range) & (r <= self.max_range)

    def invalid_count(self) -> int:
        """Pings without a single valid detection."""
        return int(np.sum(~self.valid.any(axis=1))) if self.beams else len(self)


@dataclass(frozen=True, eq=False)
class WaveProbe(_Stream):
    """Free-surface elevation (m, positive UP, as wave probes report) at fixed ``x`` (m)."""

    kind: ClassVar[str] = "wave_probe"
    _shapes: ClassVar[dict[str, tuple]] = {"elevation": ()}
    t: np.ndarray
    elevation: np.ndarray
    x: float = 0.0

    def invalid_count(self) -> int:
        return int(np.sum(~np.isfinite(self.elevation)))


@dataclass(frozen=True, eq=False)
class GroundTruth(_Stream):
    """Ground-truth pose of the body frame: ``position`` (m, world), ``orientation`` roll, pitch,
    yaw (rad); ``velocity`` (m/s, world frame) where known."""

    kind: ClassVar[str] = "ground_truth"
    _shapes: ClassVar[dict[str, tuple]] = {"position": (3,), "orientation": (3,), "velocity": (3,)}
    t: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    velocity: np.ndarray | None = None

    def usable(self, where: str = "ground truth", min_poses: int = 3) -> GroundTruth:
        """Without repeated timestamps (the first pose at each time is kept) and without
        non-finite poses, each with one warning line; DataError if fewer than ``min_poses``
        remain."""
        bad = ~(
            np.all(np.isfinite(self.position), axis=1)
            & np.all(np.isfinite(self.orientation), axis=1)
        )
        gt = self
        if bad.any():
            warnings.warn(
                f"{where}: dropped {int(bad.sum())} ground-truth poses with non-finite values",
                RuntimeWarning,
                stacklevel=3,
            )
            gt = gt.select(~bad)
        repeated = np.r_[False, np.diff(gt.t) == 0] if len(gt) else np.zeros(0, bool)
        if repeated.any():
            first = gt.t[int(np.argmax(repeated))]
            warnings.warn(
                f"{where}: ground truth repeats {int(repeated.sum())} timestamps (first at "
                f"t = {first:.6f} s, rounded times?); kept the first pose at each time",
                RuntimeWarning,
                stacklevel=3,
            )
            gt = gt.select(~repeated)
        if len(gt) < min_poses:
            raise DataError(
                f"{where}: ground truth has {len(gt)} usable poses at distinct times; "
                f"need at least {min_poses}"
            )
        return gt

    def differentiated_velocity(self, smoothing_s: float = 0.05) -> np.ndarray:
        """World-frame velocity (N, 3) as the paper measures it: differentiate the positions and
        smooth, v_k = sum_j w_j (dp/dt)_{k-j} with w a normalized Hann window spanning
        ``smoothing_s`` (odd length, centred: no delay)."""
        if len(self) < 3:
            raise DataError("ground_truth: need at least 3 poses to differentiate")
        v = np.gradient(self.position, self.t, axis=0)
        dt = float(np.median(np.diff(self.t)))
        n = max(int(round(smoothing_s / dt)), 1) | 1
        if n < 3:
            return v
        w = np.hanning(n + 2)[1:-1]
        w /= w.sum()
        pad = n // 2
        padded = np.pad(v, ((pad, n - 1 - pad), (0, 0)), mode="edge")
        return np.stack([np.convolve(padded[:, i], w, mode="valid") for i in range(3)], axis=1)

    def interpolate(self, t: np.ndarray, velocity: np.ndarray | None = None):
        """(position, roll-pitch-yaw, velocity or None) at times ``t`` inside the span: linear in
        position, in unwrapped angles and in ``velocity`` (rows aligned with ``self.t``)."""
        pos = np.stack([np.interp(t, self.t, self.position[:, i]) for i in range(3)], axis=1)
        unwrapped = np.unwrap(self.orientation, axis=0)
        rpy = wrap_angle(
            np.stack([np.interp(t, self.t, unwrapped[:, i]) for i in range(3)], axis=1)
        )
        vel = None
        if velocity is not None:
            vel = np.stack([np.interp(t, self.t, velocity[:, i]) for i in range(3)], axis=1)
        return pos, rpy, vel

    def body_velocity(self, t: np.ndarray, velocity_world: np.ndarray | None = None):
        """Body-frame velocity at ``t``: v^B = R(eta)^T v^W, with v^W the differentiated
        velocity unless given (rows aligned with ``self.t``)."""
        if velocity_world is None:
            velocity_world = self.differentiated_velocity()
        _, rpy, vel = self.interpolate(t, velocity_world)
        return world_to_body(rpy, vel)


@dataclass(frozen=True, eq=False)
class AutopilotPose(GroundTruth):
    """The autopilot's own estimate (ArduPilot EKF3's ``XKF1``, NED about its origin): a
    *reference*, not a truth; the fields and helpers of :class:`GroundTruth`."""

    kind: ClassVar[str] = "autopilot"


@dataclass(frozen=True, eq=False)
class Depth(_Stream):
    """Depth (m, positive down) as the vehicle itself reports it (a depth topic, a pose's z)."""

    kind: ClassVar[str] = "depth"
    _shapes: ClassVar[dict[str, tuple]] = {"depth": ()}
    t: np.ndarray
    depth: np.ndarray

    def invalid_count(self) -> int:
        return int(np.sum(~np.isfinite(self.depth)))


@dataclass(frozen=True, eq=False)
class GpsFix(_Stream):
    """Position fixes (GNSS at the surface, or a position reference in a local frame).

    ``position`` (m): x north, y east, z down about ``origin`` (latitude deg, longitude deg,
    altitude m; NaN where the fixes came in local metres already); ``latitude``/``longitude``
    (deg) and ``altitude`` (m) as received (NaN for local fixes); ``horizontal_std`` (m, NaN if
    absent). Only usable fixes are kept (the readers drop and count the rest)."""

    kind: ClassVar[str] = "gps"
    _shapes: ClassVar[dict[str, tuple]] = {
        "position": (3,),
        "latitude": (),
        "longitude": (),
        "altitude": (),
        "horizontal_std": (),
    }
    t: np.ndarray
    position: np.ndarray
    latitude: np.ndarray | None = None
    longitude: np.ndarray | None = None
    altitude: np.ndarray | None = None
    horizontal_std: np.ndarray | None = None
    origin: tuple[float, float, float] = (math.nan, math.nan, math.nan)

    def invalid_count(self) -> int:
        return int(np.sum(~np.all(np.isfinite(self.position), axis=1)))


STREAM_NAMES = (
    "imu",
    "dvl",
    "dead_reckoning",
    "pressure",
    "sonar",
    "wave_probe",
    "ground_truth",
    "multibeam",
    "depth",
    "gps",
    "autopilot",
)


@dataclass(frozen=True, eq=False)
class Log:
    """A robot's measurement log: optional streams plus mounting and free-form metadata.

    Any stream may be missing (a DVL-only log is legal); a stage calls :meth:`require` with the
    streams it needs and gets a clear :class:`MissingStreamError` otherwise.
    """

    imu: Imu | None = None
    dvl: Dvl | None = None
    dead_reckoning: DeadReckoning | None = None
    pressure: Pressure | None = None
    sonar: SonarRange | None = None
    wave_probe: WaveProbe | None = None
    ground_truth: GroundTruth | None = None
    mounting: Mounting = field(default_factory=Mounting)
    source: str = ""
    metadata: dict = field(default_factory=dict)
    multibeam: Multibeam | None = None
    #: the vehicle's own depth report (a reference for the pressure's depth, or its stand-in)
    depth: Depth | None = None
    #: position fixes (GNSS at the surface): a reference, never fused by the paper's filter
    gps: GpsFix | None = None
    #: the autopilot's own estimate (e.g. ArduPilot EKF3): a reference, never fused
    autopilot: AutopilotPose | None = None

    def streams(self) -> dict[str, _Stream]:
        """The streams present, by name, in :data:`STREAM_NAMES` order."""
        return {n: getattr(self, n) for n in STREAM_NAMES if getattr(self, n) is not None}

    def require(self, *names: str, stage: str = "this stage") -> None:
        """Raise :class:`MissingStreamError` naming every stream in ``names`` that is absent."""
        missing = [n for n in names if getattr(self, n, None) is None or len(getattr(self, n)) == 0]
        if missing:
            have = ", ".join(self.streams()) or "none"
            src = f" in {self.source}" if self.source else ""
            raise MissingStreamError(
                f"{stage} needs stream(s) {', '.join(missing)}{src}; the log has: {have}"
            )

    @property
    def time_span(self) -> tuple[float, float]:
        """(first, last) time over all streams; (nan, nan) for an empty log."""
        ts = [s.t for s in self.streams().values() if len(s)]
        if not ts:
            return (float("nan"), float("nan"))
        return (min(float(t[0]) for t in ts), max(float(t[-1]) for t in ts))

    def replace(self, **changes) -> Log:
        return dataclasses.replace(self, **changes)
