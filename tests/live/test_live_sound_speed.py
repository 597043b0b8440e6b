"""A live session with the water's sound speed in its settings scales the DVL's and the sonar's
ranges and the DVL's velocities before the filter and the map, as the offline reader does."""

import math

import numpy as np
import pytest

from undertow.io import LogOptions
from undertow.io.sound_speed import correct_sound_speed
from undertow.live.pipeline import LiveSession
from undertow.records import Record, records_to_log
from undertow.settings import Settings


def _records(n: int = 5) -> list[Record]:
    out = []
    for i in range(n):
        t = 0.1 * i
        out.append(Record("dvl", t, {
            "velocity": (0.5, -0.1, 0.02), "valid": True, "fom": 0.002,
            "covariance": ((4e-6, 0, 0), (0, 4e-6, 0), (0, 0, 1e-6)), "altitude": 2.0,
            "beam_range": (2.16, 2.17, 2.15, 2.16), "beam_valid": (True,) * 4,
            "beam_velocity": (0.2, -0.2, 0.1, -0.1)}))  # fmt: skip
        out.append(Record("sonar", t + 0.05, {"range": 1.9 + 0.01 * i, "confidence": 1.0}))
    return out


@pytest.mark.parametrize("water", [None, 1476.0])
def test_the_chunks_the_filter_and_the_map_take_carry_the_water_sound_speed(tmp_path, water):
    # a DVL link that is never started (nothing connects): the session is only built
    settings = Settings(log={"sound_speed_m_s": water}, live={"dvl": "tcp://127.0.0.1:9"})
    session = LiveSession(settings, tmp_path / "out")
    records = _records()
    chunk = session.chunk_log(records)
    raw = records_to_log(records)
    if water is None:
        assert not any("sound speed" in n for n in session.notes)
        np.testing.assert_array_equal(chunk.dvl.beam_range, raw.dvl.beam_range)
        return
    k = water / 1500.0
    np.testing.assert_allclose(chunk.dvl.velocity, k * raw.dvl.velocity)
    np.testing.assert_allclose(chunk.dvl.altitude, k * raw.dvl.altitude)
    np.testing.assert_allclose(chunk.dvl.beam_range, k * raw.dvl.beam_range)
    np.testing.assert_allclose(chunk.sonar.range, k * raw.sonar.range)
    # the same as the offline reader's correction of the same data
    offline = correct_sound_speed(raw, LogOptions(sound_speed_m_s=water), state=False)
    np.testing.assert_array_equal(chunk.dvl.covariance, offline.dvl.covariance)
    assert [n for n in session.notes if n.startswith(f"sound speed {water:.1f} m/s")]
    assert math.isclose(k, chunk.metadata["sound_speed"]["dvl_factor"])
