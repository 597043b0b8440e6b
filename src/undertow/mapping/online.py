"""The map online: ranges (DVL beams, sonar) of each chunk are integrated once the trajectory
covers their time, with the samples and the mapper of :func:`~undertow.mapping.run.map_log`.

A range at time t waits until the trajectory has a final state at or after t (``final_states``
of an :class:`~undertow.estimation.online.OnlineLocalizer` trajectory's ``"online"`` metadata:
states no later chunk can revise; all states of any other trajectory); its pose is interpolated
between the two states around t (:func:`~undertow.mapping.samples.pose_at`, the angles
unwrapped along the whole trajectory as the offline path does), so it is the pose the offline
map of the final trajectory uses, bit for bit. Ranges before the trajectory's first state, and
those after its last at :meth:`OnlineMapper.finish`, are dropped and counted as the offline
path counts them (``*_outside_trajectory``).

The posterior sums of eq:alpha_param / eq:beta_param add the same kernel terms as the offline
map, in another order (chunk by chunk, sonar after DVL within one): the counting model's unit
terms give the same alpha and beta exactly; the BKI kernels' sums agree to rounding (a sum of n
positive terms reordered changes by at most (n - 1) eps times the sum, eps = 2^-52).
Adaptive BKI needs fixed ``variance_bounds`` (the session normalization needs every sample
first).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import ConfigError
from ..log import Log
from ..occupancy import OccupancyMap
from ..robot import Mounting
from ..trajectory import Trajectory
from .config import MappingConfig
from .mappers import mapper_from_config
from .samples import (
    DVL_MAX_RANGE,
    DVL_MIN_RANGE,
    SENSOR_DVL,
    SENSOR_SONAR,
    check_range,
    expand,
    pose_at,
    rays_from_pose,
)

_ALL_TIME = (-np.inf, np.inf)


class OnlineMapper:
    """``OnlineMapper(config, mounting=m)``; :meth:`push` per chunk with the trajectory so far,
    :meth:`finish` with the final one, :meth:`occupancy`. ``mounting``: the session's (chunks
    carry the default one; None: each chunk's); ``prior``: a map to start from, as map_log's."""

    def __init__(self, config: MappingConfig, *, mounting: Mounting | None = None,
                 prior=None) -> None:  # fmt: skip
        if config.method == "adaptive" and config.variance_bounds is None:
            raise ConfigError("OnlineMapper: adaptive BKI online needs fixed variance_bounds "
                              "(mapping.variance_bounds)")  # fmt: skip
        self.config = config
        self.mounting = mounting
        self.mapper = mapper_from_config(config, prior=prior)
        self.poses = _Poses()
        self.dropped: dict[str, int] = {}
        self.hits = self.free = self.ranges = 0
        self._waiting: list[dict] = []  # ranges waiting for the trajectory, per chunk and sensor
        self._t_queued = -np.inf  # the newest range queued

    def push(self, chunk: Log, trajectory: Trajectory) -> int:
        """Queue the chunk's ranges; integrate those the trajectory's final states now cover.
        Returns the number of ranges (DVL beams, sonar ranges) integrated."""
        self._queue(chunk)
        online = trajectory.metadata.get("online", {})
        first = int(online.get("first_state", 0))
        final = int(online.get("final_states", first + len(trajectory)))
        self.poses.extend(trajectory, final, first)
        n = self._integrate(self.poses.t_last())
        # later chunks (in time order) bring ranges from the newest queued on: the states
        # before those still waiting and before it are no longer needed
        need = min([self._t_queued] + [float(w["t"][0]) for w in self._waiting])
        self.poses.drop_before(need)
        return n

    @property
    def states_used(self) -> int:
        """How many of the trajectory's states the map has taken: a later :meth:`push` needs
        the states from this number on (``OnlineLocalizer.committed(since=...)``)."""
        return self.poses.n

    def finish(self, trajectory: Trajectory) -> int:
        """Integrate the ranges still waiting that lie inside the final trajectory's span (the
        rest are dropped as outside it); ``trajectory``: from state ``metadata["online"]
        ["first_state"]`` on (0 when absent). Returns the number integrated."""
        first = int(trajectory.metadata.get("online", {}).get("first_state", 0))
        self.poses.extend(trajectory, first + len(trajectory), first)
        return self._integrate(np.inf)

    def occupancy(self) -> OccupancyMap:
        occupancy = self.mapper.occupancy()
        return dataclasses.replace(
            occupancy,
            metadata={**occupancy.metadata,
                      "occupied_threshold": self.config.occupied_threshold},
        )  # fmt: skip

    def metadata(self) -> dict:
        """As :func:`~undertow.mapping.run.map_log`'s, plus the ranges waiting."""
        occupancy = self.occupancy()
        return {
            "mapper": self.mapper.metadata(),
            "samples": {"hits": self.hits, "free": self.free,
                        "dropped": {k: int(v) for k, v in self.dropped.items()}},
            "cells_with_mass": len(occupancy),
            "occupied_cells": len(occupancy.occupied(self.config.occupied_threshold)),
            "ranges_integrated": self.ranges,
            "ranges_waiting": int(sum(w["t"].size for w in self._waiting)),
            "source": "online",
        }  # fmt: skip

    def _queue(self, chunk: Log) -> None:
        """The chunk's valid, in-range ranges (the checks that need no trajectory)."""
        cfg = self.config
        mounting = self.mounting if self.mounting is not None else chunk.mounting
        d, s = chunk.dvl, chunk.sonar
        if cfg.use_dvl and d is not None and len(d):
            t = np.repeat(d.t, 4)
            r = d.beam_range.reshape(-1)
            unit = d.beam_unit.reshape(-1, 3)
            flag = d.beam_valid.reshape(-1) & np.all(np.isfinite(unit), axis=1)
            ok = self._check("dvl", t, r, flag, DVL_MIN_RANGE, DVL_MAX_RANGE)
            self._wait("dvl", t[ok], r[ok], unit[ok], mounting.dvl, cfg.sigma0_dvl, SENSOR_DVL)
        if cfg.use_sonar and s is not None and len(s):
            flag = np.ones(len(s), bool)
            ok = self._check("sonar", s.t, s.range, flag, s.min_range, s.max_range)
            unit = np.tile([0.0, 0.0, 1.0], (int(ok.sum()), 1))
            self._wait("sonar", s.t[ok], s.range[ok], unit, mounting.sonar, cfg.sigma0_sonar,
                       SENSOR_SONAR)  # fmt: skip

    def _check(self, kind, t, r, flag, lo, hi) -> np.ndarray:
        dropped: dict[str, int] = {}
        ok = check_range(kind, t, r, flag, lo, hi, _ALL_TIME, dropped)
        for key, value in dropped.items():
            self.dropped[key] = self.dropped.get(key, 0) + value
        return ok

    def _wait(self, kind, t, r, unit, mount, sigma0, sensor) -> None:
        if t.size:
            self._t_queued = max(self._t_queued, float(t[-1]))
            self._waiting.append({"kind": kind, "t": t, "r": r, "unit": unit, "mount": mount,
                                  "sigma0": sigma0, "sensor": sensor})  # fmt: skip

    def _integrate(self, until: float) -> int:
        """Integrate the waiting ranges with t <= until inside the poses' span."""
        if self.poses.n == 0:
            return 0
        first, last = self.poses.t_first, self.poses.t_last()
        kept = self.poses.t_kept()
        parts, still = [], []
        for w in self._waiting:
            if w["t"][0] > until:  # all of it still waits
                still.append(w)
                continue
            if w["t"][0] >= kept and w["t"][-1] <= last:  # all of it now
                parts.append(self._rays(w, slice(None)))
                continue
            now = w["t"] <= until
            outside = now & ((w["t"] < first) | (w["t"] > last))
            gone = now & ~outside & (w["t"] < kept)  # (a chunk older than those pushed before)
            take = now & ~outside & ~gone
            for key, count in (
                (f"{w['kind']}_outside_trajectory", outside.sum()),
                (f"{w['kind']}_before_the_states_kept", gone.sum()),
            ):
                if count:
                    self.dropped[key] = self.dropped.get(key, 0) + int(count)
            if take.any():
                parts.append(self._rays(w, take))
            if not now.all():
                still.append({**w, **{k: w[k][~now] for k in ("t", "r", "unit")}})
        self._waiting = still
        if not parts:
            return 0
        columns = zip(*parts, strict=True)
        origin, direction, r, var, sig, sensor = (np.concatenate(c) for c in columns)
        samples = expand(origin, direction, r, var, sig, sensor, self.config.free_resolution, {})
        self.mapper.integrate(samples)
        hits = int((samples.label == 1).sum())
        self.hits += hits
        self.free += int((samples.label == 0).sum())
        self.ranges += int(r.size)
        return int(r.size)

    def _rays(self, w: dict, take: np.ndarray):
        t = w["t"][take]
        pos, rpy, var = self.poses.at(t)
        return rays_from_pose(w["r"][take], w["unit"][take], w["mount"], pos, rpy, var,
                              w["sigma0"], w["sensor"])  # fmt: skip


class _Poses:
    """The trajectory's states used so far: t, position, rpy unwrapped as numpy.unwrap does
    along the whole trajectory (continued state by state), position variance; grown by
    doubling. ``n`` counts every state taken; the arrays hold those from number ``base`` on
    (:meth:`drop_before` lets go of the states no range can need any more: a day's dive keeps
    a window, not the dive)."""

    def __init__(self) -> None:
        self.n = 0
        self.base = 0
        self.t_first = np.inf  # the first state's time (kept when its row is dropped)
        self.t = np.empty(0)
        self.pos, self.ang, self.var = np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3))
        self._raw_last = None  # the last state's wrapped rpy
        self._correction = None  # numpy.unwrap's running sum of corrections (None: one state)

    @property
    def held(self) -> int:
        return self.n - self.base

    def t_last(self) -> float:
        return float(self.t[self.held - 1]) if self.held else -np.inf

    def t_kept(self) -> float:
        """The time of the first state held (ranges before it can no longer be placed)."""
        return float(self.t[0]) if self.held else np.inf

    def extend(self, trajectory: Trajectory, upto: int, first: int = 0) -> None:
        """Take states n..upto-1 of a trajectory whose first state is number ``first``."""
        if upto <= self.n:
            return
        if first > self.n:
            raise ValueError(f"online map: states from {self.n} needed, given from {first}")
        sl = slice(self.held, upto - self.base)
        src = slice(self.n - first, upto - first)
        raw = np.asarray(trajectory.orientation[src], float)
        self._grow(upto - self.base)
        self.t[sl] = trajectory.t[src]
        self.pos[sl] = trajectory.position[src]
        self.var[sl] = np.einsum("nii->ni", trajectory.P[src, :3, :3])
        self.ang[sl] = self._unwrap(raw)
        if self.n == 0:
            self.t_first = float(self.t[0])
        self.n = upto

    def drop_before(self, t: float) -> None:
        """Let go of the states before the last one at or before ``t`` (:meth:`at` of times
        >= t uses none of them), once they are at least half of those held (the copy is
        then amortized)."""
        k = int(np.searchsorted(self.t[: self.held], t, "right")) - 1
        if k <= 0 or 2 * k < self.held:
            return
        m = self.held - k
        for name in ("t", "pos", "ang", "var"):
            a = getattr(self, name)
            a[:m] = a[k : self.held]
        self.base += k

    def _unwrap(self, raw: np.ndarray) -> np.ndarray:
        """numpy.unwrap's up[k] = p[k] + cumsum(correction)[k] (period 2 pi), continued."""
        prev = raw[:1] if self._raw_last is None else self._raw_last[None]
        dd = np.diff(np.concatenate([prev, raw]), axis=0)
        ddmod = np.mod(dd + np.pi, 2 * np.pi) - np.pi
        np.copyto(ddmod, np.pi, where=(ddmod == -np.pi) & (dd > 0))
        ph = ddmod - dd
        np.copyto(ph, 0, where=np.abs(dd) < np.pi)
        out = raw.copy()
        if self._raw_last is None:  # the first state is kept as it is
            ph, out_rest = ph[1:], out[1:]
        else:
            out_rest = out
        if ph.shape[0]:
            if self._correction is None:
                acc = np.cumsum(ph, axis=0)
            else:
                acc = np.cumsum(np.concatenate([self._correction[None], ph]), axis=0)[1:]
            out_rest += acc
            self._correction = acc[-1]
        self._raw_last = raw[-1].copy()
        return out

    def _grow(self, n: int) -> None:
        if n <= self.t.size:
            return
        size = max(2 * self.t.size, n, 64)
        for name in ("t", "pos", "ang", "var"):
            old = getattr(self, name)
            new = np.empty((size, *old.shape[1:]))
            new[: self.held] = old[: self.held]
            setattr(self, name, new)

    def at(self, t: np.ndarray):
        """pose_at over the states around t (the same values as over all of them)."""
        held = self.held
        lo = max(int(np.searchsorted(self.t[:held], t.min(), "right")) - 1, 0)
        hi = min(int(np.searchsorted(self.t[:held], t.max(), "left")) + 1, held)
        sl = slice(lo, hi)
        return pose_at(self.t[sl], self.pos[sl], self.ang[sl], self.var[sl], t)
