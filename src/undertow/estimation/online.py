"""The paper's UKF online: measurements arrive in chunks (each a :class:`~undertow.log.Log` of the
records released since the last one, in time order) and the filter advances with each.

:class:`OnlineLocalizer` builds the same rows as :class:`~undertow.estimation.Localizer` (same
envelopes, noise, floors, the same merged order: time, then IMU, DVL, DR, barometer) and runs
the same numba loop (:func:`~undertow.estimation.filter_loop.resume_filter`) from the state the last
chunk left. For a fixed wave condition, a log pushed in any pieces gives bit for bit the t, x,
P and counts of ``Localizer(...).run(log)``. Two things the offline run decides with the whole
log in hand are made exact by rewinding to a saved filter state (a checkpoint):

- rows at the same time are ordered by sensor; a chunk that ends inside a time's rows (never
  with the pipeline, whose chunks are split by time) is merged with the next one's: the state
  before the last time's rows is kept until a later time arrives;
- the depth-rate check (:func:`~undertow.estimation.health.depth_jumps`) judges a depth by
  the median of HALF_WINDOW depths on each side: until HALF_WINDOW later depths are in, a depth
  is judged on those so far (as if the log ended there) and the state before it is kept; when
  the later depths change the verdict (a spike seen late, rare), the filter rewinds there and
  the states since are recomputed (``revised``: how many of the states :meth:`push` returns
  replace ones returned before).

A push whose next rows are exactly the rows a preview (:meth:`peek`) filtered from the
committed state (same bytes: records, noise, depth-rate verdicts), ending at a time the push's
next row is after, takes that preview's states and end state instead of filtering the rows
again (the same arithmetic from the same state: the same bits); previews chained by
``peek(start=...)`` are taken one after another. The live pipeline previews every DVL report
and commits at a preview's end, so the filter runs each row once.

So every state :meth:`push` returns is what the offline filter would give were the log to end
with this chunk; ``trajectory().metadata["online"]["final_states"]`` counts the leading states
no later chunk can change (what the online mapper uses).

The filter starts once the data released so far has DVL velocity and an orientation source
(IMU gyro or DR attitude) and every stream in ``expected`` has a row, or ``start_timeout_s``
of log time after the first record; it then filters everything released so far, from the
initial state :func:`~undertow.estimation.rows.initial_state` takes from that data.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from ..errors import ConfigError
from ..log import STREAM_NAMES, Log
from ..robot import Mounting
from ..trajectory import Trajectory
from . import filter_loop, model
from .health import HALF_WINDOW, check_mounting, depth_jumps, per_sensor
from .localizer import (
    WAVE_AUTO,
    WAVE_GIVEN,
    Localizer,
    adapted_summary,
    nis_summary,
    sensor_coverage,
)
from .rows import dr_rows, dvl_rows, imu_rows, initial_state, merged_rows, pressure_rows

FILTER_STREAMS = ("imu", "dvl", "dead_reckoning", "pressure")


class OnlineLocalizer:
    """``OnlineLocalizer("proposed", wave=(0.1, 1.0), mounting=m).push(chunk)`` per chunk.

    ``variant``, ``profile``, ``wave`` (a fixed condition: name, (a, f), a WaveTrack or None for
    calm; not ``"auto"``: the live pipeline estimates the sea state itself and calls
    :meth:`set_wave`), ``extrapolate`` and ``params`` as :class:`Localizer`; ``mounting``: the
    session's (chunks carry the default one); ``expected``: streams to wait for before starting
    (at most ``start_timeout_s`` of log time after the first record).
    ``output_rate_hz`` is refused: the online filter outputs every measurement time."""

    def __init__(self, variant: str | None = None, profile=None, wave=None, *,
                 mounting: Mounting | None = None, expected: set[str] | None = None,
                 start_timeout_s: float = 5.0, extrapolate: bool = False,
                 **params) -> None:  # fmt: skip
        if isinstance(wave, str) and wave.strip().lower() == WAVE_AUTO:
            raise ConfigError("OnlineLocalizer: wave 'auto' is offline only; give a condition "
                              "and update it with set_wave()")  # fmt: skip
        self._offline = Localizer(variant, profile, wave, extrapolate, **params)
        self.config = self._offline.config
        if self.config.output_rate_hz is not None:
            raise ConfigError("OnlineLocalizer: output_rate_hz is offline only (the online "
                              "filter outputs every measurement time)")  # fmt: skip
        self.mounting = mounting if mounting is not None else Mounting()
        check_mounting(self.mounting)
        self.expected = set(expected or ())
        unknown = sorted(self.expected - set(STREAM_NAMES))
        if unknown:
            raise ConfigError(f"OnlineLocalizer: expected stream(s) {', '.join(unknown)} not "
                              f"among {', '.join(STREAM_NAMES)}")  # fmt: skip
        if not start_timeout_s >= 0:
            raise ConfigError(f"OnlineLocalizer: start_timeout_s {start_timeout_s} must be >= 0")
        self.start_timeout_s = float(start_timeout_s)
        self.ready = False
        self.missing: list[str] = []
        self.revised = 0
        self._waiting: list[Log] = []
        self._span = (np.inf, -np.inf)  # log time of the first and the latest record
        self._have: set[str] = set()
        self._noise = None
        self._wave_changes: list[dict] = []
        self._config_dump = self.config.model_dump()
        self._run: _Run | None = None
        self._preview = None  # the filter state the last peek reached
        self._update_missing()

    def set_wave(self, condition) -> None:
        """Wave noise of ``condition`` (name, (a, f) or "calm") for the rows of later chunks."""
        noise = self._offline.profile.noise(condition, extrapolate=self._offline.extrapolate)
        self._noise = noise
        t = None if not np.isfinite(self._span[1]) else float(self._span[1])
        self._wave_changes.append({"t": t, **noise.to_dict()})
        if self._run is not None:
            self._run.noise = noise

    def push(self, chunk: Log) -> Trajectory | None:
        """Filter the chunk's measurements; the states recorded (x, P at each new time), or None
        when there are none (not started yet, or nothing new). ``self.revised`` of them (the
        first ones) replace states an earlier push returned (see the module docstring)."""
        chunk = chunk.replace(mounting=self.mounting)
        self.revised = 0
        if self._run is None:
            self._waiting.append(chunk)
            self._note(chunk)
            if not self._update_missing():
                return None
            chunk = concat_logs(self._waiting, self.mounting)
            self._waiting = []
            self._start(chunk)
        else:
            self._note(chunk)
        n0, n_kept = self._run.feed(chunk)
        self.revised = n0 - n_kept
        if self._run.out.n <= n_kept:
            return None
        return self._run.states(n_kept)

    def peek(self, chunk: Log, *, resume: bool = False, start=None) -> Trajectory | None:
        """The states the chunk would give if pushed now, computed on a copy (the filter is
        not changed: a preview of records not yet released); None before the start.

        ``resume``: continue from the state the previous peek reached instead of the committed
        one (the caller guarantees the chunk's filter records all come after the previous
        peek's, and that nothing the committed filter took since is missing from the peeks:
        a preview advanced by the new records only, O(new rows)). Its pressure rows are judged
        by the depth-rate check with the committed depths and its own (not the previous
        peeks'), so it may differ from a fresh peek (then a push does not take it).
        Without a previous peek it starts from the committed state. ``start``: continue from
        that state instead (one :attr:`preview_state` gave; the same guarantees as ``resume``
        for the records after it).

        A later push whose next rows are exactly this peek's, from the state it started from,
        takes its states instead of filtering them again (module docstring)."""
        if self._run is None:
            return None
        if start is None and resume:
            start = self._preview
        t, x, P, self._preview = self._run.peek(chunk.replace(mounting=self.mounting), start)
        return Trajectory(t, x, P, variant=self.config.variant) if t.size else None

    @property
    def at_preview(self) -> bool:
        """Whether the committed state is one a peek reached (the last push ended by taking
        that peek's states): the peeks continued from it since continue the committed filter."""
        return self._run is not None and isinstance(self._run.key, filter_loop.FilterState)

    @property
    def preview_state(self):
        """The filter state the last peek reached (None before one); pass it back as
        ``peek(start=...)``. Not changed by later peeks (each works on its own copy)."""
        return self._preview

    def latest(self) -> Trajectory | None:
        """The last state recorded (one), or None."""
        if self._run is None or self._run.out.n == 0:
            return None
        return self._run.states(self._run.out.n - 1)

    def trajectory(self) -> Trajectory:
        """All states so far (views: a later push may revise those after ``final_states``),
        with the metadata of :meth:`Localizer.run` and ``"online"``."""
        if self._run is None:
            empty = Trajectory(np.zeros(0), np.zeros((0, 18)), np.zeros((0, 18, 18)))
            return dataclasses.replace(empty, variant=self.config.variant,
                                       metadata={"online": self._online_meta()})  # fmt: skip
        traj = self._run.states(0)
        return dataclasses.replace(traj, metadata=self._metadata())

    def committed(self, since: int = 0) -> Trajectory:
        """The states from number ``since`` on (views, unless they span storage blocks) with
        only ``metadata["online"]``: ``final_states`` (a count from the first state) and
        ``first_state`` (= since): what :meth:`trajectory` gives without the summaries, cheap
        enough for every chunk when ``since`` is recent (a consumer that took the states
        before it)."""
        if self._run is None:
            return self.trajectory()
        since = min(max(int(since), 0), self._run.out.n)
        meta = {"online": {"final_states": self._run.final_states(), "first_state": since}}
        return dataclasses.replace(self._run.states(since), metadata=meta)

    def _note(self, chunk: Log) -> None:
        for name, stream in chunk.streams().items():
            if len(stream):
                self._have.add(name)
                self._span = (min(self._span[0], float(stream.t[0])),
                              max(self._span[1], float(stream.t[-1])))  # fmt: skip

    def _update_missing(self) -> bool:
        """Refresh ``missing`` and ``ready``; True when the filter can start."""
        if self._run is not None:
            return True
        need = []
        if "dvl" not in self._have:
            need.append("dvl: no DVL velocity yet (the filter needs it)")
        if not {"imu", "dead_reckoning"} & self._have:
            need.append("orientation: no IMU gyro (imu) or DVL dead reckoning (dead_reckoning) "
                        "yet (the filter needs one)")  # fmt: skip
        waiting = [f"{s}: expected, no data yet" for s in sorted(self.expected - self._have)]
        timed_out = self._span[1] - self._span[0] >= self.start_timeout_s
        self.missing = need + waiting
        self.ready = not need and (not waiting or timed_out)
        return self.ready

    def _start(self, log: Log) -> None:
        cfg = self.config
        unobserved, held = sensor_coverage(log, cfg)
        if self._noise is None:
            self._noise, self._wave_meta = self._offline._wave_noise(log)
        else:
            self._wave_meta = {"wave_condition_source": "set_wave"}
        x0, P0 = initial_state(log, cfg)
        self._start_meta = {
            "unobserved": unobserved,
            "held_bias": held,
            "start_t": float(self._span[0]),
            "started_at": float(self._span[1]),
            "started_without": [m.split(":")[0] for m in self.missing],
        }
        self.missing = []
        self._run = _Run(cfg, self._noise, x0, P0, cfg.process_model(held=held),
                         cfg.sensor_model(self.mounting))  # fmt: skip

    def _online_meta(self) -> dict:
        meta = {"ready": self.ready, "missing": list(self.missing),
                "wave_changes": list(self._wave_changes)}  # fmt: skip
        if self._run is not None:
            meta.update(self._start_meta)
            meta.update(self._run.bookkeeping())
        return meta

    def _metadata(self) -> dict:
        cfg, run = self.config, self._run
        counts = run.counts()
        rows = run.rows_per_kind()
        noise = run.noise
        metadata = {
            "variant": cfg.variant,
            "counts": counts,
            "sensors": per_sensor(counts, rows),
            "nis": nis_summary(run.state.nis),
            **self._wave_meta,
            "wave_noise": noise.to_dict() if cfg.adds_wave_noise else None,
            "wave_condition": noise.condition,
            "unobserved": self._start_meta["unobserved"],
            "held_bias": self._start_meta["held_bias"],
            "config": self._config_dump,
            "source": "online",
            "online": self._online_meta(),
        }
        metadata.setdefault("wave_condition_source", WAVE_GIVEN)
        if cfg.adapts_r:
            kinds = np.array([rows[k] for k in model.KIND_NAMES])
            metadata["adaptive_r"] = adapted_summary(run.state.Ra, kinds, cfg.adaptive_r_alpha)
        return metadata


def concat_logs(logs: list[Log], mounting: Mounting) -> Log:
    """One Log of consecutive chunks (each stream's rows in chunk order)."""
    streams = {}
    for name in STREAM_NAMES:
        parts = [getattr(log, name) for log in logs]
        parts = [p for p in parts if p is not None and len(p)]
        if not parts:
            continue
        if len(parts) == 1:
            streams[name] = parts[0]
            continue
        changes = {"t": np.concatenate([p.t for p in parts])}
        for field in parts[0]._shapes:
            values = [getattr(p, field) for p in parts]
            if all(v is None for v in values):
                continue
            like = next(v for v in values if v is not None)
            fill = False if like.dtype == np.bool_ else np.nan
            changes[field] = np.concatenate([
                v if v is not None else np.full((len(p), *like.shape[1:]), fill, like.dtype)
                for v, p in zip(values, parts, strict=True)
            ])  # fmt: skip
        streams[name] = dataclasses.replace(parts[0], **changes)
    return Log(**streams, mounting=mounting)


class _Outputs:
    """The states recorded so far, in blocks of BLOCK states: appending never copies the states
    before (a single array grown by doubling copies them all at each growth, a stall of tens of
    ms at a few thousand states and of seconds in an hour of states). ``n`` may be set back
    (a rewind); :meth:`view` hands out views when the range lies in one block."""

    BLOCK = 2048

    def __init__(self) -> None:
        self.n = 0
        self._blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def append(self, t, x, P) -> None:
        k, i = t.size, 0
        while i < k:
            b, j = divmod(self.n, self.BLOCK)
            if b == len(self._blocks):
                B, n_x = self.BLOCK, model.N_STATE
                self._blocks.append((np.empty(B), np.empty((B, n_x)), np.empty((B, n_x, n_x))))
            m = min(k - i, self.BLOCK - j)
            bt, bx, bP = self._blocks[b]
            bt[j : j + m], bx[j : j + m], bP[j : j + m] = t[i : i + m], x[i : i + m], P[i : i + m]
            self.n += m
            i += m

    def view(self, n0: int, n1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t, x, P) of states n0..n1-1: views of one block, else the blocks' parts joined."""
        B = self.BLOCK
        if n1 <= n0:
            return np.empty(0), np.empty((0, model.N_STATE)), np.empty((0,) + (model.N_STATE,) * 2)
        b0, b1 = n0 // B, (n1 - 1) // B
        parts = [tuple(a[max(n0 - b * B, 0) : min(n1 - b * B, B)] for a in self._blocks[b])
                 for b in range(b0, b1 + 1)]  # fmt: skip
        if len(parts) == 1:
            return parts[0]
        return tuple(np.concatenate(c) for c in zip(*parts, strict=True))


class _DepthRate:
    """The depth-rate verdicts (health.depth_jumps) of the in-envelope depths seen so far:
    final for depth j once HALF_WINDOW later ones are in, else judged as if the log ended now.
    Keeps the depths from HALF_WINDOW before the first undecided one."""

    def __init__(self, cfg) -> None:
        self.cfg = cfg
        self.checked = cfg.max_vertical_speed_m_s is not None
        self.base = 0  # global index of the first depth kept
        self.t, self.d = np.zeros(0), np.zeros(0)
        self.jump = np.zeros(0, bool)  # verdicts in use, of the depths kept
        self.final_jumps = 0  # jumps among the depths no longer kept

    @property
    def count(self) -> int:
        return self.base + self.t.size

    def is_final(self, j) -> np.ndarray:
        return (np.asarray(j) < self.count - HALF_WINDOW) | (not self.checked)

    def add(self, t, d) -> int | None:
        """Add depths; the global index of the first one whose verdict changed, or None."""
        if t.size == 0:
            return None
        n_old = self.t.size
        # the first depths kept are final (their window reaches before the kept ones)
        k = min(max(self.count - HALF_WINDOW, 0) - self.base, n_old) if self.checked else n_old
        self.t, self.d = np.concatenate([self.t, t]), np.concatenate([self.d, d])
        jump = depth_jumps(self.t, self.d, self.cfg)
        jump[:k] = self.jump[:k]
        changed = np.flatnonzero(jump[:n_old] != self.jump)
        self.jump = jump
        return None if changed.size == 0 else self.base + int(changed[0])

    def peek(self, t, d) -> np.ndarray:
        """The verdicts the new depths (t, d) would get now (nothing kept): judged with the
        HALF_WINDOW depths before them, all their window reaches."""
        k = max(self.t.size - HALF_WINDOW, 0)
        jump = depth_jumps(np.concatenate([self.t[k:], t]), np.concatenate([self.d[k:], d]),
                           self.cfg)  # fmt: skip
        return jump[self.t.size - k :]

    def jumped(self, j: np.ndarray) -> np.ndarray:
        return self.jump[np.asarray(j) - self.base]

    def trim(self) -> None:
        first_open = max(self.count - HALF_WINDOW, 0)
        base = max(self.base, first_open - HALF_WINDOW)
        drop = base - self.base
        if drop > 0:
            self.final_jumps += int(self.jump[:drop].sum())
            self.t, self.d, self.jump = self.t[drop:], self.d[drop:], self.jump[drop:]
            self.base = base

    def rejected(self) -> int:
        return self.final_jumps + int(self.jump.sum())


class _Preview(NamedTuple):
    """A peek: from the state ``start`` (the committed state's key, or the state an earlier
    peek reached), the accepted ``rows`` it filtered, the states it recorded, the state it
    reached (``end``, never changed afterwards: a later peek from it works on a copy)."""

    start: object
    rows: np.ndarray
    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    end: filter_loop.FilterState


class _Run:
    """The filter once started: candidate rows (pressure rows before the depth-rate verdict),
    checkpoints (position in the candidate rows -> filter state and outputs count; a rewind to
    a position goes to the latest checkpoint at or before it, and refilters from there), the
    rows since the oldest checkpoint, the outputs, and the recent previews a push may take
    (:meth:`_adopt`)."""

    #: previews kept for a push to take, the oldest dropped first (the live pipeline chains
    #: one per DVL report between commits: 4 at 8 Hz and the default 0.5 s commits, 128 cover
    #: 16 s; each holds its states, about 40 kB)
    MAX_PREVIEWS = 128

    def __init__(self, cfg, noise, x0, P0, process, sensors) -> None:
        self.cfg, self.noise, self.process, self.sensors = cfg, noise, process, sensors
        self.state = filter_loop.start_state(np.nan, x0, P0, process, np.zeros((4, 3, 3)))
        self.out = _Outputs()
        self.depth = _DepthRate(cfg)
        self.rejected: dict[str, int] = {}
        self.candidates = np.zeros(len(model.KIND_NAMES), np.int64)
        self.late = 0
        self.t_seen = -np.inf  # latest record time fed
        self.tail = np.zeros(0, filter_loop.MEASUREMENT)  # candidate rows from position pos0 on
        self.tail_p = np.zeros(0, np.int64)  # their depth index (-1: not a pressure row)
        self.pos0 = 0
        self.checkpoints: dict[int, tuple[filter_loop.FilterState, int]] = {}
        self.group = None  # position of the first row at the latest time
        # the committed state's key: a new object whenever the state changes, except when a
        # push takes a preview (the key is then the state that preview reached)
        self.key = object()
        self.previews: dict[int, _Preview] = {}  # id(start) -> the latest peek from it
        self.adopted = 0  # rows taken from previews

    def feed(self, chunk: Log) -> tuple[int, int]:
        """Filter a chunk; returns (outputs before, outputs kept before the new ones)."""
        n_before = self.out.n
        rows, depth_idx, depths = self._rows(self._drop_late(chunk))
        changed = self.depth.add(*depths)
        rewind = None
        if rows.size and self.tail.size and rows["t"][0] == self.tail["t"][-1]:
            rewind = self.group
        if changed is not None:
            at = self.pos0 + int(np.flatnonzero(self.tail_p == changed)[0])
            rewind = at if rewind is None else min(rewind, at)
        start = self.pos0 + self.tail.size
        if rewind is not None:  # the latest checkpoint at or before it (refiltered from there)
            rewind = max(p for p in self.checkpoints if p <= rewind)
            state, n_out = self.checkpoints[rewind]
            self.checkpoints = {p: c for p, c in self.checkpoints.items() if p < rewind}
            self.state = state.copy()
            self.key = object()
            self.out.n = n_out
            k = rewind - self.pos0
            rows = np.concatenate([self.tail[k:], rows])
            depth_idx = np.concatenate([self.tail_p[k:], depth_idx])
            order = np.lexsort((rows["kind"], rows["t"]))
            rows, depth_idx = rows[order], depth_idx[order]
            self.tail, self.tail_p = self.tail[:k], self.tail_p[:k]
            start = rewind
        n_kept = min(self.out.n, n_before)
        self._filter(rows, depth_idx, start)
        self._trim()
        return n_before, n_kept

    def _drop_late(self, chunk: Log, commit: bool = True) -> Log:
        """The chunk without the filter streams' records before the latest one fed (counted
        when ``commit``)."""
        changes = {}
        latest = self.t_seen
        for name in FILTER_STREAMS:
            stream = getattr(chunk, name)
            if stream is None or not len(stream):
                continue
            late = stream.t < self.t_seen
            if late.any():
                self.late += int(late.sum()) if commit else 0
                changes[name] = stream.select(~late)
            latest = max(latest, float(stream.t[-1]))
        if commit:
            self.t_seen = latest
        return chunk.replace(**changes) if changes else chunk

    def _rows(self, chunk: Log, commit: bool = True):
        """(candidate rows merged in the offline order, their depth index, (t, depth) of the
        new in-envelope depths); ``commit``: count them."""
        cfg, rejected = self.cfg, {}
        parts, depth_idx = [], []  # each stream's accepted rows; their depth index (-1: none)
        for name, build in (("imu", imu_rows), ("dvl", dvl_rows),
                            ("dead_reckoning", dr_rows)):  # fmt: skip
            stream = getattr(chunk, name)
            if stream is not None and len(stream):
                t, kind, z, R, ok = build(chunk, cfg, self.noise, rejected, warn=False)
                parts.append((t, kind, z, R) if ok.all() else (t[ok], kind, z[ok], R[ok]))
                depth_idx.append(np.full(parts[-1][0].size, -1))
        depths = (np.zeros(0), np.zeros(0))
        if chunk.pressure is not None and len(chunk.pressure):
            t, kind, z, R, ok = pressure_rows(chunk, cfg, self.noise, rejected, warn=False,
                                               jumps=False)  # fmt: skip
            parts.append((t[ok], kind, z[ok], R[ok]))
            depth_idx.append(self.depth.count + np.arange(int(ok.sum())))
            depths = (t[ok], z[ok, 0])
        for key, value in rejected.items() if commit else ():
            self.rejected[key] = self.rejected.get(key, 0) + value
        rows, order = merged_rows(parts, cfg.std_floor**2)
        if commit:
            self.candidates += np.bincount(rows["kind"], minlength=self.candidates.size)
        idx = np.concatenate(depth_idx) if depth_idx else np.zeros(0, np.int64)
        return rows, idx[order], depths

    def peek(self, chunk: Log, start=None) -> tuple:
        """(t, x, P, state reached) of the chunk filtered on a copy of the state (``start``,
        default the committed one; nothing kept); depths judged on those so far, as :meth:`feed`
        would."""
        rows, depth_idx, (t, d) = self._rows(self._drop_late(chunk, False), commit=False)
        accepted = depth_idx < 0
        if t.size:
            jump = self.depth.peek(t, d)
            is_p = ~accepted
            accepted[is_p] = ~jump[depth_idx[is_p] - self.depth.count]
        key = self.key if start is None else start
        state = (self.state if start is None else start).copy()
        if not accepted.all():
            rows = rows[accepted]
        if np.isnan(state.clock[0]) and rows.size:
            state.clock[0] = rows["t"][0]
        t, x, P = filter_loop.resume_filter(rows, state, self.process, self.sensors, True)
        if rows.size:  # for a push to take (_adopt)
            self.previews.pop(id(key), None)
            self.previews[id(key)] = _Preview(key, rows, t, x, P, state)
            if len(self.previews) > self.MAX_PREVIEWS:
                del self.previews[next(iter(self.previews))]
        return t, x, P, state

    def _adopt(self, rows, accepted, start: int) -> int:
        """Take the previews that filtered exactly the next accepted rows from the committed
        state, one after another (module docstring): their states are recorded and the state
        becomes the one they reached, a checkpoint before each. A preview is taken only when
        the next row is at a later time than its last (it recorded that time's state) or none
        follows. Returns the candidate position (from ``start``) up to which rows are done."""
        acc = np.flatnonzero(accepted)
        i = done = 0  # accepted rows taken; candidate rows done
        while True:
            preview = self.previews.get(id(self.key))
            if preview is None or preview.start is not self.key:
                return done
            n = preview.rows.size
            if i + n > acc.size:
                return done
            if i + n < acc.size and rows["t"][acc[i + n]] == preview.rows["t"][-1]:
                return done  # a row at its last time that it did not take
            if rows[acc[i : i + n]].tobytes() != preview.rows.tobytes():
                return done
            del self.previews[id(self.key)]
            self.checkpoints[start + done] = (self.state, self.out.n)
            self.state, self.key = preview.end.copy(), preview.end
            self.out.append(preview.t, preview.x, preview.P)
            i += n
            done = int(acc[i - 1]) + 1
            self.adopted += n

    def _filter(self, rows, depth_idx, start: int) -> None:
        """Filter the candidate rows from position ``start`` (first taking the previews that
        filtered them, :meth:`_adopt`), with a checkpoint at or before every pressure row not
        finally judged and the rows at the latest time."""
        if rows.size == 0:
            return
        is_p = depth_idx >= 0
        accepted = ~is_p
        accepted[is_p] = ~self.depth.jumped(depth_idx[is_p])
        open_p = is_p.copy()
        open_p[is_p] = ~self.depth.is_final(depth_idx[is_p])
        last = int(np.searchsorted(rows["t"], rows["t"][-1]))
        self.group = start + last
        k = self._adopt(rows, accepted, start)  # (its checkpoints cover the rows it took)
        cuts = sorted({c for c in np.flatnonzero(open_p).tolist() if c >= k}
                      | ({last} if last >= k else set()))  # fmt: skip
        for cut in cuts:
            self._advance(rows[k:cut][accepted[k:cut]], flush=False)
            self.checkpoints[start + cut] = (self.state.copy(), self.out.n)
            k = cut
        self._advance(rows[k:][accepted[k:]], flush=True)
        self.tail = np.concatenate([self.tail, rows])
        self.tail_p = np.concatenate([self.tail_p, depth_idx])

    def _advance(self, rows, flush: bool) -> None:
        """Filter the accepted rows; with ``flush``, record the last time's state too (the
        offline run records it when the next row's time differs: a checkpoint precedes the
        rows at the latest time, for a next chunk that starts at that time)."""
        if rows.size == 0 and not (flush and self.state.clock[3]):
            return
        if np.isnan(self.state.clock[0]):
            self.state.clock[0] = rows["t"][0]  # t0: the first measurement's time
        self.key = object()
        out_t, out_x, out_P = filter_loop.resume_filter(
            rows, self.state, self.process, self.sensors, flush
        )
        self.out.append(out_t, out_x, out_P)

    def _trim(self) -> None:
        """Drop the checkpoints no later chunk can need (a rewind goes to the latest one at or
        before the first row still open: the rows at the latest time, or a pressure row not
        finally judged), and the rows before the oldest kept."""
        is_p = self.tail_p >= 0
        open_p = np.flatnonzero(is_p)[~self.depth.is_final(self.tail_p[is_p])]
        needed = self.group if self.group is not None else self.pos0 + self.tail.size
        if open_p.size:
            needed = min(needed, self.pos0 + int(open_p[0]))
        base = max((p for p in self.checkpoints if p <= needed), default=needed)
        keep = {p: cp for p, cp in self.checkpoints.items() if p >= base}
        self.checkpoints = keep
        first = min(keep, default=self.pos0 + self.tail.size)
        k = first - self.pos0
        self.tail, self.tail_p = self.tail[k:], self.tail_p[k:]
        self.pos0 = first
        self.depth.trim()

    def states(self, n0: int) -> Trajectory:
        return Trajectory(*self.out.view(n0, self.out.n), variant=self.cfg.variant)

    def counts(self) -> dict:
        rejected = dict(self.rejected)
        if "rejected_pressure" in rejected:
            rejected["rejected_pressure_rate"] = self.depth.rejected()
        filt = dict(zip(filter_loop.COUNT_NAMES, self.state.counts.tolist(), strict=True))
        return {**rejected, **filt}

    def rows_per_kind(self) -> dict:
        rows = self.candidates.copy()
        rows[model.BARO] -= self.depth.rejected()
        return dict(zip(model.KIND_NAMES, rows.tolist(), strict=True))

    def final_states(self) -> int:
        return int(min((n for _, n in self.checkpoints.values()), default=self.out.n))

    def bookkeeping(self) -> dict:
        final = self.final_states()
        return {"final_states": final, "late_rows": self.late,
                "checkpoints": len(self.checkpoints),
                "rows_from_previews": self.adopted}  # fmt: skip
