"""Water Linked TCP JSON reader: the real json_v1 log and protocol-spec lines (v3, position)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import REAL_DATA

from undertow.errors import ReaderError
from undertow.io import read_log
from undertow.io.a50_json import velocity_report_line

#: reads the shared real recordings (conftest.py: a missing folder fails)
pytestmark = pytest.mark.realdata

V1 = REAL_DATA / "a50_tcp_json_v1_straight.txt"


def test_real_v1_log():
    lines = [ln for ln in V1.read_text().splitlines() if ln.strip()]
    unique = list(dict.fromkeys(lines))
    reports = [json.loads(ln) for ln in unique]
    with pytest.warns(UserWarning, match=f"duplicate lines dropped: {len(lines) - len(unique)}"):
        log = read_log(V1)
    d = log.dvl
    assert len(d) == len(reports)
    ms = np.array([r["time"] for r in reports])
    np.testing.assert_allclose(d.t, (np.cumsum(ms) - ms[0]) / 1000.0, rtol=0, atol=1e-12)
    assert "cumulative" in log.metadata["time_base"]
    np.testing.assert_array_equal(np.isnan(d.altitude), [r["altitude"] == -1 for r in reports])
    beam_ok = np.array([[b["beam_valid"] for b in r["transducers"]] for r in reports])
    np.testing.assert_array_equal(d.beam_valid, beam_ok)
    assert np.isnan(d.beam_range[~beam_ok]).all() and np.isfinite(d.beam_range[beam_ok]).all()
    np.testing.assert_array_equal(d.valid, [r["velocity_valid"] for r in reports])
    np.testing.assert_array_equal(d.velocity[:, 0], [r["vx"] for r in reports])  # kept as sent


V3 = (
    '{"time":100.0,"vx":0.1,"vy":-0.2,"vz":0.01,"fom":0.002,'
    '"covariance":[[1e-6,0,0],[0,2e-6,0],[0,0,3e-7]],"altitude":%s,"transducers":['
    '{"id":0,"velocity":0.1,"distance":1.2,"rssi":-40,"nsd":-90,"beam_valid":true},'
    '{"id":1,"velocity":0.1,"distance":1.3,"rssi":-40,"nsd":-90,"beam_valid":false},'
    '{"id":2,"velocity":0.1,"distance":1.4,"rssi":-40,"nsd":-90,"beam_valid":true},'
    '{"id":3,"velocity":0.1,"distance":1.5,"rssi":-40,"nsd":-90,"beam_valid":true}],'
    '"velocity_valid":%s,"status":0,"format":"json_v3","type":"velocity",'
    '"time_of_validity":%d,"time_of_transmission":%d}'
)
POS = (
    '{"ts":%.3f,"x":1.0,"y":2.0,"z":0.5,"std":0.1,"roll":10.0,"pitch":-5.0,"yaw":90.0,'
    '"type":"position_local","status":0,"format":"json_v3"}'
)


def test_v3_velocity_and_position_reports(tmp_path):
    tov = 1_650_000_000_000_000
    lines = [
        V3 % ("1.5", "true", tov, tov + 100),
        "not json at all {",
        V3 % ("-1", "false", tov + 100_000, tov + 100_100),
        POS % 1_650_000_000.05,
        POS % 1_650_000_000.15,
    ]
    path = tmp_path / "dvl.jsonl"
    path.write_text("\n".join(lines) + "\n")
    with pytest.warns(UserWarning, match="malformed lines skipped: 1 .first: line 2"):
        log = read_log(path)
    d = log.dvl
    np.testing.assert_array_equal(d.t, [tov * 1e-6, (tov + 100_000) * 1e-6])
    np.testing.assert_array_equal(d.altitude, [1.5, np.nan])
    np.testing.assert_array_equal(d.valid, [True, False])
    np.testing.assert_array_equal(d.covariance[0], np.diag([1e-6, 2e-6, 3e-7]))
    np.testing.assert_array_equal(d.beam_valid[0], [True, False, True, True])
    assert np.isnan(d.beam_range[0, 1]) and d.beam_range[0, 3] == 1.5
    dr = log.dead_reckoning
    np.testing.assert_allclose(dr.orientation[0], np.deg2rad([10.0, -5.0, 90.0]))
    np.testing.assert_array_equal(dr.position[1], [1.0, 2.0, 0.5])
    assert log.metadata["time_base"].startswith("time_of_validity")


def test_time_going_backwards_is_sorted(tmp_path):
    tov = 1_650_000_000_000_000
    path = tmp_path / "back.json"
    path.write_text("\n".join([V3 % ("1", "true", tov + 2000, 0), V3 % ("2", "true", tov, 0)]))
    with pytest.warns(UserWarning, match="backwards"):
        log = read_log(path)
    np.testing.assert_array_equal(log.dvl.altitude, [2.0, 1.0])


def test_written_line_is_parsed_back(tmp_path):
    tov = 1_650_000_000_000_000
    path = tmp_path / "a.log"
    path.write_text(V3 % ("-1", "true", tov, tov) + "\n")
    d = read_log(path).dvl
    obj = json.loads(velocity_report_line(d, 0, 100.0, d.t[0]))
    assert obj["altitude"] == -1 and obj["time_of_validity"] == tov
    assert [b["beam_valid"] for b in obj["transducers"]] == [True, False, True, True]


def test_bad_files(tmp_path):
    with pytest.raises(ReaderError, match="no such file"):
        read_log(tmp_path / "none.txt")
    (tmp_path / "empty.txt").write_text("\n\n")
    with pytest.raises(ReaderError, match="empty"):
        read_log(tmp_path / "empty.txt")
    (tmp_path / "junk.txt").write_text("hello\n{broken\n")
    with pytest.raises(ReaderError, match=r"junk\.txt: no readable .* \(line 1\)"):
        read_log(tmp_path / "junk.txt")
