"""Localizer: Log -> Trajectory with the paper's UKF (section III-A) and its variants.

Variants (the paper's ablation, tab:ablation): ``baseline`` (no bias states, no wave noise),
``be`` (bias estimation), ``an`` (added wave noise gamma in R), ``proposed`` (both). Without
bias estimation the six bias states are held at 0 with a tiny variance and no correlation.

Measurements of all streams are merged and processed in time order (a prediction per
measurement, as in the paper); see :mod:`undertow.estimation.model` for the equations.
"""

from __future__ import annotations

import warnings
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from .._util.validate import validate
from ..errors import ConfigError
from ..log import FRESH_WATER_DENSITY, P_ATM, Log
from ..rotations import matrix_to_rpy, rpy_to_matrix
from ..trajectory import Trajectory
from . import model
from .noise import NoiseProfile, WaveNoise
from .ukf import _weights

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]
PositiveVec3 = tuple[Positive, Positive, Positive]
NonNegativeVec3 = tuple[NonNegative, NonNegative, NonNegative]
VARIANTS = ("baseline", "be", "an", "proposed")
# a run where more than this fraction of the processed measurements needed a covariance repair
# or a reverted step (or were gated) is reported: the track is then mostly frozen
TROUBLE_FRACTION = 0.5


class LocalizerConfig(BaseModel):
    """Filter parameters; units in the names. Densities are continuous-time (see model.py).

    Every number must be finite; standard deviations and acceleration densities must be > 0
    (measurement stds are also floored at ``std_floor``, so R is never 0); bias-walk densities
    may be 0 (a constant bias). Sigma points: alpha in [0.5, 2], beta in [0, 10], kappa in
    [0, 54] (kappa >= 0 keeps the centre weight from going strongly negative; NOTES.md
    section 3).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    variant: Literal["baseline", "be", "an", "proposed"] = "proposed"
    # process noise (eq:dynamics_model): Gamma = density / dt, Gamma_b dt
    accel_density: PositiveVec3 = (0.01, 0.01, 0.01)  # (m/s^2)^2/Hz
    angular_accel_density: PositiveVec3 = (0.005, 0.005, 0.005)  # (rad/s^2)^2/Hz
    dr_bias_walk_density: NonNegativeVec3 = (1e-7, 1e-7, 1e-6)  # rad^2/s
    gyro_bias_walk_density: NonNegativeVec3 = (1e-8, 1e-8, 1e-8)  # (rad/s)^2/s
    dr_bias_drift_rad_s: Vec3 = (0.0, 0.0, 0.0)  # mu_b: mean drift of the DR bias (calibration)
    gyro_bias_drift_rad_s2: Vec3 = (0.0, 0.0, 0.0)  # mean drift of the IMU gyro bias
    # measurement noise (std devs, per sample)
    imu_gyro_std_rad_s: PositiveVec3 = (0.005, 0.005, 0.005)
    dvl_velocity_std_m_s: PositiveVec3 = (0.01, 0.01, 0.01)  # used when the log has no covariance
    dvl_std_floor_m_s: Positive = 0.001
    dr_orientation_std_rad: PositiveVec3 = (0.005, 0.005, 0.01)
    depth_std_m: Positive = 0.01
    std_floor: Positive = 1e-6  # every measurement std is at least this
    dr_orientation_frame: Literal["body", "dvl"] = "body"
    # initial state (None: zeros, orientation from the first DR report, z from the first depth)
    initial_state: list[Finite] | None = None
    # start position (m, world) when initial_state is None; None: x = y = 0, z from the first depth
    initial_position: Vec3 | None = None
    # initial IMU gyro bias mean b-bar^g (rad/s) when initial_state is None, e.g. from
    # `undertow calibrate`; only the variants that estimate biases (be, proposed) use it
    gyro_bias_rad_s: Vec3 = (0.0, 0.0, 0.0)
    initial_std: list[NonNegative] = Field(
        default_factory=lambda: [0.01] * 3 + [0.05] * 3 + [0.1] * 3 + [0.05] * 3
        + [0.005] * 3 + [0.01] * 3
    )  # fmt: skip
    # sensors
    dvl_scale_factor: Positive = 1.0  # v_used = v_measured / scale
    water_density_kg_m3: Positive = FRESH_WATER_DENSITY
    surface_pressure_pa: Positive = P_ATM
    # robustness and output
    # Mahalanobis gate: chi-square probability of the NIS quantile, None = off
    gate_probability: float | None = Field(None, gt=0, lt=1, allow_inf_nan=False)
    max_dt_s: Positive = 1.0
    output_rate_hz: Positive | None = None  # None: every processed measurement time
    # sigma points (alpha ~0.5-1; NOT 1e-3 for n = 18)
    alpha: float = Field(1.0, ge=0.5, le=2.0, allow_inf_nan=False)
    beta: float = Field(2.0, ge=0.0, le=10.0, allow_inf_nan=False)
    kappa: float = Field(0.0, ge=0.0, le=3.0 * 18, allow_inf_nan=False)

    @field_validator("initial_state", "initial_std")
    @classmethod
    def _eighteen(cls, value):
        if value is not None and len(value) != model.N_STATE:
            raise ValueError(f"needs {model.N_STATE} values (one per state), got {len(value)}")
        return value

    @property
    def estimates_bias(self) -> bool:
        return self.variant in ("be", "proposed")

    @property
    def adds_wave_noise(self) -> bool:
        return self.variant in ("an", "proposed")


class Localizer:
    """The paper's UKF. ``Localizer(variant="proposed", wave="wave-a0.10-f1.00").run(log)``.

    ``profile``: a NoiseProfile, a YAML path or None (the paper's Table I); ``wave``: condition
    name, (amplitude, frequency) or None (``log.metadata["wave"]`` if present, else calm);
    other keyword arguments are :class:`LocalizerConfig` fields.
    """

    def __init__(self, variant: str = "proposed", profile=None, wave=None,
                 extrapolate: bool = False, **params) -> None:  # fmt: skip
        self.config = validate(LocalizerConfig, {"variant": variant, **params}, "Localizer: ")
        if isinstance(profile, NoiseProfile) or profile is None:
            self.profile = profile or NoiseProfile.paper()
        else:
            self.profile = NoiseProfile.from_yaml(profile)
        self.wave = wave
        self.extrapolate = extrapolate

    @classmethod
    def from_config(cls, config: LocalizerConfig, profile=None, wave=None) -> Localizer:
        return cls(profile=profile, wave=wave, **config.model_dump())

    def run(self, log: Log) -> Trajectory:
        """Filter the whole log; (x, P) at every processed measurement time (or output rate)."""
        cfg = self.config
        log.require("dvl", "imu", stage="Localizer")
        wave, wave_source = wave_condition(self.wave, log)
        noise = self.profile.noise(wave, extrapolate=self.extrapolate)
        t, kind, z, R, rejected = _measurements(log, cfg, noise)
        if t.size == 0:
            raise ConfigError("Localizer: the log has no finite, valid DVL/IMU measurements")
        x0, P0 = _initial_state(log, cfg, t[0])
        wm, wc, lam = _weights(model.N_STATE, cfg.alpha, cfg.beta, cfg.kappa)
        out_times, record_all, out_n = _output_times(t, cfg.output_rate_hz)
        gate = np.full(4, np.inf)
        if cfg.gate_probability is not None:
            from scipy.stats import chi2

            gate[:] = chi2.ppf(cfg.gate_probability, model.KIND_DIM)
        mu = np.array(cfg.dr_bias_drift_rad_s + cfg.gyro_bias_drift_rad_s2, float)
        mount = log.mounting
        nis_stats = np.zeros((4, len(model.NIS_FIELDS)))
        out_t, out_x, out_P, counts = model._run_filter(
            t, kind, z, R, x0, P0, float(t[0]), wm, wc, float(lam),
            np.array(cfg.accel_density + cfg.angular_accel_density, float),
            np.array(cfg.dr_bias_walk_density + cfg.gyro_bias_walk_density, float), mu,
            np.ascontiguousarray(mount.imu.rotation_matrix().T),
            np.ascontiguousarray(mount.dvl.rotation_matrix().T),
            np.array(mount.dvl.translation, float), np.array(mount.barometer.translation, float),
            float(cfg.max_dt_s), gate, not cfg.estimates_bias, out_times, record_all, out_n,
            nis_stats,
        )  # fmt: skip
        counts = dict(zip(model.COUNT_NAMES, counts.tolist(), strict=True))
        _warn_if_frozen(counts, int(t.size))
        metadata = {
            "variant": cfg.variant,
            "counts": {**rejected, **counts},
            "nis": _nis_summary(nis_stats),
            "wave_noise": noise.to_dict() if cfg.adds_wave_noise else None,
            "wave_condition": noise.condition,
            "wave_condition_source": wave_source,
            "config": cfg.model_dump(),
            "source": log.source,
        }
        return Trajectory(out_t, out_x, out_P, variant=cfg.variant, metadata=metadata)


def wave_condition(wave, log: Log) -> tuple[object, str]:
    """The wave condition a run uses and where it comes from: ``wave`` when given, else the
    log's metadata (a simulated log, or a bag whose sidecar ``undertow.yaml`` records it), else
    calm. Returns (condition, source): source is ``"given"``, ``"default"`` or where in the log
    the condition was found (e.g. ``"the bag's sidecar undertow.yaml"``)."""
    if wave is not None:
        return wave, "given"
    recorded = log.metadata.get("wave")
    if recorded is not None:
        sidecar = log.metadata.get("format") == "rosbag" and "recorded" in log.metadata
        if sidecar:
            return recorded, "the bag's sidecar undertow.yaml"
        return recorded, f"the metadata of {log.source}" if log.source else "the log's metadata"
    return "calm", "default"


def _warn_if_frozen(counts: dict, n_measurements: int) -> None:
    """One warning line when most processed measurements needed a covariance repair, a
    reverted step or were gated: the filter then barely moves (inconsistent parameters, a
    gate too tight for the noise, or data far from the model)."""
    processed = n_measurements - counts["nonfinite_rejected"]
    if processed <= 0:
        return
    troubled = {
        "covariance repairs": counts["cholesky_repairs"],
        "reverted steps": counts["numerical_reverts"],
        "gated measurements": sum(counts[f"gated_{name}"] for name in model.KIND_NAMES),
    }
    worst = max(troubled, key=troubled.get)
    if troubled[worst] > TROUBLE_FRACTION * processed:
        warnings.warn(
            f"Localizer: {troubled[worst]} {worst} for {processed} measurements; the track is "
            "probably frozen or wrong (check the noise parameters, the gate and the data)",
            RuntimeWarning,
            stacklevel=3,
        )


def _nis_summary(stats: np.ndarray) -> dict:
    """Per sensor: mean NIS (sum nu^T S^-1 nu / count; None without innovations), its expected
    value dof = dim z, the fraction with NIS <= chi2_95(dof) and the count."""
    out = {}
    for k, name in enumerate(model.KIND_NAMES):
        total, count, inside = stats[k]
        n = int(count)
        out[name] = {
            "mean": float(total / n) if n else None,
            "dof": model.KIND_DIM[k],
            "fraction_in_95": float(inside / n) if n else None,
            "count": n,
        }
    return out


def _measurements(log: Log, cfg: LocalizerConfig, noise: WaveNoise):
    """Merged, time-sorted (t, kind, z (N, 3), R (N, 3, 3)) and the rows rejected up front."""
    floor2 = cfg.std_floor**2
    wave_on = cfg.adds_wave_noise
    parts, rejected = [], {}

    def add(kind, t, z, R, ok, name=None):
        if name:
            rejected[f"rejected_{name}"] = int(np.sum(~ok))
        n = int(np.sum(ok))
        zz = np.full((n, 3), 0.0)
        zz[:, : z.shape[1]] = z[ok]
        RR = np.zeros((n, 3, 3))
        RR[:, : R.shape[1], : R.shape[2]] = R[ok]
        i = np.arange(3)
        RR[:, i, i] = np.maximum(RR[:, i, i], floor2)
        parts.append((t[ok], np.full(n, kind, np.int64), zz, RR))

    def diag(std, n):
        return np.tile(np.diag(np.maximum(np.asarray(std, float), cfg.std_floor) ** 2), (n, 1, 1))

    imu = log.imu
    w = imu.angular_velocity
    add(model.IMU, imu.t, w, diag(cfg.imu_gyro_std_rad_s, len(imu)), _finite_rows(w), "imu")

    dvl = log.dvl
    v = dvl.velocity / cfg.dvl_scale_factor
    cov = np.array(dvl.covariance, float) / cfg.dvl_scale_factor**2
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    has_cov = np.all(np.isfinite(cov), axis=(1, 2))
    R = np.where(has_cov[:, None, None], cov, diag(cfg.dvl_velocity_std_m_s, len(dvl)))
    i = np.arange(3)
    R[:, i, i] = np.maximum(R[:, i, i], cfg.dvl_std_floor_m_s**2)
    if wave_on:
        R[:, i, i] += noise.dvl_std**2
    finite = _finite_rows(v)
    rejected["rejected_dvl_invalid"] = int(np.sum(~dvl.valid))
    rejected["rejected_dvl_nonfinite"] = int(np.sum(dvl.valid & ~finite))
    add(model.DVL, dvl.t, v, R, finite & dvl.valid)

    dr = log.dead_reckoning
    if dr is not None and len(dr):
        rpy = np.array(dr.orientation, float)
        ok = _finite_rows(rpy)
        if cfg.dr_orientation_frame == "dvl":  # R_dr = R_body R_mount  =>  R_body = R_dr R_m^T
            Rm = log.mounting.dvl.rotation_matrix()
            rpy[ok] = matrix_to_rpy(rpy_to_matrix(rpy[ok]) @ Rm.T)
        Rdr = diag(cfg.dr_orientation_std_rad, len(dr))
        if wave_on:
            Rdr[:, i, i] += noise.dr_std**2
        add(model.DR, dr.t, rpy, Rdr, ok, "dead_reckoning")

    if log.pressure is not None and len(log.pressure):
        p = log.pressure
        d = p.depth(cfg.water_density_kg_m3, cfg.surface_pressure_pa)[:, None]
        add(model.BARO, p.t, d, diag([cfg.depth_std_m] * 3, len(p))[:, :1, :1], _finite_rows(d),
            "pressure")  # fmt: skip

    t = np.concatenate([q[0] for q in parts])
    kind = np.concatenate([q[1] for q in parts])
    order = np.lexsort((kind, t))  # time order; at equal times IMU, DVL, DR, baro
    z = np.ascontiguousarray(np.concatenate([q[2] for q in parts])[order])
    R = np.ascontiguousarray(np.concatenate([q[3] for q in parts])[order])
    return np.ascontiguousarray(t[order]), np.ascontiguousarray(kind[order]), z, R, rejected


def _finite_rows(a: np.ndarray) -> np.ndarray:
    return np.all(np.isfinite(a), axis=1)


def _initial_state(log: Log, cfg: LocalizerConfig, t0: float):
    """x0 from the config, else zeros with the first DR orientation and the first depth, and the
    configured start position (DVL and IMU observe no absolute x, y: the user gives the start)."""
    std = np.asarray(cfg.initial_std, float)
    x0 = None if cfg.initial_state is None else np.asarray(cfg.initial_state, float)
    if std.shape != (model.N_STATE,) or (x0 is not None and x0.shape != (model.N_STATE,)):
        raise ConfigError("Localizer: initial_state and initial_std need 18 values each")
    if x0 is not None:
        return x0.copy(), np.diag(np.maximum(std, 1e-9) ** 2)
    x0 = np.zeros(model.N_STATE)
    dr = log.dead_reckoning
    if dr is not None and len(dr):
        ok = np.flatnonzero(_finite_rows(np.asarray(dr.orientation)))
        if ok.size:
            rpy = np.array(dr.orientation[ok[0]], float)
            if cfg.dr_orientation_frame == "dvl":
                rpy = matrix_to_rpy(rpy_to_matrix(rpy) @ log.mounting.dvl.rotation_matrix().T)
            x0[3:6] = rpy
    if log.pressure is not None and len(log.pressure):
        d = log.pressure.depth(cfg.water_density_kg_m3, cfg.surface_pressure_pa)
        ok = np.flatnonzero(np.isfinite(d))
        if ok.size:
            lever = rpy_to_matrix(x0[3:6]) @ np.asarray(log.mounting.barometer.translation, float)
            x0[2] = d[ok[0]] - lever[2]
    if cfg.initial_position is not None:
        x0[0:3] = cfg.initial_position
    x0[15:18] = cfg.gyro_bias_rad_s  # held at 0 by the variants without bias states
    return x0, np.diag(np.maximum(std, 1e-9) ** 2)


def _output_times(t: np.ndarray, rate_hz: float | None):
    if rate_hz is None:
        return np.empty(0), True, int(np.count_nonzero(np.diff(t)) + 1)
    out = np.arange(t[0], t[-1] + 0.5 / rate_hz, 1.0 / rate_hz)
    out = out[out <= t[-1]]
    return out, False, out.size
