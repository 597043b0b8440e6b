"""When undertow sends, with a fake clock: one message per slot (a fixed rate), DVL states at
once while their slot is free, the fallback at 0.8 of a slot, never two messages closer than
EKF3's interval."""

from __future__ import annotations

import math

import numpy as np
import pytest

from undertow.live.autopilot.schedule import MIN_SPACING_S, SendSchedule


def _run(schedule, dvl_times, step=0.001, span=20.0):
    """Advance a fake clock; a DVL state arrives at each of ``dvl_times``; returns the sends
    (time, fresh)."""
    sends, fresh, k = [], False, 0
    dvl = sorted(dvl_times)
    for now in np.arange(0.0, span, step):
        while k < len(dvl) and dvl[k] <= now:
            fresh, k = True, k + 1
        if schedule.due(now, fresh):
            schedule.sent(now)
            sends.append((now, fresh))
            fresh = False
    return sends


@pytest.mark.parametrize("dvl_hz", [4.0, 7.3, 10.0, 26.0])
def test_one_message_per_slot_and_dvl_states_at_once(dvl_hz):
    rate = 10.0
    schedule = SendSchedule(rate, MIN_SPACING_S["odometry"])
    dvl = np.arange(0.013, 20.0, 1.0 / dvl_hz)
    sends = _run(schedule, dvl)
    slots = [math.floor(t * rate) for t, _ in sends]
    assert len(slots) == len(set(slots))  # never two in one slot
    assert len(sends) >= 20.0 * rate - 1  # and one in every slot
    t = np.array([s for s, _ in sends])
    assert np.diff(t).min() >= MIN_SPACING_S["odometry"] - 1e-9
    if dvl_hz <= rate:  # a DVL state goes at once while its slot is free, which it mostly is;
        # after its slot's fallback it waits for the next slot (and EKF3's spacing)
        waits = np.array([min(t[t >= d] - d) for d in dvl if d < t[-1]])
        assert np.median(waits) <= 0.001 + 1e-9
        assert waits.max() <= max(0.2 / rate, MIN_SPACING_S["odometry"]) + 0.001 + 1e-9
    fallbacks = [s for s, fresh in sends if not fresh]
    assert all(abs((s * rate) % 1.0 - 0.8) < 0.011 for s in fallbacks)


def test_velocity_delta_spacing_and_next_due():
    schedule = SendSchedule(10.0, MIN_SPACING_S["velocity-delta"])
    assert schedule.due(0.0, True)
    schedule.sent(0.0)
    assert not schedule.due(0.05, True)  # same slot
    assert schedule.next_due(0.05) == pytest.approx(0.18)  # the next slot's fallback point
    assert schedule.next_due(0.05, fresh=True) == pytest.approx(0.1)  # the next slot
    schedule.sent(0.19)  # late in slot 1
    assert not schedule.due(0.2, True)  # slot 2, but 10 ms after the last message
    assert schedule.next_due(0.2, fresh=True) == pytest.approx(0.245)
    assert schedule.due(0.246, True)


def test_missed_slots_are_counted():
    schedule = SendSchedule(10.0)
    schedule.due(0.0, True)
    schedule.sent(0.0)
    schedule.sent(0.55)  # slots 1..4 passed without a message
    assert schedule.missed == 4
    with pytest.raises(ValueError):
        SendSchedule(0.0)
