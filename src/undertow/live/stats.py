"""What a live session saw and made (:class:`LiveStats`, :class:`LiveResult`) and its timing
rules: when the view's map is redrawn (:func:`map_view_due`) and when a record's bytes were
received (:func:`received_at`, where a DVL report's latency starts)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from .._util.clocks import ScaledClock
from .._util.histogram import Durations

#: wall seconds between status updates (status line, /undertow/status, the view's map)
STATUS_PERIOD_S = 1.0
#: the largest share of the loop's time the view's map may take: updated from the chunks
#: written since (:mod:`undertow.live.map_cloud`), it is republished each STATUS_PERIOD_S, or
#: less often once one update takes longer than this share of that, :func:`map_view_due`
MAP_VIEW_SHARE = 0.05


@dataclass
class LiveStats:
    """What the session saw: records per stream, late records, latencies (wall s, DVL arrival
    to its preview pose), states committed, pings mapped."""

    records: dict = field(default_factory=dict)
    late: int = 0
    states: int = 0
    pings: int = 0
    forced_commits: int = 0  # commits that could not wait for a preview's end any longer
    latency: Durations = field(default_factory=Durations)  # bounded: a day of reports
    started_filter_at: float | None = None
    span_s: float = 0.0

    def latency_summary(self) -> dict:
        return self.latency.summary_ms()


@dataclass
class LiveResult:
    """The session's output folder and its parts (None where nothing was made)."""

    out_dir: Path
    recording: Path | None
    localization: Path | None
    map: Path | None
    summary: dict
    warnings: list[str] = field(default_factory=list)


def map_view_due(start: float, cost: float, period: float = STATUS_PERIOD_S,
                 share: float = MAP_VIEW_SHARE) -> float:  # fmt: skip
    """When to rebuild the view's map next, after a rebuild that began at ``start`` and took
    ``cost`` s: start + max(period, cost / share), so that it takes at most ``share`` of the
    loop's time once it costs more than share x period."""
    return start + max(period, cost / share)


def received_at(clock: ScaledClock, arrival: float, queued: float) -> float:
    """When (``time.perf_counter``) a link's thread received a record's bytes: its ``arrival``
    (on the session's ``clock``, taken by that thread) brought back to perf_counter time;
    ``queued`` (when the record was queued for the loop) if it has none or the clocks disagree.
    A deferred link's data waits undecoded, so the queueing time alone would leave that wait
    out of the latency."""
    if not math.isfinite(arrival):
        return queued
    behind = clock.wall_seconds(clock() - arrival)
    return min(queued, time.perf_counter() - max(behind, 0.0))
