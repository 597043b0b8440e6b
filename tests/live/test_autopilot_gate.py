"""Every safety rule of the autopilot gate with a fake clock: settling after a (re)start, DVL
loss, the position and velocity std bounds, the reset_counter after a stop, on a jump, and not
for motion the velocity explains."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.live.autopilot.gate import SendGate


def _state(p=(0.0, 0.0, 1.0), yaw=0.0, v=(0.0, 0.0, 0.0), pos_var=0.01, vel_var=1e-4):
    x = np.zeros(18)
    x[0:3], x[5], x[6:9] = p, yaw, v
    P = np.eye(18) * 1e-6
    P[0, 0] = P[1, 1] = pos_var
    P[6, 6] = P[7, 7] = vel_var
    return x, P


def _gate(**kw):
    params = dict(mode="odometry", max_position_std_m=2.0, dvl_timeout_s=1.0, settle_s=2.0,
                  jump_m=0.5, inflation=1.0, reset_counter=10)  # fmt: skip
    return SendGate(**{**params, **kw})


def _run(gate, t0, t1, dt=0.1, dvl=True, **state):
    """Feed states (and valid DVL records) from t0 to t1; the verdicts."""
    out = []
    for t in np.arange(t0, t1, dt):
        if dvl:
            gate.note_dvl(t, True)
        x, P = _state(**state)
        v = gate.check(t, t, x, P)
        if v.send:
            counter, reset = gate.prepare(t, x)
            gate.sent(t, x, reset)
        out.append((t, v))
    return out


def test_settles_after_the_start_then_sends():
    gate = _gate()
    verdicts = _run(gate, 100.0, 104.0)
    held = [t for t, v in verdicts if not v.send]
    assert held and max(held) < 102.0 and "settling" in verdicts[0][1].reason
    assert all(v.send for t, v in verdicts if t >= 102.0)
    assert gate.reset_counter == 10  # the first message is no reset


def test_dvl_loss_stops_and_the_resume_is_a_reset():
    gate = _gate()
    _run(gate, 0.0, 3.0)
    lost = _run(gate, 3.0, 5.0, dvl=False)
    last = 2.9  # the last valid DVL
    assert all(v.send for t, v in lost if t - last < 0.95)  # within the timeout
    assert all(not v.send and "DVL" in v.reason for t, v in lost if t - last > 1.05)
    gate.note_dvl(5.0, False)  # an invalid velocity is no DVL
    assert not gate.check(5.0, 5.0, *_state()).send
    resumed = _run(gate, 5.1, 6.0)
    assert all(v.send for _, v in resumed)
    assert gate.reset_counter == 11 and gate.resets == 1 and gate.jumps == 0


def test_position_std_bound_and_inflation():
    gate = _gate(inflation=2.0)
    _run(gate, 0.0, 3.0)
    # sqrt(k (Pxx + Pyy)) = sqrt(2 * 2 * 0.9) = 1.9 m: sent; 2.1 m: held
    assert gate.check(3.0, 3.0, *_state(pos_var=0.9)).send
    v = gate.check(3.1, 3.1, *_state(pos_var=1.1))
    assert not v.send and "position std" in v.reason


def test_velocity_delta_bounds_the_velocity_std_not_the_position():
    gate = _gate(mode="velocity-delta")
    _run(gate, 0.0, 3.0, pos_var=100.0)  # a large position std does not matter
    assert gate.check(3.0, 3.0, *_state(pos_var=100.0, vel_var=0.8**2)).send
    gate.max_velocity_std_m_s = 0.5  # EK3_VIS_VERR_MAX read from the vehicle
    v = gate.check(3.1, 3.1, *_state(vel_var=0.8**2))
    assert not v.send and "EK3_VIS_VERR_MAX" in v.reason


def test_a_jump_is_a_reset_and_motion_the_velocity_explains_is_not():
    gate = _gate()
    _run(gate, 0.0, 3.0)
    counter = gate.reset_counter
    t = 3.0
    for _ in range(20):  # 1 m/s north, the position following it
        x, P = _state(p=(t - 3.0, 0.0, 1.0), v=(1.0, 0.0, 0.0))
        gate.note_dvl(t, True)
        assert gate.check(t, t, x, P).send
        c, reset = gate.prepare(t, x)
        assert not reset and c == counter
        gate.sent(t, x, reset)
        t += 0.1
    x, P = _state(p=(t - 3.0 + 0.8, 0.0, 1.0), v=(1.0, 0.0, 0.0))  # 0.8 m the velocity lacks
    gate.note_dvl(t, True)
    c, reset = gate.prepare(t, x)
    assert reset and c == (counter + 1) % 256
    gate.sent(t, x, reset)
    assert gate.reset_counter == c and gate.jumps == 1


def test_time_going_back_is_a_restart():
    gate = _gate()
    _run(gate, 50.0, 53.0)
    v = gate.check(53.0, 10.0, *_state())  # the filter's states started again
    assert not v.send and "settling" in v.reason and gate.restarts == 1
    after = _run(gate, 10.1, 13.0)
    assert [v.send for t, v in after if t > 12.05] and all(v.send for t, v in after if t > 12.05)
    assert gate.resets == 1


def test_counter_wraps_and_starts_at_random():
    gate = _gate(reset_counter=255)
    _run(gate, 0.0, 3.0)
    gate.hold()
    c, reset = gate.prepare(3.0, _state()[0])
    assert reset and c == 0
    starts = {SendGate().reset_counter for _ in range(50)}
    assert len(starts) > 10 and all(0 <= s < 256 for s in starts)


@pytest.mark.parametrize("mode", ["odometry", "vision-position", "velocity-delta"])
def test_no_dvl_yet_holds_every_mode(mode):
    gate = _gate(mode=mode, settle_s=0.0)
    v = gate.check(1.0, 1.0, *_state())
    assert not v.send and "DVL" in v.reason
