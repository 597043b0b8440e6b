"""Calibration from a run with ground truth: the parameters the filter needs for later runs.

- Dead-reckoning orientation drift mu_b (the mean of the bias random walk in
  ``eq:dynamics_model``, rad/s per axis): slope of a least-squares line through the DR
  orientation error e(t) = wrap(DR(t) - truth(t)), e(t) ~ e_0 + mu_b t.
- IMU gyro bias (rad/s): mean of z_IMU - omega_true, omega_true from the ground-truth attitude
  (Euler-rate kinematics omega = T(phi, theta)^{-1} d(eta_2)/dt).
- DVL velocity scale factor s (beyond the paper): v_meas = s v_true. A DVL turns the Doppler
  shift f_D of each beam into a velocity with the sound speed it is set to, v = c f_D /
  (2 f_0 cos(beam angle)), so a wrong setting (e.g. salinity) scales every velocity by
  s = c_set / c_true (Teledyne RD Instruments, "Acoustic Doppler Current Profiler Principles of
  Operation: A Practical Primer"). Estimated by least squares over valid DVL samples while
  moving: s = sum(v_meas . v_true) / sum(|v_true|^2), with v_true the ground
  truth body velocity expressed in the DVL frame, v_true^DVL = R_DVL^T (v^B + omega x r_DVL).
  This is the persistent along-track offset the paper reports but does not model.
- Barometer noise (m, the filter's ``depth_std_m``): the standard deviation (ddof 1) of
  e = d(p) - d_true over the pressure samples, d(p) = (p - p_surface) / (rho g) with the log's
  reference and d_true the ground truth's depth moved to the barometer by its lever arm,
  z + e_3^T R_B^W r_bar. The mean of e (a surface-pressure or density offset) is left out. Run
  in calm water it is the sensor's own noise; in waves it takes the swell's dynamic pressure
  too, which the filter models apart, so a log whose metadata records waves is refused for it.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, get_args

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator

from .._util.atomic import atomic_path
from .._util.validate import read_yaml, refuse_renamed, validate
from ..errors import ConfigError, DataError
from ..io.units import depth_reference
from ..log import Log
from ..rotations import rpy_to_matrix, world_to_body, wrap_angle
from ..wavetrack import WaveTrack
from .noise import parse_wave

Finite = Annotated[float, Field(allow_inf_nan=False)]
Parameter = Literal["dr_bias_drift_rad_s", "gyro_bias_rad_s", "dvl_scale_factor", "depth_std_m"]
PARAMETERS: tuple[str, ...] = get_args(Parameter)


class Calibration(BaseModel):
    """Calibration parameters (units in the names), how well each was determined and which were
    estimated: what :func:`calibrate` returns and a calibration YAML holds (checked here)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    dr_bias_drift_rad_s: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
    gyro_bias_rad_s: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
    dvl_scale_factor: float = Field(1.0, gt=0, allow_inf_nan=False)
    dvl_scale_factor_std: float | None = float("nan")  # NaN / null: not determined
    depth_std_m: float = Field(0.01, gt=0, allow_inf_nan=False)  # the filter's default
    samples: dict[str, int] | None = None
    source: str = ""
    # the parameters estimated from data (None: not recorded, a file from an older version);
    # the others hold their defaults, with the reason in ``left_at_default``
    estimated: tuple[Parameter, ...] | None = None
    left_at_default: dict[Parameter, str] | None = None

    @field_validator("dvl_scale_factor_std")
    @classmethod
    def _std(cls, value):
        if value is None or math.isnan(value):
            return float("nan")
        if not (0 <= value < math.inf):
            raise ValueError("must be a finite number >= 0 (or .nan: not determined)")
        return value

    def to_dict(self) -> dict:
        d = self.model_dump()
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
                f"{', '.join(cls.model_fields)}, got a {type(data).__name__})"
            )
        refuse_renamed(data, f"{path}: calibration field ")
        unknown = sorted(str(k) for k in data if k not in cls.model_fields)
        if unknown:
            raise ConfigError(
                f"{path}: not a calibration file of `undertow calibrate`: unknown keys "
                f"{', '.join(unknown)}"
            )
        return validate(cls, data, f"{path}: calibration field ")


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
    """Estimate mu_b, the IMU gyro bias, the DVL scale factor and the barometer's noise from
    ``log`` and its ground truth (module doc).

    Needs the ground_truth stream (repeated timestamps are dropped with a warning, see
    :meth:`~undertow.log.GroundTruth.usable`). Each parameter is
    estimated from its stream's samples inside the ground-truth span (DVL: valid and moving)
    when there are at least ``min_samples`` of them; a parameter with fewer, or whose stream the
    log lacks, keeps its default with one warning line saying why (``estimated`` and
    ``left_at_default`` of the result record which is which, and the YAML keeps them), and a
    DataError says what overlaps when none can be estimated.
    """
    log.require("ground_truth", stage="calibrate")
    truth = _Truth(log.ground_truth.usable("calibrate"), smoothing_s, min_samples)
    fits = {
        "dr_bias_drift_rad_s": _fit_dr_drift(log, truth),
        "gyro_bias_rad_s": _fit_gyro_bias(log, truth),
        "dvl_scale_factor": _fit_dvl_scale(log, truth, min_speed_m_s),
        "depth_std_m": _fit_depth_std(log, truth),
    }
    found = dict(fit.found for fit in fits.values() if fit.found is not None)
    counts = dict(fit.samples for fit in fits.values() if fit.values)
    if not counts:
        overlap = ", ".join(f"{n} samples for {what}" for what, n in found.items()) or "no samples"
        raise DataError(
            f"calibrate: the ground truth {truth.span} ({len(truth.gt)} poses) overlaps "
            f"{overlap}; need at least {min_samples} for a parameter"
            + ("" if found else " (the log has no dead_reckoning, imu or dvl stream)")
        )
    why_not = {name: fit.why_not for name, fit in fits.items() if fit.why_not is not None}
    defaults = Calibration()
    for name, reason in why_not.items():
        warnings.warn(
            f"calibrate: {name} left at the default {_plain_value(getattr(defaults, name))}: "
            f"{reason}",
            RuntimeWarning,
            stacklevel=2,
        )
    return Calibration(
        **{k: v for fit in fits.values() for k, v in fit.values.items()},
        samples=counts,
        source=log.source,
        estimated=tuple(p for p in PARAMETERS if fits[p].values),
        left_at_default=why_not or None,
    )


class _Truth:
    """The usable ground truth and what every fit reads from it: its span, its world velocity
    (differentiated, smoothed over ``smoothing_s``) and its body rates omega = T^-1 eta_2'."""

    def __init__(self, gt, smoothing_s: float, min_samples: int) -> None:
        self.gt = gt
        self.min_samples = min_samples
        self.v_world = gt.differentiated_velocity(smoothing_s)
        rpy_dot = np.gradient(np.unwrap(gt.orientation, axis=0), gt.t, axis=0)
        self.omega = _euler_rates_to_body(gt.orientation, rpy_dot)
        self.span = f"[{gt.t[0]:.3f}, {gt.t[-1]:.3f}] s"
        self.need = f"need at least {min_samples}"

    def inside(self, t: np.ndarray) -> np.ndarray:
        return (t >= self.gt.t[0]) & (t <= self.gt.t[-1])

    def omega_at(self, t: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(t, self.gt.t, self.omega[:, i]) for i in range(3)])


@dataclass(frozen=True)
class _Fit:
    """One parameter's fit: its values (empty when left at the default, with ``why_not``), the
    samples it used (key, count) and those available (label, count; None without the stream)."""

    values: dict
    samples: tuple[str, int] | None = None
    found: tuple[str, int] | None = None
    why_not: str | None = None


def _finite_inside(stream, name: str, field: str, parameter: str, truth: _Truth, minimum: int):
    """(keep, found): the rows of ``stream`` whose ``field`` is finite inside the ground-truth
    span and found = (label, their count); or a _Fit leaving ``parameter`` at its default when
    the log lacks the stream or has fewer than max(min_samples, ``minimum``) such rows."""
    if stream is None or not len(stream):
        return _Fit({}, why_not=f"the log has no {name} stream")
    keep = truth.inside(stream.t) & np.all(np.isfinite(getattr(stream, field)), axis=1)
    n = int(keep.sum())
    found = (f"{parameter} ({name})", n)
    if n < max(truth.min_samples, minimum):
        why_not = f"{n} finite {name} samples inside the ground truth {truth.span}, {truth.need}"
        return _Fit({}, found=found, why_not=why_not)
    return keep, found


def _fit_dr_drift(log: Log, truth: _Truth) -> _Fit:
    """mu_b: slope of the line through e(t) = wrap(DR(t) - truth(t)), unwrapped, per axis."""
    dr = log.dead_reckoning
    rows = _finite_inside(dr, "dead_reckoning", "orientation", "dr_bias_drift_rad_s", truth, 3)
    if isinstance(rows, _Fit):
        return rows
    keep, found = rows
    if np.ptp(dr.t[keep]) == 0:
        return _Fit({}, found=found, why_not="all dead_reckoning samples at one time")
    _, rpy, _ = truth.gt.interpolate(dr.t[keep])
    e = np.unwrap(wrap_angle(dr.orientation[keep] - rpy), axis=0)
    drift = tuple(_line_slope(dr.t[keep], e[:, i]) for i in range(3))
    return _Fit({"dr_bias_drift_rad_s": drift}, ("dead_reckoning", found[1]), found)


def _fit_gyro_bias(log: Log, truth: _Truth) -> _Fit:
    """IMU gyro bias: mean of z_IMU - omega_true over the IMU samples inside the ground truth."""
    imu = log.imu
    rows = _finite_inside(imu, "imu", "angular_velocity", "gyro_bias_rad_s", truth, 1)
    if isinstance(rows, _Fit):
        return rows
    keep, found = rows
    omega = truth.omega_at(imu.t[keep])
    bias = tuple(float(v) for v in np.mean(imu.angular_velocity[keep] - omega, axis=0))
    return _Fit({"gyro_bias_rad_s": bias}, ("imu", found[1]), found)


def _fit_dvl_scale(log: Log, truth: _Truth, min_speed_m_s: float) -> _Fit:
    """s = sum(v_meas . v_true) / sum(|v_true|^2) over the valid DVL samples moving faster than
    ``min_speed_m_s``, v_true^DVL = R_DVL^T (v^B + omega x r_DVL); its standard error from the
    residuals v_meas - s v_true."""
    dvl = log.dvl
    if dvl is None or not len(dvl):
        return _Fit({}, why_not="the log has no dvl stream")
    keep = truth.inside(dvl.t) & dvl.valid & np.all(np.isfinite(dvl.velocity), axis=1)
    _, rpy, vel = truth.gt.interpolate(dvl.t[keep], truth.v_world)
    omega = truth.omega_at(dvl.t[keep])
    v_body = world_to_body(rpy, vel)
    mount = log.mounting.dvl
    v_true = (v_body + np.cross(omega, np.asarray(mount.translation))) @ mount.rotation_matrix()
    moving = np.linalg.norm(v_true, axis=1) > min_speed_m_s
    n = int(moving.sum())
    found = ("dvl_scale_factor (dvl, valid and moving)", n)
    if n < max(truth.min_samples, 3):
        why_not = (
            f"{n} valid dvl samples moving faster than {min_speed_m_s} m/s inside the "
            f"ground truth {truth.span}, {truth.need}"
        )
        return _Fit({}, found=found, why_not=why_not)
    vt, vm = v_true[moving], dvl.velocity[keep][moving]
    s = float(np.sum(vm * vt) / np.sum(vt * vt))
    resid = vm - s * vt
    s_std = float(np.sqrt(np.sum(resid**2) / (resid.size - 1) / np.sum(vt * vt)))
    values = {"dvl_scale_factor": s, "dvl_scale_factor_std": s_std}
    return _Fit(values, ("dvl_moving", n), found)


def _fit_depth_std(log: Log, truth: _Truth) -> _Fit:
    """The barometer's noise: std (ddof 1) of its depth about the ground truth's at the sensor
    (module doc); left at the default for a log whose metadata records waves."""
    p = log.pressure
    if p is None or not len(p):
        return _Fit({}, why_not="the log has no pressure stream")
    keep = truth.inside(p.t) & np.isfinite(p.pressure)
    n = int(keep.sum())
    found = ("depth_std_m (pressure)", n)
    if n < max(truth.min_samples, 3):
        why_not = f"{n} finite pressure samples inside the ground truth {truth.span}, {truth.need}"
        return _Fit({}, found=found, why_not=why_not)
    wave = log.metadata.get("wave") if isinstance(log.metadata, dict) else None
    if _has_waves(wave):
        why_not = ("the log records waves, whose dynamic pressure the barometer reads as depth; "
                   "calibrate its noise on a calm run")  # fmt: skip
        return _Fit({}, found=found, why_not=why_not)
    pos, rpy, _ = truth.gt.interpolate(p.t[keep])
    lever = rpy_to_matrix(rpy) @ np.asarray(log.mounting.barometer.translation, float)
    e = p.depth(*depth_reference(log.metadata))[keep] - (pos[:, 2] + lever[:, 2])
    std = float(np.std(e, ddof=1))
    if not std > 0:
        return _Fit({}, found=found, why_not="the barometer's depth about the truth is constant")
    return _Fit({"depth_std_m": std}, ("pressure", n), found)


def _has_waves(wave) -> bool:
    """Whether a log's recorded wave condition (a track or a condition,
    :meth:`~undertow.wavetrack.WaveTrack.from_dict`, or a condition's name,
    :func:`~undertow.estimation.noise.parse_wave`) has an amplitude above 0 anywhere; False for
    none or one that is neither."""
    try:
        if isinstance(wave, dict):
            return bool(np.any(WaveTrack.from_dict(wave).amplitude_m > 0))
        return wave is not None and parse_wave(wave)[1] > 0
    except ConfigError:
        return False


def _plain_value(value) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(f"{v:g}" for v in value) + "]"
    return f"{value:g}"
