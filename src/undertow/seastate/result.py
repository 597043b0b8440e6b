"""What the sea-state estimate returns: one :class:`WaveWindow` per window and the
:class:`SeaStateEstimate` of the whole log, with its plain forms (the waves command's JSON and
table, a config file's dict) and its :class:`~undertow.wavetrack.WaveTrack`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..wavetrack import WaveTrack


@dataclass(frozen=True)
class WaveWindow:
    """The wave condition fitted in one window (amplitude 0 and frequencies None when calm)."""

    t_start: float
    t_end: float
    amplitude_m: float
    frequency_hz: float | None
    encounter_frequency_hz: float | None
    significant_height_m: float
    direction_deg: float | None
    relative_direction_deg: float | None
    platform: str
    sensors: tuple[str, ...]
    explained: float
    notes: tuple[str, ...] = ()

    @property
    def calm(self) -> bool:
        return self.amplitude_m == 0.0

    def to_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out["sensors"], out["notes"] = list(self.sensors), list(self.notes)
        return out


@dataclass(frozen=True)
class SeaStateEstimate:
    """Windows of the estimate, the window length and step (s), and notes on the whole log."""

    windows: list[WaveWindow]
    window_s: float
    step_s: float
    notes: list[str] = field(default_factory=list)

    def track(self) -> WaveTrack:
        """The estimate as a :class:`WaveTrack` (source "estimated"), one node per window
        centre."""
        w = self.windows
        nan = float("nan")
        return WaveTrack(
            np.array([0.5 * (x.t_start + x.t_end) for x in w]),
            np.array([x.amplitude_m for x in w]),
            np.array([nan if x.frequency_hz is None else x.frequency_hz for x in w]),
            source="estimated",
            direction_deg=np.array(
                [nan if x.direction_deg is None else x.direction_deg for x in w]
            ),
        )

    def to_dict(self) -> dict:
        return {
            "window_s": self.window_s,
            "step_s": self.step_s,
            "notes": list(self.notes),
            "windows": [w.to_dict() for w in self.windows],
        }

    def to_table_rows(self) -> list[dict]:
        """One plain row per window for a table (None where unknown)."""

        def r(v, n):
            return None if v is None else round(float(v), n)

        return [
            {
                "t_start_s": r(w.t_start, 2), "t_end_s": r(w.t_end, 2),
                "amplitude_m": r(w.amplitude_m, 4), "frequency_hz": r(w.frequency_hz, 4),
                "encounter_hz": r(w.encounter_frequency_hz, 4),
                "hm0_m": r(w.significant_height_m, 4), "direction_deg": r(w.direction_deg, 1),
                "relative_deg": r(w.relative_direction_deg, 1), "platform": w.platform,
                "explained": r(w.explained, 3), "sensors": ",".join(w.sensors),
            }
            for w in self.windows
        ]  # fmt: skip


__all__ = ["SeaStateEstimate", "WaveWindow"]
