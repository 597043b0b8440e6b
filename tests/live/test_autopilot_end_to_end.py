"""`undertow live --autopilot` driving the virtual robot's own autopilot (`undertow serve
--autopilot`), end to end on 127.0.0.1: the robot serves a simulated dive (DVL over A50 TCP,
sonar over Ping1D UDP, IMU and pressure over MAVLink UDP) and, on the same MAVLink link, an
autopilot that consumes external navigation as ArduSub 4.x's EKF3 does
(:mod:`undertow.sim.robot.autopilot`); undertow sends its live estimate back on that link.

Everything is judged from the autopilot's side: what it says on the link (STATUSTEXT,
EKF_STATUS_REPORT, LOCAL_POSITION_NED, GPS_GLOBAL_ORIGIN, PARAM_VALUE: the serve manifest keeps
each packet it sent, decoded here with pymavlink) and its counters of what it took and why
not (``serve``'s summary). In every mode it takes undertow's messages (frames, spacing,
freshness), aids with them, and its position follows undertow's saved trajectory within the
error undertow sent; the faults: DVL loss (undertow goes silent, the autopilot's external
position times out, the resume is a reset), a restart of undertow's filter (a new session:
another reset_counter, which the autopilot takes as a reset onto the new estimate), an origin
already on the vehicle (adopted, ``--origin`` not sent), and parameters wrong on the vehicle
(listed to set; with ``--set-params`` set and the reboot-required ones named).

The robot is served at ``RATE`` times real time and undertow's clock is scaled by the same
rate, so both sides' clocks (the autopilot's time since boot, undertow's session seconds) run
alike and every rule in seconds holds as at real time. What the scaling changes: arrival
jitter is ``RATE`` times larger on the autopilot's clock, and the virtual autopilot spaces
samples by their arrival (EKF3 by their jitter-corrected stamps), so a few messages sent 21 ms
apart (state times) arrive less than 20 ms apart and are dropped as too close: bounded below.
"""

from __future__ import annotations

import socket
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest
from autopilot_checks import Estimate
from pymavlink.dialects.v20 import ardupilotmega as m

from undertow.commands.serve import serve
from undertow.live.autopilot import gate as gate_module
from undertow.live.pipeline import LiveSession
from undertow.settings import LiveSettings, Settings
from undertow.sim.robot import Faults

pytestmark = [pytest.mark.network, pytest.mark.slow]

RATE = 4.0
WAVE = "wave-a0.10-f1.00"
#: the parameters EKF3 needs for external navigation, preset on the virtual vehicle (as set
#: and rebooted before): the SITL's working set (tests/sitl_fixtures.py) and the posErr floor
EXTNAV = {"GPS1_TYPE": 0, "VISO_TYPE": 1, "EK3_SRC1_POSXY": 6, "EK3_SRC1_VELXY": 6,
          "EK3_SRC1_POSZ": 1, "EK3_SRC1_VELZ": 0, "EK3_SRC1_YAW": 1,
          "VISO_POS_M_NSE": 0.1}  # fmt: skip
ORIGIN = (47.5, 8.25)
MESSAGE = {"odometry": "ODOMETRY", "vision-position": "VISION_POSITION_ESTIMATE",
           "velocity-delta": "VISION_POSITION_DELTA"}  # fmt: skip
ABS, REL = m.EKF_POS_HORIZ_ABS, m.EKF_POS_HORIZ_REL
#: share of messages the virtual autopilot may drop as closer than 20 ms (module docstring)
MAX_RATE_DROPS = 0.05


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cut(log, span_s: float):
    t0 = log.time_span[0]
    return log.replace(**{n: s.select(s.t < t0 + span_s) for n, s in log.streams().items()})


class Run:
    """A served dive with its autopilot and the live session(s) that drove it."""

    def __init__(self, robot, results, summary):
        self.robot, self.results, self.summary = robot, results, summary
        self.ap = summary["autopilot"]  # the virtual autopilot's own report
        self.counts = self.ap["counts"]
        parser = m.MAVLink(None)
        self.heard = []  # (autopilot s since boot, message) the autopilot sent
        t0 = robot.player.clock.t0
        for e in robot.manifest.select("mavlink"):
            if e.stream == "" and e.index == -1:  # its replies, not the log's streams
                msg = parser.decode(bytearray(e.payload))
                self.heard.append((e.at - t0, msg))

    def of(self, kind: str) -> list:
        return [(t, msg) for t, msg in self.heard if msg.get_type() == kind]

    def texts(self) -> list[tuple[float, str]]:
        return [(t, msg.text) for t, msg in self.of("STATUSTEXT")]

    def first_text(self, fragment: str) -> float | None:
        return next((t for t, s in self.texts() if fragment in s), None)


def _live_settings(robot, rate=RATE, **live) -> Settings:
    ends = robot.endpoints
    return Settings(live=LiveSettings(dvl=ends.dvl, sonar=ends.sonar, mavlink=ends.mavlink_listen,
                                      wave=WAVE, time_scale=rate, reorder_s=0.3 * rate,
                                      map=False, idle_stop_s=60.0, autopilot=True,
                                      **live))  # fmt: skip


def _drive(log, out, *, faults=None, serve_kw=None, handover_s=None, late_s=None, rate=RATE,
           **live) -> Run:  # fmt: skip
    """Serve ``log`` with its autopilot and run ``live --autopilot`` against it until the data
    ends. ``handover_s``: stop that session after so many wall seconds of playback and start a
    new one (a restart of undertow and its filter) for the rest; ``late_s``: start undertow
    that many wall seconds after the robot (and its autopilot) started; ``rate``: the playback's
    speed-up (default ``RATE``)."""
    port = _free_udp_port()
    kw = {"autopilot_params": EXTNAV, **(serve_kw or {})}
    wait = None if late_s else 10.0  # (late: playing before any client)
    robot = serve(log, rate=rate, dvl_port=0, ping_port=0, mavlink=f"udpout:127.0.0.1:{port}",
                  faults=faults, wait_for_clients=wait, autopilot=True, **kw)  # fmt: skip
    robot.open()
    settings = _live_settings(robot, rate, **live)
    if late_s:
        robot.start()
        time.sleep(late_s)
    session = LiveSession(settings, out / "first").start()
    assert session.wait_connected(10.0)  # MAVLink over UDP: listening before data is sent
    if not late_s:
        robot.start()
    results = []
    try:
        if handover_s is not None:
            threading.Timer(handover_s, session.request_stop).start()
            results.append(session.run())
            session = LiveSession(settings, out / "second").start()
            assert session.wait_connected(10.0)

        def stop_after_the_last_message():
            robot.wait()
            time.sleep(1.0)
            session.request_stop()

        threading.Thread(target=stop_after_the_last_message, daemon=True).start()
        results.append(session.run())
    finally:
        summary = robot.stop()
    return Run(robot, results, summary)


def _flags_between(run: Run, t0: float, t1: float) -> list[int]:
    return [msg.flags for t, msg in run.of("EKF_STATUS_REPORT") if t0 <= t < t1]


@pytest.fixture(scope="module")
def dive(simulation):
    return simulation(WAVE).log  # 48.6 s


def _check_position_modes(run: Run, mode: str):
    kind = MESSAGE[mode]
    counts, (result,) = run.counts, run.results
    est = Estimate(result)
    n_sent = result.summary["autopilot"]["sent"]
    taken = {k.split(":", 1)[1]: v for k, v in counts.items() if k.startswith(f"{kind}:")}
    # every message arrived and decoded; none in a wrong frame pair, below the quality floor,
    # with NaNs or before the vehicle took external navigation (VISO_TYPE, sources)
    assert sum(v for k, v in taken.items() if k != "velocity_fused") == n_sent > 0
    assert not {"frame", "quality", "nan", "viso_disabled", "not_source"} & set(taken)
    assert taken.get("rate", 0) <= MAX_RATE_DROPS * n_sent
    assert taken["started"] == 1 and taken["fused"] >= 0.8 * n_sent
    # it said so, and its flags say it navigates on it from then on
    using = run.first_text("EKF3 IMU0 is using external nav data")
    assert using is not None and est.span()[0] <= using + 0.1
    end = est.span()[1]
    flags = _flags_between(run, using + 1.0, end)
    assert len(flags) >= (end - using - 1.0) - 2  # (1 Hz, its default)
    assert all(f & ABS and f & REL for f in flags)
    # its position: undertow's trajectory, within the error undertow sent
    errors, bounds = [], []
    for _, msg in run.of("LOCAL_POSITION_NED"):
        tb = msg.time_boot_ms * 1e-3
        record = est.record_before(tb)
        if tb < using + 1.0 or tb > end or record is None:
            continue
        errors.append(float(np.hypot(*(np.array([msg.x, msg.y]) - est.position(tb)))))
        bounds.append(max(record["pos_err_m"], EXTNAV["VISO_POS_M_NSE"]))
    assert len(errors) >= 4 * (end - using - 1.0)  # (asked for at 5 Hz)
    assert all(e < b for e, b in zip(errors, bounds, strict=True)), (max(errors), min(bounds))
    # and undertow saw it: the reports recorded, horizontal position used
    ekf = result.summary["autopilot"]["ekf"]
    assert ekf["horizontal_position"] and "pos_horiz_abs" in ekf["names"]
    return est, errors


@pytest.mark.parametrize("mode", ["odometry", "vision-position"])
def test_a_position_mode_is_taken_and_followed(dive, tmp_path, mode):
    # at 2x, not RATE: the bound on messages dropped as too close is a bound on arrival jitter
    # times the rate (module docstring), and a loaded machine's jitter at 4x passed it (9 of 161)
    run = _drive(_cut(dive, 20.0), tmp_path, autopilot_mode=mode, autopilot_origin=ORIGIN,
                 rate=2.0)  # fmt: skip
    _check_position_modes(run, mode)
    # the origin: none on the vehicle, undertow's set once it runs (it refuses one before)
    origin = run.of("GPS_GLOBAL_ORIGIN")[0][1]
    assert (origin.latitude, origin.longitude) == tuple(round(v * 1e7) for v in ORIGIN)
    assert run.counts["SET_GPS_GLOBAL_ORIGIN:set"] == 1
    assert run.results[0].summary["autopilot"]["origin"]["state"] == "set"


def test_velocity_delta_is_taken_as_body_odometry_and_followed(dive, tmp_path):
    """VISION_POSITION_DELTA: EKF3 starts relative aiding once its gyro biases are learned
    (about 35 s after boot, as the SITL did), from body odometry fresher than 200 ms with an
    error below 1 m/s; its position then moves as undertow's estimate within the velocity error
    undertow sent, integrated."""
    run = _drive(dive, tmp_path, autopilot_mode="velocity-delta")
    (result,) = run.results
    counts = run.counts
    n_sent = result.summary["autopilot"]["sent"]
    taken = {k.split(":", 1)[1]: v for k, v in counts.items()
             if k.startswith("VISION_POSITION_DELTA:")}  # fmt: skip
    assert sum(taken.values()) == n_sent > 0
    assert not {"nan", "viso_disabled", "not_source", "ekf_not_ready"} & set(taken)
    assert taken.get("rate", 0) <= MAX_RATE_DROPS * n_sent
    started = run.first_text("EKF3 IMU0 started relative aiding")
    assert started is not None
    est = Estimate(result)
    end = est.span()[1]
    assert taken["fused"] >= 0.8 * sum(r["time_usec"] * 1e-6 >= started for r in est.sent)
    flags = _flags_between(run, started + 0.5, end)
    assert flags and all(f & REL and not f & ABS for f in flags)
    assert run.first_text("is using external nav data") is None  # no position was sent
    # displacements since aiding started: the autopilot's against undertow's
    track = [(msg.time_boot_ms * 1e-3, np.array([msg.x, msg.y]))
             for _, msg in run.of("LOCAL_POSITION_NED")
             if started + 0.5 <= msg.time_boot_ms * 1e-3 <= end]  # fmt: skip
    assert len(track) >= 4 * (end - started - 0.5)
    (ta, pa), drift = track[0], []
    for tb, pb in track[1:]:
        moved = est.position(tb) - est.position(ta)
        used = [r for r in est.sent if ta <= r["time_usec"] * 1e-6 <= tb]
        vmin, vmax = 0.1, 0.9  # EK3_VIS_VERR_MIN/MAX on the vehicle (its defaults)
        err = [vmin + (vmax - vmin) * (1 - 0.01 * r["confidence"]) for r in used]
        bound = float(np.mean(err)) * (tb - ta) + EXTNAV["VISO_POS_M_NSE"]
        drift.append(float(np.hypot(*(pb - pa - moved))))
        assert drift[-1] < bound, (tb - ta, drift[-1], bound)
    assert np.hypot(*(est.position(track[-1][0]) - est.position(ta))) > 1.0  # it moved


def test_dvl_loss_silences_undertow_and_the_autopilot_times_out(dive, tmp_path):
    """The DVL link down 11 s, 8 s in: undertow stops within its 1 s DVL timeout, the autopilot
    loses its external position 7 s later (EKF3's posRetryTimeNoVel: ODOMETRY carried the
    velocity too), and takes undertow's resume, with a new reset_counter, as a reset."""
    faults = Faults(drop_dvl=((8.0, 11.0),))
    run = _drive(_cut(dive, 30.0), tmp_path, faults=faults, autopilot_origin=ORIGIN)
    (result,) = run.results
    est = Estimate(result)
    gaps = np.diff(est.sent_at)
    k = int(np.argmax(gaps))
    last, resumed = float(est.sent_at[k]), float(est.sent_at[k + 1])
    assert 11.0 - 1.0 - 0.5 <= resumed - last <= 11.0 + 2.0  # silent through the loss
    assert 8.0 <= last <= 8.0 + 1.0 + 0.5  # (log time = autopilot time: booted at its start)
    counters = [r["reset_counter"] for r in est.sent]
    assert len(set(counters[: k + 1])) == 1 and counters[k + 1] == (counters[k] + 1) % 256
    # the autopilot: aiding until about 7 s after the last message, then no external position
    reports = run.of("EKF_STATUS_REPORT")
    cleared = next(t for t, msg in reports if t > last and not msg.flags & ABS)
    assert 7.0 - 0.1 <= cleared - last <= 7.0 + 1.1  # (reports at 1 Hz)
    assert all(msg.flags & ABS for t, msg in reports if last + 1.0 <= t < cleared)
    assert not any(msg.flags & ABS for t, msg in reports if cleared <= t < resumed)
    # the resume: a reset onto undertow's estimate, aiding again
    assert run.counts["ODOMETRY:reset"] == 1
    again = _flags_between(run, resumed + 1.0, est.span()[1])
    assert again and all(f & ABS for f in again)
    holds = result.summary["autopilot"]["holds"]
    assert any("no valid DVL" in reason for reason in holds)


def test_a_restart_of_undertow_is_a_reset_the_autopilot_takes(dive, tmp_path, monkeypatch):
    """undertow stops and starts again (a new session, its filter from scratch) while the
    vehicle keeps aiding: the new session's reset_counter differs (each session draws its start
    at random; two different draws here), so the autopilot resets its position onto the new
    estimate at once instead of gating the step between the two sessions' frames."""
    draws = iter([10, 20])
    monkeypatch.setattr(gate_module, "random", SimpleNamespace(randrange=lambda n: next(draws)))
    # at 2x, not RATE: the gap is about 3 s of log time (the new filter's start) plus the new
    # session's start-up in wall time times the rate, 4x of which passed 7 s on a loaded machine
    run = _drive(
        _cut(dive, 36.0), tmp_path, handover_s=12.0 / 2.0, autopilot_origin=ORIGIN, rate=2.0
    )
    first, second = (Estimate(r) for r in run.results)
    assert {r["reset_counter"] for r in first.sent} == {10}
    assert {r["reset_counter"] for r in second.sent} == {20}
    gap = second.span()[0] - first.span()[1]
    assert 0 < gap < 7.0  # the autopilot has not timed out meanwhile
    assert run.counts["ODOMETRY:reset"] == 1 and run.counts["ODOMETRY:started"] == 1
    assert "ODOMETRY:rejected" not in run.counts
    reports = run.of("EKF_STATUS_REPORT")
    # from the autopilot's first absolute aiding on the first session (not a fixed delay after
    # undertow's first message: the vehicle's EKF may not have started yet, flags 0, when that
    # message comes early on a loaded machine) to the second session's end, it never loses it
    aiding = [t for t, msg in reports if msg.flags & ABS and t < first.span()[1]]
    assert aiding, "the autopilot never aided absolutely on the first session"
    lost = [
        (round(t - first.span()[0], 2), msg.flags)
        for t, msg in reports
        if aiding[0] <= t < second.span()[1] and not msg.flags & ABS
    ]
    assert not lost, (lost, aiding[0] - first.span()[0], first.span(), second.span())
    # right after the reset the autopilot is on the new session's estimate
    after = [(msg.time_boot_ms * 1e-3, msg) for _, msg in run.of("LOCAL_POSITION_NED")
             if second.span()[0] + 0.3 <= msg.time_boot_ms * 1e-3 <= second.span()[1]]  # fmt: skip
    assert after
    for tb, msg in after:
        bound = max(second.record_before(tb)["pos_err_m"], EXTNAV["VISO_POS_M_NSE"])
        assert np.hypot(*(np.array([msg.x, msg.y]) - second.position(tb))) < bound


def test_an_origin_on_the_vehicle_is_adopted(dive, tmp_path):
    """The vehicle set its origin when its EKF started (3.5 s after boot); undertow, started
    6 s after the vehicle, finds it, adopts it, and never sends its own."""
    run = _drive(_cut(dive, 16.0), tmp_path, serve_kw={"autopilot_origin": "47.37,8.54"},
                 late_s=6.0 / RATE, autopilot_origin=ORIGIN)  # fmt: skip
    (result,) = run.results
    summary = result.summary["autopilot"]
    assert summary["origin"]["state"] == "adopted"
    assert "SET_GPS_GLOBAL_ORIGIN" not in summary["link"]["sent"]
    assert not [k for k in run.counts if k.startswith("SET_GPS_GLOBAL_ORIGIN")]
    lines = [n for n in result.warnings if "EKF origin" in n]
    assert lines == ["EKF origin already on the vehicle: 47.3700000, 8.5400000, 0.0 m; adopted "
                     "(--origin not sent)"]  # fmt: skip
    assert run.ap["origin"] == [473_700_000, 85_400_000, 0]  # the vehicle's, kept


def test_wrong_parameters_are_listed_and_set_with_their_reboots(dive, tmp_path):
    """The vehicle at ArduSub's defaults (GPS, no visual odometry): undertow lists what to set
    and the autopilot ignores its messages; with --set-params undertow sets them (the
    autopilot's PARAM_VALUE echoes) and names the ones that need a reboot, which the autopilot
    indeed keeps at their boot values until one."""
    log = _cut(dive, 10.0)
    listed = _drive(log, tmp_path / "listed", serve_kw={"autopilot_params": {}})
    notes = listed.results[0].warnings
    start = notes.index("autopilot parameters for the odometry mode:")
    report = notes[start + 1 :]
    for name in ("VISO_TYPE", "GPS1_TYPE", "EK3_SRC1_POSXY", "EK3_SRC1_VELXY"):
        assert any(line.strip().startswith(name) for line in report), name
    assert any("--set-params" in line for line in report)
    assert not [k for k in listed.counts if k.startswith("PARAM_SET")]
    assert listed.counts["ODOMETRY:viso_disabled"] > 0
    assert "ODOMETRY:fused" not in listed.counts

    fixed = _drive(log, tmp_path / "set", serve_kw={"autopilot_params": {}},
                   autopilot_set_params=True)  # fmt: skip
    summary = fixed.results[0].summary["autopilot"]
    echoed = {msg.param_id: msg.param_value for _, msg in fixed.of("PARAM_VALUE")}
    for name, value in {"VISO_TYPE": 1, "GPS1_TYPE": 0, "EK3_SRC1_POSXY": 6,
                        "EK3_SRC1_VELXY": 6, "VISO_POS_M_NSE": 0.1}.items():  # fmt: skip
        assert echoed[name] == pytest.approx(value) and name in summary["params_set"], name
    assert fixed.counts["PARAM_SET:needs_reboot"] == 2  # VISO_TYPE, GPS1_TYPE
    assert any("reboot the autopilot for VISO_TYPE, GPS1_TYPE" in n
               for n in fixed.results[0].warnings)  # fmt: skip
    assert fixed.counts["ODOMETRY:viso_disabled"] > 0  # not before the reboot
    assert not summary["params_failed"]
