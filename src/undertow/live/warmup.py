"""The live session's warm-up: what the first sensor reports would otherwise wait for (numba's
compiled code loaded, rosbags' message serializers generated) done before the sensors start, on
a made-up second of a still vehicle (:meth:`undertow.live.pipeline.LiveSession.start`)."""

from __future__ import annotations

import math
import tempfile
import warnings
from pathlib import Path

import numpy as np

from ..estimation.online import OnlineLocalizer
from ..mapping.grid import load_kernels as load_grid_kernels
from ..mapping.online import OnlineMapper
from ..records import Record, records_to_log
from .recorder import Recorder


def warm_up(variant: str, mapping) -> None:
    """Run the filter (and mapper) once on one second of a still vehicle, so the compiled code
    is loaded (numba's cache) before the sensors start rather than on their first reports."""
    t = np.arange(0.0, 1.0, 0.01)
    records = [Record("imu", float(ti), {"angular_velocity": np.zeros(3)}) for ti in t]
    beams = {"beam_range": np.full(4, 2.0), "beam_valid": np.ones(4, bool),
             "beam_velocity": np.zeros(4), "altitude": 2.0}  # fmt: skip
    records += [Record("dvl", float(ti), {"velocity": np.zeros(3), "valid": True, **beams})
                for ti in t[::10]]  # fmt: skip
    records += [Record("pressure", float(ti), {"pressure": 101325.0 + 9810.0}) for ti in t[::10]]
    records += [Record("sonar", float(ti), {"range": 2.0}) for ti in t[::10]]
    records.sort(key=lambda r: r.t)
    with warnings.catch_warnings():  # what the filter says of this made-up log is no news
        warnings.simplefilter("ignore")
        localizer = OnlineLocalizer(variant=variant, expected={"imu", "dvl", "pressure"})
        mapper = OnlineMapper(mapping) if mapping is not None else None
        for part in (records[: len(records) // 2], records[len(records) // 2 :]):
            chunk = records_to_log(part)
            localizer.push(chunk)
            localizer.peek(chunk)
            if mapper is not None and localizer.ready:
                mapper.push(chunk, localizer.trajectory())
        if mapper is not None and localizer.ready:
            mapper.finish(localizer.trajectory())
        if mapper is not None:
            load_grid_kernels()
        warm_up_recorder(records, localizer.trajectory())


def warm_up_recorder(records, trajectory) -> None:
    """Write one message of every kind to a throwaway recording: rosbags generates each
    message type's serializer on its first use (about 30 ms in all here), and the generated
    code is shared by later recorders, so the session's first records do not wait for it."""
    streams = {r.stream: r for r in records}
    still = {"position": np.zeros(3), "orientation": np.zeros(3)}
    streams["dead_reckoning"] = Record("dead_reckoning", records[0].t, still)
    with tempfile.TemporaryDirectory() as tmp:
        recorder = Recorder(Path(tmp) / "warm-up")
        for record in streams.values():
            recorder.write_record(record)
        t = float(trajectory.t[-1]) if len(trajectory.t) else records[-1].t
        if len(trajectory.t):
            recorder.write_pose(t, trajectory.x[-1], trajectory.P[-1])
        recorder.write_wave(t, 0.0, math.nan)
        recorder.write_status(t, {"warm_up": True})
        recorder.close()
