"""Robust defaults around the filter: physical envelopes checked before it, the mounting it
needs, and per-sensor health judged after it.

Envelopes (:class:`~undertow.estimation.config.LocalizerConfig` fields, None: no check): a
measurement no working sensor can produce is rejected before the filter and counted by name
(``rejected_dvl_speed``, ``rejected_imu_range``, ``rejected_pressure_depth``,
``rejected_pressure_rate``), with one warning per sensor:

- DVL: speed |v| above ``dvl_max_speed_m_s`` (2 m/s, the Water Linked DVL A50's rated maximum
  velocity, https://waterlinked.github.io/docs/dvl/dvl-a50/);
- IMU: any axis beyond ``gyro_max_rate_rad_s`` (34.9 rad/s = 2000 deg/s, the largest full-scale
  range of MEMS gyroscopes such as the TDK InvenSense ICM-20602 of BlueROV2 autopilot boards);
- pressure: depth outside [``min_depth_m``, ``max_depth_m``] (300 m, the DVL A50's depth
  rating), or a depth that departs from the median of its neighbours (5 samples each side)
  by more than ``max_vertical_speed_m_s`` x their time span + ``depth_jump_tolerance_m``:
  a vertical speed no ROV reaches (thrusters give about 1 m/s; wave heave of amplitude A at f
  adds 2 pi A f, 0.6 m/s for 0.1 m at 1 Hz). The median tolerates up to 5 consecutive spikes.

Health (:func:`warn_unhealthy`): a sensor most of whose measurements were rejected, gated or
reverted prints one warning naming it and the likely cause.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import DataError
from ..robot import Mounting
from . import model

# a sensor more than this fraction of whose measurements did not update the filter is reported
TROUBLE_FRACTION = 0.5
HALF_WINDOW = 5  # neighbours each side of the depth-rate check's median


def _warn(message: str) -> None:
    warnings.warn(message, RuntimeWarning, stacklevel=4)


def _first(t: np.ndarray, bad: np.ndarray) -> str:
    return f"first at t = {float(t[np.flatnonzero(bad)[0]]):.3f} s"


def dvl_inside(t, velocity, ok, max_speed, rejected: dict, warn: bool = True) -> np.ndarray:
    """``ok`` without the reports faster than ``max_speed`` (m/s; None: no check); ``warn``:
    one warning when any is rejected."""
    bad = np.zeros(len(t), bool)
    if max_speed is not None:
        w = np.where(ok[:, None], velocity, 0.0)
        with np.errstate(invalid="ignore", over="ignore"):  # |v| as numpy.linalg.norm sums it
            bad = ok & ~(np.sqrt(np.add.reduce(w * w, axis=1)) <= max_speed)
    rejected["rejected_dvl_speed"] = int(np.count_nonzero(bad))
    if warn and bad.any():
        _warn(f"dvl: {int(bad.sum())} of {len(t)} reports faster than {max_speed:g} m/s (the "
              f"rated maximum, dvl_max_speed_m_s) rejected, {_first(t, bad)}")  # fmt: skip
    return ok & ~bad


def imu_inside(t, rate, ok, max_rate, rejected: dict, warn: bool = True) -> np.ndarray:
    """``ok`` without the samples with an axis beyond ``max_rate`` (rad/s; None: no check);
    ``warn``: one warning when any is rejected."""
    bad = np.zeros(len(t), bool)
    if max_rate is not None:
        bad = ok & ~(np.abs(np.where(ok[:, None], rate, 0.0)) <= max_rate).all(axis=1)
    rejected["rejected_imu_range"] = int(np.count_nonzero(bad))
    if warn and bad.any():
        _warn(f"imu: {int(bad.sum())} of {len(t)} angular velocities beyond {max_rate:g} rad/s "
              f"(the gyro's range, gyro_max_rate_rad_s) rejected, {_first(t, bad)}")  # fmt: skip
    return ok & ~bad


def pressure_inside(t, depth, ok, cfg, rejected: dict, warn: bool = True,
                    jumps: bool = True) -> np.ndarray:  # fmt: skip
    """``ok`` without the depths outside [min_depth_m, max_depth_m] and (``jumps``) those
    implying a vertical speed above max_vertical_speed_m_s (see the module docstring; without
    ``jumps`` the caller applies :func:`depth_jumps` to the depths kept); ``warn``: one warning
    when any is rejected."""
    lo, hi = depth_envelope(cfg)
    out_of_range = ok & ~((depth >= lo) & (depth <= hi))
    inside = ok & ~out_of_range
    jumped = np.zeros(len(t), bool)
    if jumps and cfg.max_vertical_speed_m_s is not None:
        idx = np.flatnonzero(inside)
        jumped[idx] = depth_jumps(t[idx], depth[idx], cfg)
    rejected["rejected_pressure_depth"] = int(out_of_range.sum())
    if jumps:
        rejected["rejected_pressure_rate"] = int(jumped.sum())
    bad = out_of_range | jumped
    if warn and bad.any():
        _warn(
            f"pressure: {int(bad.sum())} of {len(t)} samples rejected ("
            f"{int(out_of_range.sum())} with a depth outside [{lo:g}, {hi:g}] m "
            f"(min_depth_m, max_depth_m), {int(jumped.sum())} implying a vertical speed above "
            f"{cfg.max_vertical_speed_m_s} m/s (max_vertical_speed_m_s)), {_first(t, bad)}"
        )
    return inside & ~jumped


def depth_envelope(cfg) -> tuple[float, float]:
    """(lowest, deepest) plausible depth (m) of the config (min_depth_m, max_depth_m)."""
    lo = -np.inf if cfg.min_depth_m is None else cfg.min_depth_m
    hi = np.inf if cfg.max_depth_m is None else cfg.max_depth_m
    return lo, hi


def depth_jumps(t, d, cfg) -> np.ndarray:
    """The depths d (inside the envelope) implying a vertical speed above
    ``cfg.max_vertical_speed_m_s`` (None: none); :func:`_depth_jumps`. Sample i depends on
    samples i - HALF_WINDOW .. i + HALF_WINDOW only (the window is cut at the ends)."""
    if cfg.max_vertical_speed_m_s is None:
        return np.zeros(len(t), bool)
    return _depth_jumps(t, d, cfg.max_vertical_speed_m_s, cfg.depth_jump_tolerance_m)


def _depth_jumps(t, d, v_max: float, tol: float) -> np.ndarray:
    """Samples farther from the median of the window around them (2 x HALF_WINDOW + 1
    samples) than v_max x the window's largest time offset + tol."""
    n, h = d.size, HALF_WINDOW
    if n < 3:
        return np.zeros(n, bool)
    pad_d = np.concatenate([np.full(h, np.nan), d, np.full(h, np.nan)])
    pad_t = np.concatenate([np.full(h, t[0]), t, np.full(h, t[-1])])
    window = np.arange(n)[:, None] + _WINDOW  # (rows of the windows, as sliding windows)
    median = _window_median(pad_d[window])
    span = np.max(np.abs(pad_t[window] - t[:, None]), axis=1)
    return np.abs(d - median) > v_max * span + tol


_WINDOW = np.arange(2 * HALF_WINDOW + 1)  # offsets of a window in the padded arrays


def _window_median(windows: np.ndarray) -> np.ndarray:
    """Median of each row ignoring NaN (the pads): the middle value of the n finite ones
    sorted, (s[n/2 - 1] + s[n/2]) / 2 for even n, as numpy.nanmedian computes it for rows this
    short (through numpy.ma.median), in a few vectorized steps (the online filter calls this
    for every new depth)."""
    s = np.sort(windows, axis=1)  # NaN last
    n = np.sum(~np.isnan(windows), axis=1)
    hi = n // 2
    lo = np.where(n % 2 == 1, hi, hi - 1)
    rows = np.arange(windows.shape[0])
    return (s[rows, lo] + s[rows, hi]) / 2.0


def check_mounting(mounting: Mounting) -> None:
    """One line (DataError) when a mounting rotation or lever arm the filter uses is not
    finite: every update through it would be reverted and the track would freeze."""
    for name in ("imu", "dvl", "barometer"):
        mount = getattr(mounting, name)
        for part in ("rotation", "translation"):
            values = np.asarray(getattr(mount, part), float)
            if not np.all(np.isfinite(values)):
                raise DataError(
                    f"mounting: the {name} {part} {tuple(values.tolist())} is not finite (a "
                    f"NaN or zero quaternion in /tf_static or the sidecar undertow.yaml?): set "
                    f"mounting.{name}.{part} in the settings file"
                )


_CAUSES = {
    "rejected_dvl_invalid": "marked invalid by the DVL (no bottom lock?)",
    "rejected_dvl_nonfinite": "not finite",
    "rejected_dvl_speed": "faster than the rated maximum (dvl_max_speed_m_s)",
    "rejected_imu": "not finite",
    "rejected_imu_range": "beyond the gyro's range (gyro_max_rate_rad_s)",
    "rejected_dead_reckoning": "not finite",
    "rejected_pressure": "not finite (check water_density_kg_m3, surface_pressure_pa)",
    "rejected_pressure_depth": "outside the depth envelope (min_depth_m, max_depth_m; check "
    "the pressure units and surface_pressure_pa)",
    "rejected_pressure_rate": "implying an impossible depth rate (max_vertical_speed_m_s)",
}
_REVERTED = {
    "dvl": "check the DVL mounting rotation and lever arm (settings, sidecar or /tf_static)",
    "imu": "check the IMU mounting rotation",
}


def per_sensor(counts: dict, rows: dict) -> dict:
    """Per sensor (model.KIND_NAMES): measurements in the log, used, rejected before the
    filter, gated, reverted (passed to the filter but neither used nor gated)."""
    out = {}
    for name in model.KIND_NAMES:
        rejected = {k: v for k, v in counts.items() if k.startswith(f"rejected_{name}") and v}
        used, gated = counts[f"used_{name}"], counts[f"gated_{name}"]
        passed = rows.get(name, 0)
        out[name] = {
            "total": passed + sum(rejected.values()),
            "used": used,
            "gated": gated,
            "reverted": max(passed - used - gated, 0),
            "rejected": rejected,
        }
    return out


def warn_unhealthy(sensors: dict, gate_probability) -> None:
    """One warning per sensor more than TROUBLE_FRACTION of whose measurements did not update
    the filter, naming the main reason and its likely cause."""
    for name, s in sensors.items():
        total = s["total"]
        lost = total - s["used"]
        if total == 0 or lost <= TROUBLE_FRACTION * total:
            continue
        reasons = {**{k: v for k, v in s["rejected"].items()}, "gated": s["gated"],
                   "reverted": s["reverted"]}  # fmt: skip
        worst = max(reasons, key=reasons.get)
        share = f"{100.0 * reasons[worst] / total:.0f} % of {total} measurements"
        if worst == "gated":
            gate = (
                "the default 20-sigma gate"
                if gate_probability == "default"
                else f"the chi-square {gate_probability} quantile"
            )
            why = (
                f"gated (innovation beyond {gate}): the data disagree with the model; try "
                "--gate off, check the noise parameters and the mounting"
            )
        elif worst == "reverted":
            why = f"reverted (the update failed numerically): {_REVERTED.get(name, 'check it')}"
        else:
            why = f"rejected before the filter: {_CAUSES.get(worst, worst)}"
        _warn(f"{name}: {share} {why}; the track barely uses this sensor")
