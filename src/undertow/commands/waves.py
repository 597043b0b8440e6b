"""`undertow waves` as a library function: the wave condition over time estimated from a log's
own sensors (:func:`undertow.seastate.estimate_sea_state`), with the truth the log
carries when it has one (a simulated run's scenario, a wave probe) for comparison::

    from undertow.commands.waves import waves_file

    result = waves_file("runs/a10/log", plot="waves.png")
    for row in result.estimate.to_table_rows():
        print(row)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._util.atomic import check_output_file
from ..errors import ConfigError
from ..estimation.characterize import estimate_waves
from ..log import Log
from ..settings import Settings
from ..wavetrack import WaveTrack
from .common import as_settings, collect_warnings, load_log

PLATFORMS = ("auto", "rigid", "free")


@dataclass(frozen=True, eq=False)
class WavesResult:
    """The estimate, the truth it is compared with (None without one), the warnings raised and
    the figure written (None when none was asked for)."""

    estimate: object  # undertow.seastate.SeaStateEstimate
    truth: WaveTrack | None
    warnings: tuple[str, ...]
    plot: Path | None = None

    def to_dict(self) -> dict:
        out = {"estimate": self.estimate.to_dict()}
        out["truth"] = None if self.truth is None else self.truth.to_dict()
        out["warnings"] = list(self.warnings)
        return out


def waves_file(path: str | Path, settings: Settings | str | Path | None = None, *,
               topics: str | Path | None = None, platform: str = "auto",
               window_periods: float = 20.0, step_fraction: float = 0.5,
               water_depth_m: float | None = None,
               plot: str | Path | None = None) -> WavesResult:  # fmt: skip
    """Estimate the sea state of the log at ``path`` (options checked before it is read);
    with ``plot``, draw the estimate (and the truth, when the log has one) to that PNG."""
    from ..seastate import estimate_sea_state

    if platform not in PLATFORMS:
        raise ConfigError(f"--platform must be one of {', '.join(PLATFORMS)}, not {platform!r}")
    if plot is not None:
        if Path(plot).suffix.lower() != ".png":
            raise ConfigError(f"--plot {plot}: the figure is a PNG file (name it *.png)")
        check_output_file(plot)
    settings = as_settings(settings)
    caught: list[str] = []
    with collect_warnings(caught):
        log = load_log(path, topics, settings)
        estimate = estimate_sea_state(
            log, platform=platform, window_periods=window_periods,
            step_fraction=step_fraction, water_depth_m=water_depth_m,
        )  # fmt: skip
        truth = true_wave_track(log, estimate.windows)
    figure = None
    if plot is not None:
        from ..report.figures_waves import plot_wave_estimate

        figure = plot_wave_estimate(estimate, plot, truth, title=str(path))
    return WavesResult(estimate, truth, tuple(caught), figure)


def true_wave_track(log: Log, windows=()) -> WaveTrack | None:
    """The wave condition the log records as truth: the simulator's condition in the metadata
    (exact), else the wave probe's spectral estimate over each of ``windows`` (or over the whole
    probe record without windows), else None."""
    recorded = log.metadata.get("wave")
    if isinstance(recorded, dict):
        try:
            return WaveTrack.from_dict(recorded, source="scenario")
        except ConfigError:
            pass
    probe = log.wave_probe
    if probe is None or len(probe) <= 16:
        return None
    spans = [(w.t_start, w.t_end) for w in windows] or [(probe.t[0], probe.t[-1])]
    t, a, f = [], [], []
    for t0, t1 in spans:
        inside = (probe.t >= t0) & (probe.t <= t1)
        if inside.sum() <= 16:
            continue
        est = estimate_waves(probe.select(inside))
        t.append(0.5 * (t0 + t1))
        a.append(0.0 if est.calm else est.amplitude_m)
        f.append(np.nan if est.calm else est.frequency_hz)
    if not t:
        return None
    return WaveTrack(np.array(t), np.array(a), np.array(f), "probe")
