"""The scenario's sea state over time: its schedule as a :class:`~undertow.wavetrack.WaveTrack`
(the ground truth of the wave condition) and the wave the sensors see.

A schedule is a list of segments i = 0..n-1 in time order, segment i holding (a_i, f_i) until
``until_s`` T_i and reached by a linear ramp of ``ramp_s`` R_i from the condition before
(segment 0 from calm at t = 0 if R_0 > 0). The track's nodes are

    (0, 0) and (R_0, a_0, f_0)          or (0, a_0, f_0) without a first ramp,
    (T_{i-1}, a_{i-1}, f_{i-1}) and (T_{i-1} + R_i, a_i, f_i)      for i >= 1,
    (duration, a_{n-1}, f_{n-1})        when a duration is given,

linear in between (WaveTrack.at: a calm node has no frequency, so f is linear between the nodes
that have one and held outside them: from calm at the start, f is the first wave's f at once).
A constant sea (no schedule) is the one-node track (0, a, f).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..wavetrack import WaveTrack
from .wavefield import WaveField
from .waves import LinearWave


@dataclass(frozen=True)
class Segment:
    """A schedule segment with its frequency filled in: holds (a, f) from ``start_s + ramp_s``
    to ``until_s`` (None: to the end of the run); its ramp starts at ``start_s``."""

    index: int
    amplitude_m: float
    frequency_hz: float
    ramp_s: float
    start_s: float
    until_s: float | None


def segments(wave) -> list[Segment]:
    """The segments of ``wave.schedule`` (a scenario's WaveModel), frequencies filled in."""
    out, f_prev, start = [], wave.frequency_hz, 0.0
    for i, seg in enumerate(wave.schedule or ()):
        f = f_prev if seg.frequency_hz is None else seg.frequency_hz
        out.append(Segment(i, seg.amplitude_m, f, seg.ramp_s, start, seg.until_s))
        f_prev, start = f, (seg.until_s if seg.until_s is not None else float("inf"))
    return out


def schedule_track(wave, duration: float | None = None) -> WaveTrack:
    """The track of ``wave.schedule`` (nodes in the module docstring), source "scenario", the
    heading as ``direction_deg``. Assumes a checked schedule (times in order)."""
    nodes: list[tuple[float, float, float]] = []
    segs = segments(wave)
    for seg in segs:
        here = (seg.amplitude_m, seg.frequency_hz)
        if seg.index == 0:
            if seg.ramp_s > 0:
                nodes.append((0.0, 0.0, seg.frequency_hz))
            nodes.append((seg.ramp_s, *here))
        else:
            before = segs[seg.index - 1]
            nodes.append((seg.start_s, before.amplitude_m, before.frequency_hz))
            nodes.append((seg.start_s + seg.ramp_s, *here))
    if duration is not None and duration > nodes[-1][0]:
        nodes.append((float(duration), *nodes[-1][1:]))
    kept = [n for i, n in enumerate(nodes) if i == 0 or n != nodes[i - 1]]
    t, a, f = (np.array(v, float) for v in zip(*kept, strict=True))
    return WaveTrack(t, a, f, "scenario", np.full(t.size, float(wave.heading_deg)))


def wave_track(scenario, duration: float | None = None) -> WaveTrack:
    """The true wave condition of ``scenario`` over time (source "scenario", with the heading):
    its schedule's track (a last node at ``duration`` if given), or for a constant sea the
    one-node track (0, a, f) (f NaN when calm)."""
    w = scenario.wave
    if w.schedule is not None:
        return schedule_track(w, duration)
    f = w.frequency_hz if w.amplitude_m > 0 else np.nan
    return WaveTrack(
        np.zeros(1), np.array([w.amplitude_m]), np.array([f]), "scenario",
        np.array([float(w.heading_deg)]),
    )  # fmt: skip


def build_wave(s) -> LinearWave | WaveField:
    """The scenario's wave: a LinearWave for a constant sea, else a WaveField following the
    schedule, exact at the wave probe's position."""
    w = s.wave
    if w.schedule is None:
        return LinearWave(
            a=w.amplitude_m,
            f=w.frequency_hz,
            h=s.water.depth_m,
            beta=float(np.deg2rad(w.heading_deg)),
            phi_0=w.phase_rad,
            rho=s.water.density_kg_m3,
            g=s.water.gravity_m_s2,
        )
    return WaveField(
        schedule_track(w),
        h=s.water.depth_m,
        beta=float(np.deg2rad(w.heading_deg)),
        phi_0=w.phase_rad,
        rho=s.water.density_kg_m3,
        g=s.water.gravity_m_s2,
        reference_xy=(s.wave_probe.x_m, s.wave_probe.y_m),
    )
