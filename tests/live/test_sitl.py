"""The real autopilot: ArduSub's SITL (``sitl_fixtures``) fed external navigation at 10 Hz,
judged by what it says itself (STATUSTEXT, EKF_STATUS_REPORT, LOCAL_POSITION_NED on a second
client), and the virtual autopilot (``undertow serve --autopilot``) fed the same messages at
the same times must agree with it: that is what makes the virtual one worth testing against.

The sending is one function, :func:`send_plan` (pymavlink here). The second test sends with
``undertow live --autopilot --mavlink <sitl.sender_address>`` itself, ``undertow serve``
providing the DVL and sonar (a simulated dive) and the SITL its attitude and pressure
(:func:`test_ekf3_navigates_on_undertow_live`).

The plan, after EKF3 is tilt-aligned and the origin is set (seconds from its start):
A 0-2 ODOMETRY in a wrong frame pair (LOCAL_NED / BODY_FRD): silently dropped;
B 2-4 quality -1, below VISO_QUAL_MIN 0: dropped;
C 4-14 a track x = 1 + 0.1 t, y = 2 + 0.5 sin(0.3 t) with its velocity and a pose covariance
  that EKF3 reduces to 0.3 m: "EKF3 IMU0 is using external nav data", POS_HORIZ_ABS set and
  LOCAL_POSITION_NED on the track within the 0.3 m sent;
D 14-16 the track moved 3 m north, same reset_counter: rejected by the innovation gate;
E 16-19 the same with reset_counter 1: the position jumps to it;
F 19-28 nothing: POS_HORIZ_ABS clears about 7 s later (EKF3's posRetryTimeNoVel_ms); a second,
  different origin is ignored.
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import dataclass

import numpy as np
import pytest
from autopilot_checks import Estimate
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from sitl_fixtures import EXTNAV_PARAMS, Sitl, copy_log, find_ardusub

from undertow.commands.serve import serve
from undertow.live.pipeline import LiveSession
from undertow.settings import LiveSettings, Settings
from undertow.sim.robot.autopilot import AutopilotTiming, VirtualAutopilot
from undertow.sim.robot.autopilot_rules import covariance_for_error

ARDUSUB = find_ardusub()
pytestmark = [
    pytest.mark.sitl,
    pytest.mark.network,
    pytest.mark.slow,
    pytest.mark.xdist_group("sitl"),
    pytest.mark.skipif(
        ARDUSUB is None,
        reason="ArduSub SITL binary not found (../shared/tools/ardusub/ardusub or "
        "UNDERTOW_ARDUSUB)",
    ),
]

NAN = math.nan
POS_ERR_M = 0.3
RULE = "cbrt"  # the SITL here predates ArduPilot PR 32084 (its dataflash VISP.PErr shows it)
PHASES = (("A", 0.0), ("B", 2.0), ("C", 4.0), ("D", 14.0), ("E", 16.0), ("F", 19.0))
PLAN_END_S = 28.0
ORIGIN = (47.37, 8.54)


def phase_at(t: float) -> str:
    return [name for name, start in PHASES if t >= start][-1]


def track(t: float, phase: str) -> tuple[float, float, float, float]:
    """x, y (m, NED) and vx, vy (m/s) of the plan's track at plan time t."""
    shift = 3.0 if phase in ("D", "E") else 0.0
    return 1.0 + 0.1 * t + shift, 2.0 + 0.5 * math.sin(0.3 * t), 0.1, 0.15 * math.cos(0.3 * t)


@dataclass(frozen=True)
class Sent:
    """One external-navigation message as sent: monotonic time, plan time, phase, the
    message, and the position it carries."""

    t: float
    plan_t: float
    phase: str
    msg: object
    x: float
    y: float


def odometry_message(t: float, phase: str):
    x, y, vx, vy = track(t, phase)
    frame = mavlink2.MAV_FRAME_LOCAL_NED if phase == "A" else mavlink2.MAV_FRAME_LOCAL_FRD
    quality = -1 if phase == "B" else 100
    reset_counter = 1 if phase == "E" else 0
    cov = covariance_for_error(POS_ERR_M, 0.05, RULE)
    msg = mavlink2.MAVLink_odometry_message(
        int(t * 1e6), frame, mavlink2.MAV_FRAME_BODY_FRD, x, y, 0.0, [1, 0, 0, 0], vx, vy, 0.0,
        NAN, NAN, NAN, cov, [NAN] * 21, reset_counter, 0, quality,
    )  # fmt: skip
    return msg, x, y


def send_plan(conn, start: float, rate_hz: float = 10.0) -> list[Sent]:
    """The sending part (module docstring): ODOMETRY at ``rate_hz`` on ``conn`` per the plan
    until phase F; what was sent. Also drains ``conn`` (a UDP client must read its socket)."""
    sent: list[Sent] = []
    k = 0
    while (t := time.monotonic() - start) < PHASES[-1][1]:
        phase = phase_at(t)
        msg, x, y = odometry_message(t, phase)
        conn.mav.send(msg)
        sent.append(Sent(time.monotonic(), t, phase, msg, x, y))
        while conn.recv_match(blocking=False) is not None:
            pass
        k += 1
        time.sleep(max(start + k / rate_hz - time.monotonic(), 0.0))
    return sent


def replay_on_virtual(sitl: Sitl, sent: list[Sent], probes: list[float]) -> dict:
    """The same messages at the same times on the virtual autopilot, booted when the SITL
    rebooted with its EKF milestones; its flags and position at each probe time."""
    init = sitl.heard.first_text("EKF3 IMU0 initialised")
    timing = AutopilotTiming(init - sitl.boot, sitl.ekf_ready - init, 1e9, 1.0)
    ap = VirtualAutopilot(EXTNAV_PARAMS, covariance=RULE, timing=timing)
    gcs = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)

    def wire(msg):
        return gcs.decode(bytearray(msg.pack(gcs)))

    lat, lon = (int(round(v * 1e7)) for v in ORIGIN)
    events = [(s.t, "send", s.msg) for s in sent]
    events.append((sitl.origin_time - 0.01, "send", mavlink2.MAVLink_set_gps_global_origin_message(
        1, lat, lon, 0, 0)))  # fmt: skip
    events += [(t, "probe", None) for t in probes]
    out = {"flags": {}, "position": {}, "texts": []}
    for t, kind, msg in sorted(events, key=lambda e: e[0]):
        now = t - sitl.boot
        if kind == "send":
            replies = ap.handle(wire(msg), now)
        else:
            replies = ap.poll(now)
            out["flags"][t] = ap.nav.flags()
            out["position"][t] = ap.nav.position()
        out["texts"] += [(t, r.text) for r in replies if r.get_type() == "STATUSTEXT"]
    out["counts"] = dict(ap.counts)
    return out


def at_phase(start: float, phase: str, offset: float = 0.0) -> float:
    return start + dict(PHASES)[phase] + offset


def test_ekf3_fuses_the_sent_position_and_the_virtual_autopilot_agrees(tmp_path):
    began = time.monotonic()
    with Sitl(ARDUSUB, tmp_path / "sitl") as sitl:
        try:
            sitl.configure(EXTNAV_PARAMS, ORIGIN)
            start = time.monotonic()
            sent = send_plan(sitl.sender, start)
            last_valid = max(s.t for s in sent if s.phase != "A" and s.phase != "B")
            # F: a second, different origin must be ignored; ask for the origin back
            sitl.sender.mav.set_gps_global_origin_send(1, 480_000_000, 90_000_000, 0, 0)
            time.sleep(0.5)
            sitl.sender.mav.command_long_send(1, 1, 512, 0, 49, 0, 0, 0, 0, 0, 0)
            origin_back = sitl.sender.recv_match(type="GPS_GLOBAL_ORIGIN", blocking=True, timeout=3)
            time.sleep(max(start + PLAN_END_S - time.monotonic(), 0.0))
        except Exception:
            copy_log(sitl, tmp_path / "sitl_output.txt")
            raise
    heard = sitl.heard
    flags = heard.of("EKF_STATUS_REPORT")
    positions = heard.of("LOCAL_POSITION_NED")
    abs_bit = mavlink2.EKF_POS_HORIZ_ABS

    def flags_between(t0, t1):
        return [m.flags for t, m in flags if t0 <= t < t1]

    def sent_track(t):
        """The sent position at monotonic t (the newest message before t)."""
        before = [s for s in sent if s.t <= t and s.phase not in ("A", "B")]
        return (before[-1].x, before[-1].y) if before else (NAN, NAN)

    # A, B: dropped, EKF3 does not aid
    using = heard.first_text("EKF3 IMU0 is using external nav data", since=start)
    assert using is not None and using >= at_phase(start, "C")
    assert not any(f & abs_bit for f in flags_between(start + 0.5, at_phase(start, "C")))
    # C: fused at once (1.5 s allowed for a loaded machine), on the track within the sent error
    assert using <= at_phase(start, "C", 1.5)
    c_flags = flags_between(at_phase(start, "C", 1.0), at_phase(start, "D"))
    assert c_flags and all(f & abs_bit and f & mavlink2.EKF_POS_HORIZ_REL for f in c_flags)
    c_pos = [(t, m) for t, m in positions if at_phase(start, "C", 1.5) <= t < at_phase(start, "D")]
    errors = [math.hypot(m.x - sent_track(t)[0], m.y - sent_track(t)[1]) for t, m in c_pos]
    assert len(errors) > 40 and max(errors) < POS_ERR_M
    # D: a 3 m jump with the same reset_counter is rejected
    d_pos = [(t, m) for t, m in positions if at_phase(start, "D", 0.3) <= t < at_phase(start, "E")]
    assert all(sent_track(t)[0] - m.x > 2.0 for t, m in d_pos)
    # E: with a new reset_counter the position jumps to it
    e_pos = [(t, m) for t, m in positions if at_phase(start, "E", 1.0) <= t < at_phase(start, "F")]
    assert e_pos and all(abs(m.x - sent_track(t)[0]) < POS_ERR_M for t, m in e_pos)
    # F: the position times out about 7 s after the last message
    cleared = next(t for t, m in flags if t > last_valid and not m.flags & abs_bit)
    assert 6.0 <= cleared - last_valid <= 10.0
    # the origin: the first one stays
    assert origin_back is not None and origin_back.latitude == int(round(ORIGIN[0] * 1e7))

    virtual = replay_on_virtual(sitl, sent, [t for t, _ in flags] + [t for t, _ in positions])
    v_using = next(t for t, s in virtual["texts"] if "is using external nav data" in s)
    v_flags = sorted(virtual["flags"].items())
    v_cleared = next(t for t, f in v_flags if t > last_valid and not f & abs_bit)
    phase_end_flags = {}
    for (name, _), (_, next_start) in zip(PHASES[:-1], PHASES[1:], strict=True):
        end = start + next_start
        real = [m.flags for t, m in flags if end - 0.6 <= t < end]
        fake = [f for t, f in v_flags if end - 0.6 <= t < end]
        phase_end_flags[name] = (bool(real[-1] & abs_bit), bool(fake[-1] & abs_bit))
    diffs = [
        math.hypot(m.x - virtual["position"][t][0], m.y - virtual["position"][t][1])
        for t, m in positions
        if virtual["position"].get(t) is not None
        and phase_at(t - start) in ("C", "D", "E")
        and not any(0 <= t - at_phase(start, p) < 1.0 for p in "CE")
    ]
    report = {
        "sitl_s": round(time.monotonic() - began, 1),
        "using_external_nav_s": {"sitl": using - start, "virtual": v_using - start},
        "timeout_after_last_message_s": {
            "sitl": cleared - last_valid,
            "virtual": v_cleared - last_valid,
        },
        "horiz_abs_at_phase_end_sitl_virtual": phase_end_flags,
        "position_difference_m": {
            "rms": float(np.sqrt(np.mean(np.square(diffs)))),
            "max": max(diffs),
        },
        "sitl_track_error_m_max": max(errors),
        "virtual_counts": virtual["counts"],
    }
    print(json.dumps(report, indent=1))
    (tmp_path / "agreement.json").write_text(json.dumps(report, indent=1))
    assert all(real == fake for real, fake in phase_end_flags.values()), phase_end_flags
    assert abs(v_using - using) < 1.0
    assert abs(v_cleared - cleared) < 1.5
    assert report["position_difference_m"]["rms"] < 0.1
    assert virtual["counts"]["ODOMETRY:frame"] == sum(s.phase == "A" for s in sent)
    assert virtual["counts"]["ODOMETRY:quality"] == sum(s.phase == "B" for s in sent)


LIVE_SPAN_S = 30.0  # s of the simulated dive served
LIVE_WAVE = "wave-a0.10-f1.00"
POS_M_NSE = 0.1  # VISO_POS_M_NSE: its least value, so that undertow's error decides


def _run_live(sitl: Sitl, log, out):
    """``undertow serve`` (DVL and sonar only) and ``undertow live --autopilot --mavlink
    <the SITL's sender link> --origin`` until the served data ends; the live result."""
    robot = serve(log, rate=1.0, dvl_port=0, ping_port=0, mavlink=None, wait_for_clients=10.0)
    robot.open()
    live = LiveSettings(dvl=robot.endpoints.dvl, sonar=robot.endpoints.sonar,
                        mavlink=sitl.sender_address, mavlink_pressure="SCALED_PRESSURE",
                        map=False, idle_stop_s=60.0, autopilot=True,
                        autopilot_origin=ORIGIN)  # fmt: skip
    session = LiveSession(Settings(live=live), out).start()
    try:
        assert session.wait_connected(10.0)
        robot.start()

        def stop_after_the_last_message():
            robot.wait()
            time.sleep(1.0)
            session.request_stop()

        threading.Thread(target=stop_after_the_last_message, daemon=True).start()
        return session.run()
    finally:
        robot.stop()


def test_ekf3_navigates_on_undertow_live(tmp_path, simulation):
    """``undertow live --autopilot`` (odometry) against ArduSub's SITL: the SITL gives its
    ATTITUDE and SCALED_PRESSURE on undertow's MAVLink link (its SCALED_PRESSURE2 is nonsense:
    the README; ``live.mavlink_pressure`` chooses the other), ``undertow serve`` the DVL and
    sonar of a simulated dive. The parameters are set and the SITL rebooted by the fixture (as
    a user would before a dive); undertow reads them, sets the EKF origin (``--origin``) and
    sends. Checked from the SITL's own second link: it says the origin is set and it uses
    external navigation, its horizontal-position flags are set while undertow sends, and its
    LOCAL_POSITION_NED is undertow's saved estimate (in the autopilot's clock and frame) within
    the error undertow sent.

    What differs from a vehicle: the SITL sits still at the surface while the served DVL says
    it moves; undertow's attitude and depth are the SITL's, its DVL and sonar the simulation's.
    EKF3 then takes the motion from undertow's position and velocity alone, its accelerometers
    feeling none, and lags through the dive's accelerations: here for about a second, 4.5 s
    after the first message, it is up to 0.14 m off while undertow's error, floored at
    VISO_POS_M_NSE, is 0.1 m (elsewhere a few centimetres). So nine in ten of its positions
    must be within the error sent and every one within twice it; on a vehicle its IMU would
    feel the accelerations."""
    began = time.monotonic()
    dive = simulation(LIVE_WAVE).log
    t0 = dive.time_span[0]
    dive = dive.replace(**{n: s.select(s.t < t0 + LIVE_SPAN_S) for n, s in dive.streams().items()})
    with Sitl(ARDUSUB, tmp_path / "sitl") as sitl:
        try:
            params = {"SERIAL0_BAUD": 921, "SERIAL1_BAUD": 921, **EXTNAV_PARAMS,
                      "VISO_POS_M_NSE": POS_M_NSE}  # fmt: skip
            for name, value in params.items():
                sitl.set_param(name, value)
            sitl.reboot()
            sitl.start_monitor({193: 10.0, 32: 10.0})
            sitl.ekf_ready = sitl.wait_text("EKF3 IMU0 tilt alignment complete", 30.0)
            sitl.sender.close()  # undertow takes the sender's link
            sitl.sender = None
            result = _run_live(sitl, dive, tmp_path / "dive")
        except Exception:
            copy_log(sitl, tmp_path / "sitl_output.txt")
            raise
    summary = result.summary["autopilot"]
    heard = sitl.heard
    est = Estimate(result)
    positions = heard.of("LOCAL_POSITION_NED")
    # the monitor's clock against the autopilot's (its LOCAL_POSITION_NED carry both)
    to_mono = float(np.median([t - m.time_boot_ms * 1e-3 for t, m in positions]))
    first, last = (t + to_mono for t in est.span())
    # undertow set the origin and EKF3 took it, then undertow's position
    assert summary["origin"]["state"] == "set"
    origin_set = heard.first_text("EKF3 IMU0 origin set")
    using = heard.first_text("EKF3 IMU0 is using external nav data")
    assert origin_set is not None and using is not None and first - 0.5 <= using <= first + 1.5
    assert summary["params_to_set"] == []
    # its horizontal-position flags while undertow sends (1.5 s allowed to start)
    flags = [m.flags for t, m in heard.of("EKF_STATUS_REPORT") if using + 1.5 <= t <= last]
    assert len(flags) > 5 * (last - using - 1.5)
    abs_bit, rel_bit = mavlink2.EKF_POS_HORIZ_ABS, mavlink2.EKF_POS_HORIZ_REL
    assert all(f & abs_bit and f & rel_bit for f in flags)
    # its position: undertow's estimate, within the error undertow sent
    errors, bounds, times = [], [], []
    for t, m in positions:
        tb = m.time_boot_ms * 1e-3
        record = est.record_before(tb)
        if t < max(using, origin_set) + 1.5 or t > last or record is None:
            continue
        errors.append(float(np.hypot(m.x - est.position(tb)[0], m.y - est.position(tb)[1])))
        bounds.append(max(record["pos_err_m"], POS_M_NSE))
        times.append(t - first)
    report = {
        "sitl_s": round(time.monotonic() - began, 1),
        "sent": summary["sent"],
        "sending_s": last - first,
        "using_after_first_message_s": using - first,
        "error_m": {"max": max(errors), "median": float(np.median(errors))},
        "error_sent_m": {"min": min(bounds), "median": float(np.median(bounds))},
        "heading_offset_deg": summary["heading_offset_deg"],
        "beyond_error_sent_s": [
            round(t, 1) for t, e, b in zip(times, errors, bounds, strict=True) if e >= b
        ],  # fmt: skip
    }
    print(json.dumps(report, indent=1))
    assert len(errors) > 5 * (last - using - 2.0)
    within = np.less(errors, bounds)
    assert within.mean() >= 0.9, report  # (docstring: the lag through the dive's accelerations)
    assert np.all(np.less(errors, 2.0 * np.asarray(bounds))), report
