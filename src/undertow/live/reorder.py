"""The reorder buffer of the live pipeline: records from several links, each in its own
order, become one time-ordered sequence, released in chunks.

A record waits until the horizon H (the pipeline's clock less the buffer length) passes its
time; each release hands over every waiting record with H_previous <= t < H in (t, arrival)
order, so consecutive chunks never overlap in time and a filter fed chunk by chunk sees the
measurements in the order an offline run over the whole recording sees them. A record that
arrives with t < H_previous is late: it is refused (the caller counts and records it) because
the estimate has already moved past its time.
"""

from __future__ import annotations

import heapq
import itertools
import math

from ..records import Record


class ReorderBuffer:
    """Time-orders records and releases them behind a monotonic horizon (module docstring)."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Record]] = []
        self._seq = itertools.count()
        self.horizon = -math.inf
        self.late = 0
        self.released = 0

    def add(self, record: Record) -> bool:
        """Queue ``record``; False (and counted) when it is late."""
        if not record.t >= self.horizon:  # also refuses a NaN time
            self.late += 1
            return False
        heapq.heappush(self._heap, (record.t, next(self._seq), record))
        return True

    def release(self, horizon: float) -> list[Record]:
        """Every queued record older than ``horizon`` (never moved back), time-ordered."""
        self.horizon = max(self.horizon, horizon)
        out = []
        while self._heap and self._heap[0][0] < self.horizon:
            out.append(heapq.heappop(self._heap)[2])
        self.released += len(out)
        return out

    def pending(self) -> list[Record]:
        """The queued records in release order (not removed)."""
        return [item[2] for item in sorted(self._heap)]

    def __len__(self) -> int:
        return len(self._heap)
