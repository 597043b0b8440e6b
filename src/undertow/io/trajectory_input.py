"""A trajectory made elsewhere (a TUM file from evo, another estimator, a ground truth) as the
:class:`~undertow.trajectory.Trajectory` the mapper reads: its covariance as the user states it,
its frame checked against the log's depth. The settings' ``trajectory`` section::

    trajectory:
      position_std_m: [0.05, 0.05, 0.02]     # sx, sy, sz: a TUM file without std columns
      orientation_std_rad: [0.01, 0.01, 0.03]  # sroll, spitch, syaw (optional)
      frame: auto                            # auto | ned | enu

Frames: ``ned`` is undertow's (x north, y east, z down: the depth; body forward-right-down),
``enu`` ROS's REP-103 (x east, y north, z up; body forward-left-up), what many estimators write.

The mapper reads a trajectory's position, orientation and position covariance
(:mod:`undertow.mapping.samples`); a TUM file has no velocities or biases, so those states are
NaN (unknown), as are their covariances. The standard deviations are in the file's own axes
and go through the frame change with the positions.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field

from .._util.validate import validate
from ..errors import ConfigError, DataError
from ..log import Log
from ..rotations import matrix_to_rpy, rpy_to_matrix
from ..trajectory import ORIENTATION, POSITION, STATE_NAMES, Trajectory
from .tum import STD_COLUMNS, TumPoses, read_tum_poses
from .units import depth_reference

NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]


def _three(value):
    if isinstance(value, list | tuple) and len(value) != 3:
        raise ValueError(f"expected three values, got {len(value)}")
    return value


Std3 = Annotated[tuple[NonNegative, NonNegative, NonNegative], BeforeValidator(_three)]

#: world ENU -> NED (p_ned = C p_enu) and body FRD -> FLU (v_flu = B v_frd); both their own inverse
C_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
B_FRD_FLU = np.diag([1.0, -1.0, -1.0])


class TrajectoryOptions(BaseModel):
    """How a trajectory made elsewhere is read (the module doc): its pose standard deviations
    for a file without them (m, rad) and its frame (``auto``: detected against the log)."""

    model_config = ConfigDict(extra="forbid")

    position_std_m: Std3 | None = None
    orientation_std_rad: Std3 | None = None
    frame: Literal["auto", "ned", "enu"] = "auto"

    @classmethod
    def from_dict(cls, data: dict) -> TrajectoryOptions:
        return validate(cls, data, "trajectory.")

    @classmethod
    def stated(cls, pose_std=None, frame: str | None = None) -> TrajectoryOptions | None:
        """The options stated for one command (``undertow map --pose-std SX,SY,SZ[,SROLL,SPITCH,
        SYAW] --trajectory-frame F``): 3 or 6 standard deviations (m, rad), a frame; None
        when neither is given."""
        if pose_std is None and frame is None:
            return None
        data: dict = {"frame": "auto" if frame is None else frame}
        if pose_std is not None:
            values = list(np.atleast_1d(np.asarray(pose_std, dtype=object)))
            if len(values) not in (3, 6):
                raise ConfigError(
                    f"pose_std: expected 3 or 6 values (SX,SY,SZ[,SROLL,SPITCH,SYAW], m and rad), "
                    f"got {len(values)}"
                )
            data["position_std_m"] = values[:3]
            data["orientation_std_rad"] = values[3:] or None
        return validate(cls, data, "")


def enu_to_ned(position, orientation) -> tuple[np.ndarray, np.ndarray]:
    """Poses in ENU (body FLU) as NED (body FRD): p_ned = C p_enu, R_ned = C R_enu B with
    C = [[0, 1, 0], [1, 0, 0], [0, 0, -1]] and B = diag(1, -1, -1) (R: body to world,
    roll-pitch-yaw as :func:`~undertow.rotations.rpy_to_matrix`); the same map takes NED back
    to ENU."""
    position = np.asarray(position, float) @ C_ENU_NED.T
    R = C_ENU_NED @ rpy_to_matrix(orientation) @ B_FRD_FLU
    return position, matrix_to_rpy(R)


def trajectory_from_poses(t, position, orientation, position_std, orientation_std=None,
                          variant="", metadata=None) -> Trajectory:  # fmt: skip
    """A :class:`~undertow.trajectory.Trajectory` of poses with independent standard deviations
    (N, 3) or (3,) each: x[0:3] = p, x[3:6] = (roll, pitch, yaw), P[0:3, 0:3] = diag(sx^2,
    sy^2, sz^2), P[3:6, 3:6] = diag(sroll^2, spitch^2, syaw^2) and zero between position and
    orientation (NaN, unknown, when ``orientation_std`` is None); the other states (velocities,
    biases) and their covariances NaN: unknown."""
    t = np.asarray(t, float).reshape(-1)
    n = t.size
    x = np.full((n, len(STATE_NAMES)), np.nan)
    x[:, POSITION], x[:, ORIENTATION] = position, orientation
    std = np.full((n, 6), np.nan)
    std[:, :3] = np.broadcast_to(np.asarray(position_std, float), (n, 3))
    if orientation_std is not None:
        std[:, 3:] = np.broadcast_to(np.asarray(orientation_std, float), (n, 3))
    known = 3 if orientation_std is None else 6  # an unknown orientation: its block NaN
    if not np.all(np.isfinite(std[:, :known]) & (std[:, :known] >= 0)):
        raise DataError("trajectory_from_poses: standard deviations must be finite and >= 0")
    var = np.square(std)
    P = np.full((n, len(STATE_NAMES), len(STATE_NAMES)), np.nan)
    P[:, :known, :known] = 0.0
    P[:, np.arange(known), np.arange(known)] = var[:, :known]
    return Trajectory(t, x, P, variant=variant, metadata=metadata or {})


def is_tum_file(path: str | Path) -> bool:
    """True for a regular file that is a TUM trajectory: named ``.tum`` or ``.txt``, or text
    whose first data line has 8 or 14 numbers (a zip archive, an .npz, never is)."""
    path = Path(path)
    if not path.is_file():
        return False
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    if head.startswith(b"PK"):
        return False
    if path.suffix.lower() in (".tum", ".txt"):
        return True
    try:
        lines = head.decode("utf-8").splitlines()
    except UnicodeDecodeError:
        return False
    for line in lines[:-1] if len(head) == 4096 else lines:  # a whole line only
        text = line.strip()
        if text and not text.startswith("#"):
            fields = text.replace(",", " ").split()
            return len(fields) in (8, 14) and all(_number(f) for f in fields)
    return False


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


@dataclass(frozen=True, eq=False)
class TumInput:
    """A TUM file read before the log (:func:`read_tum_input`): its poses, the standard
    deviations that apply (file axes: position (N, 3) or (3,), orientation or None) and where
    they came from."""

    path: Path
    poses: TumPoses
    position_std: np.ndarray
    orientation_std: np.ndarray | None
    covariance: str
    frame: str

    @property
    def constant(self) -> bool:
        """The standard deviations are one constant (stated), not per pose."""
        return np.ndim(self.position_std) == 1


def read_tum_input(path: str | Path, settings: TrajectoryOptions | None = None,
                   stated: TrajectoryOptions | None = None) -> TumInput:  # fmt: skip
    """The poses of a TUM file and the standard deviations that apply: the ``stated`` ones (the
    command line's, which win), else the file's std columns, else the ``settings``' (the
    settings file's ``trajectory`` section); none of them is one line naming the options to
    add. The frame: ``stated``'s unless auto, else the settings'."""
    path = Path(path)
    settings = settings or TrajectoryOptions()
    stated = stated or TrajectoryOptions()
    poses = _finite_poses(path, read_tum_poses(path))
    if stated.position_std_m is not None:
        std = _stated(stated, "--pose-std")
        if poses.std is not None:
            std = (*std[:2], std[2] + ", replacing the file's std columns")
    elif poses.std is not None:
        std = (poses.std[:, :3], poses.std[:, 3:], f"the file's columns {' '.join(STD_COLUMNS)}")
    elif settings.position_std_m is not None:
        std = _stated(settings, "settings trajectory.position_std_m")
    else:
        raise DataError(
            f"{path}: a TUM file without std columns needs the pose's uncertainty: add "
            "--pose-std SX,SY,SZ[,SROLL,SPITCH,SYAW] (m, rad) or the settings' trajectory: "
            "{position_std_m: [SX, SY, SZ]}"
        )
    frame = stated.frame if stated.frame != "auto" else settings.frame
    return TumInput(path, poses, *std, frame)


def _finite_poses(path: Path, poses: TumPoses) -> TumPoses:
    """The poses whose position and orientation are finite (the rest dropped with a warning;
    none left is one line): a NaN pose would spread to every range interpolated next to it."""
    good = np.isfinite(poses.position).all(axis=1) & np.isfinite(poses.orientation).all(axis=1)
    if good.all():
        return poses
    if not good.any():
        raise DataError(f"{path}: no pose with a finite position and quaternion")
    warnings.warn(f"{path}: {int(np.sum(~good))} poses with a non-finite position or quaternion "
                  "dropped", stacklevel=3)  # fmt: skip
    std = None if poses.std is None else poses.std[good]
    return TumPoses(poses.t[good], poses.position[good], poses.orientation[good], std)


def _stated(options: TrajectoryOptions, where: str):
    """(position std (3,), orientation std (3,) or None, how it is described)."""
    pos = np.asarray(options.position_std_m, float)
    ori = options.orientation_std_rad
    ori = None if ori is None else np.asarray(ori, float)
    values = ",".join(f"{v:g}" for v in (*pos, *(() if ori is None else ori)))
    return pos, ori, f"{where} {values} (constant)"


def tum_trajectory(tum: TumInput, log: Log) -> tuple[Trajectory, dict]:
    """The :class:`~undertow.trajectory.Trajectory` of a TUM file for mapping ``log``, and what
    ``config.yaml`` records of it (file, format, frame, covariance). The frame: the stated one
    (a warning when the log's depth says the other), else detected from the log's depth
    (:func:`detect_frame`), else NED with a warning; an ENU file is brought to NED
    (:func:`enu_to_ned`; the standard deviations of x and y swap, roll, pitch and yaw keep
    theirs: roll' = roll, pitch' = -pitch, yaw' = pi/2 - yaw). Poses that do not overlap the
    log's ranges in time are one line naming the file."""
    path, poses = tum.path, tum.poses
    detected, reason = detect_frame(poses.t, poses.position[:, 2], log)
    frame, how = choose_frame(path, tum.frame, detected, reason)
    position, orientation, position_std = poses.position, poses.orientation, tum.position_std
    if frame == "enu":
        position, orientation = enu_to_ned(position, orientation)
        position_std = position_std[..., [1, 0, 2]]
    check_overlap(path, poses.t, log)
    record = {
        "file": str(path),
        "format": f"TUM, {8 if poses.std is None else 14} columns",
        "frame": frame,
        "frame_source": how,
        "covariance": tum.covariance,
    }
    if tum.orientation_std is None:
        record["covariance"] += "; orientation not stated (the map does not use it)"
    trajectory = trajectory_from_poses(poses.t, position, orientation, position_std,
                                       tum.orientation_std, variant=f"TUM {path.name}",
                                       metadata={"trajectory_input": record})  # fmt: skip
    return trajectory, record


def choose_frame(path: Path, requested: str, detected: str | None, reason: str):
    """(frame, how it was chosen): ``requested`` unless auto (a warning when ``detected``
    differs), else ``detected``, else NED with a warning naming the option."""
    if requested != "auto":
        if detected is not None and detected != requested:
            warnings.warn(f"{path}: frame {requested} as stated, but the log's depth says "
                          f"{detected} ({reason}): check --trajectory-frame",
                          stacklevel=3)  # fmt: skip
        return requested, "stated"
    if detected is None:
        warnings.warn(f"{path}: frame not detected ({reason}): read as NED (z down); add "
                      "--trajectory-frame enu if its z points up", stacklevel=3)  # fmt: skip
        return "ned", f"assumed, not detected ({reason})"
    return detected, f"detected: {reason}"


def log_depth(log: Log) -> tuple[np.ndarray, np.ndarray, str] | None:
    """(t, depth below the surface (m, positive down), its stream) from the log's pressure
    (d = (p - p_surface) / (rho g), the log's references) or else its depth stream."""
    if log.pressure is not None and len(log.pressure):
        return log.pressure.t, log.pressure.depth(*depth_reference(log.metadata)), "pressure"
    if log.depth is not None and len(log.depth):
        return log.depth.t, log.depth.depth, "depth"
    return None


#: a depth that varies less than this (std, m) cannot tell z down from z up by correlation
MIN_DEPTH_STD_M = 0.05
#: levels tell z down from up when one of |z - d|, |z + d| (median) is this much the larger...
LEVEL_RATIO = 4.0
#: ... and the larger is at least this (m): a vehicle at the surface has z ~ depth ~ -depth
MIN_LEVEL_M = 0.2


def detect_frame(t, z, log: Log) -> tuple[str | None, str]:
    """("ned", "enu" or None, why) from a trajectory's z (N,) against the log's depth d
    interpolated at the depth's times within the trajectory: a depth varying by at least
    :data:`MIN_DEPTH_STD_M` with |corr(z, d)| >= 0.5 says z down (r > 0) or up (r < 0), as the
    ROS reader tells a pose's z; else the levels, median |z - d| against median |z + d|
    (:data:`LEVEL_RATIO`, :data:`MIN_LEVEL_M`); else None (no depth, no overlap, or z at an
    offset from the depth that the levels cannot tell)."""
    found = log_depth(log)
    if found is None:
        return None, "the log has no pressure or depth stream"
    td, d, name = found
    t, z = np.asarray(t, float), np.asarray(z, float)
    ok = np.isfinite(d) & (td >= t[0]) & (td <= t[-1])
    if ok.sum() < 3:
        return None, f"no {name} sample within the trajectory's time span"
    d, zi = d[ok], np.interp(td[ok], t, z)
    if np.std(d) >= MIN_DEPTH_STD_M and np.std(zi) > 0:
        r = float(np.corrcoef(zi, d)[0, 1])
        if abs(r) >= 0.5:
            return ("ned" if r > 0 else "enu"), (
                f"z {'follows' if r > 0 else 'mirrors'} the log's depth ({name}; correlation "
                f"{r:+.2f})"
            )
    down, up = float(np.median(np.abs(zi - d))), float(np.median(np.abs(zi + d)))
    small, large = sorted((down, up))
    if large >= MIN_LEVEL_M and large >= LEVEL_RATIO * small:
        sign = "" if down < up else "-"
        return ("ned" if down < up else "enu"), (
            f"z = {sign}depth ({name}) within {small:.2g} m (median), against {large:.2g} m "
            "the other way"
        )
    return None, (
        f"z neither follows nor mirrors the log's depth ({name}; median |z - d| {down:.2g} m, "
        f"|z + d| {up:.2g} m)"
    )


def check_overlap(path: Path, t: np.ndarray, log: Log) -> None:
    """One DataError line naming the file when none of the log's ranges (DVL, sonar,
    multibeam) falls within the poses' time span (another log, or another clock)."""
    times = [s.t for s in (log.dvl, log.sonar, log.multibeam) if s is not None and len(s)]
    if not times or any(np.any((s >= t[0]) & (s <= t[-1])) for s in times):
        return
    first, last = min(float(s[0]) for s in times), max(float(s[-1]) for s in times)
    base = log.metadata.get("time_base")
    base = base.get("base") if isinstance(base, dict) else base
    clock = f" ({base})" if isinstance(base, str) and base else ""
    raise DataError(
        f"{path}: its poses ({t[0]:.3f} .. {t[-1]:.3f} s) do not overlap the log's ranges "
        f"({first:.3f} .. {last:.3f} s): is the TUM file from this log, in the log's clock{clock}?"
    )
