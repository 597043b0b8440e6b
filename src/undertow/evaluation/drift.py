"""Drift of a trajectory against a reference without ground truth, as the field reports it.

The reference comes from the log itself (:func:`reference_track`): its GPS fixes (``gps``), the
DVL's own dead reckoning (``dvl-dr``) or the autopilot's EKF (``autopilot``). None of them is a
truth; each is what a team compares its navigation with at sea.

- **Distance travelled** s(t): along the estimated trajectory's horizontal path, from the
  alignment time: s(t) = sum_k |(x, y)_{k+1} - (x, y)_k| over the estimate's samples up to t
  (linear in between).
- **Alignment.** The reference lives in its own frame (the DVL's reset frame, local NED about
  the first fix, the autopilot's origin). ``start`` (default) translates it so that it agrees
  with the estimate at the first common time t_a: p'_ref(t) = p_ref(t) - p_ref(t_a) +
  p_est(t_a). ``yaw`` also rotates it about that point by the least-squares yaw over the first
  segment (the reference samples within ``align_distance_m`` of path, default 10 % of the
  distance travelled; at least the first sample after t_a): with a_i = p_ref(t_i) - p_ref(t_a)
  and b_i = p_est(t_i) - p_est(t_a) (horizontal), theta = atan2(sum_i a_i x b_i, sum_i a_i . b_i)
  maximizes sum_i b_i . R(theta) a_i (the rotation-only case of Umeyama, "Least-squares
  estimation of transformation parameters between two point patterns", IEEE TPAMI 1991).
  ``none`` compares the positions as they are. Whatever was done is stated in the result
  (:meth:`DriftResult.alignment_text`).
- **Checkpoints.** GPS: one per surfacing, its first fix (a surfacing: fixes no more than
  ``SURFACING_GAP_S`` apart); the first surfacing's first fix is the alignment. GPS fixed all
  along (one surfacing: a surface run), the DVL's dead reckoning and the autopilot are
  continuous references: ``checkpoints`` (default 10) points evenly spaced in distance travelled,
  s_i = i D / N (D the distance over the common span), at the time the estimate reaches s_i,
  the reference interpolated linearly in time there. A run that travels less than
  ``MIN_DISTANCE_M`` has no drift in % of distance (one warning): its continuous checkpoints are
  evenly spaced in time.
- **Drift** at a checkpoint: e = p_est - p'_ref, horizontal; drift_m = |e|,
  drift_percent = 100 drift_m / s. Along-track and cross-track: e on the direction of travel u
  (the direction of the last ``TANGENT_M`` of path before the checkpoint) and on its right,
  u_r = (-u_y, u_x) (x north, y east): positive along is ahead of the reference, positive cross
  to its right (starboard). vertical_m = e_z (not for GPS: its altitude is not the depth).
- **Growth**: the least-squares slope of drift against distance through the origin (the
  alignment makes both zero there), 100 sum_i s_i d_i / sum_i s_i^2, in % of distance; the same
  for the signed along- and cross-track components.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import ConfigError, DataError, MissingStreamError
from ..log import Log
from ..trajectory import Trajectory

#: --reference NAME -> (the Log stream, what it is)
REFERENCES = {
    "gps": ("gps", "GPS fixes"),
    "dvl-dr": ("dead_reckoning", "the DVL's dead reckoning"),
    "autopilot": ("autopilot", "the autopilot's EKF estimate"),
}
ALIGNMENTS = ("start", "yaw", "none")
SURFACING_GAP_S = 10.0  # GPS fixes further apart than this start a new surfacing
TANGENT_M = 1.0  # the direction of travel: over the last metre of path before a checkpoint
MIN_DISTANCE_M = 1.0  # less travelled: no drift in % of distance
ALIGN_FRACTION = 0.1  # the yaw alignment's segment, default: 10 % of the distance travelled
CHECKPOINTS = 10


@dataclass(frozen=True)
class ReferenceTrack:
    """A reference's positions (m, x y z with z down, in its own frame) at times ``t`` (s),
    and whether they are sparse fixes (GPS) or a continuous track."""

    name: str
    t: np.ndarray
    position: np.ndarray
    fixes: bool = False
    source: str = ""


@dataclass(frozen=True)
class DriftCheckpoint:
    """The drift at one checkpoint (module doc); None where undefined (no distance yet, no
    direction of travel, no vertical for GPS)."""

    t_s: float
    distance_m: float
    drift_m: float
    drift_percent: float | None
    along_track_m: float | None
    cross_track_m: float | None
    vertical_m: float | None


@dataclass(frozen=True)
class Alignment:
    """What was done to bring the reference into the estimate's frame: the alignment time, the
    translation added to the reference (after the rotation) and the yaw it was turned by about
    the alignment point (0 unless ``align="yaw"``), over ``segment_m`` of path and
    ``segment_samples`` reference samples."""

    method: str
    t_s: float | None
    translation_m: tuple[float, float, float]
    yaw_rad: float = 0.0
    segment_m: float | None = None
    segment_samples: int = 0


@dataclass(frozen=True)
class DriftResult:
    """Drift of a trajectory against a reference (module doc), units in the names;
    ``start_t_s`` is the first common time (the distances count from there)."""

    reference: str
    source: str
    alignment: Alignment
    start_t_s: float
    checkpoint_rule: str
    checkpoints: tuple[DriftCheckpoint, ...]
    distance_m: float
    final_drift_m: float
    final_drift_percent: float | None
    max_drift_m: float
    growth_percent: float | None
    along_growth_percent: float | None
    cross_growth_percent: float | None
    reference_samples: int

    def to_dict(self) -> dict:
        out = asdict(self)
        out["alignment_text"] = self.alignment_text()
        return out

    def alignment_text(self) -> str:
        """The alignment in words."""
        a = self.alignment
        if a.method == "none":
            return "none: the reference's positions as they are (its own frame)"
        dx, dy, dz = a.translation_m
        text = (
            f"the reference translated by ({dx:.2f}, {dy:.2f}, {dz:.2f}) m to agree with the "
            f"trajectory at t = {a.t_s:.3f} s (the first common time)"
        )
        if a.method == "yaw":
            text += (
                f", rotated by {math.degrees(a.yaw_rad):+.2f} deg about that point (the "
                f"least-squares yaw over the first {a.segment_m:.1f} m travelled, "
                f"{a.segment_samples} reference samples)"
            )
        return text


def reference_track(log: Log, name: str) -> ReferenceTrack:
    """The reference ``name`` (a key of :data:`REFERENCES`) from ``log``; a log without it is
    one :class:`~undertow.errors.MissingStreamError` line naming the log and its streams."""
    if name not in REFERENCES:
        raise ConfigError(f"--reference must be one of {', '.join(REFERENCES)}, not {name!r}")
    stream, what = REFERENCES[name]
    data = getattr(log, stream, None)
    where = log.source or "the log"
    if data is None or len(data) == 0:
        raise MissingStreamError(
            f"{where} has no {stream} stream ({what}) for --reference {name}; it has: "
            f"{', '.join(log.streams()) or 'no streams'}"
        )
    return ReferenceTrack(name, data.t, data.position, fixes=name == "gps", source=where)


def trajectory_drift(
    estimate: Trajectory,
    reference: ReferenceTrack,
    align: str = "start",
    checkpoints: int = CHECKPOINTS,
    align_distance_m: float | None = None,
) -> DriftResult:
    """The drift of ``estimate`` against ``reference`` at its checkpoints, split into along- and
    cross-track, and its growth with distance (module doc)."""
    if align not in ALIGNMENTS:
        raise ConfigError(f"align must be one of {', '.join(ALIGNMENTS)}, not {align!r}")
    if checkpoints < 1:
        raise ConfigError(f"checkpoints must be at least 1, not {checkpoints}")
    t_est, p_est = _finite_estimate(estimate)
    t_ref, p_ref = _finite_reference(reference)
    inside = (t_ref >= t_est[0]) & (t_ref <= t_est[-1])
    if inside.sum() < 2:
        raise DataError(
            f"{reference.source}: {int(inside.sum())} {reference.name} sample(s) in the "
            f"trajectory's span [{t_est[0]:.3f}, {t_est[-1]:.3f}] s (the reference spans "
            f"[{t_ref[0]:.3f}, {t_ref[-1]:.3f}] s); need 2 (is it the log of this run, on the "
            "same clock?)"
        )
    t_ref, p_ref = t_ref[inside], p_ref[inside]
    path = _path_length(p_est)
    s_ref = np.interp(t_ref, t_est, path)
    t_a, s_a = float(t_ref[0]), float(s_ref[0])
    total = float(s_ref[-1] - s_a)
    p_est_ref = _interp_rows(t_ref, t_est, p_est)
    alignment, p_ref = _align(align, t_a, p_est_ref, p_ref, s_ref - s_a, total, align_distance_m)
    surfacings = _surfacing_starts(t_ref) if reference.fixes else None
    if surfacings is not None and surfacings.size > 1:
        t_cp = t_ref[surfacings[1:]]
        ref_cp = p_ref[surfacings[1:]]
        rule = (
            f"each surfacing's first GPS fix (fixes more than {SURFACING_GAP_S:g} s apart "
            "start a new surfacing; the first one is the alignment)"
        )
    else:
        t_cp, rule = _continuous_checkpoints(t_est, path, t_a, s_a, total, t_ref[-1], checkpoints)
        ref_cp = _interp_rows(t_cp, t_ref, p_ref)
    rows = _checkpoint_rows(t_cp, t_est, p_est, path, s_a, ref_cp, reference.fixes,
                            total >= MIN_DISTANCE_M)  # fmt: skip
    return _result(reference, alignment, t_a, rule, rows, total, int(t_ref.size))


def _finite_estimate(estimate: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    if len(estimate) == 0:
        raise DataError("trajectory has no samples (nothing to evaluate)")
    t, p = estimate.t, estimate.position
    ok = np.isfinite(t) & np.all(np.isfinite(p), axis=1)
    if ok.sum() < 2:
        raise DataError("trajectory: fewer than 2 samples with a finite time and position")
    if not ok.all():
        warnings.warn(
            f"trajectory: dropped {int((~ok).sum())} samples with a non-finite time or position",
            RuntimeWarning,
            stacklevel=3,
        )
    return t[ok], p[ok]


def _finite_reference(reference: ReferenceTrack) -> tuple[np.ndarray, np.ndarray]:
    """The reference's finite samples in time order, the first at each repeated time (the rest
    dropped with one warning)."""
    t = np.asarray(reference.t, float)
    p = np.asarray(reference.position, float)
    ok = np.isfinite(t) & np.all(np.isfinite(p), axis=1)
    order = np.argsort(t[ok], kind="stable")
    t, p = t[ok][order], p[ok][order]
    repeated = np.r_[False, np.diff(t) == 0]
    dropped = int((~ok).sum() + repeated.sum())
    if dropped:
        warnings.warn(
            f"{reference.source}: {reference.name}: dropped {dropped} of {ok.size} samples "
            "(non-finite, or a repeated time)",
            RuntimeWarning,
            stacklevel=3,
        )
    return t[~repeated], p[~repeated]


def _path_length(p: np.ndarray) -> np.ndarray:
    """s_k: the horizontal path length from the first sample to sample k."""
    step = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
    return np.concatenate([[0.0], np.cumsum(step)])


def _interp_rows(t: np.ndarray, tp: np.ndarray, rows: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, tp, rows[:, i]) for i in range(rows.shape[1])], axis=1)


def _align(method, t_a, p_est_ref, p_ref, s_rel, total, align_distance_m):
    """(Alignment, the reference's positions in the estimate's frame): ``p_est_ref`` the
    estimate at the reference's times, ``s_rel`` the distance travelled at them (module doc)."""
    if method == "none":
        return Alignment("none", None, (0.0, 0.0, 0.0)), p_ref
    origin, p_at = p_ref[0], p_est_ref[0]
    yaw, segment_m, used = 0.0, None, 0
    if method == "yaw":
        segment_m = ALIGN_FRACTION * total if align_distance_m is None else align_distance_m
        pick = (s_rel > 0) & (s_rel <= segment_m)
        pick[1] = True  # at least the first sample after t_a
        a = p_ref[pick, :2] - origin[:2]
        b = p_est_ref[pick, :2] - p_at[:2]
        yaw = least_squares_yaw(a, b)
        used = int(pick.sum())
    aligned = _rotate(p_ref - origin, yaw) + p_at
    shift = p_at - _rotate(origin[None], yaw)[0]
    translation = (float(shift[0]), float(shift[1]), float(shift[2]))
    return Alignment(method, t_a, translation, yaw, segment_m, used), aligned


def least_squares_yaw(a: np.ndarray, b: np.ndarray) -> float:
    """theta maximizing sum_i b_i . R(theta) a_i for 2-D vectors a, b (N, 2):
    theta = atan2(sum_i a_i x b_i, sum_i a_i . b_i) (0 when the sums vanish)."""
    cross = float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))
    dot = float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]))
    return math.atan2(cross, dot) if (cross or dot) else 0.0


def _rotate(p: np.ndarray, yaw: float) -> np.ndarray:
    """Rows of p (N, 3) turned by ``yaw`` about z: (x, y) -> (c x - s y, s x + c y)."""
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.array(p, float)
    out[:, 0] = c * p[:, 0] - s * p[:, 1]
    out[:, 1] = s * p[:, 0] + c * p[:, 1]
    return out


def _surfacing_starts(t: np.ndarray) -> np.ndarray:
    """Indices of the first fix of each surfacing (a gap over SURFACING_GAP_S starts one)."""
    return np.flatnonzero(np.r_[True, np.diff(t) > SURFACING_GAP_S])


def _continuous_checkpoints(t_est, path, t_a, s_a, total, t_end, n):
    """(times, rule): n checkpoints evenly spaced in distance travelled over (t_a, t_end], each
    at the first time the estimate's path reaches it; evenly spaced in time when the run
    travels less than MIN_DISTANCE_M (one warning)."""
    if total < MIN_DISTANCE_M:
        warnings.warn(
            f"the trajectory travels {total:.2f} m over the comparison (less than "
            f"{MIN_DISTANCE_M:g} m): no drift in % of distance; the drift is given at {n} "
            "times evenly spaced",
            RuntimeWarning,
            stacklevel=3,
        )
        times = t_a + (t_end - t_a) * np.arange(1, n + 1) / n
        return times, f"{n} times evenly spaced (the run travels too little for distances)"
    targets = s_a + total * np.arange(1, n + 1) / n
    k = np.clip(np.searchsorted(path, targets, side="left"), 1, path.size - 1)
    s0, s1 = path[k - 1], path[k]
    frac = np.where(s1 > s0, (targets - s0) / np.where(s1 > s0, s1 - s0, 1.0), 1.0)
    times = np.minimum(t_est[k - 1] + frac * (t_est[k] - t_est[k - 1]), t_end)
    rule = (
        f"{n} points evenly spaced in distance travelled (every {total / n:.3g} m), the "
        "reference interpolated in time"
    )
    return times, rule


def _checkpoint_rows(t_cp, t_est, p_est, path, s_a, ref_cp, fixes: bool, percent: bool):
    """DriftCheckpoint per checkpoint time (module doc); ``percent``: the run travels enough
    for drift in % of distance."""
    p_cp = _interp_rows(t_cp, t_est, p_est)
    s_cp = np.interp(t_cp, t_est, path)
    behind = np.maximum(s_cp - TANGENT_M, s_a)
    k = np.clip(np.searchsorted(path, behind, side="left"), 1, path.size - 1)
    frac = np.clip((behind - path[k - 1]) / np.maximum(path[k] - path[k - 1], 1e-300), 0, 1)
    p_behind = p_est[k - 1, :2] + frac[:, None] * (p_est[k, :2] - p_est[k - 1, :2])
    rows = []
    for i, t in enumerate(t_cp):
        e = p_cp[i] - ref_cp[i]
        drift = float(math.hypot(e[0], e[1]))
        distance = float(s_cp[i] - s_a)
        u = p_cp[i, :2] - p_behind[i]
        norm = float(math.hypot(u[0], u[1]))
        along = cross = None
        if norm > 1e-9:
            u = u / norm
            along = float(e[0] * u[0] + e[1] * u[1])
            cross = float(-e[0] * u[1] + e[1] * u[0])
        rows.append(
            DriftCheckpoint(
                t_s=float(t),
                distance_m=distance,
                drift_m=drift,
                drift_percent=100.0 * drift / distance if percent and distance > 0 else None,
                along_track_m=along,
                cross_track_m=cross,
                vertical_m=None if fixes else float(e[2]),
            )
        )
    return tuple(rows)


def _slope_percent(s: np.ndarray, d: list) -> float | None:
    """100 sum s d / sum s^2 over the checkpoints where d is defined (None if none travel)."""
    ok = np.array([v is not None for v in d]) & (s > 0)
    if not ok.any():
        return None
    dv = np.array([v for v, k in zip(d, ok, strict=True) if k], float)
    return float(100.0 * np.sum(s[ok] * dv) / np.sum(s[ok] ** 2))


def _result(reference, alignment, start, rule, rows, total, samples) -> DriftResult:
    s = np.array([r.distance_m for r in rows])
    if total < MIN_DISTANCE_M:
        s = np.zeros_like(s)  # no growth per distance for a run that does not travel
    last = rows[-1]
    return DriftResult(
        reference=reference.name,
        source=reference.source,
        alignment=alignment,
        start_t_s=start,
        checkpoint_rule=rule,
        checkpoints=rows,
        distance_m=total,
        final_drift_m=last.drift_m,
        final_drift_percent=last.drift_percent if total >= MIN_DISTANCE_M else None,
        max_drift_m=max(r.drift_m for r in rows),
        growth_percent=_slope_percent(s, [r.drift_m for r in rows]),
        along_growth_percent=_slope_percent(s, [r.along_track_m for r in rows]),
        cross_growth_percent=_slope_percent(s, [r.cross_track_m for r in rows]),
        reference_samples=samples,
    )
