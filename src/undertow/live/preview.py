"""Where a live preview may start: the states earlier previews reached.

A preview (the pose at a DVL report, before the reorder buffer releases it) runs the committed
filter on a copy over the records still in the buffer. Rerunning the whole buffer for every
report repeats most of the work; instead a preview may continue from a state an earlier preview
reached at time T, over the buffered records after T, when that gives what the full run would:

- every record that arrived after that preview has a time after T (a record at or before T, say
  a DVL report stamped at its time of validity, a little before the IMU records already
  previewed, invalidates it and every later one);
- every record after T is still in the buffer (T is not before the buffer's release horizon);
- the previews continued from descend from the committed state: after a commit, only if the
  filter took the previews' states up to its end (:attr:`OnlineLocalizer.at_preview`), else
  the next preview starts afresh from the new committed state.

Then the preview filters the same rows from the same state as a run from the committed state,
except for the depth-rate check of the pressure rows, which judges a preview's rows with the
committed depths and its own (see :meth:`OnlineLocalizer.peek`). A commit takes the previews'
states only where their rows are the commit's, verdicts included; where they differ, the next
preview starts afresh, so a preview differs from the full run for at most one commit interval.

The commit releases the records up to the latest time a kept preview reached before its
horizon (:meth:`PreviewCheckpoints.boundary`), so that it can take those previews' states.
"""

from __future__ import annotations

import collections
import math


class PreviewCheckpoints:
    """The (time reached, filter state) of recent previews that a preview may continue from
    (module docstring), oldest first: each a continuation of the one before it."""

    def __init__(self, max_kept: int = 64) -> None:
        self._kept: collections.deque = collections.deque(maxlen=max_kept)
        self._waiting_since: float | None = None  # the first horizon a commit waited at

    def arrived(self, t: float) -> None:
        """A filter record stamped ``t`` was buffered: previews that reached t or later did
        not take it, so none of them can be continued from."""
        while self._kept and self._kept[-1][0] >= t:
            self._kept.pop()

    def released(self, horizon: float, continued: bool) -> None:
        """The buffer released the records before ``horizon`` to the filter: a preview that
        reached an earlier time would need some of them; ``continued``: whether the committed
        state is the one a kept preview reached (else none is a continuation of it)."""
        if not continued:
            self._kept.clear()
        while self._kept and self._kept[0][0] < horizon:
            self._kept.popleft()

    def boundary(self, horizon: float) -> float | None:
        """The latest time before ``horizon`` a kept preview reached (None: none)."""
        before = [t for t, _ in self._kept if t < horizon]
        return before[-1] if before else None

    def commit_to(self, horizon: float, max_wait: float) -> tuple[float | None, bool]:
        """(where a commit at ``horizon`` releases up to, forced): just after the latest time
        a kept preview reached before it (:meth:`boundary`), or ``horizon`` when none is kept;
        None (wait) when every kept preview is ahead of it, unless the commits have waited so
        since a horizon more than ``max_wait`` before this one (a preview reached a time far
        ahead, e.g. of a record stamped ahead of the others): then the previews are dropped and
        the commit goes to ``horizon`` (forced: True). So a commit waits at most ``max_wait``."""
        boundary = self.boundary(horizon)
        if boundary is not None or not self._kept:
            self._waiting_since = None
            return (horizon if boundary is None else math.nextafter(boundary, math.inf)), False
        if self._waiting_since is None:
            self._waiting_since = horizon
        if horizon - self._waiting_since <= max_wait:
            return None, False
        self._kept.clear()
        self._waiting_since = None
        return horizon, True

    def start(self) -> tuple[float, object] | None:
        """(T, state) to continue from, or None for a fresh preview (none kept)."""
        return self._kept[-1] if self._kept else None

    def reached(self, t: float, state, fresh: bool) -> None:
        """A preview reached time ``t`` with ``state`` (``fresh``: from the committed one)."""
        if fresh:
            self._kept.clear()
        if state is not None:
            self._kept.append((t, state))

    def clear(self) -> None:
        self._kept.clear()
