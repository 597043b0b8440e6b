"""Localize a log end to end and write the result folder (what `undertow localize` calls).

Adds to :class:`Localizer` the choices a command line needs:

- a calibration file (``undertow calibrate``) supplies the DVL scale factor and, for the
  variants with bias states (``be``, ``proposed``), mu_b (the DR bias drift) and the initial mean
  of the IMU gyro bias state, unless the caller sets them explicitly. ``baseline`` and ``an``
  have no bias states by the paper's definition, so they use neither (they still use the scale).
  Only the parameters the file lists as ``estimated`` are used, with one warning naming those the
  variant needs that calibrate left at its default;
- smoothing needs the filter output at every measurement: ``smooth`` with ``output_rate_hz`` is
  refused before the filter runs;
- the start position: DVL and IMU observe no absolute x, y, so it is given (``initial_position``),
  or ``"auto"``: the first ground-truth pose when the log has ground truth (simulated or tank
  runs), else the origin with z from the first depth;
- the water density: from the log's metadata when it records one (simulated logs), else the
  config's (fresh water, ``log.FRESH_WATER_DENSITY``).
"""

from __future__ import annotations

import warnings
from pathlib import Path

from ..errors import ConfigError
from ..log import Log
from ..trajectory import Trajectory
from .calibration import Calibration
from .localizer import Localizer


def localize(
    log: Log,
    variant: str = "proposed",
    profile=None,
    wave=None,
    calibration: Calibration | str | Path | None = None,
    initial_position="auto",
    extrapolate: bool = False,
    smooth: bool = False,
    **params,
) -> Trajectory:
    """Run the UKF ``variant`` on ``log``; see the module docstring for the defaults it fills."""
    if smooth and params.get("output_rate_hz") is not None:
        raise ConfigError(
            f"smoothing needs the filter output at every measurement: drop output_rate_hz="
            f"{params['output_rate_hz']} (--output-rate) or the smoothing (--smooth)"
        )
    if calibration is not None and not isinstance(calibration, Calibration):
        calibration = Calibration.from_yaml(calibration)
    if calibration is not None:
        _apply_calibration(calibration, variant, params)
    if isinstance(initial_position, str):
        if initial_position != "auto":
            raise ConfigError(
                f"initial_position must be 'auto' or (x, y, z), not {initial_position!r}"
            )
        if log.ground_truth is not None and len(log.ground_truth):
            params.setdefault(
                "initial_position", tuple(float(v) for v in log.ground_truth.position[0])
            )
    elif initial_position is not None:
        params["initial_position"] = tuple(float(v) for v in initial_position)
    if "water_density_kg_m3" in log.metadata:
        params.setdefault("water_density_kg_m3", float(log.metadata["water_density_kg_m3"]))
    localizer = Localizer(
        variant=variant, profile=profile, wave=wave, extrapolate=extrapolate, **params
    )
    trajectory = localizer.run(log)
    if smooth:
        from .smoother import smooth as urts_smooth

        trajectory = urts_smooth(trajectory, localizer.config)
    if calibration is not None:
        trajectory.metadata["calibration"] = calibration.to_dict()
    return trajectory


def _apply_calibration(calibration: Calibration, variant: str, params: dict) -> None:
    """Fill ``params`` from the parameters ``calibration`` estimated (all of them in a file that
    does not say); one warning names those the variant would use but that were left at their
    default, so a run is never quietly 'calibrated' with defaults."""
    estimated = calibration.estimated
    uses = {"dvl_scale_factor": ("dvl_scale_factor", calibration.dvl_scale_factor)}
    if variant in ("be", "proposed"):  # mu_b and the gyro bias belong to the bias model
        uses["dr_bias_drift_rad_s"] = (
            "dr_bias_drift_rad_s",
            tuple(calibration.dr_bias_drift_rad_s),
        )
        if params.get("initial_state") is None:
            uses["gyro_bias_rad_s"] = (
                "gyro_bias_rad_s",
                tuple(calibration.gyro_bias_rad_s),
            )
    skipped = []
    for name, (field, value) in uses.items():
        if estimated is None or name in estimated:
            params.setdefault(field, value)
        else:
            skipped.append(name)
    if skipped:
        reasons = calibration.left_at_default or {}
        detail = "; ".join(f"{n} ({reasons.get(n, 'not estimated')})" for n in skipped)
        warnings.warn(
            f"calibration: not estimated by `undertow calibrate`, the filter's setting is used "
            f"for {detail}",
            RuntimeWarning,
            stacklevel=3,
        )
