"""Clocks of replays played faster than real time: :func:`replay_anchor`, the instant where a
scaled clock and the wall clock agree, and :class:`ScaledClock`, the arrival clock of a live
session whose sensors are a recording played ``scale`` times faster (``undertow serve --rate``,
``undertow live --time-scale``). The virtual robot's sensor clocks (:mod:`undertow.sim.robot`)
and the live links' arrival clocks (:mod:`undertow.live.links`) follow the same formula.
"""

from __future__ import annotations

import math
import time

from ..errors import ConfigError


def replay_anchor(now: float | None = None) -> float:
    """The start of the current UTC hour (Unix s): the point where a scaled clock and the wall
    clock agree. Two processes (``undertow serve --rate R`` and ``undertow live --time-scale
    R``) derive the same clock from it without talking to each other, and the scaled times stay
    within R hours of it (ROS stamps hold seconds in an int32)."""
    now = time.time() if now is None else float(now)
    return math.floor(now / 3600.0) * 3600.0


class ScaledClock:
    """An arrival clock running ``scale`` times faster than this machine's: c(w) = A + scale
    (w - A) for the wall time w, with the anchor A (default :func:`replay_anchor`). It stamps
    arrivals from a virtual robot that plays a recording ``scale`` times faster than real time
    (``undertow serve --rate``, whose sensor clocks follow the same formula), so that arrival
    spacing is in the recording's seconds; ``scale`` 1 is ``time.time``."""

    def __init__(self, scale: float = 1.0, start: float | None = None) -> None:
        if not (math.isfinite(scale) and scale > 0):
            raise ConfigError(f"time scale: expected a positive number, got {scale}")
        self.scale = float(scale)
        self.start = replay_anchor() if start is None else float(start)

    def __call__(self) -> float:
        return self.start + self.scale * (time.time() - self.start)

    def at(self, wall: float) -> float:
        """c(w) of a wall time w (``time.time`` seconds) taken earlier, e.g. by the kernel."""
        return self.start + self.scale * (wall - self.start)

    def wall_seconds(self, seconds: float) -> float:
        """The wall time in which ``seconds`` of this clock pass."""
        return seconds / self.scale
