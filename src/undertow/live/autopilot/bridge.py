"""``undertow live --autopilot``: the live session's newest estimate to the autopilot over the
session's MAVLink link, and what the autopilot says back, recorded and shown.

The session calls four hooks (:mod:`undertow.live.pipeline`): :meth:`AutopilotBridge.offer` with
every preview's states (and the arrivals of the DVL reports it took), :meth:`~AutopilotBridge.
tick` every loop turn (what the vehicle said, what to ask it, the fallback message of a slot,
for which it runs a preview of the buffered records), :meth:`~AutopilotBridge.note_dvl` with
every DVL record and :meth:`~AutopilotBridge.wait_s` for how long the loop may sleep. A message
goes when the schedule (:mod:`.schedule`) says so, the safety rules (:mod:`.gate`) allow it,
and the autopilot, its clock and (position modes) its heading are known (:mod:`.vehicle`,
:mod:`.frame`).

Recorded in the live mcap (std_msgs/String JSON unless said): ``/autopilot/sent`` (each message
as sent: what, its time, reset_counter, quality or confidence, and posErr/angErr as ArduPilot
reduces its covariance), ``/autopilot/ekf_status`` (EKF_STATUS_REPORT decoded),
``/autopilot/statustext``, ``/autopilot/state`` (every change of sending / held, and every
note) and ``/autopilot/pose`` (geometry_msgs/PoseWithCovarianceStamped, frame ``world``: the
autopilot's LOCAL_POSITION_NED turned back into undertow's frame, with its ATTITUDE; covariance
zero, the autopilot reports none), next to ``/undertow/pose``.
"""

from __future__ import annotations

import collections
import math
import time

import numpy as np

from ...errors import UndertowError
from . import covariance as cov
from . import messages
from .frame import HeadingOffset
from .gate import SendGate
from .schedule import SPACING_S, Rhythm, SendSchedule
from .stats import SendStats
from .vehicle import OBSERVED, Vehicle

#: transition notes told before the rest go to the recording only
MAX_TRANSITION_NOTES = 20
#: a velocity-delta interval longer than this (s) is not one: the next message starts anew
MAX_DELTA_S = 1.0
#: the shortest velocity-delta interval (s): EKF3 drops a delta shorter than its own time step
#: (``delTime < dtEkfAvg`` in writeBodyFrameOdom, AP_NavEKF3_Measurements.cpp; about 12 ms)
MIN_DELTA_S = 0.02


class AutopilotBridge:
    """The sender of the module docstring, for a session (duck-typed: ``live`` settings,
    ``links["mavlink"]``, ``clock``, ``recorder``, ``view``, ``notes``, ``on_notice``)."""

    def __init__(self, session, *, perf=time.perf_counter, reset_counter: int | None = None):
        live = session.live
        self.session, self.live, self.mode = session, live, live.autopilot_mode
        self.message = messages.MESSAGE_OF_MODE[self.mode]
        self.link = session.links["mavlink"]
        self.link.source_component = live.autopilot_component_id
        self.own = (255, live.autopilot_component_id)
        self.clock = session.clock
        self.perf = perf
        self.inflation = live.autopilot_covariance_inflation
        offset = live.autopilot_yaw_offset_deg
        self.heading = HeadingOffset(None if offset is None else math.radians(offset))
        self.schedule = SendSchedule(live.autopilot_rate_hz, *SPACING_S[self.mode])
        self.rhythm = Rhythm()  # when the next DVL report comes
        self.gate = SendGate(mode=self.mode, max_position_std_m=live.autopilot_max_position_std_m,
                             dvl_timeout_s=live.autopilot_dvl_timeout_s,
                             settle_s=live.autopilot_settle_s, jump_m=live.autopilot_jump_m,
                             inflation=self.inflation, reset_counter=reset_counter)  # fmt: skip
        self.reset_counter_start = self.gate.reset_counter
        pressure = self.link.mapper.config.pressure
        self.vehicle = Vehicle(mode=self.mode, own=self.own, pressure=pressure,
                               origin=live.autopilot_origin, set_params=live.autopilot_set_params,
                               send=self.link.send, note=self._note, record=self._record,
                               dvl_from_mavlink="dvl" not in session.links)  # fmt: skip
        self.stats = SendStats(self._wall(self.schedule.period))
        self._inbox: collections.deque = collections.deque()
        self.link.observe((*OBSERVED, pressure), self._queue)
        self._newest = None  # (t, x, P) of the newest state offered
        self._fresh = False  # it carries a DVL report not sent yet
        self._arrivals: list[float] = []
        self._sent_t: float | None = None
        self._delta_from = None  # (t, x): velocity-delta's interval start
        self.reason = "waiting for the autopilot's HEARTBEAT"
        self.sending = False
        self._transitions = 0
        self._held_period = None
        self._retry_at = -math.inf  # after a hold or nothing new: the next try (session s)

    # -- hooks ------------------------------------------------------------------------------
    def _queue(self, msg, arrival: float) -> None:  # the decoding thread: only queue
        self._inbox.append((msg, arrival))

    def note_dvl(self, record) -> None:
        """A DVL record (any link): its validity feeds the DVL-lost rule."""
        self.gate.note_dvl(record.t, bool(record.data.get("valid", True)))
        self.rhythm.arrived(record.arrival)

    def offer(self, states, arrivals=()) -> None:
        """A preview's states (a Trajectory; its last row is the newest state) and the
        arrivals (perf_counter s) of the DVL reports it includes."""
        if states is None or not len(states.t):
            return
        t = float(states.t[-1])
        if self._newest is None or t > self._newest[0]:
            self._newest = (t, np.array(states.x[-1], dtype=float),
                            np.array(states.P[-1], dtype=float))  # fmt: skip
            self._pair_heading()
        if arrivals:
            self._arrivals.extend(arrivals)
            self._fresh = True
        now = self.clock()
        due = self.schedule.due(now, self._fresh, self._newest[0], self.rhythm.next())
        if self._may_try(now) and due:
            self._send(now)

    def tick(self, preview=None) -> None:
        """Every loop turn: take what the vehicle said, send what is due to it, and the message
        a full token bucket calls for (after a fresh ``preview()`` of the buffered records)."""
        while self._inbox:
            msg, arrival = self._inbox.popleft()
            changed = self.vehicle.take(msg, arrival)
            if changed:
                self._show(changed)
        now = self.clock()
        self.vehicle.housekeeping(now)
        fresh, dvl_next = self._fresh, self.rhythm.next()
        if not (self._may_try(now) and self.schedule.due(now, fresh, None, dvl_next)):
            return
        newest = self._newest
        stale = newest is None or newest[0] - self.schedule.last_state < self.schedule.min_state
        if (stale or not fresh) and preview is not None:
            preview()  # the newest state over the records buffered since (offered: may send)
        now, newest = self.clock(), self._newest
        if newest is not None and self.schedule.due(now, self._fresh, newest[0], dvl_next):
            self._send(now)
        elif self.schedule.due(now, self._fresh, None, dvl_next):  # nothing new: not at once
            self._retry_at = now + self.schedule.period / 2

    def wait_s(self) -> float:
        """Wall seconds the loop may wait for data before the next message may go."""
        if not self.schedule.started or self._newest is None:
            return self._wall(self.schedule.period)
        now = self.clock()
        at = max(self.schedule.next_due(now, self._fresh, self.rhythm.next()), self._retry_at)
        return self._wall(max(at - now, 0.0))

    def _may_try(self, now: float) -> bool:
        """Not within the back-off after a hold (a fresh DVL state may always try)."""
        return self._newest is not None and (self._fresh or now >= self._retry_at)

    # -- sending ----------------------------------------------------------------------------
    def _send(self, now: float) -> None:
        newest = self._newest
        if newest is None or (self._sent_t is not None and newest[0] <= self._sent_t):
            self._retry_at = now + self.schedule.period / 2  # nothing new: try again later
            return
        t, x, P = newest
        reason = self._precondition()
        verdict = None if reason else self.gate.check(now, t, x, P)
        if reason or not verdict.send:
            if reason:
                self.gate.hold()
            return self._hold(reason or verdict.reason)
        counter, reset = self.gate.prepare(t, x)
        msg, info = self._build(t, x, P, counter)
        if msg is None:  # (velocity-delta: this state starts the interval of the next message)
            self._retry_at = now + MIN_DELTA_S
            return None
        if not self.link.send(msg):
            self.gate.hold()
            return self._hold("the link is not connected (or has heard no peer yet)")
        self.gate.sent(t, x, reset)
        self.schedule.sent(now, t)
        self._sent_t = t
        wall = self.perf()
        self.stats.on_send(wall, now - t, self._arrivals)
        self._arrivals, self._fresh = [], False
        if not self.sending:
            rate = self.live.autopilot_rate_hz
            self._transition(f"autopilot: sending {self.message} at {rate:g} Hz "
                             f"(reset_counter {counter})")  # fmt: skip
        self.sending, self.reason = True, ""
        self._record("sent", t, {**info, "reset_counter": counter, "reset": reset,
                                 "state_t": t, "age_ms": (now - t) * 1e3,
                                 "sent_at": now, "tokens": self.schedule.tokens})  # fmt: skip

    def _precondition(self) -> str:
        v = self.vehicle
        if v.target is None:
            return "waiting for the autopilot's HEARTBEAT"
        if v.clock.offset is None:
            return "waiting for the autopilot's clock (ATTITUDE time_boot_ms)"
        if self.mode != "velocity-delta" and self.heading.value is None:
            return "finding the heading offset (ATTITUDE against undertow's yaw)"
        return ""

    def _build(self, t, x, P, counter):
        usec = self.vehicle.clock.to_autopilot_usec(t)
        k, dpsi = self.inflation, self.heading.value or 0.0
        if self.mode == "odometry":
            quality = cov.quality_from_std(cov.horizontal_std(P, k),
                                           self.live.autopilot_max_position_std_m)  # fmt: skip
            msg = messages.odometry(usec, x, P, yaw_offset_rad=dpsi, inflation=k,
                                    reset_counter=counter, quality=quality)  # fmt: skip
            return msg, {"message": self.message, "time_usec": usec, "quality": quality,
                         **self._errors(msg.pose_covariance)}  # fmt: skip
        if self.mode == "vision-position":
            msg = messages.vision_position_estimate(usec, x, P, yaw_offset_rad=dpsi,
                                                    inflation=k, reset_counter=counter)  # fmt: skip
            return msg, {"message": self.message, "time_usec": usec,
                         **self._errors(msg.covariance)}  # fmt: skip
        return self._delta(usec, t, x, P)

    def _delta(self, usec, t, x, P):
        start = self._delta_from
        if start is not None and 0 < t - start[0] < MIN_DELTA_S:
            return None, "velocity-delta: interval too short"  # (the start is kept)
        self._delta_from = (t, x)
        if start is None or not MIN_DELTA_S <= t - start[0] <= MAX_DELTA_S:
            return None, "velocity-delta: starting an interval"
        vmin, vmax = self._verr()
        self.gate.max_velocity_std_m_s = vmax
        std = cov.velocity_std(P, self.inflation)
        confidence = cov.confidence_from_std(std, vmin, vmax)
        msg = messages.vision_position_delta(usec, t - start[0], start[1], x, confidence)
        return msg, {"message": self.message, "time_usec": usec, "confidence": confidence,
                     "velocity_std_m_s": std, "dt_s": t - start[0]}  # fmt: skip

    def _verr(self) -> tuple[float, float]:
        values = self.vehicle.params.values
        vmin = values.get("EK3_VIS_VERR_MIN", (cov.VIS_VERR_MIN_DEFAULT, 0))[0]
        vmax = values.get("EK3_VIS_VERR_MAX", (cov.VIS_VERR_MAX_DEFAULT, 0))[0]
        return float(vmin), float(vmax)

    def _errors(self, c) -> dict:
        pos, ang = cov.ardupilot_errors(list(c))
        return {"pos_err_m": pos, "ang_err_rad": ang}

    def _hold(self, reason: str) -> None:
        now = self.clock()
        self._retry_at = now + self.schedule.period / 2  # (a fresh DVL state may still try)
        period = int(now // self.schedule.period)
        if period != self._held_period:  # (counted once per period held)
            self._held_period = period
            self.stats.on_hold(reason)
        self._arrivals, self._fresh = [], False  # carried by no message
        self._delta_from = None  # (a held time is no velocity-delta interval)
        if reason != self.reason or self.sending:
            self._transition(f"autopilot: not sending: {reason}")
        self.sending, self.reason = False, reason

    def _pair_heading(self) -> None:
        att = self.vehicle.attitude
        if att is None or self.heading.value is not None:
            return
        t, x = self._newest[0], self._newest[1]
        if self.heading.observe(att[0], att[3], t, float(x[5])):
            self._note(self.heading.describe(self.mode != "velocity-delta"))

    # -- telling, recording, showing -----------------------------------------------------------
    def _note(self, line: str) -> None:
        self.session.notes.append(line)
        self._record("state", self.clock(), {"note": line})
        if self.session.on_notice is not None:
            self.session.on_notice(line)

    def _transition(self, line: str) -> None:
        self._transitions += 1
        if self._transitions <= MAX_TRANSITION_NOTES:
            self._note(line)
        else:
            self._record("state", self.clock(), {"note": line})

    def _record(self, kind: str, t: float, payload: dict) -> None:
        recorder = self.session.recorder
        if recorder is None:
            return
        try:
            recorder.write_status(t, payload, topic=f"/autopilot/{kind}")
        except UndertowError:  # closed, or a time no stamp holds: the record is skipped
            pass

    def _show(self, changed: dict) -> None:
        view, recorder = self.session.view, self.session.recorder
        if "ekf" in changed and view is not None:
            view.publish_autopilot_ekf(self.clock(), {**changed["ekf"], "sending": self.sending,
                                                      "reason": self.reason})  # fmt: skip
        if "position" not in changed:
            return
        t, *p = changed["position"]
        dpsi = self.heading.value or 0.0
        pos = cov.rotate_z(-dpsi) @ np.asarray(p, dtype=float)
        att = self.vehicle.attitude
        rpy = (0.0, 0.0, 0.0) if att is None else (att[1], att[2], att[3] - dpsi)
        x = np.concatenate([pos, rpy])
        if recorder is not None:
            try:
                recorder.write_pose(t, x, np.zeros((6, 6)), topic="/autopilot/pose")
            except UndertowError:
                pass
        if view is not None:
            view.publish_autopilot_pose(t, pos, rpy)

    # -- status ------------------------------------------------------------------------------
    def _wall(self, seconds: float) -> float:
        wall = getattr(self.clock, "wall_seconds", None)
        return wall(seconds) if wall is not None else seconds

    def status(self) -> dict:
        ekf = self.vehicle.ekf or {}
        return {
            "mode": self.mode,
            "sending": self.sending,
            "reason": self.reason,
            "sent": self.stats.sent,
            "reset_counter": self.gate.reset_counter,
            "ekf": ekf.get("names"),
            "ekf_horizontal_position": ekf.get("horizontal_position"),
        }

    def summary(self) -> dict:
        heading = self.heading
        return {
            "mode": self.mode,
            "message": self.message,
            "rate_hz": self.live.autopilot_rate_hz,
            "covariance_inflation": self.inflation,
            **self.stats.summary(),
            "missed_periods": self.schedule.missed,
            "reset_counter": {
                "start": self.reset_counter_start,
                "end": self.gate.reset_counter,
                "resets": self.gate.resets,
                "jumps": self.gate.jumps,
                "restarts": self.gate.restarts,
            },  # fmt: skip
            "heading_offset_deg": None if heading.value is None else math.degrees(heading.value),
            "heading_offset_source": heading.source,
            "link": {"sent": dict(self.link.sent_counts), "unsent": self.link.unsent},
            **self.vehicle.summary(),
        }


def open_bridge(session) -> AutopilotBridge | None:
    """The bridge of a session whose ``live.autopilot`` is on (else None)."""
    if not session.live.autopilot:
        return None
    return AutopilotBridge(session)
