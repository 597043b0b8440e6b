"""Where a live preview may start: the states earlier previews reached.

A preview (the pose at a DVL report, before the reorder buffer releases it) runs the committed
filter on a copy over the records still in the buffer. Rerunning the whole buffer for every
report repeats most of the work; instead a preview may continue from a state an earlier preview
reached at time T, over the buffered records after T, when that gives what the full run would:

- every record that arrived after that preview has a time after T (a record at or before T, say
  a DVL report stamped at its time of validity, a little before the IMU records already
  previewed, invalidates it and every later one);
- every record after T is still in the buffer (T is not before the buffer's release horizon).

Then the preview filters the same rows from the same state as a run from the committed state,
except for the depth-rate check of the pressure rows, which judges a preview's rows with the
committed depths and its own (see :meth:`OnlineLocalizer.peek`): the previews are a display,
and a fresh one from the committed state is made every ``resync_s`` of sensor time.
"""

from __future__ import annotations

import collections
import math


class PreviewCheckpoints:
    """The (time reached, filter state) of recent previews that a preview may continue from
    (module docstring), oldest first."""

    def __init__(self, resync_s: float, max_kept: int = 64) -> None:
        self.resync_s = float(resync_s)
        self._kept: collections.deque = collections.deque(maxlen=max_kept)
        self._resync_at = -math.inf

    def arrived(self, t: float) -> None:
        """A filter record stamped ``t`` was buffered: previews that reached t or later did
        not take it, so none of them can be continued from."""
        while self._kept and self._kept[-1][0] >= t:
            self._kept.pop()

    def released(self, horizon: float) -> None:
        """The buffer released the records before ``horizon``: a preview that reached an
        earlier time would need some of them."""
        while self._kept and self._kept[0][0] < horizon:
            self._kept.popleft()

    def start(self) -> tuple[float, object] | None:
        """(T, state) to continue from, or None for a fresh preview (none kept, or a resync
        is due)."""
        if not self._kept or self._kept[-1][0] >= self._resync_at:
            return None
        return self._kept[-1]

    def reached(self, t: float, state, fresh: bool) -> None:
        """A preview reached time ``t`` with ``state`` (``fresh``: from the committed one)."""
        if fresh:
            self._kept.clear()
            self._resync_at = t + self.resync_s
        if state is not None:
            self._kept.append((t, state))

    def clear(self) -> None:
        self._kept.clear()
