"""The virtual autopilot driven with pymavlink messages built here (packed and decoded, as on a
link): every rule of ArduSub's external navigation it claims to follow, with the times and
values ArduPilot's source states (the references are in the comments)."""

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from undertow.errors import ConfigError
from undertow.sim.robot.autopilot import AutopilotTiming, VirtualAutopilot, load_param_file
from undertow.sim.robot.autopilot_rules import covariance_for_error

NAN = math.nan
FAST = AutopilotTiming(ekf_start_s=1.0, tilt_align_s=1.0, bias_learn_s=2.0, reboot_s=1.0)
EXTNAV = {"VISO_TYPE": 1, "GPS1_TYPE": 0, "EK3_SRC1_POSXY": 6, "EK3_SRC1_VELXY": 6}
ABS = mavlink2.EKF_POS_HORIZ_ABS
GCS = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)


def wire(msg):
    """``msg`` as a receiver decodes it from the wire (MAVLink 2, from a GCS)."""
    return GCS.decode(bytearray(msg.pack(GCS)))


def odometry(t, x=1.0, y=2.0, z=0.0, frame=20, child=12, q=(1, 0, 0, 0), vel=(0, 0, 0), **kw):
    cov = kw.pop("cov", covariance_for_error(0.3, 0.05))
    return mavlink2.MAVLink_odometry_message(
        int(t * 1e6), frame, child, x, y, z, list(q), *vel, NAN, NAN, NAN, cov,
        [NAN] * 21, kw.pop("reset_counter", 0), 0, kw.pop("quality", 100),
    )  # fmt: skip


class Driver:
    """Steps an autopilot's clock and collects what it sends."""

    def __init__(self, params=EXTNAV, **kw):
        kw.setdefault("timing", FAST)
        self.ap = VirtualAutopilot(params, **kw)
        self.t = 0.0
        self.out = []

    def send(self, msg, t=None):
        """The replies to ``msg`` other than STATUSTEXTs (those are kept in :attr:`out`)."""
        if t is not None:
            self.t = t
        replies = self.ap.handle(wire(msg), self.t)
        self.out += [(self.t, r) for r in replies]
        return [r for r in replies if r.get_type() != "STATUSTEXT"]

    def run(self, until, every=0.1, make=None):
        """Advance to ``until`` in steps of ``every``, sending ``make(t)`` (if given) each."""
        while self.t < until - 1e-9:
            self.t = round(self.t + every, 9)
            if make is not None:
                m = make(self.t)
                if m is not None:
                    self.send(m)
            self.out += [(self.t, r) for r in self.ap.poll(self.t)]

    def texts(self):
        return [r.text for _, r in self.out if r.get_type() == "STATUSTEXT"]

    def of(self, kind):
        return [(t, r) for t, r in self.out if r.get_type() == kind]

    @property
    def flags(self):
        return self.ap.nav.flags()


def test_odometry_is_used_only_with_the_local_frd_body_frd_pair():
    d = Driver()
    d.run(4.0, make=lambda t: odometry(t, frame=mavlink2.MAV_FRAME_LOCAL_NED))
    assert d.ap.counts["ODOMETRY:frame"] == 40
    assert not any("external nav" in s for s in d.texts())
    assert not d.flags & ABS
    d.run(5.0, make=lambda t: odometry(t, child=mavlink2.MAV_FRAME_BODY_NED))
    assert d.ap.counts["ODOMETRY:frame"] == 50 and not d.flags & ABS
    d.run(6.0, make=lambda t: odometry(t))
    assert "EKF3 IMU0 is using external nav data" in d.texts()
    assert "EKF3 IMU0 initial pos NED = 1.0,2.0,0.0 (m)" in d.texts()
    assert d.flags & ABS and d.ap.nav.position()[:2] == pytest.approx((1.0, 2.0))


def test_nothing_is_used_before_the_tilt_is_aligned_or_with_viso_type_0():
    d = Driver()
    d.run(2.0, make=lambda t: odometry(t))  # EKF starts at 1 s, tilt aligned at 2 s
    assert d.ap.counts["ODOMETRY:ekf_not_ready"] == 9  # 0.1 ... 0.9 s
    assert d.ap.counts["ODOMETRY:not_ready"] == 10  # 1.0 ... 1.9 s: tilt not yet aligned
    assert d.ap.counts["ODOMETRY:started"] == 1
    off = Driver({**EXTNAV, "VISO_TYPE": 0})
    off.run(4.0, make=lambda t: odometry(t))
    assert off.ap.counts["ODOMETRY:viso_disabled"] == 40 and not off.flags & ABS


@pytest.mark.parametrize("rule", ["cbrt", "sqrt"])
def test_the_covariance_becomes_one_error_floored_by_viso_pos_m_nse(rule):
    d = Driver({**EXTNAV, "VISO_POS_M_NSE": 0.25, "VISO_YAW_M_NSE": 0.1}, covariance=rule)
    cov = [0.0] * 21
    cov[0], cov[6], cov[11], cov[15], cov[18], cov[20] = 0.5, 0.3, 0.2, 0.02, 0.02, 0.01
    d.run(3.0, make=lambda t: odometry(t, cov=cov))
    s = d.ap.last_sample
    if rule == "cbrt":  # GCS_Common.cpp before ArduPilot PR 32084
        assert s.pos_err == pytest.approx((0.25 + 0.09 + 0.04) ** (1 / 3))
        assert s.ang_err == pytest.approx(0.1)  # cbrt(9e-4) = 0.097 < the floor
    else:  # after PR 32084
        assert s.pos_err == pytest.approx(1.0)
        assert s.ang_err == pytest.approx(math.sqrt(0.05))
    d.run(3.5, make=lambda t: odometry(t, cov=[0.0] * 21))
    assert d.ap.last_sample.pos_err == pytest.approx(0.25)
    d.run(4.0, make=lambda t: odometry(t, cov=[NAN] * 21))
    assert (d.ap.last_sample.pos_err, d.ap.last_sample.ang_err) == pytest.approx((0.25, 0.1))
    d.run(4.5, make=lambda t: odometry(t, cov=[1e6] + [0.0] * 20))
    assert d.ap.last_sample.pos_err == pytest.approx(100.0)


def test_quality_below_viso_qual_min_is_not_used():
    d = Driver({**EXTNAV, "VISO_QUAL_MIN": 50})
    d.run(4.0, make=lambda t: odometry(t, quality=49))
    assert d.ap.counts["ODOMETRY:quality"] == 40 and not d.flags & ABS
    d.run(4.5, make=lambda t: odometry(t, quality=50))
    assert d.flags & ABS
    # VISION_POSITION_ESTIMATE has no quality: ArduPilot passes 0
    d = Driver({**EXTNAV, "VISO_QUAL_MIN": 1})
    vpe = mavlink2.MAVLink_vision_position_estimate_message(0, 1.0, 2.0, 0.0, 0.0, 0.0, 0.0)
    d.run(4.0, make=lambda t: vpe)
    assert d.ap.counts["VISION_POSITION_ESTIMATE:quality"] == 40
    d = Driver(EXTNAV)
    d.run(4.0, make=lambda t: vpe)
    assert d.flags & ABS
    assert "EKF3 IMU0 initial vel NED = 0.0,0.0,0.0 (m/s)" not in d.texts()  # no velocity


def test_samples_closer_than_20_ms_are_dropped():
    d = Driver()
    d.run(3.0, make=lambda t: odometry(t))
    before = d.ap.counts["ODOMETRY:fused"]
    d.send(odometry(3.01), 3.01)
    d.send(odometry(3.025), 3.025)
    assert d.ap.counts["ODOMETRY:rate"] == 1  # 10 ms after the previous one
    assert d.ap.counts["ODOMETRY:fused"] == before + 1


def test_a_jump_is_gated_unless_the_reset_counter_changes():
    d = Driver()
    d.run(5.0, make=lambda t: odometry(t, x=1.0))
    d.run(7.0, make=lambda t: odometry(t, x=4.0))  # 3 m: far outside 5 sigma
    assert d.ap.counts["ODOMETRY:rejected"] == 20
    assert d.ap.nav.position()[0] == pytest.approx(1.0, abs=0.05)
    d.run(7.1, make=lambda t: odometry(t, x=6.0, reset_counter=1))
    assert d.ap.counts["ODOMETRY:reset"] == 1
    assert d.ap.nav.position()[0] == pytest.approx(6.0, abs=1e-6)
    d.run(8.0, make=lambda t: odometry(t, x=6.0, reset_counter=1))
    assert d.ap.counts["ODOMETRY:reset"] == 1  # the same counter: no new reset


def test_a_stale_stream_times_out_after_7_s_and_stops_aiding_after_15_s():
    d = Driver()
    d.run(5.0, make=lambda t: odometry(t))
    assert d.flags == 831  # the SITL's flags while it fuses external navigation
    d.run(11.9)  # AP_NavEKF3.h posRetryTimeNoVel_ms = 7000
    assert d.flags & ABS
    d.run(12.1)
    assert not d.flags & ABS and d.flags == 39  # the SITL's flags after the timeout
    d.run(19.9)  # tiltDriftTimeMax_ms = 15000
    assert "EKF3 IMU0 stopped aiding" not in d.texts()
    d.run(20.1)
    assert "EKF3 IMU0 stopped aiding" in d.texts()
    assert d.flags & mavlink2.EKF_CONST_POS_MODE and d.ap.nav.position() is None
    d.run(21.0, make=lambda t: odometry(t, x=3.0))
    assert d.texts().count("EKF3 IMU0 is using external nav data") == 2
    assert d.ap.nav.position()[0] == pytest.approx(3.0, abs=0.05)


def test_a_stream_back_within_the_timeout_resets_the_position():
    d = Driver()
    d.run(5.0, make=lambda t: odometry(t, x=1.0))
    d.run(13.0)
    d.run(13.5, make=lambda t: odometry(t, x=8.0))  # outside the gate, but timed out
    assert d.flags & ABS and d.ap.nav.position()[0] == pytest.approx(8.0, abs=0.05)
    assert d.texts().count("EKF3 IMU0 is using external nav data") == 1


def test_odometry_velocity_is_rotated_from_body_to_ned():
    d = Driver({**EXTNAV, "EK3_SRC1_VELXY": 6})
    yaw90 = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))  # w, x, y, z
    d.run(8.0, make=lambda t: odometry(t, x=1.0, y=2.0 + 0.5 * t, q=yaw90, vel=(0.5, 0, 0)))
    assert d.ap.nav.velocity()[:2] == pytest.approx((0.0, 0.5), abs=0.02)
    assert d.ap.counts["ODOMETRY:velocity_fused"] > 50


def test_the_origin_is_set_once_per_boot_and_only_once_the_ekf_runs():
    d = Driver()
    origin = mavlink2.MAVLink_set_gps_global_origin_message(1, 470_000_000, 80_000_000, 0, 0)
    assert d.send(origin, 0.5) == []  # EKF not running yet: dropped silently
    assert d.ap.counts["SET_GPS_GLOBAL_ORIGIN:ekf_not_ready"] == 1
    (reply,) = d.send(origin, 1.5)
    assert reply.get_type() == "GPS_GLOBAL_ORIGIN" and reply.latitude == 470_000_000
    assert "EKF3 IMU0 origin set" in d.texts()
    other = mavlink2.MAVLink_set_gps_global_origin_message(1, 480_000_000, 80_000_000, 0, 0)
    assert d.send(other, 2.0) == []  # already set: ignored, no reply
    assert d.ap.origin == (470_000_000, 80_000_000, 0)
    request = mavlink2.MAVLink_command_long_message(1, 1, 512, 0, 49, 0, 0, 0, 0, 0, 0)
    replies = d.send(request, 2.5)
    assert replies[0].result == mavlink2.MAV_RESULT_ACCEPTED
    assert replies[1].latitude == 470_000_000
    bad = mavlink2.MAVLink_set_gps_global_origin_message(1, 950_000_000, 0, 0, 0)
    assert Driver().send(bad, 2.0) == []


def test_an_origin_already_on_the_vehicle_is_there_after_every_boot():
    d = Driver(origin=(47.5, 8.25, 400.0))
    d.run(1.5)
    assert d.ap.origin == (475_000_000, 82_500_000, 400_000)
    with pytest.raises(ConfigError, match="--autopilot-origin"):
        VirtualAutopilot(origin=(95.0, 0.0))


def param_set(name, value):
    return mavlink2.MAVLink_param_set_message(1, 1, name.encode(), float(value), 9)


def param_read(name, index=-1):
    return mavlink2.MAVLink_param_request_read_message(1, 1, name.encode(), index)


REBOOT = mavlink2.MAVLink_command_long_message(1, 1, 246, 0, 1, 0, 0, 0, 0, 0, 0)


def test_parameters_are_read_set_and_listed():
    d = Driver({})
    (value,) = d.send(param_read("VISO_POS_M_NSE"))
    assert value.param_id == "VISO_POS_M_NSE" and value.param_value == pytest.approx(0.2)
    assert value.param_type == mavlink2.MAV_PARAM_TYPE_REAL32 and value.param_index == 65535
    (value,) = d.send(param_set("VISO_QUAL_MIN", 20.7))
    assert value.param_value == 20.0 and value.param_type == mavlink2.MAV_PARAM_TYPE_INT8
    assert d.send(param_read("NO_SUCH_PARAM")) == []
    d.send(mavlink2.MAVLink_param_request_list_message(1, 1), 1.0)
    d.run(2.0)
    values = [(t, r) for t, r in d.of("PARAM_VALUE") if t >= 1.0]
    names = [r.param_id for _, r in values]
    assert len(names) == len(set(names)) == values[0][1].param_count
    assert sorted(r.param_index for _, r in values) == list(range(len(names)))
    assert "EK3_SRC1_POSXY" in names and "VISO_TYPE" in names


def test_a_parameter_that_needs_a_reboot_takes_effect_after_one():
    d = Driver({"GPS1_TYPE": 0, "EK3_SRC1_POSXY": 6, "EK3_SRC1_VELXY": 6})  # VISO_TYPE 0
    d.run(3.0)
    (value,) = d.send(param_set("VISO_TYPE", 1))
    assert value.param_value == 1.0  # stored ...
    d.run(4.0, make=lambda t: odometry(t))
    assert d.ap.counts["ODOMETRY:viso_disabled"] == 10 and not d.flags & ABS  # ... not used
    (ack,) = d.send(REBOOT, 4.05)
    assert ack.command == 246 and ack.result == mavlink2.MAV_RESULT_ACCEPTED
    d.run(5.0, make=lambda t: odometry(t))
    assert d.ap.counts["ODOMETRY:rebooting"] >= 9  # silent while rebooting
    (value,) = d.send(param_read("VISO_TYPE"), 5.1)
    assert value.param_value == 1.0 and d.ap.boots == 2
    d.run(8.0, make=lambda t: odometry(t))
    assert d.flags & ABS


def test_ek3_sources_switch_live_but_external_nav_needs_a_boot_with_one():
    live = Driver({**EXTNAV, "EK3_SRC1_POSXY": 3})  # VELXY 6 at boot: buffers allocated
    live.run(4.0, make=lambda t: odometry(t))
    assert live.ap.counts["ODOMETRY:not_source"] >= 20 and not live.flags & ABS
    live.send(param_set("EK3_SRC1_POSXY", 6))
    live.run(4.5, make=lambda t: odometry(t))
    assert live.flags & ABS  # no reboot needed
    none = Driver({**EXTNAV, "EK3_SRC1_POSXY": 3, "EK3_SRC1_VELXY": 3})
    none.run(3.0)
    none.send(param_set("EK3_SRC1_POSXY", 6))
    none.run(6.0, make=lambda t: odometry(t))
    assert not none.flags & ABS  # as the SITL: not until a reboot
    none.send(REBOOT)
    none.run(10.0, make=lambda t: odometry(t))
    assert none.flags & ABS


def test_message_intervals():
    d = Driver()
    d.run(5.0, make=lambda t: odometry(t))
    assert d.of("LOCAL_POSITION_NED") == []  # not streamed unless asked
    assert 4 <= len(d.of("EKF_STATUS_REPORT")) <= 6  # 1 Hz by default
    interval = mavlink2.MAVLink_command_long_message(1, 1, 511, 0, 32, 50_000, 0, 0, 0, 0, 0)
    (ack,) = d.send(interval)
    assert ack.result == mavlink2.MAV_RESULT_ACCEPTED
    d.run(6.0, every=0.01, make=lambda t: odometry(t) if round(t * 100) % 10 == 0 else None)
    positions = [(t, r) for t, r in d.of("LOCAL_POSITION_NED") if t > 5.0]
    assert 19 <= len(positions) <= 21  # 20 Hz
    assert positions[-1][1].x == pytest.approx(1.0, abs=0.01)
    assert all(r.time_boot_ms == round(1000 * t) for t, r in positions)
    stop = mavlink2.MAVLink_command_long_message(1, 1, 511, 0, 32, -1, 0, 0, 0, 0, 0)
    d.send(stop)
    d.run(7.0)
    assert not [r for t, r in d.of("LOCAL_POSITION_NED") if t > 6.0]
    unknown = mavlink2.MAVLink_command_long_message(1, 1, 511, 0, 27, 1e5, 0, 0, 0, 0, 0)
    assert d.send(unknown)[0].result == mavlink2.MAV_RESULT_FAILED


def delta(t, v_body=(0.5, 0.0, 0.0), dt=0.1, confidence=100):
    return mavlink2.MAVLink_vision_position_delta_message(
        int(t * 1e6), int(dt * 1e6), [0.0, 0.0, 0.0], [v * dt for v in v_body], confidence
    )


def test_body_odometry_starts_relative_aiding_and_dead_reckons():
    d = Driver({**EXTNAV, "EK3_SRC1_POSXY": 0})
    d.run(3.9, make=lambda t: delta(t))  # biases learned at 1 + 1 + 2 = 4 s
    assert "EKF3 IMU0 started relative aiding" not in d.texts()
    d.run(4.1, make=lambda t: delta(t))
    assert "EKF3 IMU0 started relative aiding" in d.texts()
    assert d.flags & mavlink2.EKF_POS_HORIZ_REL and not d.flags & ABS
    x0 = d.ap.nav.position()[0]
    d.run(8.1, make=lambda t: delta(t))
    assert d.ap.nav.position()[0] - x0 == pytest.approx(0.5 * 4.0, rel=0.05)
    d.run(13.2)  # 5 s without body odometry: aiding stops
    assert "EKF3 IMU0 stopped aiding" in d.texts()


def test_body_odometry_rules():
    # confidence 0 with EK3_VIS_VERR_MAX 1.5: velErr 1.5 m/s >= 1, never starts
    d = Driver({**EXTNAV, "EK3_VIS_VERR_MAX": 1.5})
    d.run(6.0, make=lambda t: delta(t, confidence=0))
    assert not d.flags & mavlink2.EKF_POS_HORIZ_REL
    # VISO_DELAY_MS of 200 ms or more: never fresh enough
    d = Driver({**EXTNAV, "VISO_DELAY_MS": 250})
    d.run(6.0, make=lambda t: delta(t))
    assert not d.flags & mavlink2.EKF_POS_HORIZ_REL
    # spacing under 50 ms or a delta shorter than EKF3's step: dropped
    d = Driver()
    d.run(5.0, make=lambda t: delta(t))
    d.send(delta(5.03), 5.03)
    d.send(delta(5.1, dt=0.005), 5.1)
    assert d.ap.counts["VISION_POSITION_DELTA:rate"] == 2


def test_body_odometry_is_rotated_by_the_vehicles_attitude():
    d = Driver({**EXTNAV, "EK3_SRC1_POSXY": 0}, attitude=lambda t: (0.0, 0.0, math.pi / 2))
    d.run(10.0, make=lambda t: delta(t))
    assert d.ap.nav.velocity()[:2] == pytest.approx((0.0, 0.5), abs=0.02)


def test_default_timing_refuses_an_origin_before_the_ekf_starts():
    d = Driver(timing=AutopilotTiming())
    origin = mavlink2.MAVLink_set_gps_global_origin_message(1, 470_000_000, 80_000_000, 0, 0)
    d.run(3.0)
    assert d.send(origin) == []
    d.run(4.0)
    assert d.send(origin)[0].get_type() == "GPS_GLOBAL_ORIGIN"


def test_load_param_file(tmp_path):
    path = tmp_path / "ext.parm"
    path.write_text("# ext nav\nVISO_TYPE 1\nEK3_SRC1_POSXY,6\n\nvery_custom 2.5 # kept\n")
    assert load_param_file(path) == {"VISO_TYPE": 1.0, "EK3_SRC1_POSXY": 6.0, "VERY_CUSTOM": 2.5}
    path.write_text("VISO_TYPE\n")
    with pytest.raises(ConfigError, match=r"ext.parm:1"):
        load_param_file(path)
    with pytest.raises(ConfigError, match="cannot read"):
        load_param_file(tmp_path / "missing.parm")
