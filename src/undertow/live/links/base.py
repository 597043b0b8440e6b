"""What every live sensor link shares: counters, the arrival-time policy, reconnection with
exponential backoff and a bounded delivery queue.

A link delivers :class:`~undertow.records.Record` objects, one per measurement (the stream it
belongs to and that stream's fields in the Log's units and frames), stamped by its
:class:`ClockPolicy` on an arrival clock (``time.time``, or a
:class:`~undertow._util.clocks.ScaledClock` for a replay played faster than real time).

Timestamp policy (:class:`ClockPolicy`), per link:

- no sensor time (Ping1D, json_v1 A50 reports): ``t`` = the arrival time on this machine
  (``time.time()``, Unix s);
- a sensor time ``s`` (Unix s) within ``max_offset_s`` of the arrival time ``a``: ``t = s``
  (the sensor's own clock, e.g. an NTP-synchronized A50, is more precise than arrival);
- a sensor clock far off (|a - s| > max_offset_s, e.g. a clock counting from boot): ``t = s +
  o`` with the offset o = a - s latched at the first such report, so the sensor's spacing
  between reports is kept; o is latched again (and counted as a clock jump) whenever
  |a - (s + o)| exceeds ``max_offset_s``. Every latched offset is recorded in
  :attr:`LinkCounters.clock_offsets` as (arrival time, offset).

Counted per link (:class:`LinkCounters`): received, delivered, malformed (could not be
decoded), duplicate (same sensor time and content as a recent report), out_of_order (older than
the newest report of its stream, delivered: a consumer reorders), stale (older than the newest by
more than ``stale_after_s``: dropped), overflow (dropped because the consumer is too slow and
the queue is full), connects and disconnects.
"""

from __future__ import annotations

import collections
import math
import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from ...errors import ConfigError
from ...records import Record


@dataclass
class LinkCounters:
    """What a link received, delivered and dropped (see the module docstring)."""

    received: int = 0
    delivered: int = 0
    malformed: int = 0
    duplicate: int = 0
    out_of_order: int = 0
    stale: int = 0
    overflow: int = 0
    connects: int = 0
    disconnects: int = 0
    clock_jumps: int = 0
    clock_offsets: list[tuple[float, float]] = field(default_factory=list)
    last_error: str = ""

    def as_dict(self) -> dict:
        out = dict(self.__dict__)
        out["clock_offsets"] = [list(p) for p in self.clock_offsets[-100:]]
        return out


class ClockPolicy:
    """Chooses a record's time from the sensor's time and the arrival time (module docstring).

    ``max_offset_s``: the largest |arrival - sensor time| taken as the same clock (transport
    delay and NTP error; ``math.inf`` trusts the sensor clock whatever it says, e.g. for a
    recording replayed faster than real time); ``stale_after_s``: how far behind the newest
    report of its stream a report may be before it is dropped as stale. Offsets are kept per
    stream (one sensor may stamp two reports with two clocks: the A50's ``position_local``
    ``ts`` may count from boot while its velocity reports carry Unix time).

    One bad sensor time must not move the clock: an offset is latched at a stream's first
    report and again only after ``confirm`` consecutive reports disagree with it by more than
    ``max_offset_s`` and agree with each other on a new offset; until then a report that would
    lie in the future is stamped with its arrival time, and a late one keeps its time
    (transport delay). Likewise a report more than ``stale_after_s`` ahead of the newest is
    delivered but becomes the newest (against which staleness is judged) only when the next
    report confirms the jump.
    """

    def __init__(
        self,
        counters: LinkCounters,
        max_offset_s: float = 1.0,
        stale_after_s: float = 5.0,
        confirm: int = 3,
    ):
        if not (max_offset_s > 0 and stale_after_s > 0 and confirm >= 1):
            raise ConfigError(
                "link clock: max_offset_s, stale_after_s and confirm must be positive"
            )
        self.counters = counters
        self.max_offset_s = float(max_offset_s)
        self.stale_after_s = float(stale_after_s)
        self.confirm = int(confirm)
        self.offset: dict[str, float] = {}
        self._disagree: dict[str, int] = {}
        self._candidate: dict[str, float] = {}
        self._jump: dict[str, float] = {}
        self.newest: dict[str, float] = {}
        self.recent: dict[str, collections.deque] = {}

    def _latch(self, stream: str, arrival: float, sensor_time: float) -> None:
        near = abs(arrival - sensor_time) <= self.max_offset_s
        new = 0.0 if near else arrival - sensor_time
        old = self.offset.get(stream)
        self.offset[stream] = new
        self._disagree[stream] = 0
        if old is not None and new != old:
            self.counters.clock_jumps += 1
        if (old is None and new != 0.0) or (old is not None and new != old):
            self.counters.clock_offsets.append((arrival, new))

    def _sensor_to_local(self, stream: str, arrival: float, sensor_time: float) -> float:
        if stream not in self.offset:
            self._latch(stream, arrival, sensor_time)
        t = sensor_time + self.offset[stream]
        if abs(arrival - t) <= self.max_offset_s:
            self._disagree[stream] = 0
            self._candidate.pop(stream, None)
            return t
        implied = arrival - sensor_time  # the offset this report suggests
        candidate = self._candidate.get(stream)
        if candidate is not None and abs(implied - candidate) <= self.max_offset_s:
            self._disagree[stream] = self._disagree.get(stream, 0) + 1
        else:
            self._candidate[stream], self._disagree[stream] = implied, 1
        if self._disagree[stream] >= self.confirm:
            self._latch(stream, arrival, sensor_time)
            return sensor_time + self.offset[stream]
        return min(t, arrival)  # never in the future of its arrival

    def stamp(self, stream: str, arrival: float, sensor_time: float | None, key=None):
        """The record time for a report, or None when it is a duplicate or stale (counted).
        ``key`` identifies the report's content for duplicate detection (None: no check)."""
        newest = self.newest.get(stream, -math.inf)
        if sensor_time is None or not math.isfinite(sensor_time):
            t = arrival
        elif sensor_time + self.offset.get(stream, 0.0) < newest - self.stale_after_s:
            self.counters.stale += 1  # an old report: it must not move the clock offset
            return None
        else:
            t = self._sensor_to_local(stream, arrival, sensor_time)
        recent = self.recent.setdefault(stream, collections.deque(maxlen=64))
        if key is not None and key in recent:
            self.counters.duplicate += 1
            return None
        if t < newest:
            self.counters.out_of_order += 1
        if key is not None:
            recent.append(key)
        self._advance(stream, newest, t)
        return t

    def _advance(self, stream: str, newest: float, t: float) -> None:
        if t <= newest:
            return
        if newest == -math.inf or t <= newest + self.stale_after_s:
            self.newest[stream] = t
            self._jump.pop(stream, None)
            return
        pending = self._jump.get(stream)
        if pending is not None and abs(t - pending) <= self.stale_after_s:
            self.newest[stream] = max(t, pending)  # a second report confirms the jump
            self._jump.pop(stream)
        else:
            self._jump[stream] = t


@dataclass(frozen=True)
class Backoff:
    """Reconnection delays: ``initial`` s, times ``factor`` after each failed attempt, at most
    ``maximum`` s (d_n = min(initial factor^n, maximum)); reset after a good connection."""

    initial: float = 0.2
    factor: float = 2.0
    maximum: float = 5.0

    def delay(self, attempt: int) -> float:
        return min(self.initial * self.factor ** min(attempt, 64), self.maximum)


class Link:
    """Base of the live links: a thread that connects, reads until the connection drops,
    waits with :class:`Backoff` and reconnects, until :meth:`stop`.

    An unexpected exception in a session (a bug, or a callback raising) ends that session, is
    recorded in ``counters.last_error`` and the link reconnects: a link never dies silently.
    Records go to ``callback(record)`` when given (called from the link's thread), else to a
    bounded queue read with :meth:`get` or by iterating :meth:`records` (the oldest record is
    dropped and counted as ``overflow`` when the queue is full). Subclasses implement
    :meth:`_connect` (return a session object or raise OSError) and :meth:`_run_session`
    (read until the session ends; raise OSError on a drop); they call :meth:`_emit`.
    """

    name = "link"

    def __init__(
        self,
        callback: Callable[[Record], None] | None = None,
        *,
        backoff=None,
        max_queue: int = 10_000,
        clock: ClockPolicy | None = None,
        now: Callable[[], float] | None = None,
    ) -> None:
        self.counters = LinkCounters()
        #: the arrival clock (Unix s): time.time, or a
        #: :class:`~undertow._util.clocks.ScaledClock` for replays
        self.now: Callable[[], float] = now or time.time
        self.clock = clock or ClockPolicy(self.counters)
        self.clock.counters = self.counters
        self.backoff = backoff or Backoff()
        self.callback = callback
        self._queue: queue.Queue[Record] = queue.Queue(maxsize=max(int(max_queue), 1))
        # what a deferred link's thread received, undecoded, for pump(); bounded as the queue
        self._raw: collections.deque = collections.deque()
        self._max_raw = max(int(max_queue), 1)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.info: dict[str, Any] = {}

    # -- lifecycle -------------------------------------------------------------------------
    def load(self) -> None:
        """Import what the link's thread needs, in the calling thread (the thread would do it
        at its first connection). A live session calls this before it freezes its long-lived
        objects out of the garbage collector's reach: a protocol library imported later stays
        young, and the collector's first full pass over it stalls the session."""

    def pump(self) -> None:
        """Decode what the link's thread queued undecoded and deliver its records, in the
        calling thread (a link built ``deferred``: ``A50TcpLink``, ``MavlinkLink`` over UDP);
        nothing for the others. A consumer that runs a loop calls it each turn."""

    def start(self) -> Link:
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._loop, name=self.name, daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        self._interrupt()
        if self._thread is not None:
            self._thread.join(timeout)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def __enter__(self) -> Link:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- delivery --------------------------------------------------------------------------
    def get(self, timeout: float | None = None) -> Record | None:
        """The next record, or None after ``timeout`` s without one."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def records(self, idle_timeout: float = 1.0) -> Iterator[Record]:
        """Records as they come, until none arrived for ``idle_timeout`` s."""
        while (record := self.get(idle_timeout)) is not None:
            yield record

    def _defer(self, item) -> None:
        """Queue what the thread received for :meth:`pump` (the oldest dropped and counted as
        overflow beyond ``max_queue``)."""
        if len(self._raw) >= self._max_raw:
            self._raw.popleft()
            self.counters.overflow += 1
        self._raw.append(item)

    def _emit(self, record: Record) -> None:
        self.counters.delivered += 1
        if self.callback is not None:
            self.callback(record)
            return
        while True:
            try:
                self._queue.put_nowait(record)
                return
            except queue.Full:
                try:
                    self._queue.get_nowait()
                    self.counters.overflow += 1
                except queue.Empty:
                    pass

    # -- the connection loop -----------------------------------------------------------------
    def _loop(self) -> None:
        attempt = 0
        while not self._stop.is_set():
            try:
                session = self._connect()
            except (OSError, ValueError) as exc:
                self.counters.last_error = f"connect: {exc}"
                self._stop.wait(self.backoff.delay(attempt))
                attempt += 1
                continue
            self.counters.connects += 1
            attempt = 0
            try:
                self._run_session(session)
            except (OSError, ValueError) as exc:
                self.counters.last_error = f"session: {exc}"
            except Exception as exc:  # a link thread must outlive any bad input
                self.counters.last_error = f"session: {type(exc).__name__}: {exc}"
            finally:
                self._close(session)
            if not self._stop.is_set():
                self.counters.disconnects += 1
                self._stop.wait(self.backoff.delay(0))

    def _connect(self):  # pragma: no cover - abstract
        raise NotImplementedError

    def _run_session(self, session) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _close(self, session) -> None:
        close = getattr(session, "close", None)
        if close is not None:
            try:
                close()
            except OSError:
                pass

    def _interrupt(self) -> None:
        """Wake a session blocked in a read (subclasses close their socket)."""

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()
