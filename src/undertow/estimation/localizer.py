"""Localizer: Log -> Trajectory with the paper's UKF (section III-A) and its variants, and
:func:`localize`, the Localizer with the settings a run takes from its log and calibration.

Variants (the paper's ablation, tab:ablation): ``baseline`` (no bias states, no wave noise),
``be`` (bias estimation), ``an`` (added wave noise gamma in R), ``proposed`` (both). Without
bias estimation the six bias states are held at 0 with a tiny variance and no correlation.
``adaptive-r``, a peer baseline outside the paper: bias estimation as ``be``, no wave noise, and
the DVL and DR noise R adapted from the residuals after each update (Akhlaghi, Zhou and Huang
2017; :func:`~undertow.estimation.model.adapt_r`):

    R_k = alpha R_{k-1} + (1 - alpha) (eps_k eps_k^T + H P_k^+ H^T),   eps_k = z_k - h(x_k^+)

starting from the nominal R, alpha = ``adaptive_r_alpha`` (0.98).

Wave noise (variants ``an``, ``proposed``): a constant condition adds gamma^2 to every DVL (and
DR) row, and the swell's pressure head at the barometer (variance a^2 K_p^2 / 2) is carried by
the filter's two swell states (``pressure_wave_noise``; :mod:`~undertow.estimation.model`,
:func:`~undertow.estimation.rows.swell_columns`); a condition that
changes over time (a :class:`~undertow.wavetrack.WaveTrack`, a log whose ``metadata["wave"]`` is
a track with ``t`` lists, or ``wave="auto"``: estimated from the log by
:mod:`undertow.seastate`) adds each row's gamma(t)^2, gamma interpolated in time between the
track's nodes (:class:`~undertow.estimation.noise.TrackNoise`); the recording of a live session
with ``--wave auto`` replays the conditions that session gave its filter, in the steps it gave
them (:mod:`~undertow.estimation.wave_schedule`; with ``wave`` None or ``"auto"``: the replay
gives the live trajectory). A condition (or track node) outside the characterized ones gets the
``extrapolate`` policy (:mod:`~undertow.estimation.noise`): ``"physics"`` by default (False):
the nearest characterized condition scaled by the orbital velocity at the DVL's depth in the log
(:func:`~undertow.estimation.noise_physics.sensor_site`), stated in one warning and recorded in
``metadata["wave_noise"]``; ``"nearest"`` (True, ``--extrapolate``): the nearest as is;
``"refuse"``: an error (an estimated track is never refused: physics).

Sensors: the filter needs DVL velocity and an orientation source (the IMU gyro or the DVL's
dead-reckoning attitude); barometer and DR are optional. A state no sensor of the log informs is
left to the motion model and named in ``metadata["unobserved"]`` (one warning): without the IMU
its gyro bias b-bar^g is held at 0, without DR the DR bias b^g is held at 0 (and the initial
attitude comes from the ground truth, else the IMU's orientation report, else zeros), without a
barometer the depth is integrated from the DVL velocity only.

Measurements of all streams are merged (:mod:`undertow.estimation.rows`) and processed in time
order (a prediction per measurement, as in the paper; :mod:`undertow.estimation.filter_loop`); see
:mod:`undertow.estimation.model` for the equations.

:class:`Localizer` runs with exactly its :class:`~undertow.estimation.config.LocalizerConfig`;
:func:`localize` (what ``undertow localize`` runs) fills, for every field the caller leaves
unset:

- from a calibration file (``undertow calibrate``): the DVL scale factor and, for the variants
  with bias states (``be``, ``proposed``), mu_b (the DR bias drift) and the initial mean of the
  IMU gyro bias state. ``baseline`` and ``an`` have no bias states by the paper's definition,
  so they use neither (they still use the scale). Only the parameters the file lists as
  ``estimated`` are used, with one warning naming those the variant needs that calibrate left
  at its default;
- the start position: DVL and IMU observe no absolute x, y, so it is given
  (``initial_position``), else the first ground-truth pose when the log has ground truth
  (simulated or tank runs), else the origin with z from the first depth;
- the water density: from the log's metadata when it records one (simulated logs), else the
  config's (fresh water).

Smoothing needs the filter output at every measurement: ``smooth`` with ``output_rate_hz`` is
refused before anything runs (:func:`check_options`).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .._util.validate import validate
from ..errors import ConfigError, MissingStreamError
from ..io.units import reading_record
from ..log import Log
from ..trajectory import Trajectory
from ..trajectory_chunks import StoredTrajectory, TrajectoryStore
from ..wavetrack import WaveTrack
from . import filter_loop, model
from .calibration import Calibration
from .config import LocalizerConfig
from .consistency import innovation_consistency
from .health import check_mounting, per_sensor, warn_unhealthy
from .noise import NoiseProfile
from .noise_physics import PHYSICS, REFUSE, extrapolation_note, outside_policy, sensor_site
from .rows import depth_reference, initial_state, measurements, start_attitude
from .smoother import smooth as urts_smooth
from .smoother import smooth_store
from .wave_schedule import WAVE_LIVE, recorded_schedule, schedule_noise

# a run where more than this fraction of the processed measurements needed a covariance repair
# or a reverted step (or were gated) is reported: the track is then mostly frozen
TROUBLE_FRACTION = 0.5
# where a run's wave condition came from (metadata "wave_condition_source"), besides the place
# in the log that recorded it
WAVE_GIVEN = "given"
WAVE_DEFAULT = "default"
WAVE_ESTIMATED = "estimated from the log (undertow.seastate)"
WAVE_AUTO = "auto"
# measurements filtered between two appends to a trajectory store (about 10 000 states)
FILTER_ROWS = 12_000


class MissingSensorError(ConfigError, MissingStreamError):
    """The log lacks what the filter needs: DVL velocity and an orientation source (one line).
    A ConfigError as a wrong input, and a MissingStreamError for callers that catch those."""


class Localizer:
    """The paper's UKF. ``Localizer(variant="proposed", wave="wave-a0.10-f1.00").run(log)``.

    ``profile``: a NoiseProfile, a YAML path or None (the paper's Table I); ``wave``: condition
    name, (amplitude, frequency), a :class:`~undertow.wavetrack.WaveTrack` (or its dict),
    ``"auto"`` (estimated from the log) or None (``log.metadata["wave"]`` if present, else calm);
    ``variant`` and the other keyword arguments are :class:`LocalizerConfig` fields (unset ones
    keep the config's defaults).
    """

    def __init__(self, variant: str | None = None, profile=None, wave=None,
                 extrapolate: bool = False, **params) -> None:  # fmt: skip
        if variant is not None:
            params["variant"] = variant
        self.config = validate(LocalizerConfig, params, "Localizer: ")
        if isinstance(profile, NoiseProfile) or profile is None:
            self.profile = profile or NoiseProfile.paper()
        else:
            self.profile = NoiseProfile.from_yaml(profile)
        self.wave = wave
        self.extrapolate = outside_policy(extrapolate, default=PHYSICS)

    def run(self, log: Log, store: TrajectoryStore | None = None,
            store_rows: int = FILTER_ROWS) -> Trajectory:  # fmt: skip
        """Filter the whole log; (x, P) at every processed measurement time (or output rate).
        The metadata records the wave condition used and where it came from, the states the
        log's sensors leave unobserved, and the innovations' consistency per sensor
        (``consistency``, :mod:`undertow.estimation.consistency`).

        With ``store`` (a :class:`~undertow.trajectory_chunks.TrajectoryStore`; no output rate)
        the states go to it every ``store_rows`` measurements (:func:`filter_to_store`) and a
        :class:`~undertow.trajectory_chunks.StoredTrajectory` is returned: the same states, on
        disk."""
        cfg = with_log_heading(self.config, log)
        if store is not None and cfg.output_rate_hz is not None:
            raise ConfigError("Localizer: a trajectory store takes every state (output_rate_hz "
                              "None); a decimated trajectory fits in memory")  # fmt: skip
        unobserved, held = sensor_coverage(log, cfg)
        check_mounting(log.mounting)
        noise, wave_meta = self.wave_noise(log)
        meas, rejected = measurements(log, cfg, noise)
        if meas.size == 0:
            raise ConfigError("Localizer: the log has no finite, valid DVL/IMU measurements")
        x0, P0 = initial_state(log, cfg)
        r_adapted = np.zeros((len(model.KIND_NAMES), 3, 3))
        whitened = np.full((meas.size, 3), np.nan)  # each row's innovation, for the report
        records = (meas, x0, P0, cfg.process_model(held=held), cfg.sensor_model(log.mounting))
        if store is None:
            out_t, out_x, out_P, counts, nis = filter_loop.run_filter(
                meas, float(meas["t"][0]), *records[1:],
                _output_times(meas["t"], cfg.output_rate_hz), r_adapted, whitened,
            )  # fmt: skip
        else:
            counts, nis = filter_to_store(*records, r_adapted, whitened, store, store_rows)
        consistency = innovation_consistency(meas["kind"], whitened)
        rows = np.bincount(meas["kind"], minlength=len(model.KIND_NAMES))
        metadata = run_metadata(log, cfg, (rejected, counts, nis, rows, r_adapted), consistency,
                                wave_meta, (unobserved, held))  # fmt: skip
        if store is not None:
            return StoredTrajectory(store, variant=cfg.variant, metadata=metadata)
        return Trajectory(out_t, out_x, out_P, variant=cfg.variant, metadata=metadata)

    def wave_noise(self, log: Log, site=None):
        """(noise, metadata): the run's wave noise (:class:`WaveNoise` for a constant condition,
        :class:`TrackNoise` for one that changes; for a live recording asked for no condition or
        "auto", the live session's own decisions: :mod:`.wave_schedule`) and its metadata
        entries (module doc). ``site``: a callable giving the DVL's site of the whole log
        (default :func:`~undertow.estimation.noise_physics.sensor_site` of ``log``), called
        only when a condition is extrapolated by physics (elsewhere the site plays no part)."""
        schedule = recorded_schedule(self.wave, log)
        if schedule is not None:
            noise = schedule_noise(self.profile, schedule, self.extrapolate)
            return noise, {
                "wave_noise": noise.to_dict() if self.config.adds_wave_noise else None,
                "wave_condition": noise.condition,
                "wave_condition_source": WAVE_LIVE,
                "wave_schedule": schedule,
            }
        wave, source = wave_condition(self.wave, log)
        meta = {}
        estimated = False
        if isinstance(wave, str) and wave.strip().lower() == WAVE_AUTO:
            wave, estimate = _estimated_track(log)
            source, estimated = WAVE_ESTIMATED, True
            meta["wave_estimate"] = estimate.to_dict()
        elif isinstance(wave, dict) and "t" in wave:
            wave = WaveTrack.from_dict(wave)
        if isinstance(wave, WaveTrack):
            estimated = estimated or wave.source == "estimated"
            if wave.is_constant:
                a, f = float(wave.amplitude_m[0]), float(wave.frequency_hz[0])
                wave = "calm" if a == 0 else (a, f)
        policy = PHYSICS if estimated and self.extrapolate == REFUSE else self.extrapolate
        cfg = self.config
        if site is None:
            site = lambda: sensor_site(log, *depth_reference(log, cfg),  # noqa: E731
                                       default=self.profile.site())  # fmt: skip
        noise = self._condition_noise(wave, policy, None)
        if policy == PHYSICS and extrapolation_note(noise):  # the site plays a part
            noise = self._condition_noise(wave, policy, site())
        if isinstance(wave, WaveTrack):
            meta["wave_track"] = wave.to_dict()
        note = extrapolation_note(noise)
        if note and cfg.adds_wave_noise:
            warnings.warn(f"Localizer: {note}", RuntimeWarning, stacklevel=3)
        meta = {
            "wave_noise": noise.to_dict() if self.config.adds_wave_noise else None,
            "wave_condition": noise.condition,
            "wave_condition_source": source,
            **meta,
        }
        return noise, meta

    def _condition_noise(self, wave, policy, site):
        """The profile's noise of ``wave`` (a condition or a WaveTrack) at ``site``."""
        if isinstance(wave, WaveTrack):
            return self.profile.noise_track(wave, extrapolate=policy, site=site)
        return self.profile.noise(wave, extrapolate=policy, site=site)


def run_metadata(log: Log, cfg: LocalizerConfig, run: tuple, consistency, wave_meta: dict,
                 coverage: tuple) -> dict:  # fmt: skip
    """The metadata of a run (:meth:`Localizer.run`) from ``run`` = (rows rejected up front,
    the filter's counts and NIS sums, rows per sensor kind, adaptive-r's R), the innovations'
    ``consistency`` report, the wave entries and ``coverage`` = (unobserved, held); warns when
    the track is frozen or a sensor unhealthy."""
    rejected, counts, nis, rows, r_adapted = run
    counts = {**rejected, **dict(zip(filter_loop.COUNT_NAMES, counts.tolist(), strict=True))}
    _warn_if_frozen(counts, int(rows.sum()))
    sensors = per_sensor(counts, dict(zip(model.KIND_NAMES, rows.tolist(), strict=True)))
    warn_unhealthy(sensors, cfg.gate_probability)
    metadata = {
        "variant": cfg.variant,
        "counts": counts,
        "sensors": sensors,
        "nis": nis_summary(nis),
        "consistency": consistency.to_dict(),
        **wave_meta,
        "unobserved": coverage[0],
        "held_bias": coverage[1],
        "config": cfg.model_dump(),
        "source": log.source,
        "log": reading_record(log.metadata),
    }
    if cfg.adapts_r:
        metadata["adaptive_r"] = adapted_summary(r_adapted, rows, cfg.adaptive_r_alpha)
    return metadata


def filter_to_store(meas, x0, P0, process, sensors, r_adapted, innovations, store,
                    rows: int = FILTER_ROWS) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """:func:`~undertow.estimation.filter_loop.run_filter` (every state, no output rate) with
    its states appended to ``store`` after each ``rows`` measurements
    (:func:`~undertow.estimation.filter_loop.resume_filter`: the same states bit for bit).
    Returns (counts, nis)."""
    state = filter_loop.start_state(float(meas["t"][0]), x0, P0, process, r_adapted)
    for k0 in range(0, meas.size, rows):
        k1 = min(k0 + rows, meas.size)
        out = filter_loop.resume_filter(meas[k0:k1], state, process, sensors, k1 == meas.size,
                                        innovations[k0:k1])  # fmt: skip
        store.append(*out)
    return state.counts, state.nis


def resolved_localizer(log: Log, profile, wave, calibration, extrapolate, params: dict,
                       smooth: bool = False) -> tuple[Localizer, Calibration | None]:  # fmt: skip
    """(the Localizer :func:`localize` runs on ``log``, the calibration read): the options
    checked, and the fields filled from the calibration (a Calibration or its YAML file) and
    the log (the start position from its ground truth, its water density)."""
    config = check_options(smooth, params)
    if calibration is not None and not isinstance(calibration, Calibration):
        calibration = Calibration.from_yaml(calibration)
    filled = {} if calibration is None else calibration_fields(calibration, config)
    if log.ground_truth is not None and len(log.ground_truth):
        filled["initial_position"] = tuple(float(v) for v in log.ground_truth.position[0])
    if "water_density_kg_m3" in log.metadata:
        filled["water_density_kg_m3"] = float(log.metadata["water_density_kg_m3"])
    localizer = Localizer(profile=profile, wave=wave, extrapolate=extrapolate,
                          **{**filled, **params})  # fmt: skip
    return localizer, calibration


def localize(
    log: Log,
    variant: str | None = None,
    profile=None,
    wave=None,
    calibration: Calibration | str | Path | None = None,
    extrapolate: bool = False,
    smooth: bool = False,
    store: TrajectoryStore | None = None,
    **params,
) -> Trajectory:
    """Run the UKF ``variant`` on ``log`` (optionally URTS-smoothed); see the module docstring
    for what it fills from the log and ``calibration`` (a Calibration or its YAML file).
    With ``store`` the states are filtered into it and smoothed there, backward chunk by chunk
    (:func:`~undertow.estimation.smoother.smooth_store`), and a
    :class:`~undertow.trajectory_chunks.StoredTrajectory` is returned."""
    if variant is not None:
        params["variant"] = variant
    localizer, calibration = resolved_localizer(log, profile, wave, calibration, extrapolate,
                                                params, smooth)  # fmt: skip
    trajectory = localizer.run(log, store=store)
    if smooth and store is not None:
        meta = smooth_store(store, trajectory.metadata, localizer.config)
        trajectory = trajectory.replace(metadata=meta)
    elif smooth:
        trajectory = urts_smooth(trajectory, localizer.config)
    if calibration is not None:
        trajectory.metadata["calibration"] = calibration.to_dict()
    return trajectory


def check_options(smooth: bool, params: dict) -> LocalizerConfig:
    """The LocalizerConfig of ``params`` (a ConfigError names a wrong field), refusing smoothing
    of a decimated output: the smoother needs the filter output at every measurement."""
    config = validate(LocalizerConfig, params, "Localizer: ")
    if smooth and config.output_rate_hz is not None:
        raise ConfigError(
            f"smoothing (--smooth) needs the filter output at every measurement: drop "
            f"output_rate_hz={config.output_rate_hz} (--output-rate, or the settings file's) or "
            "the smoothing"
        )
    return config


def with_log_heading(cfg: LocalizerConfig, log: Log) -> LocalizerConfig:
    """``cfg`` with the waves' direction ``wave_heading_deg`` the log records (metadata
    ``wave_heading_deg``, a simulated log's) when the config leaves it None and the variant
    models the swell; as it is otherwise."""
    if cfg.wave_heading_deg is not None or not cfg.adds_pressure_wave_noise:
        return cfg
    try:
        value = float(log.metadata.get("wave_heading_deg"))
    except (TypeError, ValueError):
        return cfg
    return cfg.model_copy(update={"wave_heading_deg": value}) if np.isfinite(value) else cfg


def calibration_fields(calibration: Calibration, config: LocalizerConfig) -> dict:
    """The config fields ``calibration`` supplies to ``config``'s variant: those it estimated
    (all of them in a file that does not say). One warning names those the variant would use
    but that were left at their default, so a run is never quietly 'calibrated' with defaults.
    The barometer's noise ``depth_std_m`` goes to the variants that carry the swell apart (its
    states, ``pressure_wave_noise``): for the others the barometer's R must hold the swell too,
    so they keep the configured value."""
    names = ["dvl_scale_factor"]
    if config.adds_pressure_wave_noise:
        names.append("depth_std_m")
    if config.estimates_bias:  # mu_b and the gyro bias belong to the bias model
        names.append("dr_bias_drift_rad_s")
        if config.initial_state is None:
            names.append("gyro_bias_rad_s")
    estimated = calibration.estimated
    skipped = [n for n in names if estimated is not None and n not in estimated]
    if skipped:
        reasons = calibration.left_at_default or {}
        detail = "; ".join(f"{n} ({reasons.get(n, 'not estimated')})" for n in skipped)
        warnings.warn(
            f"calibration: not estimated by `undertow calibrate`, the filter's setting is used "
            f"for {detail}",
            RuntimeWarning,
            stacklevel=3,
        )
    return {n: getattr(calibration, n) for n in names if n not in skipped}


def wave_condition(wave, log: Log) -> tuple[object, str]:
    """The wave condition a run uses and where it comes from: ``wave`` when given, else the
    log's metadata (a simulated log, or a bag whose sidecar ``undertow.yaml`` records it), else
    calm. Returns (condition, source): source is :data:`WAVE_GIVEN`, :data:`WAVE_DEFAULT` or
    where in the log the condition was found (e.g. ``"the bag's sidecar undertow.yaml"``).
    The condition may be a WaveTrack or its dict (``t`` lists), or ``"auto"``."""
    if wave is not None:
        return wave, WAVE_GIVEN
    recorded = log.metadata.get("wave")
    if recorded is not None:
        sidecar = log.metadata.get("format") == "rosbag" and "recorded" in log.metadata
        if sidecar:
            return recorded, "the bag's sidecar undertow.yaml"
        return recorded, f"the metadata of {log.source}" if log.source else "the log's metadata"
    return "calm", WAVE_DEFAULT


def _estimated_track(log: Log):
    """(track, estimate): the sea state estimated from the log itself (wave="auto")."""
    try:
        from ..seastate import estimate_sea_state
    except ImportError as exc:  # pragma: no cover - the module ships with the package
        msg = f"Localizer: wave 'auto' needs undertow.seastate ({exc})"
        raise ConfigError(msg) from None
    estimate = estimate_sea_state(log)
    return estimate.track(), estimate


def sensor_coverage(log: Log, cfg: LocalizerConfig) -> tuple[list[str], list[str]]:
    """(unobserved, held): one line per state the log's sensors leave to the motion model, and
    the bias groups (config.HELD_GROUPS) held at 0 for want of their sensor; one warning names
    them. A log without DVL velocity or without an orientation source (IMU gyro or DR attitude)
    is one :class:`MissingSensorError` line."""
    has = {n: getattr(log, n) is not None and len(getattr(log, n)) > 0
           for n in ("dvl", "imu", "dead_reckoning", "pressure")}  # fmt: skip
    where = f" ({log.source})" if log.source else ""
    if not has["dvl"]:
        raise MissingSensorError(
            f"Localizer: the log{where} has no DVL velocity (stream dvl): the filter needs it "
            "and an orientation source (an IMU gyro or the DVL's dead reckoning, position_local); "
            f"it has: {', '.join(log.streams()) or 'none'}"
        )
    if not (has["imu"] or has["dead_reckoning"]):
        raise MissingSensorError(
            f"Localizer: the log{where} has DVL velocity but no orientation source: needs an "
            "IMU gyro (stream imu) or the DVL's dead reckoning (position_local, stream "
            f"dead_reckoning); it has: {', '.join(log.streams())}"
        )
    units = log.metadata.get("imu_units")
    if has["imu"] and isinstance(units, dict) and units.get("unit") == "ambiguous":
        raise MissingSensorError(
            f"Localizer: the gyro's unit in the log{where} is ambiguous ({units.get('evidence')});"
            " set it in the settings file: log: {imu_units: deg/s} (or rad/s)"
        )
    unobserved, held = [], []
    if not has["imu"]:
        held.append("gyro_bias")
        unobserved.append("no IMU: the IMU gyro bias b-bar^g (x[15:18]) is held at 0; the "
                          "angular velocity is inferred from the DR attitude alone")  # fmt: skip
    if not has["dead_reckoning"]:
        held.append("dr_bias")
        start = start_attitude(log)[1]
        unobserved.append(
            "no DVL dead reckoning: the DR bias b^g (x[12:15]) is held at 0; roll, pitch and yaw "
            f"are integrated from the IMU gyro only, their variance grows; {start}"
        )
        if cfg.estimates_bias and has["imu"]:
            unobserved.append(
                "no DVL dead reckoning: the IMU gyro bias b-bar^g (x[15:18]) is not separable from "
                "the angular velocity (only its prior, e.g. gyro_bias_rad_s of `undertow "
                "calibrate`, and the DVL lever arm inform it)"
            )
    if not has["pressure"]:
        unobserved.append("no barometer: depth from DVL integration only, its variance grows")
    if unobserved:
        warnings.warn(f"Localizer: {'; '.join(unobserved)}", RuntimeWarning, stacklevel=3)
    return unobserved, held


def adapted_summary(r_adapted: np.ndarray, rows: np.ndarray, alpha: float) -> dict:
    """adaptive-r's final R per adapted sensor (DVL, DR) with the run's alpha."""
    out = {"alpha": float(alpha)}
    for kd in (model.DVL, model.DR):
        if rows[kd]:
            out[model.KIND_NAMES[kd]] = {"final_R": r_adapted[kd].tolist()}
    return out


def _warn_if_frozen(counts: dict, n_measurements: int) -> None:
    """One warning line when most processed measurements needed a covariance repair or a
    reverted step: the filter then barely moves (inconsistent parameters, or data far from
    the model). Gated and rejected measurements are judged per sensor
    (:func:`~undertow.estimation.health.warn_unhealthy`)."""
    processed = n_measurements - counts["nonfinite_rejected"]
    if processed <= 0:
        return
    troubled = {
        "covariance repairs": counts["cholesky_repairs"],
        "reverted steps": counts["numerical_reverts"],
    }
    worst = max(troubled, key=troubled.get)
    if troubled[worst] > TROUBLE_FRACTION * processed:
        warnings.warn(
            f"Localizer: {troubled[worst]} {worst} for {processed} measurements; the track is "
            "probably frozen or wrong (check the noise parameters, the mounting and the data)",
            RuntimeWarning,
            stacklevel=3,
        )


def nis_summary(stats: np.ndarray) -> dict:
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


def _output_times(t: np.ndarray, rate_hz: float | None):
    """None (every distinct measurement time) or the times t0 + k / rate up to the last."""
    if rate_hz is None:
        return None
    out = np.arange(t[0], t[-1] + 0.5 / rate_hz, 1.0 / rate_hz)
    return out[out <= t[-1]]
