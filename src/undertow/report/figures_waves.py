"""The wave condition over time: the onboard estimate (:mod:`undertow.seastate`) per
window against the truth when there is one (a scenario's schedule, a wave probe)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..wavetrack import WaveTrack
from .figures import GROUND_TRUTH_COLOR, new_figure, save_figure


def plot_wave_estimate(estimate, path: str | Path, truth: WaveTrack | None = None,
                       title: str = "") -> Path:  # fmt: skip
    """Amplitude a (m) and frequency f (Hz) per estimation window (a bar over the window's
    span, a dot at its centre) and the truth as a line (``truth``, optional). ``estimate``: a
    SeaStateEstimate or its ``to_dict()`` (as a trajectory's metadata holds it)."""
    fig, (ax_a, ax_f) = new_figure(7.5, 4.6, 2, 1, sharex=True)
    windows = _windows(estimate)
    for w in windows:
        centre = 0.5 * (w.t_start + w.t_end)
        f = np.nan if w.frequency_hz is None else w.frequency_hz
        for ax, value in ((ax_a, w.amplitude_m), (ax_f, f)):
            ax.plot([w.t_start, w.t_end], [value, value], color="tab:blue", lw=1.0, alpha=0.5)
            ax.plot([centre], [value], "o", color="tab:blue", ms=3.5)
    ax_a.plot([], [], "o-", color="tab:blue", ms=3.5, label="estimated (window span)")
    if truth is not None:
        t0 = min(w.t_start for w in windows) if windows else 0.0
        t1 = max(w.t_end for w in windows) if windows else 1.0
        t = np.linspace(min(t0, truth.t[0]), max(t1, truth.t[-1]), 1000)
        a, f = truth.at(t)
        ax_a.plot(t, a, color=GROUND_TRUTH_COLOR, lw=1.5, label=f"truth ({truth.source})")
        ax_f.plot(t, f, color=GROUND_TRUTH_COLOR, lw=1.5)
    ax_a.set_ylabel("amplitude a (m)")
    ax_f.set_ylabel("frequency f (Hz)")
    ax_f.set_xlabel("time (s)")
    ax_a.legend(loc="best", fontsize=8)
    for ax in (ax_a, ax_f):  # from zero: an error reads against the size of the wave
        ax.grid(True, alpha=0.3)
        top = ax.get_ylim()[1]
        ax.set_ylim(0.0, top * 1.1 if np.isfinite(top) and top > 0 else 1.0)
    if title:
        ax_a.set_title(title)
    return save_figure(fig, path)


def _windows(estimate) -> list:
    if isinstance(estimate, dict):
        return [SimpleNamespace(**w) for w in estimate.get("windows", [])]
    return list(estimate.windows)
