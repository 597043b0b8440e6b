"""The sea state estimated while the data arrives:
:func:`~undertow.seastate.estimate_sea_state` over a sliding window of the latest records.

Every ``update_s`` seconds of sensor time, the records of the last ``window_s`` seconds (IMU,
DVL, dead reckoning, pressure) are fitted as one log and the newest complete window of that
estimate is the current condition (a, f). The window must hold about 20 wave periods for the
fit (the offline estimator's window, see :mod:`undertow.seastate.windows`), so ``window_s`` =
60 s serves waves down to about 0.35 Hz; until it spans three periods there is no estimate.
What a live filter adds to its measurement noise is then piecewise constant in time, changing at
the updates.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass

from ..errors import DataError
from ..records import Record, records_to_log
from ..robot import Mounting
from .estimate import estimate_sea_state
from .result import WaveWindow

#: the streams the estimator reads
WAVE_STREAMS = ("imu", "dvl", "dead_reckoning", "pressure")


@dataclass(frozen=True)
class WaveUpdate:
    """One update: the sensor time it was made at and the newest window fitted."""

    t: float
    window: WaveWindow

    @property
    def condition(self):
        """ "calm" or (amplitude m, frequency Hz), as the filters take a wave condition."""
        w = self.window
        if w.calm or w.frequency_hz is None:
            return "calm"
        return (float(w.amplitude_m), float(w.frequency_hz))


class OnlineSeaState:
    """Keeps the last ``window_s`` s of records and re-estimates every ``update_s`` s."""

    def __init__(self, mounting: Mounting | None = None, *, window_s: float = 60.0,
                 update_s: float = 10.0, water_depth_m: float | None = None) -> None:  # fmt: skip
        self.mounting = mounting or Mounting()
        self.window_s = float(window_s)
        self.update_s = float(update_s)
        self.water_depth_m = water_depth_m
        self._records: collections.deque[Record] = collections.deque()
        self._next = -math.inf
        self.updates: list[WaveUpdate] = []
        self.failures = 0

    def push(self, records: list[Record]) -> WaveUpdate | None:
        """Add released records (time order); returns the new condition when one was made."""
        for r in records:
            if r.stream in WAVE_STREAMS:
                self._records.append(r)
        if not self._records:
            return None
        t_new = self._records[-1].t
        while self._records and self._records[0].t < t_new - self.window_s:
            self._records.popleft()
        if self._next == -math.inf:
            self._next = self._records[0].t + self.update_s
        if t_new < self._next:
            return None
        self._next = t_new + self.update_s
        return self._estimate(t_new)

    def _estimate(self, t_new: float) -> WaveUpdate | None:
        log = records_to_log(self._records).replace(mounting=self.mounting)
        try:
            estimate = estimate_sea_state(log, water_depth_m=self.water_depth_m)
        except DataError:  # too short yet, or a stream missing: no estimate this time
            self.failures += 1
            return None
        if not estimate.windows:
            return None
        update = WaveUpdate(t_new, estimate.windows[-1])
        self.updates.append(update)
        return update

    def to_dict(self) -> dict:
        """The updates made (time, amplitude, frequency, the window) for a config file."""
        return {
            "window_s": self.window_s,
            "update_s": self.update_s,
            "updates": [{"t": u.t, **u.window.to_dict()} for u in self.updates],
            "failed_updates": self.failures,
        }
