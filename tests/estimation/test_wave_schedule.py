"""The wave conditions an online filter took (set_wave before a chunk), replayed offline in the
same steps (estimation.wave_schedule), give the online trajectory bit for bit; a schedule that
interpolates instead (a WaveTrack of the same conditions) does not."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.estimation import Localizer
from undertow.estimation.noise import NoiseProfile
from undertow.estimation.online import OnlineLocalizer
from undertow.estimation.wave_schedule import WAVE_LIVE, schedule_noise
from undertow.log import Log
from undertow.wavetrack import WaveTrack

STREAMS = ("imu", "dvl", "dead_reckoning", "pressure")
#: chunk index -> the condition set before it is pushed (chunk 0: before the filter starts)
CHANGES = {0: (0.12, 0.9), 3: (0.1, 1.0), 5: "calm", 7: (0.15, 0.8)}


def _log(simulation) -> Log:
    log = simulation("calm").log  # (the conditions are the filter's, whatever the sea)
    t0 = log.time_span[0]
    streams = {n: getattr(log, n).select(getattr(log, n).t < t0 + 16.0) for n in STREAMS}
    return Log(**streams, mounting=log.mounting)  # no ground truth, no recorded wave


def test_the_steps_replayed_offline_give_the_online_trajectory(simulation):
    log = _log(simulation)
    t0 = log.time_span[0]
    online = OnlineLocalizer("proposed", mounting=log.mounting)
    entries = []
    for k in range(8):
        a, b = t0 + 2.0 * k, t0 + 2.0 * (k + 1) if k < 7 else np.inf
        chunk = log.replace(**{n: s.select((s.t >= a) & (s.t < b))
                               for n, s in log.streams().items()})  # fmt: skip
        if k in CHANGES:
            first = min(float(s.t[0]) for s in chunk.streams().values() if len(s))
            entries.append({"t": b, "from_t": first if online.ready else None,
                            "condition": CHANGES[k]})  # fmt: skip
            online.set_wave(CHANGES[k])
        online.push(chunk)
    expected = online.trajectory()
    assert entries[0]["from_t"] is None and entries[1]["from_t"] is not None
    recorded = log.replace(metadata={"live_wave": entries})
    replay = Localizer("proposed", wave="auto").run(recorded)
    assert replay.metadata["wave_condition_source"] == WAVE_LIVE
    assert np.array_equal(replay.t, expected.t)
    assert np.array_equal(replay.x, expected.x)
    assert np.array_equal(replay.P, expected.P)
    # the same conditions as nodes of a track (interpolated between them): another filter
    track = WaveTrack(
        np.array([e["from_t"] or t0 for e in entries]),
        np.array([0.0 if c == "calm" else c[0] for c in CHANGES.values()]),
        np.array([np.nan if c == "calm" else c[1] for c in CHANGES.values()]),
    )
    other = Localizer("proposed", wave=track).run(log)
    assert not np.array_equal(other.x, expected.x)


def test_step_noise_takes_each_rows_step_and_refuses_bad_entries():
    profile = NoiseProfile.paper()
    entries = [{"from_t": None, "condition": [0.1, 1.0]}, {"from_t": 5.0, "condition": "calm"},
               {"from_t": 5.0, "condition": [0.15, 0.8]}]  # fmt: skip
    noise = schedule_noise(profile, entries, "nearest")
    first, last = (profile.noise(c, extrapolate="nearest") for c in ((0.1, 1.0), (0.15, 0.8)))
    std = noise.std_at("dvl", np.array([-1e9, 4.999, 5.0, 9.0]))
    np.testing.assert_array_equal(std, [first.dvl_std, first.dvl_std, last.dvl_std,
                                        last.dvl_std])  # a tie: the later one  # fmt: skip
    with pytest.raises(ConfigError, match="live wave condition 0"):
        schedule_noise(profile, [{"condition": "calm"}], "nearest")
    with pytest.raises(ConfigError, match="backwards"):
        schedule_noise(profile, [{"from_t": 5.0, "condition": "calm"},
                                 {"from_t": 1.0, "condition": "calm"}], "nearest")  # fmt: skip
