"""The windows of the sea-state estimate: their edges, each window's channels cut and high-passed
for the fit, the best platform model's fit in it, and the :class:`WaveWindow` a fit gives.

Per window of about 20 wave periods (stepped by half a window) the rigid and free models are
fitted (:mod:`undertow.seastate.fit`) and the one with the larger profile likelihood
-1/2 sum_c n_c log(RSS_c / n_c) is kept ("auto" tries the free model when the DVL shows the
encounter peak); the high-pass follows the fitted encounter frequency. H_m0 = 4 sqrt(m0) =
2 sqrt(2) a for a regular wave. The vehicle is assumed slower than the waves (omega_e > 0, the
rising branch of omega - k U).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..rotations import wrap_angle
from .fit import Direction, FitWindow, WaveFit, encounter, fit_model, judge
from .prepare import Channel, SensorData
from .result import WaveWindow
from .signal import circular_mean, highpass, spectrum_peaks

MIN_VELOCITY_PEAK = 100.0  # auto: the free model is tried when the DVL shows the encounter peak
_CLEAR_LOGLIK = 50.0  # free over rigid-at-its-direction: no full rigid search needed


@dataclass(frozen=True, eq=False)
class WindowEstimate:
    """One window as the passes over the windows see it: its ``result``; the fitted
    ``direction`` a neighbour may borrow (None unless omega is determined); the beam-sea
    direction to refit at when the window's own is not observable and no neighbour lends one
    (None when the window needs no refit); the window and fit (None when calm)."""

    result: WaveWindow
    direction: Direction | None = None
    beam_sea: Direction | None = None
    window: FitWindow | None = None
    fit: WaveFit | None = None


def window_edges(t0: float, t1: float, length: float, step: float) -> list[tuple[float, float]]:
    """(start, end) of the windows of ``length`` s stepped by ``step`` s over [t0, t1]: one
    window when the span is shorter than 1.5 lengths."""
    span = t1 - t0
    if span < 1.5 * length:
        return [(t0, t1)]
    n = int(math.ceil((span - length) / step)) + 1
    starts = np.linspace(t0, t1 - length, n)
    return [(float(s), float(s + length)) for s in starts]


def _track_summary(chans: list[Channel], vs: list):
    """(mean velocity, distinct velocities (the mean and at 5 times, 0.05 m/s apart), course,
    straight) of a window's track."""
    v_mean = np.mean(vs, axis=0) if vs else np.zeros(2)
    segments = [v_mean]
    track = next((c for c in chans if c.x_m is not None), None)
    if track is not None:
        for i in np.linspace(0, track.t.size - 1, 5).astype(int):
            v = np.array([track.vx_m_s[i], track.vy_m_s[i]])
            if all(np.hypot(*(v - s)) > 0.05 for s in segments):
                segments.append(v)
    course = float(np.arctan2(v_mean[1], v_mean[0])) if np.hypot(*v_mean) > 1e-3 else 0.0
    straight = True
    if track is not None:
        perp = -track.x_m * np.sin(course) + track.y_m * np.cos(course)
        straight = bool(np.ptp(perp) < 0.1)
    return v_mean, segments, course, straight


def slice_window(data: SensorData, t0: float, t1: float, omega_e: float | None):
    """The :class:`FitWindow` of [t0, t1] (None without 8 samples of any channel): times from
    t0, track from its value at t0, data high-passed over one encounter period (``omega_e``;
    1 s when unknown)."""
    chans, n_hp, tss, n = [], [], [], []
    period = 2 * np.pi / omega_e if omega_e else 1.0
    vs = []
    for c in data.channels:
        i0, i1 = np.searchsorted(c.t, t0, "left"), np.searchsorted(c.t, t1, "right")
        if i1 - i0 < 8:
            continue
        nh = max(int(round(period * c.rate_hz)), 1)
        y = c.value[i0:i1]
        prev = chans[-1] if chans else None
        same = prev is not None and prev.name == c.name and prev.t.size == i1 - i0
        t_rel = prev.t if same else c.t[i0:i1] - t0
        track = {}
        if c.x_m is not None:
            track = {"x_m": c.x_m[i0:i1] - c.x_m[i0], "y_m": c.y_m[i0:i1] - c.y_m[i0],
                     "vx_m_s": c.vx_m_s[i0:i1], "vy_m_s": c.vy_m_s[i0:i1]}  # fmt: skip
        hp = highpass(y - y.mean(), nh)
        sub = Channel(c.name, c.kind, t_rel, hp, c.depth_m, c.rate_hz, **track)
        if track:
            vs.append([sub.vx_m_s.mean(), sub.vy_m_s.mean()])
        chans.append(sub)
        n_hp.append(nh)
        tss.append(float(sub.value @ sub.value))
        n.append(float(sub.value.size))
    if not chans:
        return None
    has_track = any(c.x_m is not None for c in chans)
    v_mean, segments, course, straight = _track_summary(chans, vs)
    return FitWindow(chans, n_hp, np.array(tss), np.array(n), t1 - t0, has_track, v_mean,
                     segments, course, straight, data.water_depth_m, data.gravity_m_s2)  # fmt: skip


def _fit_models(win: FitWindow, models: list[str], peaks) -> list[WaveFit]:
    """The fits of ``models``. With both, the free model first; the rigid one is first fitted
    only at the free fit's direction, and searched in full unless the free fit is better than
    that by more than ``_CLEAR_LOGLIK`` (the same wave drives the barometer either way, so the
    rigid optimum is then near the free one's and the search would not change the choice)."""
    if models != ["rigid", "free"]:
        return [f for m in models if (f := fit_model(win, m, peaks)) is not None]
    free = fit_model(win, "free", peaks)
    rigid = None
    if free is not None:
        quick = fit_model(win, "rigid", np.array([abs(encounter(win, free))]), free.direction)
        if quick is not None and free.loglik - quick.loglik > _CLEAR_LOGLIK:
            rigid = quick
    rigid = rigid or fit_model(win, "rigid", peaks)
    return [f for f in (rigid, free) if f is not None]


def fit_window(data: SensorData, t0: float, t1: float, models: list[str]):
    """(the best fit, judged and with its peaks, or None; the window; notes) for [t0, t1]."""
    notes: list[str] = []
    inside = []
    for c in data.channels:
        i0, i1 = np.searchsorted(c.t, t0, "left"), np.searchsorted(c.t, t1, "right")
        if i1 - i0 >= 8:
            inside.append(Channel(c.name, c.kind, c.t[i0:i1], c.value[i0:i1], c.depth_m,
                                  c.rate_hz))  # fmt: skip
    peaks, prominence = spectrum_peaks(inside, t0, t1) if inside else (np.array([]), 0.0)
    if peaks.size == 0:
        return None, None, ["too few samples in the window for a spectrum"]
    if len(models) > 1 and prominence < MIN_VELOCITY_PEAK:
        models = ["rigid"]
        notes.append("rigid: the DVL velocity shows no orbital peak")
    omega_hp = float(peaks[0])
    for _ in range(2):  # the high-pass follows the fitted encounter frequency
        win = slice_window(data, t0, t1, omega_hp)
        if win is None:
            return None, win, ["too few samples in the window for a spectrum"]
        fits = _fit_models(win, models, peaks)
        if not fits:
            return None, win, ["no encounter frequency in the searched band"]
        best = max(fits, key=lambda f: f.loglik)
        we = abs(encounter(win, best))
        if abs(we / omega_hp - 1) < 0.2:
            break
        omega_hp, peaks = we, np.r_[we, peaks]
    if len(fits) > 1:
        other = min(fits, key=lambda f: f.loglik)
        notes.append(f"{best.model} fits better than {other.model} (log-likelihood "
                     f"{best.loglik - other.loglik:+.1f})")  # fmt: skip
    best = judge(win, best, peaks_rad_s=peaks)
    return best, win, notes


def sensors_used(data: SensorData, fit: WaveFit | None) -> tuple[str, ...]:
    """The sensors a fit used: a rigid fit uses the IMU only for the track."""
    if fit is not None and fit.model == "rigid":
        return tuple(s for s in data.sensors if s != "imu" or data.velocity is not None)
    return data.sensors


def window_result(
    data: SensorData,
    t0,
    t1,
    fit: WaveFit | None,
    win: FitWindow | None,
    notes,
    sensors,
    beta_note=None,
    direction_known: bool = False,
) -> WaveWindow:
    """The WaveWindow of a fit (calm if the fit is None or calm); its direction only when
    ``direction_known`` and the window has a track."""
    notes = list(notes)
    heading = 0.0
    if data.heading is not None:
        m = (data.heading[0] >= t0) & (data.heading[0] <= t1)
        heading = circular_mean(data.heading[1][m])
    if fit is None or fit.calm:
        model = fit.model if fit else ("rigid" if "pressure" in sensors else "free")
        notes = [*notes, "calm: no wave stands out of the noise"]
        return WaveWindow(t0, t1, 0.0, None, None, 0.0, None, None, model, sensors,
                          float(fit.explained) if fit else 0.0, tuple(notes))  # fmt: skip
    a, w, b = fit.amplitude_m, fit.omega_rad_s, fit.beta_rad
    if fit.gain < 0:  # a fitted cos(beta - course) < 0: the waves come from ahead
        b = b + np.pi
    we = encounter(win, fit)
    if we <= 0:
        notes.append("encounter frequency <= 0: the vehicle outruns the waves (assumed not)")
    direction = relative = None
    if direction_known and win.has_track:
        relative = float(180.0 - (180.0 - np.rad2deg(wrap_angle(b - heading))) % 360)
        if data.frame == "world":
            direction = float(np.rad2deg(b) % 360)
    if beta_note:
        notes.append(beta_note)
    return WaveWindow(
        float(t0), float(t1), a, float(w / (2 * np.pi)), float(abs(we) / (2 * np.pi)),
        2.0 * math.sqrt(2.0) * a, direction, relative, fit.model, sensors,
        float(fit.explained), tuple(notes),
    )  # fmt: skip


__all__ = [
    "MIN_VELOCITY_PEAK",
    "WindowEstimate",
    "fit_window",
    "sensors_used",
    "slice_window",
    "window_edges",
    "window_result",
]
