"""Property-based tests (hypothesis) of what undertow reads from the vehicle for --autopilot:
any bytes through pymavlink's parser, and messages with any field values (NaN, infinities,
out-of-range integers, garbage parameter names), go through :class:`Vehicle` without an
exception, and the state it keeps stays sane (a known target, finite times and positions, an
origin only within the Earth's coordinates). The settings' origin parser takes any text
without a traceback."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir
from pymavlink.dialects.v20 import ardupilotmega as m

from undertow.commands.live import live_settings
from undertow.errors import UndertowError
from undertow.live.autopilot.vehicle import Vehicle

set_hypothesis_home_dir(Path(tempfile.gettempdir()) / "undertow-hypothesis")
FAST = hsettings(max_examples=60, deadline=None, database=None,
                 suppress_health_check=[HealthCheck.too_slow])  # fmt: skip

FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=32)
U32 = st.integers(0, 2**32 - 1)
I32 = st.integers(-(2**31), 2**31 - 1)


def _vehicle(sent):
    notes = []
    v = Vehicle(mode="odometry", own=(255, 197), pressure="SCALED_PRESSURE2",
                origin=(1.0, 2.0), set_params=True, send=lambda msg: sent.append(msg) or True,
                note=notes.append, record=lambda *a: None, dvl_from_mavlink=True)  # fmt: skip
    return v, notes


def _packed(msg, sysid=1, compid=1) -> bytes:
    return bytes(msg.pack(m.MAVLink(None, srcSystem=sysid, srcComponent=compid)))


MESSAGES = st.one_of(
    st.builds(m.MAVLink_heartbeat_message, st.integers(0, 255), st.integers(0, 255),
              st.integers(0, 255), U32, st.integers(0, 255), st.integers(0, 255)),
    st.builds(m.MAVLink_attitude_message, U32, FLOATS, FLOATS, FLOATS, FLOATS, FLOATS, FLOATS),
    st.builds(m.MAVLink_param_value_message, st.binary(max_size=16), FLOATS,
              st.integers(0, 255), st.integers(0, 65535), st.integers(0, 65535)),
    st.builds(m.MAVLink_gps_global_origin_message, I32, I32, I32),
    st.builds(m.MAVLink_ekf_status_report_message, st.integers(0, 65535), FLOATS, FLOATS,
              FLOATS, FLOATS, FLOATS),
    st.builds(m.MAVLink_local_position_ned_message, U32, FLOATS, FLOATS, FLOATS, FLOATS,
              FLOATS, FLOATS),
    st.builds(m.MAVLink_command_ack_message, st.integers(0, 65535), st.integers(0, 255)),
    st.builds(m.MAVLink_statustext_message, st.integers(0, 255), st.binary(max_size=50)),
    st.builds(m.MAVLink_vision_position_delta_message, st.integers(0, 2**63), st.integers(0, 2**63),
              st.lists(FLOATS, min_size=3, max_size=3), st.lists(FLOATS, min_size=3, max_size=3),
              FLOATS),
    st.builds(m.MAVLink_system_time_message, st.integers(0, 2**63), U32),
)  # fmt: skip


def _sane(v: Vehicle) -> None:
    assert v.target is None or v.target == (1, 1)  # only a heartbeat from 1/1 came
    if v.clock.offset is not None:
        assert math.isfinite(v.clock.offset)
    if v.position is not None:
        assert all(math.isfinite(p) for p in v.position)
    if v.origin.origin is not None:
        lat, lon, alt = v.origin.origin
        assert abs(lat) <= 90 and abs(lon) <= 180 and math.isfinite(alt)
    for value, _ in v.params.values.values():
        assert math.isfinite(value)


@FAST
@given(st.lists(st.tuples(MESSAGES, st.sampled_from([(1, 1), (255, 0), (7, 42)])), max_size=30),
       st.floats(0.0, 1e6))  # fmt: skip
def test_any_field_values_are_taken_without_an_exception(items, start):
    sent = []
    v, _ = _vehicle(sent)
    parser = m.MAVLink(None)
    for k, (msg, sender) in enumerate(items):
        try:
            data = _packed(msg, *sender)
        except Exception:  # pymavlink cannot pack it (a value out of its struct's range)
            continue
        for decoded in parser.parse_buffer(data) or ():
            v.take(decoded, start + 0.1 * k)
        v.housekeeping(start + 0.1 * k)
    _sane(v)


@FAST
@given(st.binary(max_size=600), st.floats(0.0, 1e6))
def test_any_bytes_are_taken_without_an_exception(data, t):
    sent = []
    v, _ = _vehicle(sent)
    parser = m.MAVLink(None)
    parser.robust_parsing = True
    heartbeat = _packed(m.MAVLink_heartbeat_message(12, 3, 0, 0, 4, 3))
    for decoded in parser.parse_buffer(heartbeat + data) or ():
        if decoded.get_type() != "BAD_DATA":
            v.take(decoded, t)
    v.housekeeping(t + 1.0)
    _sane(v)


@FAST
@given(st.text(max_size=40))
def test_origin_text_is_a_value_or_one_line(text):
    try:
        settings = live_settings(None, mavlink="udpin:0.0.0.0:14550", autopilot=True,
                                 autopilot_origin=text)  # fmt: skip
    except UndertowError as exc:
        assert "\n" not in str(exc)
        return
    origin = settings.live.autopilot_origin
    assert origin is None or (2 <= len(origin) <= 3 and abs(origin[0]) <= 90)


@pytest.mark.parametrize("text", ["47.1,8.2", " 47.1 , 8.2 , -3 ", "-90,180,0"])
def test_origin_text_examples(text):
    s = live_settings(None, mavlink="udpin:0.0.0.0:1", autopilot=True, autopilot_origin=text)
    assert s.live.autopilot_origin == tuple(float(v) for v in text.replace(" ", "").split(","))
