"""When undertow sends, with a fake clock: a fixed rate on average (a token bucket), DVL states
at once while the DVL is not faster than the rate, the newest state when the bucket is full,
never more than r W + 2 messages in a window W, EKF3's spacings kept."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.live.autopilot.schedule import SPACING_S, Rhythm, SendSchedule


def _run(schedule, dvl_times, step=0.001, span=30.0, lag=0.0, predict=True):
    """Advance a fake clock; a DVL state (its time ``lag`` before its arrival) comes at each of
    ``dvl_times``, an IMU-advanced state every millisecond; the sends (time, fresh, state t).
    ``predict``: the schedule is told when the next DVL comes."""
    sends, fresh, k = [], False, 0
    dvl = sorted(dvl_times)
    for now in np.arange(0.0, span, step):
        while k < len(dvl) and dvl[k] <= now:
            fresh, k = True, k + 1
        state_t = now - lag
        nxt = dvl[k] if predict and k < len(dvl) else None
        if schedule.due(now, fresh, state_t, nxt):
            schedule.sent(now, state_t)
            sends.append((now, fresh, state_t))
            fresh = False
    return sends


@pytest.mark.parametrize("dvl_hz", [0.0, 4.0, 7.3, 9.9, 10.0, 26.0])
def test_fixed_rate_on_average_and_bounded_in_every_window(dvl_hz):
    rate, span = 10.0, 30.0
    schedule = SendSchedule(rate, *SPACING_S["odometry"])
    dvl = np.arange(0.013, span, 1.0 / dvl_hz) if dvl_hz else []
    sends = _run(schedule, dvl, span=span)
    t = np.array([s for s, _, _ in sends])
    assert abs(len(t) - rate * span) <= 2  # r on average, whatever the DVL does
    for w in (0.05, 0.1, 0.5, 2.0):  # at most r W + 3 in any window W
        counts = np.searchsorted(t, t + w, side="left") - np.arange(len(t))
        assert counts.max() <= rate * w + 3
    states = np.array([st for _, _, st in sends])
    assert np.diff(states).min() >= SPACING_S["odometry"][1] - 1e-9
    if not dvl_hz:  # no DVL: exactly one period apart
        np.testing.assert_allclose(np.diff(t), 1.0 / rate, atol=0.0011)
    if 0 < dvl_hz <= rate:  # every DVL state goes in the millisecond it comes
        waits = np.array([min(t[t >= d] - d) for d in dvl if d < t[-1]])
        assert waits.max() <= 0.001 + 1e-9


def test_without_knowing_the_dvl_it_waits_at_most_the_state_spacing():
    schedule = SendSchedule(10.0, *SPACING_S["odometry"])
    dvl = np.arange(0.013, 30.0, 1 / 7.3)
    sends = _run(schedule, dvl, predict=False)
    t = np.array([s for s, _, _ in sends])
    waits = np.array([min(t[t >= d] - d) for d in dvl if d < t[-1]])
    assert waits.max() <= SPACING_S["odometry"][1] + 0.001 + 1e-9
    assert np.mean(waits > 0.001) > 0.01  # (which happens: what the prediction is for)


def test_a_faster_dvl_is_thinned_to_the_rate():
    schedule = SendSchedule(10.0, *SPACING_S["odometry"])
    sends = _run(schedule, np.arange(0.0, 30.0, 1 / 26.0), span=30.0)
    assert all(fresh for _, fresh, _ in sends[1:])  # only DVL states: none is ever stale
    assert abs(len(sends) - 300) <= 2


def test_velocity_delta_send_spacing_and_next_due():
    schedule = SendSchedule(10.0, *SPACING_S["velocity-delta"])
    assert schedule.due(0.0, True, 0.0)
    schedule.sent(0.0, 0.0)
    assert schedule.tokens == pytest.approx(0.0)
    assert not schedule.due(0.03, True, 0.03)  # a token (borrowed), but 55 ms not passed
    assert schedule.next_due(0.03, fresh=True) == pytest.approx(0.055)
    assert schedule.next_due(0.03) == pytest.approx(0.1)  # the bucket full again
    assert schedule.due(0.056, True, 0.056)
    schedule.sent(0.056, 0.056)  # tokens 0.56 - 1
    assert not schedule.due(0.07, True, 0.07)  # below 0 until 0.1
    assert schedule.next_due(0.07, fresh=True) == pytest.approx(0.111)  # then the 55 ms
    assert schedule.next_due(0.07) == pytest.approx(0.2)  # a whole token
    assert schedule.next_due(0.07, dvl_next=0.205) == pytest.approx(0.215)  # the DVL's


def test_a_fallback_waits_for_a_dvl_report_due_now_but_not_for_a_late_one():
    schedule = SendSchedule(10.0, *SPACING_S["odometry"])
    schedule.due(0.0, False)
    schedule.sent(0.0, 0.0)
    assert not schedule.due(0.1, False, 0.1, dvl_next=0.11)  # expected in 10 ms
    assert schedule.due(0.1, False, 0.1, dvl_next=0.2)  # not near
    assert schedule.due(0.121, False, 0.121, dvl_next=0.11)  # 11 ms late: not waited for


def test_missed_periods_are_counted():
    schedule = SendSchedule(10.0)
    schedule.due(0.0, False)
    schedule.sent(0.0)
    schedule.due(0.65, False)  # the bucket was full (2 tokens) from 0.2 on: 4.5 periods lost
    assert schedule.missed == 4
    with pytest.raises(ValueError):
        SendSchedule(0.0)


def test_rhythm_predicts_a_steady_dvl_and_not_an_irregular_one():
    rhythm = Rhythm()
    for t in np.arange(10.0, 11.0, 0.125):
        rhythm.arrived(t)
    assert rhythm.next() == pytest.approx(11.0)
    rng = np.random.default_rng(0)
    irregular = Rhythm()
    for t in np.cumsum(rng.uniform(0.05, 0.4, 20)):
        irregular.arrived(t)
    assert irregular.next() is None
    assert Rhythm().next() is None
