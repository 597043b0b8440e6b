"""From range measurements to BKI training samples (points labelled occupied / free).

Every valid range r of a DVL beam (slant range along its unit vector u, DVL frame: the beam
geometry the log carries, ``Dvl.beam_unit``), of the sonar (along the sonar frame's +z axis) or
of a multibeam beam (r = |p|, u = p / r for its detection p in the multibeam frame) gives,
with the body pose (p, R) interpolated at the range's time and the sensor mounting (lever arm
t_s, rotation R_s, both in the body frame):

    origin o = p + R t_s,   direction v = R R_s u,   hit m = o + r v   (label y = 1),

plus free samples m = o + s v for s = 0, f, 2f, ... <= r - f (label y = 0), f = free_resolution,
as the reference BKI implementation la3dm does (Doherty et al., "Learning-aided 3-D occupancy
mapping with Bayesian generalized kernel inference", IEEE T-RO 2019;
github.com/RobustFieldAutonomyLab/la3dm: free points every free_resolution along each ray, from
the origin, labelled 0). Position and its per-axis variance are interpolated linearly,
roll/pitch/yaw on the unwrapped angles. Invalid beams, non-finite or out-of-range values (DVL
0.05-50 m, sonar and multibeam min_range-max_range) and ranges outside the trajectory's time
span are dropped and counted in ``Samples.dropped``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit

from ..errors import DataError, MissingStreamError
from ..log import Log
from ..rotations import rpy_to_matrix, wrap_angle
from ..trajectory import Trajectory
from .config import MappingConfig
from .threads import parallel_slot, run_parts

SENSOR_DVL, SENSOR_SONAR, SENSOR_MULTIBEAM = 0, 1, 2
DVL_MIN_RANGE, DVL_MAX_RANGE = 0.05, 50.0


@dataclass(frozen=True, eq=False)
class Samples:
    """Training samples: ``points`` (N, 3) world, ``label`` (N,) 1 hit / 0 free, ``sigma0`` (N,),
    ``pose_variance`` (N, 3) m^2, ``ray`` (N,) index into ``origins`` (R, 3) (-1 if unknown),
    ``sensor`` (N,) 0 DVL / 1 sonar / 2 multibeam / -1 unknown, ``dropped`` counts of rejected
    ranges."""

    points: np.ndarray
    label: np.ndarray
    sigma0: np.ndarray
    pose_variance: np.ndarray
    ray: np.ndarray
    sensor: np.ndarray
    origins: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    dropped: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        pts = np.ascontiguousarray(self.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise DataError(f"Samples.points: shape {pts.shape}, expected (N, 3)")
        n = pts.shape[0]
        if not np.all(np.isfinite(pts)):
            raise DataError(f"Samples.points: {int(np.sum(~np.isfinite(pts).all(1)))} non-finite")
        arrays = {
            "label": (self.label, float, (n,)),
            "sigma0": (self.sigma0, float, (n,)),
            "pose_variance": (self.pose_variance, float, (n, 3)),
            "ray": (self.ray, np.int64, (n,)),
            "sensor": (self.sensor, np.int8, (n,)),
        }
        object.__setattr__(self, "points", pts)
        for name, (value, dtype, shape) in arrays.items():
            arr = np.asarray(value, dtype=dtype)
            if arr.ndim < len(shape) and arr.shape == shape[len(shape) - arr.ndim :]:
                arr = np.broadcast_to(arr, shape)  # scalars (and one (3,) row) broadcast
            arr = np.require(arr, requirements=["C", "W"])  # one array type for the kernels
            if arr.shape != shape:
                raise DataError(f"Samples.{name}: shape {arr.shape}, expected {shape}")
            object.__setattr__(self, name, arr)
        if np.any((self.label < 0) | (self.label > 1)) or not np.all(np.isfinite(self.label)):
            raise DataError("Samples.label: labels must be in [0, 1]")
        if not np.all(np.isfinite(self.sigma0) & (self.sigma0 > 0)):
            raise DataError("Samples.sigma0: must be finite and > 0")
        if not np.all(np.isfinite(self.pose_variance) & (self.pose_variance >= 0)):
            raise DataError("Samples.pose_variance: must be finite and >= 0")
        object.__setattr__(self, "origins", np.asarray(self.origins, dtype=float).reshape(-1, 3))

    @classmethod
    def from_points(cls, points, label, sigma0=1.0, pose_variance=0.0) -> Samples:
        """Samples from plain arrays (no ray bookkeeping); scalars and a (3,) variance broadcast."""
        return cls(points, label, sigma0, pose_variance, -1, -1)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_hits(self) -> int:
        return int(np.sum(self.label > 0.5))


class Rays(NamedTuple):
    """Rays as :func:`expand` takes them (one row per ray: origin, direction, range, pose
    variance, sigma_0, sensor) and the rows of their samples: ray i's hit in row i, its free
    samples (s = k f along it, k = 0, 1, ...) in rows ``rows[i]`` .. ``rows[i + 1] - 1``."""

    origin: np.ndarray
    direction: np.ndarray
    r: np.ndarray
    var: np.ndarray
    sig: np.ndarray
    sensor: np.ndarray
    rows: np.ndarray
    f: float


class RaySamples(Samples):
    """:class:`Samples` of checked rays (finite, sigma_0 > 0, variance >= 0) kept as the rays
    (``rays``, :class:`Rays`): the per-sample arrays are written on first access, and the
    adaptive and tpu mappers scatter straight from the rays (:mod:`undertow.mapping.rayscatter`,
    :mod:`undertow.mapping.tpuscatter`; the same maps bit for bit), so a mapping call need not
    write 65 bytes per sample."""

    def __init__(self, rays: Rays, dropped: dict) -> None:  # frozen: the fields set directly
        object.__setattr__(self, "rays", rays)
        object.__setattr__(self, "origins", rays.origin)
        object.__setattr__(self, "dropped", dropped)
        object.__setattr__(self, "_written", None)

    def _column(self, index: int) -> np.ndarray:
        if self._written is None:
            object.__setattr__(self, "_written", write_samples(self.rays))
        return self._written[index]

    points = property(lambda self: self._column(0), doc="(N, 3) world points, written on use")
    label = property(lambda self: self._column(1), doc="(N,) 1 hit / 0 free, written on use")
    sigma0 = property(lambda self: self._column(2), doc="(N,) sigma_0, written on use")
    pose_variance = property(lambda self: self._column(3), doc="(N, 3) m^2, written on use")
    ray = property(lambda self: self._column(4), doc="(N,) ray index, written on use")
    sensor = property(lambda self: self._column(5), doc="(N,) sensor code, written on use")

    def __len__(self) -> int:
        return int(self.rays.rows[-1])

    @property
    def n_hits(self) -> int:
        return int(self.rays.r.size)  # one hit (label 1) per ray, every other sample free


def _interpolate_pose(trajectory: Trajectory, t: np.ndarray):
    """Position (linear), rpy (on unwrapped angles) and position variance at times t (the
    angles unwrapped along the whole trajectory: a window of a PoseTrack carries them)."""
    ang = getattr(trajectory, "unwrapped_orientation", None)
    if ang is None:
        ang = np.unwrap(trajectory.orientation, axis=0)
    return pose_at(trajectory.t, trajectory.position, ang, trajectory.position_variance, t)


def pose_at(tt, position, unwrapped_rpy, variance, t):
    """(position, rpy wrapped, position variance) at times t, interpolated linearly between the
    states (tt, position (N, 3), unwrapped rpy (N, 3), variance (N, 3)); any run of states
    that brackets every t gives the same values as the whole trajectory."""
    pos = np.stack([np.interp(t, tt, position[:, j]) for j in range(3)], axis=1)
    ang = unwrapped_rpy
    rpy = wrap_angle(np.stack([np.interp(t, tt, ang[:, j]) for j in range(3)], axis=1))
    var = np.stack([np.interp(t, tt, variance[:, j]) for j in range(3)], axis=1)
    return pos, rpy, var


def _rays(t, r, unit, ok, mount, trajectory, sigma0, sensor):
    """World origins, directions and ranges of the kept rays (flattened), with their metadata."""
    t, r, unit = t[ok], r[ok], unit[ok]
    return rays_from_pose(r, unit, mount, *_interpolate_pose(trajectory, t), sigma0, sensor)


def rays_from_pose(r, unit, mount, pos, rpy, var, sigma0, sensor):
    """(origin o = p + R t_s, direction v = R R_s u, r, pose variance, sigma0, sensor) of rays
    with ranges r along units u (sensor frame) from body poses (pos, rpy, var)."""
    R = rpy_to_matrix(rpy)
    origin = pos + R @ np.asarray(mount.translation, float)
    direction = np.einsum("nij,nj->ni", R @ mount.rotation_matrix(), unit)
    n = r.size
    return origin, direction, r, var, np.full(n, sigma0), np.full(n, sensor, np.int8)


def check_range(kind, t, r, flag, lo, hi, span, dropped) -> np.ndarray:
    """flag & in [lo, hi] & t inside span; the rest counted in ``dropped`` by reason."""
    finite = np.isfinite(r)
    in_range = finite & (r >= lo) & (r <= hi)
    in_time = (t >= span[0]) & (t <= span[1])
    dropped[f"{kind}_invalid"] = int(np.sum(~flag))
    dropped[f"{kind}_nonfinite"] = int(np.sum(flag & ~finite))
    dropped[f"{kind}_out_of_range"] = int(np.sum(flag & finite & ~in_range))
    dropped[f"{kind}_outside_trajectory"] = int(np.sum(flag & in_range & ~in_time))
    return flag & in_range & in_time


def build_samples(log: Log, trajectory: Trajectory, **settings) -> Samples:
    """Hits and free samples from the log's DVL beam ranges and sonar ranges (see module doc).

    ``settings`` are :class:`~undertow.mapping.config.MappingConfig` fields (``free_resolution``,
    ``sigma0_dvl``, ``sigma0_sonar``, ``sigma0_multibeam``, ``use_dvl``, ``use_sonar``,
    ``use_multibeam``); the ones not given take its
    defaults, and all are checked there."""
    return samples_from_config(log, trajectory, MappingConfig.from_dict(settings))


def samples_from_config(log: Log, trajectory: Trajectory, config: MappingConfig) -> Samples:
    """:func:`build_samples` with the config's (checked) values."""
    f = config.free_resolution
    use = {"dvl": config.use_dvl, "sonar": config.use_sonar, "multibeam": config.use_multibeam}
    wanted = [n for n, on in use.items() if on]
    if not any(getattr(log, n) is not None and len(getattr(log, n)) for n in wanted):
        raise MissingStreamError(f"mapping needs a range stream ({' or '.join(wanted)} "
                                 "enabled) but the log has none of them")  # fmt: skip
    if len(trajectory) == 0:
        raise DataError("mapping needs a non-empty trajectory")
    span = (float(trajectory.t[0]), float(trajectory.t[-1]))
    dropped: dict[str, int] = {}
    parts = []
    if use["dvl"] and log.dvl is not None and len(log.dvl):
        d = log.dvl
        t = np.repeat(d.t, d.beam_range.shape[1])
        r = d.beam_range.reshape(-1)
        unit = d.beam_unit.reshape(-1, 3)
        flag = d.beam_valid.reshape(-1) & np.all(np.isfinite(unit), axis=1)
        ok = check_range("dvl", t, r, flag, DVL_MIN_RANGE, DVL_MAX_RANGE, span, dropped)
        parts.append(_rays(t, r, unit, ok, log.mounting.dvl, trajectory, config.sigma0_dvl,
                           SENSOR_DVL))  # fmt: skip
    if use["sonar"] and log.sonar is not None and len(log.sonar):
        s = log.sonar
        flag = np.ones(len(s), bool)
        ok = check_range("sonar", s.t, s.range, flag, s.min_range, s.max_range, span, dropped)
        unit = np.tile([0.0, 0.0, 1.0], (len(s), 1))
        parts.append(_rays(s.t, s.range, unit, ok, log.mounting.sonar, trajectory,
                           config.sigma0_sonar, SENSOR_SONAR))  # fmt: skip
    if use["multibeam"] and log.multibeam is not None and len(log.multibeam):
        parts.append(_multibeam_rays(log, trajectory, config, span, dropped))
    named = [n for n in wanted if n != "multibeam" or log.multibeam is not None]
    _check_time_overlap(log, span, dropped, sum(p[2].size for p in parts), named)
    origin, direction, r, var, sig, sensor = (np.concatenate(c) for c in zip(*parts, strict=True))
    return expand(origin, direction, r, var, sig, sensor, f, dropped)


def _multibeam_rays(log: Log, trajectory: Trajectory, config: MappingConfig, span, dropped):
    """Rays of every multibeam detection p: r = |p|, u = p / r (multibeam frame); beams without
    a detection count as ``multibeam_invalid``."""
    m = log.multibeam
    t = np.repeat(m.t, m.beams)
    r = m.range.reshape(-1)
    unit = m.beam_unit.reshape(-1, 3)
    flag = np.all(np.isfinite(unit), axis=1)
    ok = check_range("multibeam", t, r, flag, m.min_range, m.max_range, span, dropped)
    return _rays(t, r, unit, ok, log.mounting.multibeam, trajectory, config.sigma0_multibeam,
                 SENSOR_MULTIBEAM)  # fmt: skip


def _check_time_overlap(log: Log, span, dropped: dict, kept: int, streams: list[str]) -> None:
    """No usable range inside the trajectory's time span is an error naming both spans (a
    trajectory of another log, or times in another clock); more than half outside it, a
    warning (the map covers only part of the log)."""
    outside = sum(v for k, v in dropped.items() if k.endswith("_outside_trajectory"))
    if outside == 0:
        return
    times = [getattr(log, n).t for n in streams if getattr(log, n) is not None]
    times = [t for t in times if len(t)]
    first, last = min(float(t[0]) for t in times), max(float(t[-1]) for t in times)
    spans = (
        f"trajectory {span[0]:.3f} .. {span[1]:.3f} s, ranges ({', '.join(streams)}) "
        f"{first:.3f} .. {last:.3f} s"
    )
    if kept == 0:
        raise DataError(
            f"no range measurement falls inside the trajectory's time span ({spans}): is the "
            "trajectory from this log?"
        )
    if outside > 0.5 * (outside + kept):
        warnings.warn(
            f"{outside} of {outside + kept} valid ranges lie outside the trajectory's time span "
            f"and were dropped ({spans})",
            stacklevel=3,
        )


def _ray_splits(first: np.ndarray, parts: int) -> np.ndarray:
    """``parts`` + 1 ray boundaries (0 .. R) giving each part about as many samples: ray i has
    its hit and first[i + 1] - first[i] free samples."""
    done = np.arange(len(first)) + first - first[0]  # samples of the rays before ray i
    splits = np.searchsorted(done, np.linspace(0, done[-1], parts + 1))
    splits[0], splits[-1] = 0, len(first) - 1
    return splits.astype(np.int64)


def expand(origin, direction, r, var, sig, sensor, f, dropped) -> Samples:
    """One hit per ray plus free samples at s = k f, k = 0 .. while s <= r - f: rays that pass
    the checks :class:`Samples` makes of its samples give :class:`RaySamples` (the samples
    written only when read), the others the written samples, checked (the one-line error
    names the bad field)."""
    origin, direction, r, var, sig = (np.ascontiguousarray(a, float)
                                      for a in (origin, direction, r, var, sig))  # fmt: skip
    rows, rays_ok = _layout(origin, direction, r, var, sig, float(f))
    rays = Rays(origin, direction, r, var, sig, np.ascontiguousarray(sensor, np.int8), rows,
                float(f))  # fmt: skip
    if rays_ok:  # every sample is finite, labelled 0 or 1, with its ray's sigma_0 and variance
        return RaySamples(rays, dropped)
    return Samples(*write_samples(rays), origin, dropped)


def write_samples(rays: Rays) -> tuple:
    """(points, label, sigma0, pose_variance, ray, sensor) of the rays' samples (numba kernel
    :func:`_expand_part`: hits first, then free samples ray by ray, on several threads for
    large batches, :func:`~undertow.mapping.threads.run_parts`)."""
    total = int(rays.rows[-1])
    arrays = (np.empty((total, 3)), np.empty(total), np.empty(total), np.empty((total, 3)),
              np.empty(total, np.int64), np.empty(total, np.int8))  # fmt: skip
    args = (rays.origin, rays.direction, rays.r, rays.var, rays.sig, rays.sensor, rays.rows,
            rays.f)  # fmt: skip
    with parallel_slot(total) as parts:  # hits first, then free samples ray by ray
        if parts > 1:  # a range of rays per part, each writing only its rays' rows
            splits = _ray_splits(rays.rows, parts)
            run_parts(lambda t: _expand_part(splits[t], splits[t + 1], *args, *arrays), parts)
        else:
            _expand_part(0, len(rays.r), *args, *arrays)
    return arrays


@njit(cache=True)
def _layout(origin, direction, r, var, sig, f):
    """(rows (R + 1,): ray i's free samples in rows rows[i] .. rows[i + 1] - 1 after the R
    hits, whether every ray passes the checks :class:`Samples` makes): ray i has
    floor((r - f) / f + 1e-9) + 1 free samples when r >= f (none for a non-finite r)."""
    n = r.shape[0]
    rows = np.empty(n + 1, np.int64)
    rows[0] = n
    ok = True
    for i in range(n):
        free = 0
        if r[i] >= f and r[i] < np.inf:
            free = np.int64(np.floor((r[i] - f) / f + 1e-9)) + 1
        rows[i + 1] = rows[i] + free
        ok = ok and np.isfinite(r[i]) and sig[i] > 0 and sig[i] < np.inf
        for j in range(3):
            ok = ok and np.isfinite(origin[i, j]) and np.isfinite(direction[i, j])
            ok = ok and var[i, j] >= 0 and var[i, j] < np.inf
    return rows, ok


@njit(cache=True, nogil=True)
def _expand_part(i0, i1, origin, direction, r, var, sig, sensor, first, f, points, label, sigma0,
                 pose_variance, ray, sensor_out):  # fmt: skip
    """Training samples of rays i0 .. i1 - 1 (see ``samples.py``): ray i's hit at o + r v (label
    1) in row i, its free samples at o + k f v, k = 0 .. (label 0), in rows first[i] ..
    first[i + 1] - 1; every sample carries its ray's variance, sigma_0, index and sensor. Each
    ray writes only its own rows, so parts run on separate threads."""
    for i in range(i0, i1):
        for j in range(3):
            points[i, j] = origin[i, j] + r[i] * direction[i, j]
            pose_variance[i, j] = var[i, j]
        label[i] = 1.0
        sigma0[i] = sig[i]
        ray[i] = i
        sensor_out[i] = sensor[i]
        for k in range(first[i], first[i + 1]):
            s = (k - first[i]) * f
            for j in range(3):
                points[k, j] = origin[i, j] + s * direction[i, j]
                pose_variance[k, j] = var[i, j]
            label[k] = 0.0
            sigma0[k] = sig[i]
            ray[k] = i
            sensor_out[k] = sensor[i]
