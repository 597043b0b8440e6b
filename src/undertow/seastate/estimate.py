"""The sea state from the robot's own sensors (barometer, DVL, orientation), no wave probe:
:func:`estimate_sea_state`, the steps of :mod:`undertow.seastate` in order."""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError, DataError
from ..log import Log
from .directions import borrow, consensus_free, estimate_window, pool_straight
from .prepare import attach_track, check_options, crop, platform_models, prepare, water_density
from .result import SeaStateEstimate
from .signal import spectrum_peaks
from .windows import window_edges


def estimate_sea_state(
    log: Log,
    *,
    platform: str = "auto",
    window_periods: float = 20.0,
    step_fraction: float = 0.5,
    water_depth_m: float | None = None,
    water_density_kg_m3: float | None = None,
    t_start: float | None = None,
    t_end: float | None = None,
) -> SeaStateEstimate:
    """Estimate the wave condition (a, f, beta) per window from the robot's own sensors (see
    :mod:`undertow.seastate` for the model). ``platform``: "rigid" (held firm: barometer reads
    a K_p), "free" (rides the orbit: DVL sees it), or "auto" (the likelier, per window)."""
    check_options(platform, window_periods, step_fraction, water_depth_m, water_density_kg_m3,
                  t_start, t_end)  # fmt: skip
    if not isinstance(log, Log):
        raise ConfigError(f"estimate_sea_state: expected a Log, got {type(log).__name__}")
    rho = water_density(log, water_density_kg_m3)
    data = prepare(crop(log, t_start, t_end), rho, water_depth_m)
    t0 = min(float(c.t[0]) for c in data.channels)
    t1 = max(float(c.t[-1]) for c in data.channels)
    peaks, _ = spectrum_peaks(data.channels, t0, t1, 1)
    notes = list(dict.fromkeys(data.notes))
    period = 2 * np.pi / float(peaks[0]) if peaks.size else 1.0
    if t1 - t0 < 3 * period:
        raise DataError(
            f"sea-state estimate: the log spans {t1 - t0:.1f} s, less than 3 wave periods "
            f"({3 * period:.1f} s)"
        )
    data = attach_track(data, period)
    models = platform_models(data, platform, notes)
    notes.append(f"window length from the whole log's encounter period {period:.2f} s")
    length = float(window_periods) * period
    edges = window_edges(t0, t1, length, float(step_fraction) * length)
    first = pool_straight(data, [estimate_window(data, a, b, models) for a, b in edges])
    windows = borrow(data, consensus_free(data, first))
    step = edges[1][0] - edges[0][0] if len(edges) > 1 else t1 - t0
    return SeaStateEstimate(windows, edges[0][1] - edges[0][0], step, notes)


__all__ = ["estimate_sea_state"]
