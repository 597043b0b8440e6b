"""info summaries of the real recordings, checked against counts made here with json/rosbags."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from conftest import REAL_DATA
from rosbags.highlevel import AnyReader

from undertow.io import read_log, summarize

#: reads the shared real recordings (conftest.py: a missing folder fails)
pytestmark = pytest.mark.realdata

REAL = REAL_DATA


def test_summary_of_ros1_bag():
    with AnyReader([REAL / "a50_ros1_circle.bag"]) as reader:
        conns = [c for c in reader.connections if c.topic == "/dvl/data"]
        msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(conns)]
    summary = summarize(read_log(REAL / "a50_ros1_circle.bag"))
    (dvl,) = summary.streams
    assert dvl.messages == len(msgs) == 378
    assert dvl.invalid == sum(not m.velocity_valid for m in msgs)
    assert dvl.missing_detail["altitude"] == sum(m.altitude < 0 for m in msgs)
    assert dvl.missing_detail["invalid_beams"] == sum(not b.valid for m in msgs for b in m.beams)
    stamps = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs])
    assert dvl.duration_s == stamps.max() - stamps.min()
    assert dvl.rate_hz == 1.0 / np.median(np.diff(np.sort(stamps)))
    data = json.loads(json.dumps(summary.to_dict()))
    assert data["streams"][0]["rate_hz"] == dvl.rate_hz


def test_summary_of_v1_text_log():
    reports = [
        json.loads(ln)
        for ln in dict.fromkeys(
            ln for ln in (REAL / "a50_tcp_json_v1_straight.txt").read_text().splitlines() if ln
        )
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        summary = summarize(read_log(REAL / "a50_tcp_json_v1_straight.txt"))
    d = summary.to_dict()
    dvl = d["streams"][0]
    assert dvl["messages"] == len(reports)
    assert dvl["missing_detail"]["altitude"] == sum(r["altitude"] == -1 for r in reports)
    assert dvl["invalid"] == sum(not r["velocity_valid"] for r in reports)
    assert any("duplicate" in w for w in d["warnings"])
    assert np.isclose(d["duration_s"], sum(r["time"] for r in reports[1:]) / 1000.0, rtol=1e-12)
