"""What every peer estimator reads from a log: the UKF's sensors and noise, as plain arrays.

:func:`peer_inputs` resolves a run exactly as :func:`undertow.estimation.localizer.localize`
does (the same :class:`~undertow.estimation.config.LocalizerConfig`, the calibration's fields,
the start position from the ground truth, the water density of the log, the wave noise of the
noise profile for the run's condition) and builds the same measurement rows
(:mod:`undertow.estimation.rows`: the same envelopes, floors and wave noise gamma^2), then
expresses them in the body frame, which the peers' factors and filters use:

- IMU: gyro omega_b = R_imu z (rad/s), per-sample std ``imu_gyro_std_rad_s``; the specific force
  f_b = R_imu a (m/s^2, ``Imu.linear_acceleration``; at rest (0, 0, -g) in FRD) when the log has
  it. **The UKF does not read the accelerometer**: the peers do (IMU preintegration needs it);
  its per-sample std, bias walk and initial bias std are the peer-only settings
  ``accel_std_m_s2``, ``accel_bias_walk_density``, ``accel_bias_std_m_s2`` (defaults: the
  MPU-9250 datasheet's 300 ug/sqrt(Hz) at 100 Hz, and a MEMS order of magnitude, assumed).
- DVL: the velocity of the DVL point in the body frame, v_d = R_dvl z (z = v_measured / scale,
  DVL frame), with the row's covariance rotated, C_b = R_dvl R R_dvl^T (the log's covariance or
  ``dvl_velocity_std_m_s``, floored, plus gamma_DVL^2 for the variants with wave noise). The
  measurement model of the UKF (eq:dvl_meas_model) is v_d = v_b + omega_b x r_dvl; the gyro
  interpolated at each DVL time is ``dvl_gyro_rad_s`` (omega for the lever-arm term).
- Depth: d = (p - p_surface) / (rho g) (m) with std ``depth_std_m`` at the barometer's lever arm
  r_bar: d = z + e_3^T R r_bar (eq:bar_meas_model).
- DR orientation: roll, pitch, yaw of the body (rad), covariance diag(dr_orientation_std_rad^2)
  plus gamma_DR^2, modelled as z = (phi, theta, psi) + b^g (eq:dr_meas_model) with the DR bias
  b^g a random walk of density ``dr_bias_walk_density`` and mean drift mu_b
  (``dr_bias_drift_rad_s``) for the variants that estimate biases, held at its initial value
  otherwise.
- The initial state x0 and covariance P0 of the UKF (:func:`undertow.estimation.rows.initial_state`;
  the bias states at 0 for the variants without them, as the UKF holds them).

:func:`to_trajectory` turns a peer's estimates into an 18-state
:class:`~undertow.trajectory.Trajectory` (see its docstring for the states a peer does not
estimate).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..estimation.calibration import Calibration
from ..estimation.config import LocalizerConfig
from ..estimation.localizer import resolved_localizer, sensor_coverage
from ..estimation.rows import dr_rows, dvl_rows, imu_rows, initial_state, pressure_rows
from ..io.units import reading_record
from ..log import Log
from ..rotations import matrix_to_rpy
from ..trajectory import Trajectory

#: peer-only accelerometer settings (the UKF has none): per-sample white-noise std (m/s^2;
#: MPU-9250 datasheet 300 ug/sqrt(Hz) at 100 Hz), bias random-walk density ((m/s^2)^2/s,
#: assumed MEMS order) and initial bias std (m/s^2, an uncalibrated MEMS accelerometer, assumed)
ACCEL_STD_M_S2 = 0.03
ACCEL_BIAS_WALK_DENSITY = 1e-6
ACCEL_BIAS_STD_M_S2 = 0.05
#: the variance a state a peer does not estimate carries (the UKF's held bias states' variance)
HELD_VARIANCE = 1e-12


@dataclass(frozen=True, eq=False)
class PeerInputs:
    """The sensors and noise of one run, body frame, SI units (module doc). Streams a log lacks
    are empty arrays (``accel_m_s2`` is None without an accelerometer)."""

    config: LocalizerConfig
    t0: float  # the first measurement time (the UKF starts there)
    x0: np.ndarray  # (18,) the UKF's initial state
    P0: np.ndarray  # (18, 18) its covariance
    imu_t: np.ndarray  # (n,)
    gyro_rad_s: np.ndarray  # (n, 3) body
    accel_m_s2: np.ndarray | None  # (n, 3) body specific force, or None
    gyro_std_rad_s: np.ndarray  # (3,) per sample
    accel_std_m_s2: np.ndarray  # (3,) per sample
    gyro_bias_walk_density: np.ndarray  # (3,) (rad/s)^2/s (tiny when not estimated)
    accel_bias_walk_density: np.ndarray  # (3,) (m/s^2)^2/s
    accel_bias_std_m_s2: np.ndarray  # (3,) initial accelerometer bias std
    dvl_t: np.ndarray  # (m,)
    dvl_velocity_m_s: np.ndarray  # (m, 3) velocity of the DVL point, body frame
    dvl_covariance: np.ndarray  # (m, 3, 3) body frame, wave noise included when the variant adds it
    dvl_gyro_rad_s: np.ndarray  # (m, 3) gyro (body) interpolated at the DVL times (NaN: no IMU)
    dvl_lever_arm_m: np.ndarray  # (3,) r_dvl, body
    depth_t: np.ndarray  # (k,)
    depth_m: np.ndarray  # (k,)
    depth_std_m: np.ndarray  # (k,)
    baro_lever_arm_m: np.ndarray  # (3,) r_bar, body
    dr_t: np.ndarray  # (j,)
    dr_rpy_rad: np.ndarray  # (j, 3) body attitude reported by the DVL
    dr_covariance: np.ndarray  # (j, 3, 3)
    estimates_bias: bool  # the variant's bias states (gyro bias b-bar^g, DR bias b^g)
    dr_bias_walk_density: np.ndarray  # (3,) rad^2/s
    dr_bias_drift_rad_s: np.ndarray  # (3,) mu_b (zeros when the variant has no bias states)
    held: tuple[str, ...]  # bias groups held for want of their sensor (config.HELD_GROUPS)
    metadata: dict = field(default_factory=dict)

    @property
    def has_imu(self) -> bool:
        return self.imu_t.size > 0

    @property
    def has_accelerometer(self) -> bool:
        return self.accel_m_s2 is not None

    @property
    def t_end(self) -> float:
        ends = [a[-1] for a in (self.imu_t, self.dvl_t, self.depth_t, self.dr_t) if a.size]
        return float(max(ends))


def peer_inputs(
    log: Log,
    *,
    profile=None,
    wave=None,
    calibration: Calibration | str | Path | None = None,
    extrapolate: bool = False,
    accel_std_m_s2: float | None = None,
    accel_bias_walk_density: float | None = None,
    accel_bias_std_m_s2: float | None = None,
    **params,
) -> PeerInputs:
    """The run's :class:`PeerInputs`, resolved as :func:`~undertow.estimation.localizer.localize`
    resolves it (``params``: LocalizerConfig fields, e.g. ``variant``); the accelerometer's
    settings are the peers' own (module doc)."""
    localizer, calibration = resolved_localizer(log, profile, wave, calibration, extrapolate,
                                                params)  # fmt: skip
    cfg = localizer.config
    unobserved, held = sensor_coverage(log, cfg)
    noise, wave_meta = localizer.wave_noise(log)
    rejected: dict = {}
    imu = _imu(log, cfg, noise, rejected)
    dvl = _dvl(log, cfg, noise, rejected, imu)
    depth = _depth(log, cfg, noise, rejected)
    dr = _dr(log, cfg, noise, rejected)
    x0, P0 = initial_state(log, cfg)
    if not cfg.estimates_bias:  # the UKF holds its bias states at 0 (model.freeze_states)
        x0[12:18] = 0.0
    starts = [a[0] for a in (imu[0], dvl[0], depth[0], dr[0]) if a.size]
    bias = cfg.estimates_bias
    metadata = {
        "variant": cfg.variant,
        "counts": rejected,
        **wave_meta,
        "unobserved": unobserved,
        "held_bias": held,
        "config": cfg.model_dump(),
        "source": log.source,
        "log": reading_record(log.metadata),
    }
    if calibration is not None:
        metadata["calibration"] = calibration.to_dict()
    return PeerInputs(
        config=cfg, t0=float(min(starts)), x0=x0, P0=P0,
        imu_t=imu[0], gyro_rad_s=imu[1], accel_m_s2=imu[2],
        gyro_std_rad_s=np.maximum(np.array(cfg.imu_gyro_std_rad_s, float), cfg.std_floor),
        accel_std_m_s2=np.full(3, accel_std_m_s2 or ACCEL_STD_M_S2),
        gyro_bias_walk_density=np.array(cfg.gyro_bias_walk_density, float) if bias
        else np.full(3, HELD_VARIANCE),
        accel_bias_walk_density=np.full(3, accel_bias_walk_density or ACCEL_BIAS_WALK_DENSITY),
        accel_bias_std_m_s2=np.full(3, accel_bias_std_m_s2 or ACCEL_BIAS_STD_M_S2),
        dvl_t=dvl[0], dvl_velocity_m_s=dvl[1], dvl_covariance=dvl[2], dvl_gyro_rad_s=dvl[3],
        dvl_lever_arm_m=np.array(log.mounting.dvl.translation, float),
        depth_t=depth[0], depth_m=depth[1], depth_std_m=depth[2],
        baro_lever_arm_m=np.array(log.mounting.barometer.translation, float),
        dr_t=dr[0], dr_rpy_rad=dr[1], dr_covariance=dr[2],
        estimates_bias=bias,
        dr_bias_walk_density=np.array(cfg.dr_bias_walk_density, float) if bias
        else np.full(3, HELD_VARIANCE),
        dr_bias_drift_rad_s=np.array(cfg.dr_bias_drift_rad_s, float) if bias else np.zeros(3),
        held=tuple(held), metadata=metadata,
    )  # fmt: skip


def _floored(R: np.ndarray, floor: float) -> np.ndarray:
    """R with its diagonal floored at floor^2 (as the filter's merged rows are)."""
    R = np.array(R, float)
    i = np.arange(R.shape[1])
    R[:, i, i] = np.maximum(R[:, i, i], floor**2)
    return R


def _imu(log, cfg, noise, rejected):
    """(t, gyro body, specific force body or None) of the IMU rows the UKF keeps."""
    part = imu_rows(log, cfg, noise, rejected)
    if part is None:
        return np.zeros(0), np.zeros((0, 3)), None
    t, _, z, _, ok = part
    R_imu = log.mounting.imu.rotation_matrix()
    accel = log.imu.linear_acceleration
    if accel is not None:
        finite = np.isfinite(np.asarray(accel, float)).all(axis=1)
        rejected["rejected_accelerometer"] = int(np.count_nonzero(ok & ~finite))
        if np.any(ok & finite):
            ok = ok & finite
        else:
            accel = None
    f = None if accel is None else np.asarray(accel, float)[ok] @ R_imu.T
    return np.asarray(t, float)[ok], np.asarray(z, float)[ok] @ R_imu.T, f


def _dvl(log, cfg, noise, rejected, imu):
    """(t, velocity of the DVL point in the body, covariance in the body, gyro at t)."""
    t, _, z, R, ok = dvl_rows(log, cfg, noise, rejected)
    R_dvl = log.mounting.dvl.rotation_matrix()
    t = np.asarray(t, float)[ok]
    v = np.asarray(z, float)[ok] @ R_dvl.T
    C = R_dvl @ _floored(R[ok], cfg.std_floor) @ R_dvl.T
    gyro = np.full((t.size, 3), np.nan)
    if imu[0].size:
        gyro = np.stack([np.interp(t, imu[0], imu[1][:, j]) for j in range(3)], axis=1)
    return t, v, 0.5 * (C + np.swapaxes(C, 1, 2)), gyro


def _depth(log, cfg, noise, rejected):
    """(t, depth, std) of the barometer rows the UKF keeps."""
    part = pressure_rows(log, cfg, noise, rejected)
    if part is None:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    t, _, d, R, ok = part
    var = np.maximum(np.asarray(R, float)[ok, 0, 0], cfg.std_floor**2)
    return np.asarray(t, float)[ok], np.asarray(d, float)[ok, 0], np.sqrt(var)


def _dr(log, cfg, noise, rejected):
    """(t, body roll pitch yaw, covariance) of the DR rows the UKF keeps."""
    part = dr_rows(log, cfg, noise, rejected)
    if part is None:
        return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3))
    t, _, z, R, ok = part
    return np.asarray(t, float)[ok], np.asarray(z, float)[ok], _floored(R[ok], cfg.std_floor)


def euler_rate_matrix(rpy: np.ndarray) -> np.ndarray:
    """T(phi, theta) (n, 3, 3): rpy-rates = T omega_body (Fossen), so a body-frame attitude
    perturbation R Exp(d) changes (phi, theta, psi) by T d to first order."""
    rpy = np.atleast_2d(rpy)
    sr, cr = np.sin(rpy[:, 0]), np.cos(rpy[:, 0])
    sp, cp = np.sin(rpy[:, 1]), np.cos(rpy[:, 1])
    cp = np.where(np.abs(cp) < 1e-6, np.copysign(1e-6, cp), cp)
    T = np.zeros((rpy.shape[0], 3, 3))
    T[:, 0, 0] = 1.0
    T[:, 0, 1], T[:, 0, 2] = sr * sp / cp, cr * sp / cp
    T[:, 1, 1], T[:, 1, 2] = cr, -sr
    T[:, 2, 1], T[:, 2, 2] = sr / cp, cr / cp
    return T


def to_trajectory(
    inputs: PeerInputs,
    t: np.ndarray,
    R: np.ndarray,
    p: np.ndarray,
    v_world: np.ndarray,
    gyro_bias: np.ndarray,
    pose_cov: np.ndarray,
    *,
    estimator: str,
    attitude_error: str = "body",
    velocity_cov: np.ndarray | None = None,
    gyro_bias_cov: np.ndarray | None = None,
    dr_bias: np.ndarray | None = None,
    dr_bias_cov: np.ndarray | None = None,
    metadata: dict | None = None,
) -> Trajectory:
    """An 18-state :class:`~undertow.trajectory.Trajectory` from a peer's estimates at ``t``:
    attitude R (n, 3, 3) world from body, position p and velocity v (world, n x 3), gyro bias
    (body, n x 3) and the covariance ``pose_cov`` (n, 6, 6) of (d_theta, d_p) with d_p the world
    position error and d_theta the attitude error, R = R_hat Exp(d_theta) (``attitude_error``
    "body") or Exp(d_theta) R_hat ("world").

    The pose block of P is that marginal in the trajectory's parameters: with
    J = T(phi, theta) ("body") or T R^T ("world"), P[rpy] = J C_tt J^T, P[rpy, xyz] = J C_tp,
    P[xyz] = C_pp. Body velocity nu = R^T v with covariance R^T C_v R; angular velocity
    omega = gyro(t) - b (the gyro interpolated at t), variance gyro_std^2 + var(b). Blocks
    between groups are 0 (the peers give each group's marginal). States a peer does not estimate
    (the DR bias without ``dr_bias``; a velocity or bias without its covariance) keep their
    value (x0's DR bias) with the tiny variance the UKF gives its held states
    (:data:`HELD_VARIANCE`), and are named in ``metadata["not_estimated"]``: never NaN."""
    t = np.asarray(t, float)
    n = t.size
    rpy = matrix_to_rpy(R)
    x = np.zeros((n, 18))
    P = np.zeros((n, 18, 18))
    x[:, 0:3], x[:, 3:6] = p, rpy
    x[:, 6:9] = np.einsum("nji,nj->ni", R, v_world)
    J = euler_rate_matrix(rpy)
    if attitude_error == "world":
        J = J @ np.swapaxes(R, 1, 2)
    elif attitude_error != "body":
        raise ValueError(f"attitude_error {attitude_error!r}: expected 'body' or 'world'")
    C_tt, C_tp, C_pp = pose_cov[:, :3, :3], pose_cov[:, :3, 3:], pose_cov[:, 3:, 3:]
    P[:, 0:3, 0:3] = C_pp
    P[:, 3:6, 3:6] = J @ C_tt @ np.swapaxes(J, 1, 2)
    P[:, 3:6, 0:3] = J @ C_tp
    P[:, 0:3, 3:6] = np.swapaxes(P[:, 3:6, 0:3], 1, 2)
    missing = []
    held = np.broadcast_to(np.eye(3) * HELD_VARIANCE, (n, 3, 3))
    if velocity_cov is None:
        missing.append("body velocity covariance")
    Rt = np.swapaxes(R, 1, 2)
    P[:, 6:9, 6:9] = held if velocity_cov is None else Rt @ velocity_cov @ R
    x[:, 15:18] = gyro_bias
    P[:, 15:18, 15:18] = held if gyro_bias_cov is None else gyro_bias_cov
    if inputs.has_imu:
        gyro = np.stack([np.interp(t, inputs.imu_t, inputs.gyro_rad_s[:, j]) for j in range(3)], 1)
        x[:, 9:12] = gyro - gyro_bias
    i = np.arange(3)
    P[:, 9 + i, 9 + i] = inputs.gyro_std_rad_s**2 + P[:, 15 + i, 15 + i]
    if dr_bias is None:
        missing.append("DR bias b^g (held at x0's)")
        x[:, 12:15] = inputs.x0[12:15]
        P[:, 12:15, 12:15] = held
    else:
        x[:, 12:15] = dr_bias
        P[:, 12:15, 12:15] = held if dr_bias_cov is None else dr_bias_cov
    P = 0.5 * (P + np.swapaxes(P, 1, 2))
    meta = {
        **inputs.metadata,
        "estimator": estimator,
        "accelerometer": inputs.has_accelerometer,
        "not_estimated": missing + ["angular velocity (the gyro minus the bias estimate)"],
        **(metadata or {}),
    }
    return Trajectory(t, x, P, variant=estimator, metadata=meta)
