"""The virtual robot's clock, schedule, faults and manifest: plays a Log in real time x ``rate``.

Time. Log time t (s, the Log's own times) is played so that a row of time t is served at the
wall time w(t) = w0 + (t - t0) / rate (t0: the log's first time, w0: the start of playback).
With ``loop`` the log repeats with period P = (t_last - t0) + dt_min (dt_min: the smallest
median sample spacing of the served streams) and lap k serves row t at the playback time
tau = t + k P, so every served clock keeps increasing. Sensor clocks in the served messages are
playback time plus a fixed ``epoch``: s = epoch + tau (A50 ``time_of_validity``, ``ts``) or
milliseconds since the autopilot booted at t0 (MAVLink ``time_boot_ms`` = 1000 (tau - t0)): the
virtual sensor's clock runs at the log's pace whatever the rate. The default epoch is
A + rate (w0 - A) - t0 with A the start of the hour
(:func:`~undertow._util.clocks.replay_anchor`), so that s = A + rate (w - A): the clock of
:class:`~undertow._util.clocks.ScaledClock` ``(rate)`` that ``undertow live --time-scale
rate`` stamps arrivals with (in another process), and Unix time when ``rate`` is 1 (a sensor
synchronized by NTP).

Faults (:class:`Faults`), at playback times T counted from the start (T = tau - t0), drawn from
a generator seeded with ``seed`` (numpy ``SeedSequence``), each one listed in the
:class:`Manifest`: the A50 TCP server closes its connections and refuses new ones for N s of
playback time from T (the reports of that window are not sent); a fraction of A50 lines, Ping
distance replies and MAVLink packets are corrupted (one byte flipped where the receiver must
detect it: a JSON structural character, a Ping payload or checksum byte, a MAVLink payload or
CRC byte); a fraction of A50 reports is sent twice or held back and sent after the next report
of the same stream; a sensor clock jumps by S s at T (and stays jumped).
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ..._util.clocks import replay_anchor
from ...errors import ConfigError
from ...log import Log

#: the sensor clocks a clock jump may name, and the streams whose served times they shift
CLOCK_TARGETS: dict[str, tuple[str, ...]] = {
    "dvl": ("dvl",),
    "dead_reckoning": ("dead_reckoning",),
    "a50": ("dvl", "dead_reckoning"),
    "imu": ("imu",),
    "pressure": ("pressure",),
    "mavlink": ("imu", "pressure", "sonar"),
}
#: what a manifest entry's ``fault`` may say
FAULT_TAGS = ("", "corrupt", "duplicate", "reordered", "dropped")


def _fraction(value, name: str) -> float:
    try:
        f = float(value)
    except (TypeError, ValueError):
        f = math.nan
    if not 0.0 <= f <= 1.0:
        raise ConfigError(f"{name}: expected a fraction between 0 and 1, got {value!r}")
    return f


def _numbers(text: str, count: int, name: str, form: str) -> list[float]:
    parts = str(text).split(":")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise ConfigError(f"{name}: expected {form}, got {text!r}")
    return values


@dataclass(frozen=True)
class Faults:
    """Faults to inject (module docstring). ``drop_dvl``: (T, N) pairs, s; ``corrupt``,
    ``duplicate``, ``reorder``: fractions in [0, 1]; ``clock_jumps``: (clock, T, S) with clock
    one of :data:`CLOCK_TARGETS`."""

    drop_dvl: tuple[tuple[float, float], ...] = ()
    corrupt: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    clock_jumps: tuple[tuple[str, float, float], ...] = ()

    def __post_init__(self) -> None:
        for name in ("corrupt", "duplicate", "reorder"):
            object.__setattr__(self, name, _fraction(getattr(self, name), f"--{name}"))
        drops = tuple((float(t), float(n)) for t, n in self.drop_dvl)
        if not all(math.isfinite(t) and t >= 0 and math.isfinite(n) and n > 0 for t, n in drops):
            raise ConfigError("--drop-dvl: expected T:N with T >= 0 and N > 0 (s)")
        object.__setattr__(self, "drop_dvl", tuple(sorted(drops)))
        jumps = tuple((str(c), float(t), float(s)) for c, t, s in self.clock_jumps)
        for clock, t, s in jumps:
            if clock not in CLOCK_TARGETS:
                raise ConfigError(
                    f"--clock-jump: clock '{clock}' is not one of {', '.join(CLOCK_TARGETS)}"
                )
            if not (math.isfinite(t) and t >= 0 and math.isfinite(s)):
                raise ConfigError("--clock-jump: expected STREAM:T:S with T >= 0 and finite S")
        object.__setattr__(self, "clock_jumps", jumps)

    @classmethod
    def from_options(
        cls,
        drop_dvl: Iterable[str] = (),
        corrupt: float = 0.0,
        duplicate: float = 0.0,
        reorder: float = 0.0,
        clock_jump: Iterable[str] = (),
    ) -> Faults:
        """Faults from command-line strings: ``T:N`` per drop, ``STREAM:T:S`` per clock jump."""
        drops = [tuple(_numbers(d, 2, "--drop-dvl", "T:N (s)")) for d in drop_dvl]
        jumps = []
        for text in clock_jump:
            clock, _, rest = str(text).partition(":")
            t, s = _numbers(rest, 2, "--clock-jump", "STREAM:T:S (s)")
            jumps.append((clock, t, s))
        return cls(tuple(drops), corrupt, duplicate, reorder, tuple(jumps))

    @property
    def any(self) -> bool:
        return bool(
            self.drop_dvl or self.corrupt or self.duplicate or self.reorder or self.clock_jumps
        )

    def to_dict(self) -> dict:
        return {
            k: [list(v) for v in vs] if isinstance(vs, tuple) else vs
            for k, vs in asdict(self).items()
        }

    def jump(self, stream: str, since_start: float) -> float:
        """The total clock jump (s) of ``stream``'s served clock at playback time T."""
        return sum(
            s for c, t, s in self.clock_jumps if stream in CLOCK_TARGETS[c] and since_start >= t
        )


def flip_one_byte(data: bytes, first: int, rng: np.random.Generator) -> bytes:
    """``data`` with one byte at or after ``first`` XORed with 1..255 (the corrupt fault of
    the binary protocols: the length fields before ``first`` are kept, so the stream stays in
    step, and the checksum no longer matches)."""
    out = bytearray(data)
    k = int(rng.integers(min(first, len(out) - 1), len(out)))
    out[k] ^= int(rng.integers(1, 256))
    return bytes(out)


@dataclass(frozen=True)
class Served:
    """One message served: ``protocol`` (a50, ping1d, mavlink), ``message`` (velocity,
    position_local, distance, ATTITUDE, ...), ``stream`` (the undertow stream its values
    belong to; "" for none), ``index`` (the row of that stream in the log; -1 none), ``t``
    (the row's playback time, s: log time + lap x period), ``at`` (playback time when it was
    sent; a Ping reply's request time), ``sensor_time`` (the sensor clock in the message, s;
    NaN: none), ``wall`` (Unix s when sent), ``fault`` (:data:`FAULT_TAGS`), ``clients`` (TCP
    clients it was written to; -1 for datagrams) and ``payload`` (the bytes as encoded,
    before any corruption)."""

    protocol: str
    message: str
    stream: str
    index: int
    t: float
    at: float
    sensor_time: float
    wall: float
    fault: str = ""
    clients: int = -1
    payload: bytes = b""

    @property
    def delivered(self) -> bool:
        """Sent intact to someone (a datagram counts as sent)."""
        return self.fault in ("", "duplicate", "reordered") and self.clients != 0


class Manifest:
    """Every message served, in sending order (thread-safe; at most ``limit`` entries are kept,
    the rest only counted in :attr:`overflow`)."""

    def __init__(self, limit: int = 5_000_000) -> None:
        self.entries: list[Served] = []
        self.limit = int(limit)
        self.overflow = 0
        self._lock = threading.Lock()

    def add(self, entry: Served) -> None:
        with self._lock:
            if len(self.entries) < self.limit:
                self.entries.append(entry)
            else:
                self.overflow += 1

    def __len__(self) -> int:
        return len(self.entries)

    def select(
        self, protocol: str | None = None, message: str | None = None, delivered: bool | None = None
    ) -> list[Served]:
        with self._lock:
            entries = list(self.entries)
        return [
            e
            for e in entries
            if (protocol is None or e.protocol == protocol)
            and (message is None or e.message == message)
            and (delivered is None or e.delivered == delivered)
        ]

    def summary(self) -> dict:
        """Counts per protocol and message, and per fault."""
        with self._lock:
            entries = list(self.entries)
        messages: dict[str, int] = {}
        faults: dict[str, int] = {}
        for e in entries:
            key = f"{e.protocol}/{e.message}"
            messages[key] = messages.get(key, 0) + 1
            if e.fault:
                faults[e.fault] = faults.get(e.fault, 0) + 1
        undelivered = sum(1 for e in entries if e.fault == "" and e.clients == 0)
        return {
            "served": len(entries) + self.overflow,
            "messages": messages,
            "faults": faults,
            "no_client": undelivered,
            "not_kept": self.overflow,
        }

    def write(self, path: str | Path) -> Path:
        """JSON lines, one per entry (``payload``: text for A50 lines, hex otherwise)."""
        path = Path(path)
        with self._lock:
            entries = list(self.entries)
        with path.open("w", encoding="utf-8") as fh:
            for e in entries:
                row: dict[str, Any] = asdict(e)
                raw = e.payload
                row["payload"] = raw.decode() if e.protocol == "a50" else raw.hex()
                fh.write(json.dumps(row, allow_nan=True) + "\n")
        return path


class Sink(Protocol):
    """What the player feeds: ``schedule(log)`` gives the playback times of the rows it serves
    per stream key; ``emit(key, index, at)`` serves row ``index`` of ``key`` at playback time
    ``at``; ``ready()`` says a client is there (for ``wait_for_clients``)."""

    def schedule(self, log: Log) -> dict[str, np.ndarray]: ...

    def emit(self, key: str, index: int, at: float) -> None: ...

    def ready(self) -> bool: ...


@dataclass
class PlayClock:
    """Playback time tau of the wall clock (module docstring): tau(w) = t0 + rate (w - w0)."""

    t0: float
    period: float
    rate: float
    epoch: float | None = None
    loop: bool = False
    wall0: float = math.nan
    mono0: float = math.nan
    started: threading.Event = field(default_factory=threading.Event)

    def begin(self) -> None:
        self.mono0, self.wall0 = time.monotonic(), time.time()
        if self.epoch is None:  # the sensor clock of ScaledClock(rate) (module docstring)
            anchor = replay_anchor(self.wall0)
            self.epoch = anchor + self.rate * (self.wall0 - anchor) - self.t0
        self.started.set()

    def now(self) -> float:
        """The playback time now (t0 before the start)."""
        if not self.started.is_set():
            return self.t0
        return self.t0 + self.rate * (time.monotonic() - self.mono0)

    def wall_delay(self, at: float) -> float:
        """Wall seconds until playback time ``at``."""
        return self.mono0 + (at - self.t0) / self.rate - time.monotonic()

    def sensor_time(self, at: float) -> float:
        """The served Unix-like sensor clock at playback time ``at``: epoch + at."""
        return float(self.epoch) + at

    def boot_ms(self, at: float, jump_s: float = 0.0) -> int:
        """MAVLink ``time_boot_ms`` at ``at``: 1000 (at - t0 + jump), clipped to uint32."""
        return int(min(max(round((at - self.t0 + jump_s) * 1e3), 0), 2**32 - 1))

    def latest(self, times: np.ndarray, at: float) -> tuple[int, float, int]:
        """(row, its playback time, lap) of the newest row of ``times`` (log times, sorted) at
        playback time ``at``; row -1 when there is none yet (after the end of a log played
        without ``loop``: its last row)."""
        lap = max(int(math.floor((at - self.t0) / self.period)), 0) if self.loop else 0
        k = int(np.searchsorted(times, at - lap * self.period, side="right")) - 1
        if k < 0 and lap > 0:
            lap, k = lap - 1, len(times) - 1
        if k < 0:
            return -1, math.nan, 0
        return k, float(times[k]) + lap * self.period, lap


def _median_step(t: np.ndarray) -> float:
    d = np.diff(t)
    d = d[d > 0]
    return float(np.median(d)) if d.size else math.inf


class Player:
    """Plays ``log`` into ``sinks`` in real time x ``rate`` (module docstring) in a thread;
    ``faults`` drives the scheduled faults (A50 drops via ``on_drop(down)``)."""

    def __init__(
        self,
        log: Log,
        sinks: list,
        *,
        rate: float = 1.0,
        loop: bool = False,
        faults: Faults | None = None,
        epoch: float | None = None,
        on_drop: Callable[[bool], None] | None = None,
        wait_for_clients: float | None = None,
    ) -> None:
        if not (math.isfinite(rate) and rate > 0):
            raise ConfigError(f"--rate: expected a positive number, got {rate}")
        self.log, self.sinks, self.loop = log, list(sinks), bool(loop)
        self.faults = faults or Faults()
        self.on_drop = on_drop
        self.wait_for_clients = wait_for_clients
        keys, times, codes, index = [], [], [], []
        for sink in self.sinks:
            for key, t in sink.schedule(log).items():
                codes.append(np.full(len(t), len(keys)))
                keys.append((sink, key))
                times.append(np.asarray(t, float))
                index.append(np.arange(len(t)))
        if not keys or not sum(len(t) for t in times):
            raise ConfigError(
                f"{log.source or 'log'}: nothing to serve (no DVL, dead "
                "reckoning, IMU, pressure or sonar rows)"
            )
        t_all = np.concatenate(times)
        order = np.argsort(t_all, kind="stable")
        self.t, self.code, self.index = (
            t_all[order],
            np.concatenate(codes)[order],
            np.concatenate(index)[order],
        )
        self.keys = keys
        t0, t1 = float(self.t[0]), float(self.t[-1])
        step = min(_median_step(t) for t in times)
        period = (t1 - t0) + (step if math.isfinite(step) else 1.0)
        self.clock = PlayClock(t0, period, float(rate), epoch, self.loop)
        for sink in self.sinks:
            sink.clock = self.clock
        self.done = threading.Event()
        self.error: BaseException | None = None
        self.laps = 0
        #: playback time of the last row served (NaN before the first)
        self.position = math.nan
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def span(self) -> float:
        """Seconds of log played per lap."""
        return float(self.t[-1] - self.t[0])

    def start(self) -> Player:
        self._thread = threading.Thread(target=self._main, name="serve-player", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def _main(self) -> None:
        try:
            self._wait_for_clients()
            if not self._stop.is_set():
                self.clock.begin()
                self._play()
        except BaseException as exc:  # reported by the session, never silent
            self.error = exc
        finally:
            self.done.set()

    def _wait_for_clients(self) -> None:
        if not self.wait_for_clients:
            return
        deadline = time.monotonic() + float(self.wait_for_clients)
        while time.monotonic() < deadline and not self._stop.is_set():
            if all(s.ready() for s in self.sinks):
                return
            self._stop.wait(0.02)

    def _fault_events(self) -> list[tuple[float, bool]]:
        """(playback time, down) of the A50 drop windows' starts and ends."""
        events = []
        for t, n in self.faults.drop_dvl:
            events += [(self.clock.t0 + t, True), (self.clock.t0 + t + n, False)]
        return sorted(events)

    def _play(self) -> None:
        clock, events = self.clock, self._fault_events()
        lap = 0
        while True:
            base = lap * clock.period
            for k in range(len(self.t)):
                at = float(self.t[k]) + base
                while events and events[0][0] <= at:
                    if not self._sleep_until(events[0][0]):
                        return
                    self._drop(events.pop(0)[1])
                if not self._sleep_until(at):
                    return
                sink, key = self.keys[self.code[k]]
                sink.emit(key, int(self.index[k]), at)
                self.position = at
            self.laps = lap + 1
            if not self.loop:
                break
            lap += 1
        for sink in self.sinks:
            flush = getattr(sink, "flush", None)
            if flush is not None:
                flush()

    def _drop(self, down: bool) -> None:
        if self.on_drop is not None:
            self.on_drop(down)

    def _sleep_until(self, at: float) -> bool:
        delay = self.clock.wall_delay(at)
        if delay > 5e-4:
            return not self._stop.wait(delay)
        return not self._stop.is_set()
