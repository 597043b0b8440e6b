"""LocalizerConfig: every parameter of the paper's UKF (section III-A), checked in one place.

The filter's numba loop takes two records built here: :meth:`LocalizerConfig.process_model`
(eq:dynamics_model's densities and drifts, the unscented weights, dt_max) and
:meth:`LocalizerConfig.sensor_model` (the log's mounting and the Mahalanobis gates).
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PlainValidator, field_validator
from pydantic_core import PydanticCustomError

from ..robot import Mounting
from . import model
from .ukf import weights

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]
PositiveVec3 = tuple[Positive, Positive, Positive]
NonNegativeVec3 = tuple[NonNegative, NonNegative, NonNegative]
Variant = Literal["baseline", "be", "an", "proposed", "adaptive-r"]
VARIANTS: tuple[str, ...] = Variant.__args__
# the default gate ("default"): an innovation of the DVL, DR or barometer whose NIS exceeds this,
# a 20-sigma Mahalanobis distance, is dropped; the IMU is not gated (its range envelope catches
# spikes, and a turn's legitimate innovations reach NIS ~5000: a gate would lock it out)
DEFAULT_GATE = "default"
DEFAULT_GATE_NIS = 20.0**2
# bias-state groups a log can leave without a sensor (ProcessModel.hold_*): the DR bias b^g
# (x[12:15], needs the DVL's dead reckoning) and the IMU gyro bias b-bar^g (x[15:18], the IMU)
HELD_GROUPS = ("dr_bias", "gyro_bias")


def _gate(value):
    """gate_probability: None (off), "default" or a chi-square probability in (0, 1)."""
    if value is None or value == DEFAULT_GATE:
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PydanticCustomError(
            "gate", "Input should be a probability in (0, 1), 'default' or null (off)"
        )
    value = float(value)
    if not np.isfinite(value):
        raise PydanticCustomError("finite_number", "Input should be a finite number")
    if value <= 0:
        raise PydanticCustomError("greater_than", "Input should be greater than 0")
    if value >= 1:
        raise PydanticCustomError("less_than", "Input should be less than 1")
    return value


Gate = Annotated[float | str | None, PlainValidator(_gate)]


class LocalizerConfig(BaseModel):
    """Filter parameters; units in the names. Densities are continuous-time (see model.py).

    Every number must be finite; standard deviations and acceleration densities must be > 0
    (measurement stds are also floored at ``std_floor``, so R is never 0); bias-walk densities
    may be 0 (a constant bias). Sigma points: alpha in [0.5, 2], beta in [0, 10], kappa in
    [0, 54]. The centre weight is W^m_0 = lambda / (n + lambda) = 1 - n / (alpha^2 (n + kappa)):
    kappa >= 0 and alpha >= 0.5 keep it >= -3 for n = 18, where the often quoted alpha = 1e-3
    gives W^m_0 ~ -1e6, which breaks the angle means and the positive definiteness of the
    covariances (Wan and van der Merwe, "The unscented Kalman filter for nonlinear
    estimation", 2000, suggest a small alpha, e.g. 1e-3).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    variant: Variant = "proposed"
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
    # the variants with wave noise (an, proposed) carry the swell's pressure head at the
    # barometer (variance a^2 K_p^2 / 2, noise_physics.pressure_head_variance) as two states of
    # a narrow-band wave model (model.py's module doc); False: eq:bar_meas_model with
    # depth_std_m alone, as the paper lists its wave noise (DVL and DR only)
    pressure_wave_noise: bool = True
    # the wave model's relative damping lambda: its band around the wave's frequency f is about
    # +-lambda f wide (a single regular wave is lambda -> 0; Fossen's MSS toolbox, exLinspec.m,
    # fits lambda to the PM and JONSWAP spectra from 0.1)
    swell_damping: float = Field(0.1, gt=0.0, lt=1.0, allow_inf_nan=False)
    # the waves' propagation direction beta (deg, world x-y, toward which they travel): the
    # swell band sits at the vehicle's encounter frequency (model.encounter); None: the log's
    # (metadata wave_heading_deg: a simulated log records it), else unknown (the band widened)
    wave_heading_deg: float | None = Field(None, allow_inf_nan=False)
    std_floor: Positive = 1e-6  # every measurement std is at least this
    dr_orientation_frame: Literal["body", "dvl"] = "body"
    # initial state (None: zeros, orientation from the first DR report, z from the first depth)
    initial_state: list[Finite] | None = None
    # start position (m, world) when initial_state is None; None: x = y = 0, z from the first
    # depth (localize() fills it from the log's ground truth when it has one)
    initial_position: Vec3 | None = None
    # initial IMU gyro bias mean b-bar^g (rad/s) when initial_state is None, e.g. from
    # `undertow calibrate`; only the variants that estimate biases (be, proposed) use it
    gyro_bias_rad_s: Vec3 = (0.0, 0.0, 0.0)
    # initial DR bias mean b^g (rad, roll pitch yaw) when initial_state is None: an offset of the
    # DVL's attitude reports, e.g. the pitch offset `undertow check` finds from the depth rate;
    # only the variants that estimate biases use it
    dr_bias_rad: Vec3 = (0.0, 0.0, 0.0)
    initial_std: list[NonNegative] = Field(
        default_factory=lambda: [0.01] * 3 + [0.05] * 3 + [0.1] * 3 + [0.05] * 3
        + [0.005] * 3 + [0.01] * 3
    )  # fmt: skip
    # sensors
    dvl_scale_factor: Positive = 1.0  # v_used = v_measured / scale
    # depth from pressure: None takes what the log reader resolved and stated (the log's
    # metadata: the surface pressure found in the log, the water of the settings' log section),
    # else fresh water (FRESH_WATER_DENSITY) and the standard atmosphere (P_ATM)
    water_density_kg_m3: Positive | None = None
    surface_pressure_pa: Positive | None = None
    # robustness and output
    # Mahalanobis gate: chi-square probability of the NIS quantile (every sensor), "default"
    # (DEFAULT_GATE_NIS for the DVL, DR and barometer) or None (off)
    gate_probability: Gate = DEFAULT_GATE
    # physical envelopes (None: no check): a measurement beyond one is rejected before the filter
    # and counted (rejected_<sensor>_<limit>); see docs/localization.md, "Robust defaults"
    dvl_max_speed_m_s: Positive | None = 2.0  # Water Linked DVL A50 datasheet: 2 m/s max velocity
    gyro_max_rate_rad_s: Positive | None = 34.9  # MEMS full scale +-2000 deg/s (ICM-20602)
    max_depth_m: Finite | None = 300.0  # DVL A50 and Bar30 depth rating: 300 m
    min_depth_m: Finite | None = -2.0  # above the surface beyond air-pressure/altitude offsets
    max_vertical_speed_m_s: Positive | None = 5.0  # depth rate no ROV reaches, heave included
    depth_jump_tolerance_m: NonNegative = 0.5  # sensor noise allowance of the depth-rate check
    max_dt_s: Positive = 1.0
    output_rate_hz: Positive | None = None  # None: every processed measurement time
    # sigma points (alpha ~0.5-1; NOT 1e-3 for n = 18)
    alpha: float = Field(1.0, ge=0.5, le=2.0, allow_inf_nan=False)
    beta: float = Field(2.0, ge=0.0, le=10.0, allow_inf_nan=False)
    kappa: float = Field(0.0, ge=0.0, le=3.0 * 18, allow_inf_nan=False)
    # adaptive-r: forgetting factor alpha of R_k = alpha R_{k-1} + (1 - alpha)(eps eps^T +
    # H P^+ H^T) (model.adapt_r). Akhlaghi et al. (2017) use alpha = 0.3 on 1-per-step power
    # system data; here R must follow the wave-induced variance, stationary over many wave
    # periods, not each wave's phase: 1 / (1 - alpha) = 50 updates, 6-10 s of the A50's
    # 5-8 Hz (6-10 periods of a 1 Hz wave), within the 0.95-0.99 fading factors usual for
    # Sage-Husa estimators (Sage and Husa 1969).
    adaptive_r_alpha: float = Field(0.98, gt=0.0, lt=1.0, allow_inf_nan=False)

    @field_validator("initial_state", "initial_std")
    @classmethod
    def _eighteen(cls, value):
        if value is not None and len(value) != model.N_POSE:
            raise ValueError(f"needs {model.N_POSE} values (one per state), got {len(value)}")
        return value

    @property
    def estimates_bias(self) -> bool:
        return self.variant in ("be", "proposed", "adaptive-r")

    @property
    def adapts_r(self) -> bool:
        """adaptive-r: the DVL and DR noise R adapted from the residuals (model.adapt_r)."""
        return self.variant == "adaptive-r"

    @property
    def adds_wave_noise(self) -> bool:
        return self.variant in ("an", "proposed")

    @property
    def adds_pressure_wave_noise(self) -> bool:
        """The swell's pressure head at the barometer is modelled (``pressure_wave_noise``): as
        the filter's swell states, as white noise in R for the estimators without them."""
        return self.adds_wave_noise and self.pressure_wave_noise

    def process_model(self, held=()) -> model.ProcessModel:
        """The record the filter and the smoother predict with: unscented weights of the
        filter's N_STATE states, Gamma densities, the mean drifts (zeros for the variants without
        bias states), the swell's damping. ``held``: names of :data:`HELD_GROUPS` held at 0
        because the log has no sensor that informs them."""
        wm, wc, lam = weights(model.N_STATE, self.alpha, self.beta, self.kappa)
        unknown = set(held) - set(HELD_GROUPS)
        if unknown:
            raise ValueError(f"held bias groups {sorted(unknown)}: expected {HELD_GROUPS}")
        drift = self.dr_bias_drift_rad_s + self.gyro_bias_drift_rad_s2
        return model.ProcessModel(
            wm=wm,
            wc=wc,
            lam=float(lam),
            q_acc=np.array(self.accel_density + self.angular_accel_density, float),
            q_bias=np.array(self.dr_bias_walk_density + self.gyro_bias_walk_density, float),
            mu_bias=np.array(drift, float) if self.estimates_bias else np.zeros(6),
            dt_max=float(self.max_dt_s),
            freeze_bias=not self.estimates_bias,
            hold_dr_bias="dr_bias" in held,
            hold_gyro_bias="gyro_bias" in held,
            swell_damping=float(self.swell_damping),
        )

    def sensor_model(self, mounting: Mounting) -> model.SensorModel:
        """The record the filter's measurement models use: ``mounting``'s rotations (as body ->
        sensor R^T) and lever arms, and the NIS gate per kind, the chi-square quantile of
        ``gate_probability`` with dim z degrees of freedom, or the default gate (inf: no gate)."""
        gate = np.full(len(model.KIND_DIM), np.inf)
        if self.gate_probability == DEFAULT_GATE:
            gate[:] = DEFAULT_GATE_NIS
            gate[model.IMU] = np.inf
        elif self.gate_probability is not None:
            from scipy.stats import chi2

            gate[:] = chi2.ppf(self.gate_probability, model.KIND_DIM)
        return model.SensorModel(
            imu_Rt=np.ascontiguousarray(mounting.imu.rotation_matrix().T),
            dvl_Rt=np.ascontiguousarray(mounting.dvl.rotation_matrix().T),
            dvl_r=np.array(mounting.dvl.translation, float),
            baro_r=np.array(mounting.barometer.translation, float),
            gate=gate,
            adapt_r=self.adapts_r,
            adapt_alpha=float(self.adaptive_r_alpha),
        )
