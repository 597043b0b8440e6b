"""Regression tests of every reader failure found by fuzzing (issue 10 and ``make fuzz``).

Each test is a real recording (or a small simulated bag) plus the one damage that once gave a
traceback, a hang, a weak message or a leaked numpy warning. The expected behaviour: the bad
line, message or sidecar is skipped and counted in ONE warning naming its first line/message,
the good data is kept; a file with nothing usable is one UndertowError line.
"""

from __future__ import annotations

import json
import os
import shutil
import threading
import warnings

import numpy as np
import pytest
import yaml
from conftest import REAL_DATA

from undertow.commands.data import info_file
from undertow.errors import ConfigError, ReaderError, UndertowError
from undertow.io import read_log, write_log
from undertow.io.collect import Notes
from undertow.io.rosbag_streams import Rows
from undertow.log import GroundTruth, Log, Pressure
from undertow.sim import load_scenario

#: reads the shared real recordings (conftest.py: a missing folder fails)
pytestmark = pytest.mark.realdata

V1 = REAL_DATA / "a50_tcp_json_v1_straight.txt"
BAG = REAL_DATA / "a50_ros1_circle.bag"


def _read_quietly(path, **kwargs):
    """read_log with numpy warnings as errors; (log, reader warning lines)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warnings.simplefilter("error", RuntimeWarning)
        log = read_log(path, **kwargs)
    return log, [str(w.message) for w in caught]


def _real_v1_plus(tmp_path, bad_line: str, at: int = 3):
    lines = V1.read_text().splitlines()
    distinct = len({ln for ln in lines if ln.strip()})
    lines.insert(at, bad_line)
    path = tmp_path / "log.txt"
    path.write_text("\n".join(lines) + "\n")
    return path, distinct


def _v1_report() -> dict:
    return json.loads(V1.read_text().splitlines()[0])


def _set(obj: dict, path: tuple, value) -> str:
    target = obj
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return json.dumps(obj)


BAD_LINES = {
    "deep nesting (RecursionError)": "[" * 100_000 + "]" * 100_000,
    "deep nesting, unbalanced": '{"vx": ' + "[" * 100_000,
    "velocity int too large (OverflowError)": _set(_v1_report(), ("vx",), 10**400),
    "covariance int too large": _set(_v1_report(), ("covariance",), [[10**400] * 3] * 3),
    "beam id infinite (OverflowError)": _set(_v1_report(), ("transducers", 0, "id"), 1e999),
    "beam distance int too large": _set(_v1_report(), ("transducers", 1, "distance"), 10**400),
    "position report int too large": json.dumps(
        {
            "type": "position_local",
            "ts": 10**400,
            "x": 0,
            "y": 0,
            "z": 0,
            "roll": 0,
            "pitch": 0,
            "yaw": 0,
        }  # fmt: skip
    ),
    "time field 1e308 (would push later reports to inf)": _set(_v1_report(), ("time",), 1e308),
}


@pytest.mark.parametrize("bad", list(BAD_LINES.values()), ids=list(BAD_LINES))
def test_a50_json_malformed_line_is_skipped_and_counted(tmp_path, bad):
    path, distinct = _real_v1_plus(tmp_path, bad.replace("1e+999", "1e999"), at=3)
    log, lines = _read_quietly(path)
    assert len(log.dvl) == distinct  # every report of the real log kept
    skipped = [ln for ln in lines if "malformed lines skipped: 1" in ln]
    assert len(skipped) == 1 and "(first: line 4)" in skipped[0]


def test_a50_json_every_position_time_nonfinite(tmp_path):
    """Every position_local report with a non-finite ``ts``: the stream is dropped with a
    warning (the empty stream crashed ``info``); the velocity reports are kept."""
    report = _v1_report()
    position = '{"type": "position_local", "ts": NaN, "x": 1, "y": 2, "z": 0.5, "std": 0.1, '
    position += '"roll": 0, "pitch": 0, "yaw": 90}'
    path = tmp_path / "log.txt"
    path.write_text(
        json.dumps(report) + "\n" + position + "\n" + position.replace("NaN", "Infinity")
    )
    with pytest.warns(UserWarning) as caught:
        result = info_file(path)
    assert any("dead_reckoning: no report with a finite time" in str(w.message) for w in caught)
    assert [s.name for s in result.summary.streams] == ["dvl"]
    path.write_text(position + "\n")
    with pytest.raises(ReaderError, match=r"log\.txt: no report with a finite time"):
        _read_quietly(path)


def test_named_pipe_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "live.txt"
    os.mkfifo(fifo)
    outcome = {}

    def read():
        try:
            read_log(fifo)
        except UndertowError as exc:
            outcome["error"] = str(exc)

    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    thread.join(timeout=10)
    if thread.is_alive():  # unblock the reader before failing
        with open(fifo, "w"):
            pass
        pytest.fail("reading a named pipe blocked")
    assert "live.txt: is a named pipe, not a log file" in outcome["error"]


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory, simulation):
    """The first 2 s of the simulated ``calm`` run as a ROS 2 bag with its sidecar."""
    log = simulation("calm").log
    short = log.replace(**{n: s.select(s.t < 2.0) for n, s in log.streams().items()})
    return write_log(short, tmp_path_factory.mktemp("bag") / "bag")


def _bag_copy(small_bag, tmp_path):
    return shutil.copytree(small_bag, tmp_path / "bag")


@pytest.mark.parametrize("content", [[1, 2], "just text", 3], ids=["list", "string", "number"])
def test_sidecar_not_a_mapping(tmp_path, small_bag, content):
    bag = _bag_copy(small_bag, tmp_path)
    (bag / "undertow.yaml").write_text(yaml.safe_dump(content))
    clean, _ = _read_quietly(small_bag)
    log, lines = _read_quietly(bag)
    assert any("undertow.yaml unreadable" in ln and "mapping is expected" in ln for ln in lines)
    np.testing.assert_array_equal(log.imu.angular_velocity, clean.imu.angular_velocity)
    assert log.metadata["mounting_source"] != "undertow.yaml"


@pytest.mark.parametrize("density", ["sea", -1, 0, 10**400, None, [1025]])
def test_sidecar_water_density_not_a_number(tmp_path, small_bag, density):
    bag = _bag_copy(small_bag, tmp_path)
    sidecar = yaml.safe_load((bag / "undertow.yaml").read_text())
    sidecar["metadata"]["water_density_kg_m3"] = density
    (bag / "undertow.yaml").write_text(yaml.safe_dump(sidecar))
    log, lines = _read_quietly(bag)
    # the malformed value is dropped; the water of the settings (fresh by default) is stated
    assert log.metadata["water_density_kg_m3"] == 998.0 and log.metadata["water"] == "fresh"
    assert any("water_density_kg_m3 is not a positive number (ignored)" in ln for ln in lines)
    assert log.metadata["mounting_source"] == "undertow.yaml"  # the rest of the sidecar kept


@pytest.mark.parametrize("field", ["tilt_deg", "azimuths_deg", "beam_width_deg"])
def test_sidecar_dvl_geometry_int_too_large(field):
    """A YAML integer too large for a float in the sidecar's dvl_geometry (found by
    test_ros2_sidecar_undertow_yaml): the one-line ConfigError the reader turns into a note,
    not an OverflowError."""
    from undertow.robot import DvlGeometry

    data = {"tilt_deg": 22.5, "azimuths_deg": [135, -135, -45, 45], "beam_width_deg": 2.0}
    data[field] = [10**400] * 4 if field == "azimuths_deg" else 10**400
    with pytest.raises(ConfigError, match=r"^dvl_geometry: malformed \(OverflowError"):
        DvlGeometry.from_dict(data)


def test_metadata_yaml_non_string_topic_name(tmp_path, small_bag):
    bag = _bag_copy(small_bag, tmp_path)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    topics = meta["rosbag2_bagfile_information"]["topics_with_message_count"]
    topics[0]["topic_metadata"]["name"] = 12345
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    from undertow.io.topics import TopicMap

    try:  # a user topic map makes the reader list the bag's topics (the TypeError was there)
        _read_quietly(bag, topics=TopicMap(dvl=["/not/there"]))
    except UndertowError as exc:
        assert "\n" not in str(exc)


def test_metadata_yaml_files_entry_a_string_keeps_what_was_read(tmp_path, small_bag):
    """Fuzz (make fuzz, seed 0): ``files: "\\0"`` in metadata.yaml made rosbags' close raise
    AttributeError after the messages were read, leaving the bag's file open; the log is kept,
    the entry noted, and the file closed (no ResourceWarning when collected)."""
    import gc

    bag = _bag_copy(small_bag, tmp_path)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    meta["rosbag2_bagfile_information"]["files"] = "\0"
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    good, _ = _read_quietly(small_bag)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_log(bag)
        gc.collect()
    lines = [str(w.message) for w in caught]
    assert any("metadata.yaml: 'files' is not a list (ignored)" in line for line in lines)
    assert not [line for line in lines if "unclosed file" in line], lines
    assert len(log.dvl) == len(good.dvl) > 0 and len(log.imu) == len(good.imu)


def test_a_bag_that_fails_to_close_keeps_what_was_read(small_bag, monkeypatch):
    """Any other failure of rosbags to close the bag after reading: the log is the one read,
    the failure one noted line."""
    from rosbags.highlevel import AnyReader

    good, _ = _read_quietly(small_bag)
    real_close = AnyReader.close

    def failing_close(self):
        real_close(self)
        raise RuntimeError("cannot close\nat all")

    monkeypatch.setattr(AnyReader, "close", failing_close)
    with pytest.warns(UserWarning, match=r"closing the bag failed .*RuntimeError: cannot close\)$"):
        log = read_log(small_bag)  # one line: the exception's first
    assert len(log.dvl) == len(good.dvl) > 0 and len(log.pressure) == len(good.pressure)


def test_corrupt_bag_message_says_what_is_wrong(tmp_path, small_bag):
    """rosbags raises a bare MemoryError on a damaged mcap record length; the one line says
    what that means instead of only "(MemoryError)"."""
    bag = _bag_copy(small_bag, tmp_path)
    mcap = next(bag.glob("*.mcap"))
    raw = bytearray(mcap.read_bytes())
    raw[12:16] = b"\xff\xff\xff\x7f"  # the length field of the first record
    mcap.write_bytes(bytes(raw))
    with pytest.raises(ReaderError) as caught:
        _read_quietly(bag)
    text = str(caught.value)
    assert "\n" not in text and "(MemoryError)" not in text
    assert "bag: cannot open bag (a record claims a length too large to allocate" in text


def test_extreme_values_leak_no_numpy_warning(tmp_path):
    """hPa pressure with one absurd sample overflowed in the x100 conversion, a damaged
    ground-truth quaternion in its norm: the reader reports inf/NaN values, no numpy warning."""
    t = np.arange(3.0)
    log = Log(
        pressure=Pressure(t=t, pressure=[1013.0, 1014.0, 1e308]),
        ground_truth=GroundTruth(t=t, position=np.zeros((3, 3)), orientation=np.zeros((3, 3))),
    )
    bag = write_log(log, tmp_path / "bag")
    read, _ = _read_quietly(bag)
    assert read.pressure.pressure[2] == np.inf and read.pressure.pressure[0] == 101300.0
    rows = Rows(Notes("x"))  # the quaternion as a damaged message holds it
    rows.rows["ground_truth"] += [
        (0.0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0),
        (1.0, 0, 0, 0, 1e200, 1e200, 0, 1, 0, 0, 0),
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with np.errstate(all="ignore"):  # as read_rosbag runs the builders
            assert len(rows.ground_truth()) == 2


def test_scenario_base_not_a_name():
    """``base: 1e400`` (hypothesis) made a file name too long for the OS: a ConfigError now."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.yaml"
        path.write_text("base: " + "1" * 400 + "\n")
        with pytest.raises(ConfigError, match="field base: the name of a scenario or a file"):
            load_scenario(path)


def test_sidecar_nan_mounting_is_ignored(tmp_path, small_bag):
    """A NaN DVL mounting froze the track with no warning: the sidecar's mounting is ignored
    with a warning and the bag's /tf_static (or the default) used."""
    bag = _bag_copy(small_bag, tmp_path)
    sidecar = yaml.safe_load((bag / "undertow.yaml").read_text())
    sidecar["mounting"]["dvl"]["rotation"] = [float("nan"), 0.0, 0.0]
    (bag / "undertow.yaml").write_text(yaml.safe_dump(sidecar))
    log, lines = _read_quietly(bag)
    assert any("non-finite values" in ln and "mounting" in ln for ln in lines)
    assert log.metadata["mounting_source"] != "undertow.yaml"
    assert np.isfinite(log.mounting.dvl.rotation).all()


@pytest.mark.parametrize("quaternion", [(float("nan"), 0, 0, 1), (0, 0, 0, 0)], ids=["nan", "zero"])
def test_tf_static_bad_rotation_is_ignored(quaternion):
    from undertow.io.rosbag import _tf_mounting
    from undertow.io.topics import TopicMap

    notes = Notes("bag")
    transforms = [("base_link", "dvl_link", (0.1, 0.0, 0.2), quaternion)]
    assert _tf_mounting(transforms, TopicMap(), notes) is None  # the default mounting is used
    assert (
        "tf_static: sensor transforms with a non-finite or zero rotation (ignored)" in notes.counts
    )


@pytest.mark.parametrize("value", ["[1" + "0" * 400 + ", 0, 0]", "[.nan, 0, 0]", "[.inf, 0, 0]"])
def test_a_settings_mounting_too_large_or_not_finite_is_one_line(tmp_path, value):
    """float() of a 400-digit integer overflows; NaN/inf are numbers but no rotation."""
    from undertow.settings import Settings

    path = tmp_path / "s.yaml"
    path.write_text(f"mounting: {{imu: {{rotation: {value}}}}}\n")
    with pytest.raises(ConfigError, match=r"mounting\.imu\.rotation"):
        Settings.from_yaml(path)


def test_a_settings_key_with_a_newline_is_named_on_one_line(tmp_path):
    """Found by hypothesis (test_settings_yaml): an extra key "\\n" made a two-line error."""
    from undertow.errors import ConfigError
    from undertow.settings import Settings

    path = tmp_path / "settings.yaml"
    path.write_text('"\\n": 1\n')
    with pytest.raises(ConfigError) as info:
        Settings.from_yaml(path)
    assert "\n" not in str(info.value) and "'\\n'" in str(info.value)
