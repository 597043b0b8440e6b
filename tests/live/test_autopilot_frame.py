"""The autopilot's clock (least-lag offset, drift, reboot) and heading offset (circular mean),
with synthetic times: the answer is known by construction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from undertow.live.autopilot.frame import AutopilotClock, HeadingOffset


def test_clock_offset_is_the_least_lag():
    rng = np.random.default_rng(0)
    clock = AutopilotClock()
    epoch = 1_700_000_000.0  # session time of the autopilot's boot
    boots = np.arange(0.0, 20.0, 0.02)
    lags = 0.003 + rng.exponential(0.01, boots.size)  # every transport delay >= 3 ms
    for b, lag in zip(boots, lags, strict=True):
        assert not clock.observe(b, epoch + b + lag)
    assert clock.offset == pytest.approx(epoch + lags[boots > 20.0 - 30.0].min())
    assert clock.to_autopilot_usec(epoch + 12.5 + lags.min()) == 12_500_000
    assert clock.to_session(4.0) == pytest.approx(epoch + 4.0 + lags.min())


def test_clock_follows_a_drift_through_its_window():
    clock = AutopilotClock(window_s=5.0)
    epoch = 100.0
    for b in np.arange(0.0, 60.0, 0.1):  # the autopilot's clock runs 1e-3 slow
        clock.observe(b, epoch + b * 1.001 + 0.002)
    assert clock.offset == pytest.approx(epoch + 0.002 + 0.001 * (60.0 - 5.0), abs=2e-3)


def test_clock_reboot_starts_again():
    clock = AutopilotClock()
    for b in np.arange(10.0, 20.0, 0.1):
        clock.observe(b, 1000.0 + b)
    assert clock.observe(0.5, 1021.0)  # time since boot went back: a reboot
    assert clock.reboots == 1 and clock.offset == pytest.approx(1020.5)
    assert not clock.observe(math.nan, 1022.0) and not clock.observe(-1.0, 1022.0)
    assert AutopilotClock().to_autopilot_usec(5.0) is None


def test_heading_offset_is_a_circular_mean_across_the_wrap():
    h = HeadingOffset(samples=4)
    yaws = [3.10, -3.12, 3.13, -3.11]  # undertow's heading near +-pi, the autopilot's at 0.05
    for k, yaw in enumerate(yaws[:-1]):
        assert not h.observe(k, 0.05, k, yaw)
    assert h.value is None
    assert h.observe(3.0, 0.05, 3.02, yaws[-1])
    diffs = [0.05 - y for y in yaws]
    expected = math.atan2(sum(map(math.sin, diffs)), sum(map(math.cos, diffs)))
    assert h.value == pytest.approx(expected)
    assert abs(abs(h.value) - math.pi) < 0.1  # near pi, not the arithmetic mean near 0
    assert not h.observe(4.0, 1.0, 4.0, 0.0)  # latched: no more changes
    assert "turned" in h.describe()


def test_heading_pairs_too_far_apart_are_skipped_and_an_override_wins():
    h = HeadingOffset(samples=1, max_gap_s=0.1)
    assert not h.observe(0.0, 1.0, 0.5, 0.0) and h.value is None
    assert h.observe(0.0, 1.0, 0.05, 0.0) and h.value == pytest.approx(1.0)
    fixed = HeadingOffset(fixed_rad=0.25)
    assert fixed.value == 0.25 and not fixed.observe(0.0, 1.0, 0.0, 0.0)
    assert "live.autopilot_yaw_offset_deg" in fixed.describe()
