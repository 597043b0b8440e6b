"""The online filter's run once started (:class:`OnlineRun`, what
:class:`~undertow.estimation.online.OnlineLocalizer` drives): the candidate rows of the chunks
pushed so far, the depth-rate verdicts as later depths arrive (:class:`DepthRateCheck`), the
checkpoints a rewind goes back to, the states recorded (:class:`OutputBlocks`) and the previews
a push may take (:class:`Preview`). The rows are built as offline (:mod:`undertow.estimation.rows`)
and filtered by the same numba loop (:func:`~undertow.estimation.filter_loop.resume_filter`);
the module docstring of :mod:`undertow.estimation.online` says why the result is the offline
filter's, bit for bit.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..log import Log
from ..trajectory import Trajectory
from . import filter_loop, model
from .health import HALF_WINDOW, depth_jumps
from .rows import FILTER_STREAMS, dr_rows, dvl_rows, filter_pressure_rows, imu_rows, merged_rows


class OutputBlocks:
    """The states recorded so far, in blocks of BLOCK states: appending never copies the states
    before (a single array grown by doubling copies them all at each growth, a stall of tens of
    ms at a few thousand states and of seconds in an hour of states). ``n`` may be set back
    (a rewind); :meth:`view` hands out views when the range lies in one block. :meth:`release`
    frees the blocks wholly before a state number (a consumer that took them: a day's live
    session keeps a window of states, not the day's)."""

    BLOCK = 2048

    def __init__(self) -> None:
        self.n = 0
        self.released = 0  # states before this number are freed (a multiple of BLOCK)
        self._blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = []

    def release(self, n: int) -> None:
        """Free the blocks whose states all lie before state number ``n`` (<= self.n)."""
        b_end = min(int(n), self.n) // self.BLOCK
        for b in range(self.released // self.BLOCK, b_end):
            self._blocks[b] = None
        self.released = max(self.released, b_end * self.BLOCK)

    def append(self, t, x, P) -> None:
        k, i = t.size, 0
        while i < k:
            b, j = divmod(self.n, self.BLOCK)
            if b == len(self._blocks):
                B, n_x = self.BLOCK, model.N_POSE
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
            return np.empty(0), np.empty((0, model.N_POSE)), np.empty((0,) + (model.N_POSE,) * 2)
        if n0 < self.released:
            raise ValueError(f"online filter: states from {n0} asked for, those before "
                             f"{self.released} were released")  # fmt: skip
        b0, b1 = n0 // B, (n1 - 1) // B
        parts = [tuple(a[max(n0 - b * B, 0) : min(n1 - b * B, B)] for a in self._blocks[b])
                 for b in range(b0, b1 + 1)]  # fmt: skip
        if len(parts) == 1:
            return parts[0]
        return tuple(np.concatenate(c) for c in zip(*parts, strict=True))


class DepthRateCheck:
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


class Preview(NamedTuple):
    """A peek: from the state ``start`` (the committed state's key, or the state an earlier
    peek reached), the accepted ``rows`` it filtered, the states it recorded, the state it
    reached (``end``, never changed afterwards: a later peek from it works on a copy)."""

    start: object
    rows: np.ndarray
    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    end: filter_loop.FilterState


class OnlineRun:
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
        self.out = OutputBlocks()
        self.depth = DepthRateCheck(cfg)
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
        self.previews: dict[int, Preview] = {}  # id(start) -> the latest peek from it
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
            t, kind, z, R, ok, swell = filter_pressure_rows(chunk, cfg, self.noise, rejected,
                                                             warn=False, jumps=False)  # fmt: skip
            parts.append((t[ok], kind, z[ok], R[ok], swell[ok]))
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
            self.previews[id(key)] = Preview(key, rows, t, x, P, state)
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
