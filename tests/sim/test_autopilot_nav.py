"""EKF3's horizontal-position innovation gate in the virtual autopilot's filter, against the
closed form of a constant-velocity Kalman filter one step after a reset."""

import pytest

from undertow.sim.robot.autopilot_nav import AID_ABSOLUTE, ExtNavSample, NavFilter
from undertow.sim.robot.autopilot_rules import PARAMS


def started_filter(pos_err):
    params = {name: spec.default for name, spec in PARAMS.items()}
    params.update(EK3_SRC1_POSXY=6, EK3_SRC1_VELXY=6)
    nav = NavFilter(params.__getitem__, True, [])
    nav.initialised = nav.tilt_aligned = True
    nav.t = 0.0
    assert nav.extnav_position(ExtNavSample((0.0, 0.0, 0.0), pos_err, 0.1, 0.0), None) == "started"
    assert nav.mode == AID_ABSOLUTE
    return nav


@pytest.mark.parametrize("factor, outcome", [(0.99, "fused"), (1.01, "rejected")])
def test_the_position_gate_is_five_sigma_of_the_innovation(factor, outcome):
    # after the reset: P_pos = R = 0.2^2, P_vel = 0.5^2, no cross term; one step of dt = 0.1 s
    # with white acceleration noise q = EK3_ACC_P_NSE^2 gives P_pos = R + dt^2 P_vel + q dt^3/3
    r, dt, q = 0.2**2, 0.1, 0.35**2
    p_pos = r + dt**2 * 0.5**2 + q * dt**3 / 3
    # EK3_POS_I_GATE 500 (5 sigma): iN^2 + iE^2 < 5^2 (vN + vE), v = P + R, here iE = 0
    limit = (25 * 2 * (p_pos + r)) ** 0.5
    nav = started_filter(0.2)
    sample = ExtNavSample((factor * limit, 0.0, 0.0), 0.2, 0.1, dt)
    assert nav.extnav_position(sample, None) == outcome
    assert nav.pos_test_ratio == pytest.approx(factor**2, rel=1e-9)
