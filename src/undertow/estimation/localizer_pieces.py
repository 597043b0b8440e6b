"""A log of any length localized piece by piece: the UKF over a log given as consecutive time
pieces (:func:`undertow.io.iter_log_pieces`), its states appended to a
:class:`~undertow.trajectory_chunks.TrajectoryStore` and smoothed there, in memory bounded by a
piece, not the log.

The filter loop is resumable (:func:`~undertow.estimation.filter_loop.resume_filter`: rows fed
in any pieces give the states, counts and NIS sums of one run over all of them, bit for bit);
what :meth:`~undertow.estimation.localizer.Localizer.run` decides with the whole log in hand
is made the same way here:

- the measurement rows of a piece are those of the whole log in its window: each stream's
  rows are built per row (:mod:`undertow.estimation.rows`), merged by time then sensor, and a
  piece holds every stream's messages of its time window, so the merged rows of the pieces end
  to end are the whole log's;
- the depth-rate check judges a depth by the median of ``HALF_WINDOW`` depths on each side
  (:func:`~undertow.estimation.health.depth_jumps`): a piece is judged with the depths kept of
  the piece before and after it around its own (the pieces are taken one ahead);
- the start (initial state, sensors present, the wave noise, the calibration's and the log's
  settings) comes from the first piece, which holds the log's first rows; the wave noise's site
  (the DVL's median depth and the water depth, used only when a condition is extrapolated by
  physics) is the whole log's when the caller gives ``site_pieces``: a first pass over the
  log's depth, ground-truth and DVL streams alone (:func:`~.noise_physics.sensor_site` of
  pieces), made only when a condition is extrapolated; without it, the first piece's;
- the innovations' consistency report (:mod:`~undertow.estimation.consistency`) is per sensor
  over its evaluated innovations in time order: the whitened innovations are appended to one
  raw file per sensor beside the store and the report is made from them at the end (the IMU's
  at 100 Hz: 2.4 kB per second of log on disk; in memory only at the end, one sensor at once).

Not here (the whole log's path): an output rate (decimated states fit in memory), a wave
condition estimated from the log (``"auto"``: the sea-state estimate reads the whole log) and
the replay of a live session's wave decisions (``live_wave``: its schedule is the recording's).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..log import Log
from ..trajectory_chunks import StoredTrajectory, TrajectoryStore
from . import filter_loop, model
from .consistency import ConsistencyReport, sensor_consistency
from .health import HALF_WINDOW, check_mounting, depth_jumps
from .localizer import (
    FILTER_ROWS,
    Localizer,
    check_options,
    resolved_localizer,
    run_metadata,
    sensor_coverage,
    with_log_heading,
)
from .noise_physics import sensor_site
from .rows import (
    depth_reference,
    dr_rows,
    dvl_rows,
    filter_pressure_rows,
    imu_rows,
    initial_state,
    merged_rows,
    pressure_rows,
)
from .smoother import smooth_store


def localize_pieces(pieces: Iterable[Log], store: TrajectoryStore, variant: str | None = None,
                    profile=None, wave=None, calibration=None, extrapolate: bool = False,
                    smooth: bool = False, store_rows: int = FILTER_ROWS, site_pieces=None,
                    **params) -> StoredTrajectory:  # fmt: skip
    """:func:`~undertow.estimation.localizer.localize` of the log the consecutive ``pieces``
    make, into ``store`` (see the module docstring): the same states, counts and metadata.
    ``calibration``: a Calibration (read by the caller). ``site_pieces``: a callable giving
    the log's pieces again (their depth, ground-truth and DVL streams suffice), for the wave
    noise's site of the whole log (module docstring); None: the first piece's."""
    if variant is not None:
        params["variant"] = variant
    config = check_options(smooth, params)
    if config.output_rate_hz is not None:
        raise ConfigError("localize in pieces: every state is stored (no output rate)")
    ahead = _ahead(iter(pieces))
    first = next(ahead, None)
    if first is None:
        raise ConfigError("localize in pieces: the log has no piece")
    log = first[1]
    localizer, calibration = resolved_localizer(log, profile, wave, calibration, extrapolate,
                                                params, smooth)  # fmt: skip
    if isinstance(wave, str) and wave.strip().lower() == "auto" or log.metadata.get("live_wave"):
        raise ConfigError("localize in pieces: wave 'auto' and a live session's wave decisions "
                          "need the whole log")  # fmt: skip
    trajectory = _filter(localizer, first, ahead, store, (store_rows, site_pieces))
    if smooth:
        meta = smooth_store(store, trajectory.metadata, localizer.config)
        trajectory = trajectory.replace(metadata=meta)
    if calibration is not None:
        trajectory.metadata["calibration"] = calibration.to_dict()
    return trajectory


def _ahead(pieces: Iterator[Log]) -> Iterator[tuple[Log | None, Log, Log | None]]:
    """(the piece before, the piece, the piece after) for each piece."""
    before, current = None, next(pieces, None)
    while current is not None:
        after = next(pieces, None)
        yield before, current, after
        before, current = current, after


def _filter(localizer: Localizer, first: tuple, rest: Iterator, store: TrajectoryStore,
            options: tuple) -> StoredTrajectory:  # fmt: skip
    """Filter the pieces (``first`` and ``rest``: :func:`_ahead`'s triples) into ``store``
    (``options``: the rows per append and ``site_pieces``)."""
    log = first[1]
    cfg = with_log_heading(localizer.config, log)
    rows, site_pieces = options
    unobserved, held = sensor_coverage(log, cfg)
    check_mounting(log.mounting)
    site = None
    if site_pieces is not None:
        site = lambda: sensor_site(site_pieces(), *depth_reference(log, cfg),  # noqa: E731
                                   default=localizer.profile.site())  # fmt: skip
    noise, wave_meta = localizer.wave_noise(log, site=site)
    x0, P0 = initial_state(log, cfg)
    process, sensors = cfg.process_model(held=held), cfg.sensor_model(log.mounting)
    r_adapted = np.zeros((len(model.KIND_NAMES), 3, 3))
    innovations = _Innovations(Path(store.folder))
    rejected: dict[str, int] = {}
    per_kind = np.zeros(len(model.KIND_NAMES), np.int64)
    state, flushed = None, False
    for triple in _chain(first, rest):
        meas = _piece_rows(triple, cfg, noise, rejected)
        if meas.size == 0:
            continue
        if state is None:
            state = filter_loop.start_state(float(meas["t"][0]), x0, P0, process, r_adapted)
        per_kind += np.bincount(meas["kind"], minlength=len(model.KIND_NAMES))
        for k0 in range(0, meas.size, rows):
            k1 = min(k0 + rows, meas.size)
            flushed = triple[2] is None and k1 == meas.size
            whitened = np.full((k1 - k0, 3), np.nan)
            out = filter_loop.resume_filter(meas[k0:k1], state, process, sensors, flushed,
                                            whitened)  # fmt: skip
            store.append(*out)
            innovations.append(meas["kind"][k0:k1], whitened)
    if state is None:
        raise ConfigError("Localizer: the log has no finite, valid DVL/IMU measurements")
    if not flushed:  # the last pieces had no row: the last state is recorded now
        empty = np.zeros(0, filter_loop.MEASUREMENT)
        store.append(*filter_loop.resume_filter(empty, state, process, sensors, True))
    run = (rejected, state.counts, state.nis, per_kind, r_adapted)
    metadata = run_metadata(log, cfg, run, innovations.report(), wave_meta, (unobserved, held))
    return StoredTrajectory(store, variant=cfg.variant, metadata=metadata)


def _chain(first, rest):
    yield first
    yield from rest


def _piece_rows(triple: tuple, cfg, noise, rejected: dict) -> np.ndarray:
    """The merged measurement rows of the middle piece of ``triple`` (the whole log's rows in
    its window), its rows rejected up front added to ``rejected``."""
    before, log, after = triple
    parts, counts = [], {}
    for stream in (imu_rows, dvl_rows, dr_rows):
        part = stream(log, cfg, noise, counts)
        if part is not None:
            parts.append(part)
    kept = [(t[ok], kind, z[ok], R[ok]) for t, kind, z, R, ok in parts]
    part = filter_pressure_rows(log, cfg, noise, counts, jumps=False)
    if part is not None:
        t, kind, z, R, ok, swell = part
        jumped = _jumps(t, z[:, 0], ok, before, after, cfg, noise)
        counts["rejected_pressure_rate"] = int(jumped.sum())
        ok = ok & ~jumped
        kept.append((t[ok], kind, z[ok], R[ok], swell[ok]))
    for key, n in counts.items():
        rejected[key] = rejected.get(key, 0) + n
    return merged_rows(kept, cfg.std_floor**2)[0]


def _jumps(t, d, ok, before: Log | None, after: Log | None, cfg, noise) -> np.ndarray:
    """The depth-rate check of the piece's depths kept (``ok``), each judged with its
    HALF_WINDOW neighbours kept on either side, in this piece or the next or previous one."""
    jumped = np.zeros(t.size, bool)
    if cfg.max_vertical_speed_m_s is None:
        return jumped
    tb, db = _kept_depths(before, cfg, noise, slice(-HALF_WINDOW, None))
    ta, da = _kept_depths(after, cfg, noise, slice(0, HALF_WINDOW))
    idx = np.flatnonzero(ok)
    tt = np.concatenate([tb, t[idx], ta])
    dd = np.concatenate([db, d[idx], da])
    jumped[idx] = depth_jumps(tt, dd, cfg)[tb.size : tb.size + idx.size]
    return jumped


def _kept_depths(log: Log | None, cfg, noise, part: slice) -> tuple[np.ndarray, np.ndarray]:
    """(t, depth) of the depths a neighbouring piece keeps before the rate check (``part`` of
    them: its last or first HALF_WINDOW)."""
    empty = np.zeros(0)
    if log is None:
        return empty, empty
    rows = pressure_rows(log, cfg, noise, {}, warn=False, jumps=False)
    if rows is None:
        return empty, empty
    t, _, z, _, ok = rows
    return t[ok][part], z[ok, 0][part]


class _Innovations:
    """Each sensor's evaluated whitened innovations, appended to a raw float64 file beside the
    store (``innovations-<sensor>.f8``), and the consistency report made from them."""

    def __init__(self, folder: Path) -> None:
        self.files = [folder / f"innovations-{name}.f8" for name in model.KIND_NAMES]
        for file in self.files:
            file.write_bytes(b"")

    def append(self, kind: np.ndarray, whitened: np.ndarray) -> None:
        for k, file in enumerate(self.files):
            w = whitened[kind == k, : model.KIND_DIM[k]]
            w = w[np.isfinite(w).all(axis=1)]
            if w.size:
                with open(file, "ab") as fh:
                    fh.write(np.ascontiguousarray(w, "<f8").tobytes())

    def report(self) -> ConsistencyReport:
        """:func:`~undertow.estimation.consistency.innovation_consistency` of them all."""
        sensors = []
        for k, (name, file) in enumerate(zip(model.KIND_NAMES, self.files, strict=True)):
            w = np.fromfile(file, "<f8").reshape(-1, model.KIND_DIM[k])
            sensors.append(sensor_consistency(name, w))
            file.unlink()
        return ConsistencyReport(tuple(sensors))
