"""`undertow live` against the virtual robot (`undertow serve`), end to end on 127.0.0.1.

Equivalence: a simulated log is served faster than real time (DVL over A50 TCP, sonar over
Ping1D UDP, IMU and pressure over MAVLink UDP) and the live pipeline runs against it with its
clock scaled by the same rate. Then (1) every message served is in the recording, (2) the
offline `localize` and `map` of the recording give exactly the live trajectory and map, and
(3) against the original log the live trajectory agrees within what the arrival-time stamping
of the clockless MAVLink and Ping streams explains.

Faults: with the DVL link dropped, lines corrupted, reports duplicated and reordered and a clock
jump, the session keeps running, counts each fault, predicts through the gap (covariance
grows, then shrinks after the reconnect) and writes complete outputs.
"""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import pytest

from undertow.commands.serve import serve
from undertow.estimation import Localizer
from undertow.io import read_log
from undertow.live.pipeline import LiveSession
from undertow.mapping.run import map_log
from undertow.occupancy import OccupancyMap
from undertow.settings import LiveSettings, Settings
from undertow.sim.robot import Faults
from undertow.trajectory import Trajectory

# one worker runs this module's tests, so its module fixtures are built once (make test:
# --dist loadgroup)
pytestmark = [pytest.mark.network, pytest.mark.slow, pytest.mark.xdist_group("live")]

RATE = 8.0  # the log is served 8 times faster than real time
SPAN_S = 24.0  # seconds of the simulated log served
VARIANT = "proposed"
WAVE = "wave-a0.10-f1.00"
#: the reorder buffer in wall seconds: the links' threads and the pipeline share two cores with
#: the served robot, and a wall delay d is RATE * d sensor seconds
REORDER_WALL_S = 0.3


def _by_cell(occupancy: OccupancyMap) -> OccupancyMap:
    c = occupancy.cells
    return occupancy.select(np.lexsort((c[:, 2], c[:, 1], c[:, 0])))


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _run_live(log, out, faults=None, seed=0):
    """Serve ``log`` and run a live session against it until the data stops."""
    port = _free_udp_port()
    session = serve(log, rate=RATE, dvl_port=0, ping_port=0,
                    mavlink=f"udpout:127.0.0.1:{port}", faults=faults, seed=seed,
                    wait_for_clients=10.0)  # fmt: skip
    session.open()
    ends = session.endpoints
    settings = Settings(
        live=LiveSettings(
            dvl=ends.dvl,
            sonar=ends.sonar,
            mavlink=ends.mavlink_listen,
            wave=WAVE,
            time_scale=RATE,
            idle_stop_s=60.0,  # stopped by the thread below once the data has ended
            reorder_s=REORDER_WALL_S * RATE,
        ),  # fmt: skip
        localizer={"variant": VARIANT},
    )
    live = LiveSession(settings, out).start()
    assert live.wait_connected(10.0)  # MAVLink over UDP: the link listens before data is sent
    return session, live, _run_to_the_end(session, live)


def _run_to_the_end(session, live):
    """Start serving, run ``live`` until a second after the last message was sent (a loaded
    machine may delay the sender's last packets), stop both; the live result."""
    session.start()

    def stop_after_the_last_message():
        session.wait()
        time.sleep(1.0)
        live.request_stop()

    threading.Thread(target=stop_after_the_last_message, daemon=True).start()
    try:
        return live.run()
    finally:
        session.stop()


@pytest.fixture(scope="module")
def source_log(simulation):
    log = simulation(WAVE).log
    t0 = log.time_span[0]
    return log.replace(**{n: s.select(s.t < t0 + SPAN_S) for n, s in log.streams().items()})


@pytest.fixture(scope="module")
def clean_run(source_log, tmp_path_factory):
    out = tmp_path_factory.mktemp("live") / "dive"
    session, live, result = _run_live(source_log, out)
    return source_log, session, live, result


def test_every_served_message_is_in_the_recording(clean_run):
    _, session, _, result = clean_run
    served = session.served_log()
    recorded = read_log(result.recording)
    for name in ("imu", "pressure", "dvl", "dead_reckoning", "sonar"):
        a, b = getattr(served, name), getattr(recorded, name)
        assert b is not None and len(b) == len(a), name
    # the A50's own clock: recorded time = served sensor time + one latched offset
    dt = recorded.dvl.t - served.dvl.t
    assert np.ptp(dt) < 1e-5
    np.testing.assert_allclose(recorded.dvl.velocity, served.dvl.velocity, rtol=0, atol=1e-9)
    np.testing.assert_allclose(recorded.imu.angular_velocity, served.imu.angular_velocity,
                               rtol=0, atol=1e-6)  # fmt: skip
    np.testing.assert_allclose(recorded.pressure.pressure, served.pressure.pressure, atol=1e-6)
    assert result.summary["late"] == 0


def test_replaying_the_recording_gives_exactly_the_live_trajectory_and_map(clean_run):
    _, _, live, result = clean_run
    recorded = read_log(result.recording)
    offline = Localizer(variant=VARIANT, wave=WAVE).run(recorded)
    online = Trajectory.load_npz(result.localization / "trajectory.npz")
    assert np.array_equal(offline.t, online.t)
    assert np.array_equal(offline.x, online.x)
    assert np.array_equal(offline.P, online.P)
    # the session wrote them from the disk: the filter had let go of the early ones
    assert 0 < live.localizer.release(0) < len(online)
    assert not any(p.name.endswith(".states") for p in result.out_dir.iterdir())
    live_map = OccupancyMap.load(result.map / "map.npz")
    replay = map_log(recorded, online, live.mapping_config).map
    assert len(live_map) == len(replay) > 0
    a, b = _by_cell(live_map), _by_cell(replay)
    assert np.array_equal(a.cells, b.cells)
    # the kernel sums accumulate in float32 per grid chunk: integrating chunk by chunk adds the
    # same terms in another order (tests/test_online.py bounds it per cell); 2e-6 is ~16 ulp
    np.testing.assert_allclose(a.alpha, b.alpha, rtol=2e-6, atol=0)
    np.testing.assert_allclose(a.beta, b.beta, rtol=2e-6, atol=0)


def test_live_agrees_with_the_original_log_within_the_arrival_jitter(clean_run):
    """The live run differs from the original log only in the times of the streams stamped on
    arrival (MAVLink IMU and pressure; the Ping, which only the map uses): each is the
    measurement of the vehicle at most delta = max |arrival lag - its median| away in time, so
    the position can differ by at most the distance the vehicle covers in delta, v_max delta
    (plus 1 cm for the filter's own rounding). The attitude integrates the gyro over the stamped
    intervals: with stamp errors e_k (|e_k| <= delta) the integral over an interval changes by
    sum_k omega_k (e_(k+1) - e_k), whose end terms give 2 omega_max delta; the rest,
    -sum_k e_k (omega_k - omega_(k-1)), the DVL and DR updates keep within the 1 mrad allowed
    for rounding. (omega_max delta alone was exceeded by 2 % in one clean-clone run.)"""
    source, session, _, result = clean_run
    recorded = read_log(result.recording)
    served = session.served_log()
    lag = recorded.imu.t - served.imu.t
    delta = float(np.max(np.abs(lag - np.median(lag))))
    lag_p = recorded.pressure.t - served.pressure.t
    delta = max(delta, float(np.max(np.abs(lag_p - np.median(lag_p)))))
    offset = float(np.median(recorded.dvl.t - served.dvl.t))  # the A50's clock: exact times
    original = Localizer(variant=VARIANT, wave=WAVE).run(source)
    online = Trajectory.load_npz(result.localization / "trajectory.npz")
    t = online.t - offset  # in the original log's time
    inside = (t > original.t[0]) & (t < original.t[-1])
    assert inside.sum() > 0.9 * len(t)

    def at(values):
        return np.stack([np.interp(t[inside], original.t, values[:, j]) for j in range(3)], 1)

    dp = np.linalg.norm(online.position[inside] - at(original.position), axis=1)
    unwrap = np.unwrap(original.orientation, axis=0)
    da = np.abs(np.unwrap(online.orientation[inside], axis=0) - at(unwrap))
    gt = source.ground_truth
    v_max = float(np.max(np.linalg.norm(gt.velocity, axis=1)))
    w_max = float(np.max(np.abs(source.imu.angular_velocity)))
    assert dp.max() <= v_max * delta + 0.01, (dp.max(), delta)
    assert da.max() <= 2 * w_max * delta + 1e-3, (da.max(axis=0), delta)


DROP = (6.0, 3.0)  # the A50 link is down for 3 s from 6 s into the log


@pytest.fixture(scope="module")
def faulty_run(source_log, tmp_path_factory):
    faults = Faults(drop_dvl=(DROP,), corrupt=0.05, duplicate=0.05, reorder=0.05,
                    clock_jumps=(("dvl", 15.0, 30.0),))  # fmt: skip
    out = tmp_path_factory.mktemp("live_faults") / "dive"
    session, live, result = _run_live(source_log, out, faults=faults, seed=3)
    return session, live, result


def test_faults_are_counted_and_the_session_survives_them(faulty_run):
    session, _, result = faulty_run
    links = result.summary["links"]
    served = session.summary()
    assert links["dvl"]["disconnects"] >= 1 and links["dvl"]["connects"] >= 2
    assert links["dvl"]["malformed"] > 0  # corrupted A50 lines
    assert links["dvl"]["duplicate"] > 0 and links["dvl"]["out_of_order"] > 0
    assert links["dvl"]["clock_jumps"] >= 1  # the +30 s jump of the A50's clock, re-latched
    assert links["mavlink"]["malformed"] > 0 and links["sonar"]["malformed"] > 0
    assert served["faults"]["corrupt"] > 0
    for part in ("localization/trajectory.npz", "localization/trajectory.tum", "map/map.npz",
                 "map/map.ply", "live.yaml"):  # fmt: skip
        assert (result.out_dir / part).is_file(), part
    recorded = read_log(result.recording)
    assert len(recorded.imu) > 0.9 * len(session.log.imu)


def test_the_filter_predicts_through_the_dvl_gap(faulty_run):
    """Without the DVL the velocity is unobserved: its variance grows through the gap and
    shrinks again once the link is back."""
    session, _, result = faulty_run
    recorded = read_log(result.recording)
    online = Trajectory.load_npz(result.localization / "trajectory.npz")
    t_dvl = recorded.dvl.t
    gap = np.argmax(np.diff(t_dvl))
    start, end = t_dvl[gap], t_dvl[gap + 1]
    assert end - start > 0.8 * DROP[1]
    var = online.P[:, 6, 6] + online.P[:, 7, 7]  # horizontal body velocity
    before = var[(online.t > start - 1.0) & (online.t <= start)].max()
    during = var[(online.t > start) & (online.t < end)].max()
    after = var[(online.t > end + 1.0) & (online.t < end + 3.0)].max()
    assert during > 10 * before
    assert after < 0.1 * during


def test_a_dvl_without_orientation_is_recorded_and_named_once(source_log, tmp_path):
    """An A50 sending velocity only (no dead reckoning) and no autopilot: no orientation
    source, so the filter waits; what arrives is recorded and the missing sensor named once."""
    log = source_log.replace(dead_reckoning=None)
    session = serve(log, rate=RATE, dvl_port=0, ping_port=None, mavlink=None,
                    wait_for_clients=10.0).open()  # fmt: skip
    settings = Settings(
        live=LiveSettings(
            dvl=session.endpoints.dvl,
            time_scale=RATE,
            idle_stop_s=60.0,
            reorder_s=REORDER_WALL_S * RATE,
        )
    )
    live = LiveSession(settings, tmp_path / "dvl-only").start()
    notices = []
    live.on_notice = notices.append
    result = _run_to_the_end(session, live)
    assert len(notices) == 1 and "orientation" in notices[0]
    assert result.localization is None and result.map is None
    assert any("never started" in n for n in result.warnings)
    recorded = read_log(result.recording)
    assert len(recorded.dvl) == len(log.dvl)
