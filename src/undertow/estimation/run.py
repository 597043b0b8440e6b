"""Localize a log end to end and write the result folder (what `undertow localize` calls).

Adds to :class:`Localizer` the choices a command line needs:

- a calibration file (``undertow calibrate``) supplies the DVL scale factor and, for the
  variants with bias states (``be``, ``proposed``), mu_b (the DR bias drift) and the initial mean
  of the IMU gyro bias state, unless the caller sets them explicitly. ``baseline`` and ``an``
  have no bias states by the paper's definition, so they use neither (they still use the scale);
- the start position: DVL and IMU observe no absolute x, y, so it is given (``initial_position``),
  or ``"auto"``: the first ground-truth pose when the log has ground truth (simulated or tank
  runs), else the origin with z from the first depth;
- the water density: from the log's metadata when it records one (simulated logs), else the
  config's (fresh water, ``log.FRESH_WATER_DENSITY``).
"""

from __future__ import annotations

from pathlib import Path

import yaml

from .._atomic import output_folder
from .._plain import to_plain
from ..errors import ConfigError
from ..io.tum import write_tum
from ..log import Log
from ..trajectory import Trajectory
from .calibration import Calibration
from .localize import Localizer


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
    if calibration is not None and not isinstance(calibration, Calibration):
        calibration = Calibration.from_yaml(calibration)
    if calibration is not None:
        if variant in ("be", "proposed"):  # mu_b is a parameter of the bias model
            params.setdefault(
                "dr_bias_drift_rad_s", tuple(calibration.dead_reckoning_drift_rad_per_s)
            )
            if params.get("initial_state") is None:
                params.setdefault(
                    "initial_gyro_bias_rad_s", tuple(calibration.imu_gyro_bias_rad_per_s)
                )
        params.setdefault("dvl_scale_factor", calibration.dvl_scale_factor)
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


def save_trajectory(trajectory: Trajectory, out_dir: str | Path, overwrite: bool = False) -> Path:
    """Write ``trajectory.tum`` (evo), ``trajectory.npz`` (t, x, P) and ``config.yaml``, all
    at once (a non-empty folder is replaced only with ``overwrite``)."""
    with output_folder(out_dir, overwrite) as out:
        write_tum(out / "trajectory.tum", trajectory.t, trajectory.position, trajectory.orientation)
        trajectory.save_npz(out / "trajectory.npz")
        (out / "config.yaml").write_text(
            yaml.safe_dump(to_plain(trajectory.metadata), sort_keys=False)
        )
    return Path(out_dir)
