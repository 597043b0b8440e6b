"""A live session with ``--wave auto`` against the virtual robot (`undertow serve`: DVL over A50
TCP, the Ping over UDP, IMU and pressure over MAVLink), then its recording read back:

- the Ping's confidences are in the recording as the Ping sent them (the served frames decoded
  independently, :func:`undertow.sim.robot.decode.served_log`), and the map made from the
  recording is the live map (no mapper or filter weighs a range by its confidence, live or
  offline: both carry it in ``SonarRange.confidence``);
- the offline filter of the recording (``wave="auto"``, as ``undertow localize --wave auto``)
  takes the conditions the live sea state gave the live filter, in the same steps, and gives the
  live trajectory bit for bit; the offline sea-state estimate of the same log (what
  ``--wave auto`` gives on a log that is not a live recording) gives another one.
"""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import pytest

from undertow.commands.serve import serve
from undertow.estimation import Localizer
from undertow.estimation.wave_schedule import WAVE_LIVE
from undertow.io import read_log
from undertow.live.pipeline import LiveSession
from undertow.mapping.run import map_log
from undertow.occupancy import OccupancyMap
from undertow.settings import LiveSettings, Settings
from undertow.trajectory import Trajectory

pytestmark = [pytest.mark.network, pytest.mark.slow]

RATE = 8.0
SPAN_S = 30.0
VARIANT = "proposed"


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def auto_run(simulation, tmp_path_factory):
    log = simulation("wave-a0.10-f1.00").log
    t0 = log.time_span[0]
    log = log.replace(**{n: s.select(s.t < t0 + SPAN_S) for n, s in log.streams().items()})
    port = _free_udp_port()
    session = serve(log, rate=RATE, dvl_port=0, ping_port=0,
                    mavlink=f"udpout:127.0.0.1:{port}", wait_for_clients=10.0)  # fmt: skip
    session.open()
    ends = session.endpoints
    live_settings = LiveSettings(
        dvl=ends.dvl, sonar=ends.sonar, mavlink=ends.mavlink_listen, wave="auto",
        wave_window_s=15.0, wave_update_s=4.0, time_scale=RATE, idle_stop_s=60.0,
        reorder_s=0.3 * RATE,
    )  # fmt: skip
    settings = Settings(live=live_settings, localizer={"variant": VARIANT})
    live = LiveSession(settings, tmp_path_factory.mktemp("live_auto") / "dive").start()
    assert live.wait_connected(10.0)
    session.start()

    def stop_after_the_last_message():
        session.wait()
        time.sleep(1.0)
        live.request_stop()

    threading.Thread(target=stop_after_the_last_message, daemon=True).start()
    try:
        result = live.run()
    finally:
        session.stop()
    return session, live, result


def test_the_pings_confidence_is_recorded_as_sent(auto_run):
    session, live, result = auto_run
    served, recorded = session.served_log(), read_log(result.recording)
    assert len(recorded.sonar) == len(served.sonar) > 0
    assert recorded.sonar.confidence is not None
    np.testing.assert_array_equal(recorded.sonar.confidence, served.sonar.confidence)
    assert np.unique(recorded.sonar.confidence).size > 1  # confidences that vary, not a constant
    online = Trajectory.load_npz(result.localization / "trajectory.npz")
    live_map = OccupancyMap.load(result.map / "map.npz")
    replay = map_log(recorded, online, live.mapping_config).map
    assert len(live_map) == len(replay) > 0
    assert {tuple(c) for c in live_map.cells.tolist()} == {tuple(c) for c in replay.cells.tolist()}


def test_the_replay_of_a_wave_auto_session_takes_its_conditions_and_trajectory(auto_run):
    _, live, result = auto_run
    recorded = read_log(result.recording)
    updates = live.sea.updates
    assert len(updates) >= 2  # the sea state changed the filter's condition during the session
    offline = Localizer(variant=VARIANT, wave="auto").run(recorded)
    meta = offline.metadata
    assert meta["wave_condition_source"] == WAVE_LIVE
    conditions = [e["condition"] for e in meta["wave_schedule"]]
    assert conditions == [c if c == "calm" else list(c) for c in (u.condition for u in updates)]
    assert [e["t"] for e in meta["wave_schedule"]] == [u.t for u in updates]
    assert any(e["from_t"] is not None for e in meta["wave_schedule"])  # a change mid-run
    online = Trajectory.load_npz(result.localization / "trajectory.npz")
    assert np.array_equal(offline.t, online.t)
    assert np.array_equal(offline.x, online.x)
    assert np.array_equal(offline.P, online.P)
    # the offline estimate of the same data (what --wave auto gives a log without the live
    # session's decisions) fits the whole log at once: another noise, another trajectory
    without = recorded.replace(metadata={k: v for k, v in recorded.metadata.items()
                                         if k != "live_wave"})  # fmt: skip
    estimated = Localizer(variant=VARIANT, wave="auto").run(without)
    assert estimated.metadata["wave_condition_source"] != WAVE_LIVE
    assert not np.array_equal(estimated.x, online.x)
