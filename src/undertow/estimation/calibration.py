"""Calibration from a run with ground truth: the parameters the filter needs for later runs.

- Dead-reckoning orientation drift mu_b (the mean of the bias random walk in
  ``eq:dynamics_model``, rad/s per axis): slope of a least-squares line through the DR
  orientation error e(t) = wrap(DR(t) - truth(t)), e(t) ~ e_0 + mu_b t.
- IMU gyro bias (rad/s): mean of z_IMU - omega_true, omega_true from the ground-truth attitude
  (Euler-rate kinematics omega = T(phi, theta)^{-1} d(eta_2)/dt).
- DVL velocity scale factor s (beyond the paper): v_meas = s v_true, as a sound-speed error
  gives s = c_set / c_true (NOTES.md section 1), estimated by least squares over valid DVL
  samples while moving: s = sum(v_meas . v_true) / sum(|v_true|^2), with v_true the ground
  truth body velocity expressed in the DVL frame, v_true^DVL = R_DVL^T (v^B + omega x r_DVL).
  This is the persistent along-track offset the paper reports but does not model.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Annotated, Literal, get_args

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator

from .._util.atomic import atomic_path
from .._util.validate import read_yaml, refuse_renamed, validate
from ..errors import ConfigError, DataError
from ..log import Log
from ..rotations import world_to_body, wrap_angle


@dataclass(frozen=True)
class Calibration:
    """Calibration parameters (units in the names) and how well each was determined."""

    dr_bias_drift_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dvl_scale_factor: float = 1.0
    dvl_scale_factor_std: float = float("nan")
    samples: dict | None = None
    source: str = ""
    # the parameters estimated from data (None: not recorded, a file from an older version);
    # the others hold their defaults, with the reason in ``left_at_default``
    estimated: tuple[str, ...] | None = None
    left_at_default: dict[str, str] | None = None

    def to_dict(self) -> dict:
        d = asdict(self)
        d["dr_bias_drift_rad_s"] = [float(v) for v in self.dr_bias_drift_rad_s]
        d["gyro_bias_rad_s"] = [float(v) for v in self.gyro_bias_rad_s]
        if self.estimated is not None:
            d["estimated"] = list(self.estimated)
        else:
            del d["estimated"]
        if self.left_at_default is None:
            del d["left_at_default"]
        return d

    def save_yaml(self, path: str | Path) -> Path:
        path = Path(path)
        with atomic_path(path) as tmp:
            tmp.write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))
        return path

    @classmethod
    def from_yaml(cls, path: str | Path) -> Calibration:
        """Read a file written by :meth:`save_yaml`; anything else (another YAML file, unknown
        keys, a non-finite or non-positive value) is a ConfigError naming the problem."""
        data = read_yaml(path, "calibration file")
        data = {} if data is None else data
        if not isinstance(data, dict):
            raise ConfigError(
                f"{path}: not a calibration file (expected a mapping of "
                f"{', '.join(_CalibrationFile.model_fields)}, got a {type(data).__name__})"
            )
        refuse_renamed(data, f"{path}: calibration field ")
        unknown = sorted(str(k) for k in data if k not in _CalibrationFile.model_fields)
        if unknown:
            raise ConfigError(
                f"{path}: not a calibration file of `undertow calibrate`: unknown keys "
                f"{', '.join(unknown)}"
            )
        checked = validate(_CalibrationFile, data, f"{path}: calibration field ")
        fields = checked.model_dump()
        if fields["estimated"] is not None:
            fields["estimated"] = tuple(fields["estimated"])
        return cls(**fields)


Finite = Annotated[float, Field(allow_inf_nan=False)]
Parameter = Literal["dr_bias_drift_rad_s", "gyro_bias_rad_s", "dvl_scale_factor"]
PARAMETERS: tuple[str, ...] = get_args(Parameter)


class _CalibrationFile(BaseModel):
    """What a calibration YAML may hold (all optional; defaults as :class:`Calibration`)."""

    model_config = ConfigDict(extra="forbid")

    dr_bias_drift_rad_s: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
    gyro_bias_rad_s: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
    dvl_scale_factor: float = Field(1.0, gt=0, allow_inf_nan=False)
    dvl_scale_factor_std: float | None = float("nan")  # NaN / null: not determined
    samples: dict[str, int] | None = None
    source: str = ""
    estimated: list[Parameter] | None = None
    left_at_default: dict[Parameter, str] | None = None

    @field_validator("dvl_scale_factor_std")
    @classmethod
    def _std(cls, value):
        if value is None or math.isnan(value):
            return float("nan")
        if not (0 <= value < math.inf):
            raise ValueError("must be a finite number >= 0 (or .nan: not determined)")
        return value


def _euler_rates_to_body(rpy: np.ndarray, rpy_dot: np.ndarray) -> np.ndarray:
    """omega = T^{-1}(phi, theta) eta_2_dot: p = phi' - sin(theta) psi', q = cos(phi) theta' +
    sin(phi) cos(theta) psi', r = -sin(phi) theta' + cos(phi) cos(theta) psi'."""
    phi, theta = rpy[:, 0], rpy[:, 1]
    d_phi, d_theta, d_psi = rpy_dot.T
    return np.column_stack(
        [
            d_phi - np.sin(theta) * d_psi,
            np.cos(phi) * d_theta + np.sin(phi) * np.cos(theta) * d_psi,
            -np.sin(phi) * d_theta + np.cos(phi) * np.cos(theta) * d_psi,
        ]
    )


def _line_slope(t: np.ndarray, y: np.ndarray) -> float:
    tc = t - t.mean()
    return float(np.dot(tc, y - y.mean()) / np.dot(tc, tc))


MIN_SAMPLES = 20  # per parameter: fewer overlapping samples leave it at its default


def calibrate(
    log: Log,
    min_speed_m_s: float = 0.05,
    smoothing_s: float = 0.05,
    min_samples: int = MIN_SAMPLES,
) -> Calibration:
    """Estimate mu_b, the IMU gyro bias and the DVL scale factor from ``log`` and its ground truth.

    Needs the ground_truth stream (repeated timestamps are dropped with a warning, see
    :meth:`~undertow.log.GroundTruth.usable`). Each parameter is
    estimated from its stream's samples inside the ground-truth span (DVL: valid and moving)
    when there are at least ``min_samples`` of them; a parameter with fewer, or whose stream the
    log lacks, keeps its default with one warning line saying why (``estimated`` and
    ``left_at_default`` of the result record which is which, and the YAML keeps them), and a
    DataError says what overlaps when none can be estimated.
    """
    log.require("ground_truth", stage="calibrate")
    gt = log.ground_truth.usable("calibrate")
    v_world = gt.differentiated_velocity(smoothing_s)
    rpy_dot_full = np.gradient(np.unwrap(gt.orientation, axis=0), gt.t, axis=0)
    omega_full = _euler_rates_to_body(gt.orientation, rpy_dot_full)
    counts: dict[str, int] = {}
    found: dict[str, int] = {}  # samples available per parameter, estimated or not
    result = {}
    span = f"[{gt.t[0]:.3f}, {gt.t[-1]:.3f}] s"
    need = f"need at least {min_samples}"
    why_not: dict[str, str] = {}  # parameter -> why it keeps its default

    def inside(t):
        return (t >= gt.t[0]) & (t <= gt.t[-1])

    dr = log.dead_reckoning
    if dr is None or not len(dr):
        why_not["dr_bias_drift_rad_s"] = "the log has no dead_reckoning stream"
    else:
        keep = inside(dr.t) & np.all(np.isfinite(dr.orientation), axis=1)
        n = found["dr_bias_drift_rad_s (dead_reckoning)"] = int(keep.sum())
        if n < max(min_samples, 3):
            why_not["dr_bias_drift_rad_s"] = (
                f"{n} finite dead_reckoning samples inside the ground truth {span}, {need}"
            )
        elif np.ptp(dr.t[keep]) == 0:
            why_not["dr_bias_drift_rad_s"] = "all dead_reckoning samples at one time"
        else:
            _, rpy, _ = gt.interpolate(dr.t[keep])
            e = np.unwrap(wrap_angle(dr.orientation[keep] - rpy), axis=0)
            result["dr_bias_drift_rad_s"] = tuple(
                _line_slope(dr.t[keep], e[:, i]) for i in range(3)
            )
            counts["dead_reckoning"] = n
    imu = log.imu
    if imu is None or not len(imu):
        why_not["gyro_bias_rad_s"] = "the log has no imu stream"
    else:
        keep = inside(imu.t) & np.all(np.isfinite(imu.angular_velocity), axis=1)
        n = found["gyro_bias_rad_s (imu)"] = int(keep.sum())
        if n < max(min_samples, 1):
            why_not["gyro_bias_rad_s"] = (
                f"{n} finite imu samples inside the ground truth {span}, {need}"
            )
        else:
            omega = np.column_stack(
                [np.interp(imu.t[keep], gt.t, omega_full[:, i]) for i in range(3)]
            )
            result["gyro_bias_rad_s"] = tuple(
                float(v) for v in np.mean(imu.angular_velocity[keep] - omega, axis=0)
            )
            counts["imu"] = n
    dvl = log.dvl
    if dvl is None or not len(dvl):
        why_not["dvl_scale_factor"] = "the log has no dvl stream"
    else:
        keep = inside(dvl.t) & dvl.valid & np.all(np.isfinite(dvl.velocity), axis=1)
        _, rpy, vel = gt.interpolate(dvl.t[keep], v_world)
        omega = np.column_stack([np.interp(dvl.t[keep], gt.t, omega_full[:, i]) for i in range(3)])
        v_body = world_to_body(rpy, vel)
        mount = log.mounting.dvl
        v_true = (v_body + np.cross(omega, np.asarray(mount.translation))) @ mount.rotation_matrix()
        moving = np.linalg.norm(v_true, axis=1) > min_speed_m_s
        n = found["dvl_scale_factor (dvl, valid and moving)"] = int(moving.sum())
        if n < max(min_samples, 3):
            why_not["dvl_scale_factor"] = (
                f"{n} valid dvl samples moving faster than {min_speed_m_s} m/s inside the "
                f"ground truth {span}, {need}"
            )
        else:
            vt, vm = v_true[moving], dvl.velocity[keep][moving]
            s = float(np.sum(vm * vt) / np.sum(vt * vt))
            resid = vm - s * vt
            s_std = float(np.sqrt(np.sum(resid**2) / (resid.size - 1) / np.sum(vt * vt)))
            result["dvl_scale_factor"] = s
            result["dvl_scale_factor_std"] = s_std
            counts["dvl_moving"] = n
    overlap = ", ".join(f"{n} samples for {what}" for what, n in found.items()) or "no samples"
    if not counts:
        raise DataError(
            f"calibrate: the ground truth {span} ({len(gt)} poses) overlaps {overlap}; "
            f"need at least {min_samples} for a parameter"
            + ("" if found else " (the log has no dead_reckoning, imu or dvl stream)")
        )
    defaults = Calibration()
    for name, reason in why_not.items():
        warnings.warn(
            f"calibrate: {name} left at the default {_plain_value(getattr(defaults, name))}: "
            f"{reason}",
            RuntimeWarning,
            stacklevel=2,
        )
    return Calibration(
        **result,
        samples=counts,
        source=log.source,
        estimated=tuple(p for p in PARAMETERS if p in result),
        left_at_default=why_not or None,
    )


def _plain_value(value) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(f"{v:g}" for v in value) + "]"
    return f"{value:g}"
