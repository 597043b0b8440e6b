"""`undertow live` as a library: sensor links in, the online filter, map and sea state, a
recording of everything, and the final results out.

Data flow (one thread does the work; each link has its own thread that only queues: records,
or for the A50 and MAVLink over UDP the bytes received with their arrival times, decoded by
this loop each turn):

    links -> recorder (every raw record, as it arrives) -> reorder buffer -> chunks (time order)
          -> OnlineLocalizer (committed states, recorded) -> OnlineMapper (every MAP_EVERY_S:
             the pings the trajectory covers)
          -> OnlineSeaState (--wave auto: a new condition for the filter every update)
    each DVL report -> a preview pose (before the commit of the same step; with --autopilot also
                       sent to the autopilot, :mod:`undertow.live.autopilot`): the committed
                       filter run on a copy over the records still in the buffer, or an
                       earlier preview's state advanced by the buffered records after it
                       (:mod:`.preview`: same states when the depth-rate check agrees),
                       published to the live view at once; a commit releases the records up
                       to a preview's end and the filter takes the previews' states where
                       they filtered exactly its rows (each row filtered once)

The committed estimate lags real time by the reorder buffer (``reorder_s``); it is what a replay
of the recording reproduces exactly (``undertow localize``/``map`` on the recording, same
variant, wave condition and bounds). The preview has no lag and is not recorded.

Time: every link stamps with one clock, ``time.time`` or a :class:`ScaledClock` when the
sensors are a recording played ``time_scale`` times faster than real time (``undertow serve
--rate``), so the buffer and the filter work in sensor seconds either way.

Stopping: :meth:`LiveSession.request_stop` (SIGINT/SIGTERM in the command), ``duration_s``, or
``idle_stop_s`` without a record after data came. Then the buffer is flushed, the results are
written (each folder atomically) and the recording is closed.
"""

from __future__ import annotations

import collections
import gc
import json
import math
import threading
import time
from pathlib import Path

import numpy as np
import yaml

from .._util.atomic import check_output_folder
from .._util.clocks import ScaledClock
from .._util.plain import to_plain
from ..errors import ConfigError
from ..estimation.calibration import Calibration
from ..estimation.config import LocalizerConfig
from ..estimation.localizer import calibration_fields
from ..estimation.online import OnlineLocalizer
from ..estimation.rows import FILTER_STREAMS
from ..io.results import save_map
from ..io.sound_speed import correct_sound_speed, sound_speed_line, water_sound_speed
from ..io.trajectory_stream import save_stored_trajectory
from ..log import Log
from ..mapping.online import OnlineMapper
from ..mapping.samples import rays_from_pose
from ..records import Record, concat_logs, records_to_log
from ..robot import Mounting
from ..seastate.online import OnlineSeaState
from ..settings import LIVE_VARIANCE_BOUNDS, Settings
from ..trajectory_chunks import StoredTrajectory, TrajectoryStore
from .autopilot import open_bridge
from .map_cloud import MapCloud
from .preview import PreviewCheckpoints
from .recorder import Recorder
from .reorder import ReorderBuffer
from .sensors import expected_streams, open_links
from .stats import (  # noqa: F401  (map_view_due, received_at: part of this module's API)
    MAP_VIEW_SHARE,
    STATUS_PERIOD_S,
    LiveResult,
    LiveStats,
    map_view_due,
    received_at,
)
from .view import PathTrail, newest_ranges
from .warmup import warm_up

#: wall seconds the main loop waits for a record before it checks the clock again, or
#: POLL_SENSOR_S of sensor time when that is longer (real time: 0.1 s, a fifth of the commit
#: interval; each turn has more to do and the turns' fixed costs, which run cold after a
#: wait, are paid 10 rather than 50 times a second). A DVL report wakes the loop at once.
POLL_S = 0.02
POLL_SENSOR_S = 0.1
#: every n-th committed state goes into the path shown in the view
PATH_DECIMATION = 10
#: sensor seconds between online map updates (the chunks released meanwhile at once: the map
#: is the same to rounding, module :mod:`undertow.mapping.online`, for a tenth of the calls)
MAP_EVERY_S = 1.0
#: sensor seconds the commits wait at most for a preview's end (module preview)
MAX_COMMIT_WAIT_S = 2.0
#: the folder (in the output folder) that holds the final states until the end of the session
STATES_DIR = ".localization.states"


class LiveSession:
    """One live run (module docstring). ``settings``: a :class:`~undertow.settings.Settings`
    whose ``live`` section names the links; its ``localizer`` and ``mapping`` sections set the
    filter and the map (the adaptive map gets fixed variance bounds,
    :data:`~undertow.settings.LIVE_VARIANCE_BOUNDS` unless set)."""

    def __init__(self, settings: Settings, out_dir: str | Path, *, mounting: Mounting | None = None,
                 profile=None, calibration=None, overwrite: bool = False,
                 view=None) -> None:  # fmt: skip
        self.settings = settings
        self.live = settings.live
        self.out_dir = Path(out_dir)
        check_output_folder(self.out_dir, overwrite)
        self.overwrite = overwrite
        self.mounting = mounting or Mounting()
        self.clock = ScaledClock(self.live.time_scale)
        # records from the link threads; only a DVL report (whose pose is previewed at once)
        # wakes the loop, the rest wait for its next turn (POLL_S): fewer wake-ups per record
        self._queue: collections.deque = collections.deque()
        self._wake = threading.Event()
        self._loop_thread = threading.get_ident()  # the thread that runs step() (set by it)
        self.links = open_links(self.live, self._ingest, self.clock, wake=self._wake.set)
        self.expected = expected_streams(self.links)
        wave = self.live.wave
        self.auto_wave = isinstance(wave, str) and wave.strip().lower() == "auto"
        self.localizer = OnlineLocalizer(
            profile=profile, wave=None if self.auto_wave else wave, mounting=self.mounting,
            expected=self.expected, **_filter_params(settings, calibration),
        )  # fmt: skip
        self.mapping_config = _live_mapping(settings)
        self.mapper = OnlineMapper(self.mapping_config) if self.live.map else None
        self.sea = None
        if self.auto_wave:
            self.sea = OnlineSeaState(self.mounting, window_s=self.live.wave_window_s,
                                      update_s=self.live.wave_update_s)  # fmt: skip
        self.buffer = ReorderBuffer()
        self.stats = LiveStats()
        self.view = view
        self.recorder: Recorder | None = None
        self._stop = threading.Event()
        self._pending_dvl: list[float] = []
        self._checkpoints = PreviewCheckpoints()  # where a preview may start
        self._last_preview = None  # the states of the last preview
        self._first_wall: float | None = None
        self._last_wall: float | None = None
        self._next_status = 0.0
        self._next_map_view = 0.0
        self._path = PathTrail()  # the positions shown, in bounded memory
        self._store = None  # the final states on disk (TrajectoryStore), from the first one
        self._cloud = None  # the view's map (MapCloud), made at the first draw
        self._early: list = []  # chunks released before the filter started (for the map)
        self._first_t: float | None = None
        self._said_missing = False
        self.on_notice = None  # called once with a line when the filter cannot start
        self._to_map: list = []  # chunks released since the last map update
        self._next_map = -math.inf
        self._next_pose = -math.inf
        self._next_commit = -math.inf
        self.status_callback = None  # called with the status dict every STATUS_PERIOD_S
        self.notes: list[str] = []
        # the water's sound speed (log: {sound_speed_m_s | water_temperature_c}): the DVL's and
        # the sonar's ranges and velocities scaled to it before the filter and the map
        self._water = water_sound_speed(settings.log)[0]
        if self._water is not None:
            self.notes.append(sound_speed_line(settings.log))
        self.autopilot = open_bridge(self)  # live.autopilot: the estimate to the autopilot

    # -- lifecycle ---------------------------------------------------------------------------
    def start(self) -> LiveSession:
        warm_up(self.localizer.config.variant, self.mapping_config if self.mapper else None)
        for link in self.links.values():
            link.load()
        # the objects made so far (modules, compiled code, settings) live as long as the
        # session: out of the collector's reach, a full collection during the run scans only
        # what the run made (one took 50 ms on this machine, stalling every pose behind it)
        gc.collect()
        gc.freeze()
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.recorder = Recorder(self.out_dir / "recording", self.mounting,
                                 metadata={"live": self.live.model_dump()})  # fmt: skip
        self.recorder.declare(sorted(self.expected), wave=self.auto_wave)
        for link in self.links.values():
            link.start()
        return self

    def wait_connected(self, timeout: float = 5.0) -> bool:
        """Wait until every link has connected (a UDP link: bound its socket); False if one
        has not within ``timeout`` s (it keeps trying in the background)."""
        deadline = time.monotonic() + timeout
        while any(link.counters.connects == 0 for link in self.links.values()):
            if time.monotonic() > deadline:
                return False
            time.sleep(0.01)
        return True

    def request_stop(self) -> None:
        self._stop.set()

    def run(self) -> LiveResult:
        """Work until stopped (module docstring), then finish."""
        started = time.monotonic()
        poll = max(POLL_S, POLL_SENSOR_S / self.live.time_scale)
        while not self._stop.is_set():
            self.step(poll)
            if (
                self.live.duration_s is not None
                and time.monotonic() - started > self.live.duration_s
            ):
                break
            idle = self.live.idle_stop_s
            if idle is not None and self._last_wall is not None:
                if time.perf_counter() - self._last_wall > idle:
                    break
        return self.finish()

    def abort(self) -> None:
        """Stop at once: links closed, the recording closed as far as written, no results."""
        for link in self.links.values():
            link.stop(timeout=1.0)
        if self.recorder is not None:
            self.recorder.close()
        if self.view is not None:
            self.view.close()

    # -- the work ----------------------------------------------------------------------------
    def _ingest(self, record: Record) -> None:  # a link thread, or the loop's pump: only queue
        self._queue.append((time.perf_counter(), record))
        if record.stream == "dvl" and threading.get_ident() != self._loop_thread:
            self._wake.set()  # (a record the loop decoded itself is taken in this turn)

    def _drain(self) -> list:
        batch = []
        try:
            while True:
                batch.append(self._queue.popleft())
        except IndexError:
            return batch

    def step(self, timeout: float = POLL_S) -> None:
        """Take what arrived (waiting at most ``timeout`` s for the first), preview the DVL
        reports that came, release what the horizon passed, report status when due."""
        self._loop_thread = threading.get_ident()
        autopilot = self.autopilot  # (it wakes the loop for its next message)
        self._wake.wait(timeout if autopilot is None else min(timeout, autopilot.wait_s()))
        self._wake.clear()
        # the horizon from the clock read before the queue is emptied: a record stamped before
        # it is in this batch, so the loop falling behind never makes a record late
        horizon = self.clock() - self.live.reorder_s
        for link in self.links.values():  # the datagrams a deferred link queued, decoded here
            link.pump()
        for wall, record in self._drain():
            self._take(wall, record)
        if self._pending_dvl:  # first: a DVL report's pose does not wait for the commit
            self._preview()
        if horizon >= self._next_commit and self._commit(horizon):
            self._next_commit = horizon + self.live.commit_every_s
        if time.perf_counter() >= self._next_status:
            self._next_status = time.perf_counter() + STATUS_PERIOD_S
            self._status()
        if self.autopilot is not None:  # what the vehicle said; the slot's fallback message
            self.autopilot.tick(self._preview)

    def _take(self, wall: float, record: Record) -> None:
        if self._first_wall is None:
            self._first_wall = wall
        self._last_wall = wall
        record = self.recorder.write_record(record)
        counts = self.stats.records
        counts[record.stream] = counts.get(record.stream, 0) + 1
        if record.stream == "dvl" and self.autopilot is not None:
            self.autopilot.note_dvl(record)
        if not self.buffer.add(record):
            self.stats.late += 1
            self.recorder.write_late(record)
            return
        if record.stream in FILTER_STREAMS:
            self._checkpoints.arrived(record.t)
        if record.stream == "dvl":  # the latency counts from the link's receipt
            self._pending_dvl.append(received_at(self.clock, record.arrival, wall))

    def _commit(self, horizon: float) -> bool:
        """Release the records before ``horizon`` (all at the end: inf) to the filter, the
        sea state, the recording of final states, the map and the view's rays. Up to the end
        of the latest preview before the horizon, so that the filter takes the previews'
        states; when every preview kept is ahead of the horizon, not yet (False: the next
        step tries again; the wait is at most MAX_COMMIT_WAIT_S)."""
        if not math.isinf(horizon):
            horizon, forced = self._checkpoints.commit_to(horizon, MAX_COMMIT_WAIT_S)
            if horizon is None:
                return False
            self.stats.forced_commits += forced
        released = self.buffer.release(horizon)
        if not released:
            self._checkpoints.released(self.buffer.horizon, continued=True)
            return True
        if self.sea is not None:
            update = self.sea.push(released)
            if update is not None:  # for this chunk's rows on (all of them before the start)
                from_t = released[0].t if self.localizer.ready else None
                self.localizer.set_wave(update.condition)
                self.recorder.write_wave_condition(update.t, from_t, update.condition)
                w = update.window
                self.recorder.write_wave(update.t, w.amplitude_m, w.frequency_hz or math.nan)
                if self.view is not None:
                    self.view.publish_wave(update.t, w.amplitude_m, w.frequency_hz or math.nan)
        chunk = self.chunk_log(released)
        self.localizer.push(chunk)
        self._checkpoints.released(self.buffer.horizon, continued=self.localizer.at_preview)
        if not self.localizer.ready:  # the filter will start from these records: keep them
            self._early.append(chunk)
            self._say_missing(released)
            return True
        # the states from the first one the recording or the map has not taken yet
        trajectory = self.localizer.committed(self._taken())
        self._record_final(trajectory, final_only=not math.isinf(horizon))
        if self.mapper is not None:
            self._to_map += [*self._early, chunk]
            if horizon >= self._next_map:
                self._next_map = horizon + MAP_EVERY_S
                self._update_map(trajectory)
        self._early = []
        if self.view is not None:
            self._show_rays(chunk, trajectory)
        # the states both have taken are on disk: the filter lets go of them
        self.localizer.release(self._taken())
        return True

    def chunk_log(self, records) -> Log:
        """The records as a Log with the session's mounting, its ranges and DVL velocities in
        the water's sound speed when the settings give it (the recording keeps them as
        received)."""
        chunk = records_to_log(records).replace(mounting=self.mounting)
        if self._water is None:
            return chunk
        return correct_sound_speed(chunk, self.settings.log, state=False)

    def _taken(self) -> int:
        """The states the recording (and the store) and the map have both taken."""
        if self.mapper is None:
            return self.stats.states
        return min(self.stats.states, self.mapper.states_used)

    def _say_missing(self, released) -> None:
        """Once, when the filter still cannot start well after the first record: what is
        missing (the records keep being recorded, and filtered once the sensors appear)."""
        if self._first_t is None:
            self._first_t = released[0].t
        waited = released[-1].t - self._first_t
        if self._said_missing or waited < self.localizer.start_timeout_s:
            return
        self._said_missing = True
        note = (f"the filter is waiting after {waited:.0f} s of data: "
                + "; ".join(self.localizer.missing))  # fmt: skip
        self.notes.append(note)
        if self.on_notice is not None:
            self.on_notice(note)

    def _record_final(self, trajectory, final_only: bool = True) -> None:
        """Record the states no later data can revise (all of them at the end); the
        trajectory holds the states from number ``metadata["online"]["first_state"]`` on."""
        online = trajectory.metadata.get("online", {})
        first = int(online.get("first_state", 0))
        n = first + len(trajectory.t)
        if final_only:
            n = int(online.get("final_states", n))
        if n <= self.stats.states:
            return
        if self.stats.started_filter_at is None:
            self.stats.started_filter_at = float(trajectory.t[0])  # (first is 0 then)
        k0, self.stats.states = self.stats.states, n
        period = 1.0 / self.live.record_pose_hz if self.live.record_pose_hz else 0.0
        t_all, x_all, P_all = trajectory.t, trajectory.x, trajectory.P
        for k in range(k0 - first, n - first):
            t = float(t_all[k])
            if t >= self._next_pose or k == n - first - 1 and not final_only:
                self.recorder.write_pose(t, x_all[k], P_all[k])
                self._next_pose = t + period
        if self._store is None:
            self._store = TrajectoryStore(self.out_dir / STATES_DIR)
        part = slice(k0 - first, n - first)
        self._store.append(t_all[part], x_all[part], P_all[part])
        self.stats.span_s = float(t_all[n - first - 1]) - self.stats.started_filter_at
        self._path.extend(trajectory.position[k0 - first : n - first : PATH_DECIMATION])

    def _update_map(self, trajectory) -> None:
        """The chunks released since the last update, to the map as one."""
        if self._to_map:
            chunk = concat_logs(self._to_map, self.mounting)
            self._to_map = []
            self.stats.pings += self.mapper.push(chunk, trajectory)

    def _show_rays(self, chunk, trajectory) -> None:
        """The chunk's newest DVL report's beams and newest sonar range as rays from the newest
        pose (display: older reports of the chunk were taken from other poses)."""
        if not len(trajectory.t):  # no state after those taken already: the newest
            trajectory = self.localizer.latest()
        pos, rpy = trajectory.position[-1:], trajectory.orientation[-1:]
        t = float(trajectory.t[-1])
        for kind, units, ranges, mount in newest_ranges(chunk):
            if ranges.size == 0 or not self.view.subscribed(f"/undertow/rays/{kind}"):
                continue
            var = np.zeros((1, 3))
            o, d, r, *_ = rays_from_pose(ranges, units, mount, np.repeat(pos, ranges.size, 0),
                                         np.repeat(rpy, ranges.size, 0),
                                         np.repeat(var, ranges.size, 0), 0.0, 0)  # fmt: skip
            self.view.publish_rays(t, o, o + d * r[:, None], kind)

    def _preview(self) -> None:
        """The pose at the newest DVL report: the committed filter, on a copy, over the
        records still waiting in the buffer, published to the view; latency measured. When an
        earlier preview's state may be continued from (:mod:`.preview`), only the buffered
        records after it are filtered. The preview is a display (not recorded); a commit
        takes its states only where they are the committed filter's, bit for bit."""
        arrivals, self._pending_dvl = self._pending_dvl, []
        if not self.localizer.ready:
            self._checkpoints.clear()
            return
        start = self._checkpoints.start()
        after = -math.inf if start is None else start[0]
        pending = [r for r in self.buffer.pending() if r.stream in FILTER_STREAMS and r.t > after]
        states = None
        if pending:
            chunk = self.chunk_log(pending)
            states = self.localizer.peek(chunk, start=None if start is None else start[1])
            self._checkpoints.reached(pending[-1].t, self.localizer.preview_state,
                                      fresh=start is None)  # fmt: skip
            if states is not None and len(states.t):
                self._last_preview = states
        elif start is not None:  # nothing new since the state continued from
            states = self._last_preview
        if states is None or not len(states.t):
            states = self.localizer.latest()
        if states is None or not len(states.t):
            return
        if self.view is not None:
            self.view.publish_pose(float(states.t[-1]), states.x[-1], states.P[-1])
        done = time.perf_counter()
        self.stats.latency.add([done - a for a in arrivals])
        if self.autopilot is not None:  # sent at once when its slot is free
            self.autopilot.offer(states, arrivals)

    def status(self) -> dict:
        """Rates, link counters, filter health and map size now."""
        links = {name: link.counters.as_dict() for name, link in self.links.items()}
        for c in links.values():
            c.pop("clock_offsets", None)
        return {
            "clock": self.clock(),
            "records": dict(self.stats.records),
            "late": self.stats.late,
            "buffered": len(self.buffer),
            "filter": "running" if self.localizer.ready else "waiting: "
            + "; ".join(self.localizer.missing),
            "states": self.stats.states,
            "pings_mapped": self.stats.pings,
            "links": links,
            **({} if self.autopilot is None else {"autopilot": self.autopilot.status()}),
        }  # fmt: skip

    def _status(self) -> None:
        status = self.status()
        if self.recorder is not None:
            self.recorder.write_status(status["clock"], status)
        view = self.view
        if view is not None and self.mapper is not None and self.stats.pings:
            start = time.perf_counter()
            if view.subscribed("/undertow/map") and start >= self._next_map_view:
                if self._cloud is None:
                    self._cloud = MapCloud(self.mapper.mapper,
                                           self.mapping_config.occupied_threshold)  # fmt: skip
                self._cloud.update()
                view.publish_cloud(status["clock"], self._cloud.points())
                self._next_map_view = map_view_due(start, time.perf_counter() - start)
        if view is not None and len(self._path) and view.subscribed("/undertow/path"):
            view.publish_path(status["clock"], self._path.positions())
        if self.status_callback is not None:
            self.status_callback(status)

    # -- the end -------------------------------------------------------------------------------
    def finish(self) -> LiveResult:
        """Links stopped, the buffer flushed, results written, the recording closed."""
        for link in self.links.values():
            link.stop(timeout=2.0)
        gc.unfreeze()  # (start) the session's long-lived objects are collectable again
        for link in self.links.values():
            link.pump()
        for item in self._drain():  # what the links queued before they stopped
            self._take(*item)
        self._commit(math.inf)
        localization = map_dir = None
        if self.localizer.ready:
            trajectory = self.localizer.trajectory(since=self._taken())
            self._record_final(trajectory, final_only=False)
            localization = self._save_localization(trajectory)
            map_dir = self._save_map(trajectory)
            missing = trajectory.metadata.get("online", {}).get("started_without")
            if missing:
                self.notes.append(f"the filter started without {missing} (start timeout)")
        else:
            self.notes.append("the filter never started: " + "; ".join(self.localizer.missing))
        recording = self.recorder.close() if self.recorder is not None else None
        if self.view is not None:
            self.view.close()
        summary = self.summary()
        _write_yaml(self.out_dir / "live.yaml", summary)
        return LiveResult(self.out_dir, recording, localization, map_dir, summary,
                          list(self.notes))  # fmt: skip

    def _save_localization(self, trajectory) -> Path:
        """``localization/`` from the states stored as they became final (all of them now),
        with the metadata of the filter's run and the session's summary."""
        meta = trajectory.metadata
        online = {k: v for k, v in meta.get("online", {}).items() if k != "first_state"}
        metadata = {**meta, "online": online, "live": self.summary()}
        if self._store is None:  # (no state became final)
            self._store = TrajectoryStore(self.out_dir / STATES_DIR)
        stored = StoredTrajectory(self._store, trajectory.variant, metadata)
        out = save_stored_trajectory(stored, self.out_dir / "localization", self.overwrite)
        self._store.remove()
        return out

    def _save_map(self, trajectory) -> Path | None:
        if self.mapper is None:
            return None
        self._update_map(trajectory)
        self.stats.pings += self.mapper.finish(trajectory)
        occupancy = self.mapper.occupancy()
        if not len(occupancy):
            return None
        config = self.mapping_config
        return save_map(occupancy, config.model_dump(mode="json"), self.mapper.metadata(),
                        self.out_dir / "map", self.overwrite,
                        threshold=config.occupied_threshold)  # fmt: skip

    def summary(self) -> dict:
        return to_plain({
            "settings": self.live.model_dump(),
            "records": dict(self.stats.records),
            "late": self.stats.late,
            "states": self.stats.states,
            "pings_mapped": self.stats.pings,
            "forced_commits": self.stats.forced_commits,
            "filter_started_at": self.stats.started_filter_at,
            "filter_span_s": self.stats.span_s,
            "latency": self.stats.latency_summary(),
            "links": {n: link.counters.as_dict() for n, link in self.links.items()},
            "link_info": {n: link.info for n, link in self.links.items()},
            "wave": self.sea.to_dict() if self.sea is not None else None,
            "notes": list(self.notes),
            **({} if self.autopilot is None else {"autopilot": self.autopilot.summary()}),
        })  # fmt: skip


def _filter_params(settings: Settings, calibration) -> dict:
    """The localizer fields of the settings, with what a calibration (file) supplies."""
    params = settings.localizer_params()
    if calibration is None:
        return params
    if not isinstance(calibration, Calibration):
        calibration = Calibration.from_yaml(calibration)
    config = LocalizerConfig(**params)
    return {**calibration_fields(calibration, config), **params}


def _live_mapping(settings: Settings):
    """The mapping config of a live session: the adaptive kernel needs fixed bounds online; tpu
    maps without the wave terms, in the ranges and in the poses' depth (the wave, and the
    filter's pressure updates, are not known yet when a ping is mapped)."""
    config = settings.mapping
    if config.method == "adaptive" and config.variance_bounds is None:
        config = config.model_copy(update={"variance_bounds": LIVE_VARIANCE_BOUNDS})
    return config.model_copy(update={"wave_range_noise": False, "wave_depth_noise": False})


def _write_yaml(path: Path, doc: dict) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(yaml.safe_dump(json.loads(json.dumps(doc, default=str)), sort_keys=False))
    tmp.replace(path)


def check_live_settings(settings: Settings) -> None:
    """A live section that names no link is an error before anything starts."""
    live = settings.live
    if not (live.dvl or live.sonar or live.mavlink):
        raise ConfigError("live: no sensor link given (--dvl, --sonar and/or --mavlink)")


__all__ = ["LiveResult", "LiveSession", "LiveStats", "check_live_settings"]
