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

The run's bookkeeping (rows, checkpoints, rewinds, previews, the states recorded) is
:mod:`undertow.estimation.online_run`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import ConfigError
from ..log import STREAM_NAMES, Log
from ..records import concat_logs
from ..robot import Mounting
from ..trajectory import Trajectory
from . import filter_loop, model
from .health import check_mounting, per_sensor
from .localizer import (
    WAVE_AUTO,
    WAVE_GIVEN,
    Localizer,
    adapted_summary,
    nis_summary,
    sensor_coverage,
)
from .online_run import OnlineRun
from .rows import initial_state


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
        self._run: OnlineRun | None = None
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

    def trajectory(self, since: int = 0) -> Trajectory:
        """All states so far (views: a later push may revise those after ``final_states``),
        with the metadata of :meth:`Localizer.run` and ``"online"``; ``since``: from that state
        number on (``metadata["online"]["first_state"]``; those before may be released)."""
        if self._run is None:
            empty = Trajectory(np.zeros(0), np.zeros((0, 18)), np.zeros((0, 18, 18)))
            return dataclasses.replace(empty, variant=self.config.variant,
                                       metadata={"online": self._online_meta()})  # fmt: skip
        traj = self._run.states(min(max(int(since), 0), self._run.out.n))
        metadata = self._metadata()
        if since:
            metadata["online"]["first_state"] = int(since)
        return dataclasses.replace(traj, metadata=metadata)

    def release(self, n: int) -> int:
        """Let go of the states before number ``n`` (at most the final ones: a later push can
        revise none of them), which the caller has taken (recorded, mapped, stored); a later
        :meth:`trajectory` or :meth:`committed` cannot return them. Returns the number of
        states before which all are freed (whole storage blocks)."""
        if self._run is None:
            return 0
        self._run.out.release(min(int(n), self._run.final_states()))
        return self._run.out.released

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
            self._noise, self._wave_meta = self._offline.wave_noise(log)
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
        self._run = OnlineRun(cfg, self._noise, x0, P0, cfg.process_model(held=held),
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
