"""The wave conditions a live session gave its filter (``undertow live --wave auto``), replayed
offline so that the replay of its recording gives the live trajectory.

Live, :class:`~undertow.seastate.online.OnlineSeaState` re-estimates the sea state every
``wave_update_s`` and the filter takes each new condition for the rows of the chunks released
from then on (:meth:`~undertow.estimation.online.OnlineLocalizer.set_wave`): the noise added to
a DVL or DR row is piecewise constant in time,

    gamma(t) = gamma(c_i)   for from_t_i <= t < from_t_(i+1),

with c_i the i-th condition, from_t_i the time of the first record of the chunk it was given
before (the live recording's ``/undertow/wave_condition``, :mod:`undertow.live.recorder`;
``from_t`` null: given before the filter started, so for every row), and calm before the first
(what the online filter starts with when it has no condition). The offline sea-state estimate
(``--wave auto`` on a log) fits the whole log at once and interpolates between its windows
(:class:`~undertow.estimation.noise.TrackNoise`): other numbers, so the replay of a live
recording takes these recorded decisions instead. Each gamma(c_i) is
:meth:`~undertow.estimation.noise.NoiseProfile.noise` of c_i with the filter's ``extrapolate``
policy and the profile's own site, as ``set_wave`` computes it: the same bits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..log import Log
from .noise import WaveNoise

#: where the condition came from, as the localizer's metadata says it
WAVE_LIVE = "the live session's wave conditions recorded in the bag (/undertow/wave_condition)"


@dataclass(frozen=True)
class StepNoise:
    """Wave noise that changes in steps (module docstring): ``nodes[i]`` for the rows at or
    after ``starts[i]`` (``starts[0]`` = -inf, the starting condition)."""

    starts: np.ndarray
    nodes: list[WaveNoise]

    @property
    def condition(self) -> str:
        return f"as the live session applied ({len(self.nodes) - 1} change(s))"

    def std_at(self, which: str, t: np.ndarray) -> np.ndarray:
        """(len(t), 3) std devs of ``which`` ("dvl" or "dr"): each row's step's, unchanged."""
        values = np.array([n.dvl_std if which == "dvl" else n.dr_std for n in self.nodes])
        index = np.searchsorted(self.starts, np.asarray(t, float), side="right") - 1
        return values[index]

    def wave_at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(amplitude m, frequency Hz) of each row's step (f NaN in a calm step)."""
        index = np.searchsorted(self.starts, np.asarray(t, float), side="right") - 1
        waves = [n.wave_at(np.zeros(1)) for n in self.nodes]
        a = np.array([w[0][0] for w in waves])
        f = np.array([w[1][0] for w in waves])
        return a[index], f[index]

    def to_dict(self) -> list[dict]:
        """Per step: the time it starts at (None: from the start) and its noise."""
        return [
            {"from_t": None if not np.isfinite(s) else float(s), **n.to_dict()}
            for s, n in zip(self.starts, self.nodes, strict=True)
        ]


def recorded_schedule(wave, log: Log) -> list[dict] | None:
    """The live session's wave decisions of ``log`` (``metadata["live_wave"]``) when the run
    asks for none in particular (``wave`` None) or for the sea state estimated from the data
    (``"auto"``, which the live session did); None otherwise."""
    entries = log.metadata.get("live_wave")
    asked = wave is None or (isinstance(wave, str) and wave.strip().lower() == "auto")
    if not entries or not asked:
        return None
    return list(entries)


def schedule_noise(profile, entries: list[dict], extrapolate) -> StepNoise:
    """:class:`StepNoise` of the recorded decisions ``entries`` (dicts with ``from_t`` and
    ``condition``: "calm" or [a, f]), each step's noise as the live filter computed it."""
    starts, nodes = [-np.inf], [profile.noise("calm", extrapolate=extrapolate)]
    for k, entry in enumerate(entries):
        try:
            condition = entry["condition"]
            if condition != "calm":
                condition = (float(condition[0]), float(condition[1]))
            from_t = entry["from_t"]
            start = -np.inf if from_t is None else float(from_t)
        except (KeyError, TypeError, ValueError, IndexError):
            raise ConfigError(f"live wave condition {k}: expected from_t and condition "
                              f"(\"calm\" or [a, f]), got {entry!r:.80}") from None  # fmt: skip
        noise = profile.noise(condition, extrapolate=extrapolate)
        if start == -np.inf:  # given before the filter started: every row so far
            starts, nodes = [-np.inf], [noise]
        else:
            starts.append(start)
            nodes.append(noise)
    if np.any(np.diff(starts) < 0):
        raise ConfigError("live wave conditions: their from_t times go backwards")
    return StepNoise(np.array(starts), nodes)


__all__ = ["StepNoise", "WAVE_LIVE", "recorded_schedule", "schedule_noise"]
