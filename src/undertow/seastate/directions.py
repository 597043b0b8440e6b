"""The waves' direction: whether a window observes it, and the passes over the windows that pool
it, check it against the neighbours' and lend it where a window does not observe it.

The free vehicle's orbital velocity gives beta (its axis, and the sense from the phase of the
vertical motion and the Doppler shift). A rigid mount sees beta only through the track, and only
when speed or heading vary in the window (at constant velocity only omega_e is observable): on a
curved track it is tested on the profile likelihood over beta (:func:`direction_status`); on a
straight track only c = cos(beta - course) enters, fitted in [-1.3, 1.3] (not clipped to +-1,
which would push a head-sea c = -1 inward and bias omega up) and pooled (median) over the
nearest windows where the speed changes (:func:`pool_straight`). A free window whose direction
strays from its neighbours' is refitted at theirs when that fits nearly as well
(:func:`consensus_free`). A window whose direction is not observable borrows it from the nearest
window where it was (and says so), else reports the encounter frequency as the intrinsic one
(at rest exact; moving: beam seas assumed) (:func:`borrow`).
"""

from __future__ import annotations

import bisect
import dataclasses

import numpy as np

from ..rotations import wrap_angle
from ..sim.waves import wavenumber
from .fit import BETAS, Direction, FitWindow, WaveFit, evaluate, fit_model, judge, ridge
from .prepare import SensorData
from .result import WaveWindow
from .windows import WindowEstimate, fit_window, sensors_used, window_result

POOL_WINDOWS = 4  # straight rigid tracks: informed windows pooled on each side
_CONSENSUS_LOGLIK = 10.0  # log-likelihood a neighbours' direction may cost (module doc)
_DIR_CHI2 = 10.8  # chi-square(1) at 99.9 %: a direction is rejected above this


def _steady(win: FitWindow) -> bool:
    """Constant velocity over the window: the mean velocities of its thirds agree within
    0.05 m/s (means, so the DVL noise averages out). Then only omega_e is observable, and a
    fit would favour beam seas, whose phase does not feel the track's integrated noise."""
    track = next((c for c in win.channels if c.x_m is not None), None)
    if track is None:
        return True
    thirds = np.array_split(np.arange(track.t.size), 3)
    means = np.array([[track.vx_m_s[i].mean(), track.vy_m_s[i].mean()] for i in thirds])
    return bool(np.max(np.hypot(*(means - means.mean(axis=0)).T)) < 0.05)


def _direction_profile(win: FitWindow, fit: WaveFit, weights) -> tuple[np.ndarray, np.ndarray]:
    """chi2 profile over the direction grid: each beta at its best omega, found by a 1-D zoom
    (all directions in one batch per level) from the ridge of the fitted encounter frequency."""
    w, b = fit.omega_rad_s, fit.beta_rad
    k = float(wavenumber(w, win.water_depth_m, win.gravity_m_s2))
    we = w - k * (win.mean_velocity_m_s @ [np.cos(b), np.sin(b)])
    step = 0.5 * 2 * np.pi / win.duration_s
    w0 = ridge(win, we, BETAS)
    w0 = np.where(np.isfinite(w0), w0, np.nan)
    ok = np.isfinite(w0)
    best = np.full(BETAS.size, np.inf)
    offs = np.array([-1.0, 0.0, 1.0])
    for _ in range(5):
        om = (w0[ok, None] + offs[None] * step).ravel()
        chi2 = evaluate(win, fit.model, np.maximum(om, 1e-3), np.repeat(BETAS[ok], 3),
                        weights)[0].reshape(-1, 3)  # fmt: skip
        j = np.argmin(chi2, axis=1)
        w0[ok] = w0[ok] + offs[j] * step
        best[ok] = chi2[np.arange(j.size), j]
        step /= 2
    return best, w0


def direction_status(win: FitWindow, fit: WaveFit, course: float) -> tuple[str, list[float]]:
    """("observed" | "mirror" | "unobservable" | "omega-only", rival betas): a beta whose
    profile chi2 is within the 99.9 % level of the best and more than 30 deg away is a rival;
    rivals only at the mirror image about the course leave omega determined ("mirror"); rivals
    whose omega is within 1 % of the fit's also leave omega determined ("omega-only")."""
    if not win.has_track:
        return "unobservable", []
    if fit.model == "free":
        return "observed", []  # the horizontal orbital velocity's axis and phase give it
    if _steady(win):
        return "unobservable", []
    if fit.mode == "cos":  # straight track: only c = cos(beta - course) is observable
        c = float(np.clip(fit.gain, -1.0, 1.0))
        if abs(c) > 0.97:
            return "observed", []
        spread = float(np.rad2deg(np.arccos(c)))
        rivals = [(np.rad2deg(course) + sign * spread) % 360 for sign in (1, -1)]
        return "mirror", rivals
    weights = fit.weights
    best = float(evaluate(win, fit.model, fit.omega_rad_s, fit.beta_rad, weights)[0][0])
    prof, om = _direction_profile(win, fit, weights)
    far = np.abs(wrap_angle(BETAS - fit.beta_rad)) > np.deg2rad(30)
    rival = far & (prof - best < _DIR_CHI2)
    if not rival.any():
        return "observed", []
    mirror = wrap_angle(2 * course - fit.beta_rad)
    near_mirror = np.abs(wrap_angle(BETAS - mirror)) <= np.deg2rad(30)
    rivals = [float(np.rad2deg(b) % 360) for b in BETAS[rival]]
    if not (rival & ~near_mirror).any():
        return "mirror", rivals
    if np.all(np.abs(om[rival] / fit.omega_rad_s - 1) < 0.01):
        return "omega-only", rivals
    return "unobservable", rivals


def estimate_window(data: SensorData, t0: float, t1: float, models: list[str]) -> WindowEstimate:
    """Pass 1 of one window: its fit and what its direction is worth (a direction to lend when
    omega is determined, a beam-sea refit when the direction is not observable)."""
    fit, win, notes = fit_window(data, t0, t1, models)
    sensors = sensors_used(data, fit)
    if fit is None or fit.calm:
        return WindowEstimate(window_result(data, t0, t1, fit, win, notes, sensors))
    status, rivals = direction_status(win, fit, win.course_rad)
    if status == "observed" or not win.has_track:
        if not win.has_track and fit.model == "rigid":
            notes.append("no track: frequency is the encounter frequency (vehicle assumed at "
                         "rest), direction not observable")  # fmt: skip
        result = window_result(data, t0, t1, fit, win, notes, sensors,
                               direction_known=status == "observed")  # fmt: skip
        return WindowEstimate(result, fit.direction, None, win, fit)
    shown = ", ".join(f"{r:.0f}" for r in rivals[:6])
    if status in ("mirror", "omega-only"):
        notes.append(f"direction not observable (also fits beta = {shown} deg)")
        # omega is determined: the fitted direction serves neighbours on the same course
        result = window_result(data, t0, t1, fit, win, notes, sensors)
        return WindowEstimate(result, fit.direction, None, win, fit)
    # pass 2 refits at a neighbour's direction, or for beam seas (course + 90 deg)
    result = window_result(data, t0, t1, fit, win, notes, sensors)
    beam = Direction(win.course_rad + np.pi / 2, 1.0)
    return WindowEstimate(result, None, beam, win, fit)


def pool_straight(data: SensorData, first: list[WindowEstimate]) -> list[WindowEstimate]:
    """Pass 2a: on a straight track a rigid window sees the direction only through
    c = cos(beta - course), and only while the speed changes; its c is noisy. The median c of
    the windows where it was determined, over the windows on the same course (within 10 deg),
    is the estimate for each of them (the sea's direction is assumed steady meanwhile): each
    is refitted with it. Only the nearest ``POOL_WINDOWS`` informed windows on each side count,
    so a slowly turning sea is followed. Returns ``first`` with those windows replaced."""
    out = list(first)
    fits = [(i, e.fit) for i, e in enumerate(first) if e.fit is not None]
    informed = [(i, fit) for i, fit in fits if fit.mode == "cos" and first[i].direction is not None]
    keys = [i for i, _ in informed]
    for i, fit in fits:
        if fit.mode != "cos" or fit.model != "rigid":
            continue
        win = first[i].window
        near = informed[max(bisect.bisect_left(keys, i) - POOL_WINDOWS, 0) :][: 2 * POOL_WINDOWS]
        same = [f for _, f in near if abs(wrap_angle(f.beta_rad - fit.beta_rad)) < 0.17]
        if not same or (len(same) == 1 and same[0] is fit):
            continue
        c = float(np.median([f.gain for f in same]))
        refit = fit_model(win, "rigid", fit.peaks_rad_s, Direction(fit.beta_rad, c))
        if refit is None:
            continue
        refit = judge(win, refit)
        w = first[i].result
        notes = [n for n in w.notes if not n.startswith("direction not observable")]
        note = (f"straight track: cos(beta - course) = {c:+.2f}, the median over {len(same)} "
                "windows where the speed changes")  # fmt: skip
        if abs(c) <= 0.97:
            note += f" (beta = course +- {np.rad2deg(np.arccos(np.clip(c, -1, 1))):.0f} deg)"
        result = window_result(data, w.t_start, w.t_end, refit, win, notes, w.sensors, note,
                               direction_known=abs(c) > 0.97)  # fmt: skip
        out[i] = dataclasses.replace(first[i], result=result, beam_sea=None)
    return out


def consensus_free(data: SensorData, first: list[WindowEstimate]) -> list[WindowEstimate]:
    """Pass 2b: a free window whose direction is more than 45 deg from the circular median of
    its neighbours' (``POOL_WINDOWS`` each side) is refitted at that median; the refit is kept
    when its log-likelihood is within ``_CONSENSUS_LOGLIK`` of the window's own (a likelihood
    ratio test at about 99.99 % for 2 parameters): where the horizontal orbital velocity is
    near the DVL's noise (a deep vehicle, following seas), the ridge omega - k V . e_beta =
    omega_e lets a wrong direction and frequency fit nearly as well, and the sea's direction
    is steadier than that."""
    out = list(first)
    free = [(i, e.fit) for i, e in enumerate(first) if e.fit is not None
            and e.fit.model == "free" and e.direction is not None]  # fmt: skip
    for n, (i, fit) in enumerate(free):
        others = [f.beta_rad for j, f in free[max(n - POOL_WINDOWS, 0) : n + POOL_WINDOWS + 1]
                  if j != i]  # fmt: skip
        if len(others) < 2:
            continue
        centre = circular_median(np.array(others))
        if abs(wrap_angle(fit.beta_rad - centre)) <= np.pi / 4:
            continue
        win = first[i].window
        refit = fit_model(win, "free", fit.peaks_rad_s, Direction(centre, 1.0))
        if refit is None or refit.loglik < fit.loglik - _CONSENSUS_LOGLIK:
            continue
        refit = judge(win, refit)
        w = first[i].result
        note = (f"direction {np.rad2deg(fit.beta_rad) % 360:.0f} deg replaced by the neighbours' "
                f"{np.rad2deg(centre) % 360:.0f} deg (log-likelihood "
                f"{refit.loglik - fit.loglik:+.1f})")  # fmt: skip
        result = window_result(data, w.t_start, w.t_end, refit, win, list(w.notes), w.sensors,
                               note, direction_known=True)  # fmt: skip
        out[i] = WindowEstimate(result, refit.direction, None, win, refit)
    return out


def circular_median(a: np.ndarray) -> float:
    """The element of ``a`` minimizing the sum of angular distances to the others."""
    d = np.abs(wrap_angle(a[:, None] - a[None, :])).sum(axis=1)
    return float(a[int(np.argmin(d))])


def borrow(data: SensorData, first: list[WindowEstimate]) -> list[WaveWindow]:
    """Pass 2: a window whose direction is not observable (one with a beam-sea direction) is
    refitted at the nearest observed window's direction, else for beam seas."""
    windows = [e.result for e in first]
    have = [i for i, e in enumerate(first) if e.direction is not None]
    known = [w.relative_direction_deg is not None for w in windows]
    out = list(windows)
    for i, e in enumerate(first):
        if e.beam_sea is None:
            continue
        w = windows[i]
        if have:
            j = min(have, key=lambda j: abs(j - i))
            beta, known_j = first[j].direction, known[j]
            note = (f"direction not observable in this window: taken from the window "
                    f"{windows[j].t_start:.1f}-{windows[j].t_end:.1f} s")  # fmt: skip
        elif np.hypot(*e.window.mean_velocity_m_s) < 0.05:
            beta, known_j = e.beam_sea, False
            note = "vehicle at rest: the encounter frequency is the wave frequency; no direction"
        else:
            beta, known_j = e.beam_sea, False
            note = ("direction not observable (steady course and speed): frequency from the "
                    "encounter frequency for beam seas")  # fmt: skip
        fit = fit_model(e.window, e.fit.model, e.fit.peaks_rad_s, beta)
        if fit is None:
            continue
        fit = judge(e.window, fit)
        notes = [n for n in w.notes if not n.startswith("direction not observable")]
        out[i] = window_result(data, w.t_start, w.t_end, fit, e.window, notes, w.sensors, note,
                               direction_known=known_j)  # fmt: skip
    return out


__all__ = [
    "POOL_WINDOWS",
    "borrow",
    "circular_median",
    "consensus_free",
    "direction_status",
    "estimate_window",
    "pool_straight",
]
