"""Property-based tests (hypothesis) of every reader on untrusted input.

Each reader gets inputs derived from real data (the A50 recordings in the shared folder, a
simulated ROS 2 bag) with hypothesis-chosen damage, and must either return its result, or raise
an ``UndertowError`` subclass (one line), possibly after warning -- never another exception and
never a numpy warning. Where the good part of the input is known, it must be kept. Each test is
bounded to a few seconds (``max_examples``); ``make fuzz`` runs the long campaign.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REAL_DATA
from hypothesis import HealthCheck, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir

from undertow.errors import UndertowError
from undertow.io import read_log, read_ply, read_tum, write_log, write_ply
from undertow.settings import Settings
from undertow.sim import load_scenario

#: reads the shared real recordings (conftest.py: a missing folder fails)
pytestmark = pytest.mark.realdata

V1 = REAL_DATA / "a50_tcp_json_v1_straight.txt"
BAG = REAL_DATA / "a50_ros1_circle.bag"
CORPUS = Path(__file__).resolve().parents[2] / "fuzz" / "corpus"
# hypothesis's own cache outside the working tree, and no example database
set_hypothesis_home_dir(Path(tempfile.gettempdir()) / "undertow-hypothesis")
FAST, SLOW_IO = (
    hsettings(
        max_examples=n,
        deadline=None,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture],
    )
    for n in (30, 8)
)

# values that broke readers: huge ints, infinities, NaN, wrong types, absurd strings
WEIRD = st.one_of(
    st.sampled_from([10**400, -(10**30), 2**63, 1e308, math.inf, -math.inf, math.nan, None]),
    st.sampled_from(["", "sea", "1e999", True, [], {}, [1, 2], [[1, 2], [3, 4]], {"a": 1}]),
    st.integers(),
    st.floats(),
    st.text(st.characters(blacklist_categories=("Cs",)), max_size=5),
)
TEXT = st.text(st.characters(blacklist_categories=("Cs",)), max_size=8)  # encodable as UTF-8
YAMLISH = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | TEXT,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(TEXT, inner, max_size=3),
    max_leaves=8,
)


def outcome(read, *args):
    """Call ``read``: its result, or None after an UndertowError of one line. Fails on any other
    exception or on a warning that is not a reader's UserWarning (numpy warnings must not leak)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result = read(*args)
        except UndertowError as exc:
            assert str(exc) and "\n" not in str(exc), repr(str(exc))
            result = None
    leaked = [str(w.message) for w in caught if not issubclass(w.category, UserWarning)]
    assert not leaked, leaked
    return result


def _paths(obj, prefix=()):
    yield prefix
    items = (
        obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, list) else ()
    )
    for key, value in items:
        yield from _paths(value, (*prefix, key))


@st.composite
def mutated_report(draw, obj):
    """``obj`` (a JSON report) with one field replaced by a weird value or deleted."""
    obj = json.loads(json.dumps(obj))
    path = draw(st.sampled_from([p for p in _paths(obj) if p]))
    target = obj
    for key in path[:-1]:
        target = target[key]
    if draw(st.booleans()) and isinstance(target, dict):
        del target[path[-1]]
    else:
        target[path[-1]] = draw(WEIRD)
    return json.dumps(obj)


def _v1_reports() -> list[str]:
    return list(dict.fromkeys(ln for ln in V1.read_text().splitlines() if ln.strip()))


def _v3_reports() -> list[str]:
    return [ln for ln in (CORPUS / "a50_json_v3.txt").read_text().splitlines() if ln.strip()]


JUNK_LINE = st.one_of(
    st.text(max_size=40),
    st.sampled_from(["[" * 100_000, "{}", "[]", "null", '{"type": "position_local"}', "1e999"]),
)


@FAST
@given(data=st.data(), v3=st.booleans())
def test_a50_json_lines_keep_the_good_reports(tmp_path, data, v3):
    good = _v3_reports() if v3 else _v1_reports()
    damaged = {}
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(good) - 1))
        line = json.loads(good[i])
        damaged[i] = data.draw(st.one_of(mutated_report(line), JUNK_LINE))
    lines = [damaged.get(i, line) for i, line in enumerate(good)]
    path = tmp_path / "log.txt"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8", errors="surrogatepass")
    log = outcome(read_log, path)
    intact = {line for i, line in enumerate(good) if i not in damaged}
    velocity = [ln for ln in intact if json.loads(ln).get("type", "velocity") == "velocity"]
    if velocity:  # the untouched velocity reports are all kept
        assert log is not None and log.dvl is not None and len(log.dvl) >= len(velocity)


@FAST
@given(bad=st.sampled_from(["NaN", "Infinity", "-Infinity", "null", "1e999", '"x"']))
def test_a50_json_nonfinite_position_time_drops_the_stream(tmp_path, bad):
    lines = [ln.replace('"ts": ', f'"ts": {bad}, "_ts": ') for ln in _v3_reports()]
    path = tmp_path / "log.txt"
    path.write_text("\n".join(lines) + "\n")
    log = outcome(read_log, path)
    assert log is not None and log.dead_reckoning is None and len(log.dvl) > 0


def _bag_bytes(data, raw: bytes) -> bytes:
    out = bytearray(raw)
    kind = data.draw(st.sampled_from(["flip", "truncate", "fill"]))
    if kind == "truncate":
        return bytes(out[: data.draw(st.integers(0, len(out)))])
    for _ in range(data.draw(st.integers(1, 8))):
        i = data.draw(st.integers(0, len(out) - 1))
        if kind == "flip":
            out[i] ^= 1 << data.draw(st.integers(0, 7))
        else:
            out[i : i + 8] = bytes(len(out[i : i + 8]))
    return bytes(out)


@SLOW_IO
@given(data=st.data())
def test_ros1_bag_bytes(tmp_path, data):
    path = tmp_path / "damaged.bag"
    path.write_bytes(_bag_bytes(data, BAG.read_bytes()))
    outcome(read_log, path)


@pytest.fixture(scope="module")
def small_ros2_bag(tmp_path_factory, simulation):
    """The first 2 s of the simulated ``calm`` run as a ROS 2 bag (with its sidecar)."""
    log = simulation("calm")
    log = log.log if hasattr(log, "log") else log
    short = log.replace(**{n: s.select(s.t < 2.0) for n, s in log.streams().items()})
    return write_log(short, tmp_path_factory.mktemp("ros2") / "bag")


def _copy(bag: Path, tmp_path: Path) -> Path:
    out = tmp_path / "bag"
    shutil.rmtree(out, ignore_errors=True)
    return Path(shutil.copytree(bag, out))


@SLOW_IO
@given(data=st.data())
def test_ros2_bag_mcap_bytes(tmp_path, small_ros2_bag, data):
    bag = _copy(small_ros2_bag, tmp_path)
    mcap = next(bag.glob("*.mcap"))
    mcap.write_bytes(_bag_bytes(data, mcap.read_bytes()))
    outcome(read_log, bag)


@SLOW_IO
@given(data=st.data(), whole=st.booleans())
def test_ros2_sidecar_undertow_yaml(tmp_path, small_ros2_bag, data, whole):
    bag = _copy(small_ros2_bag, tmp_path)
    sidecar = bag / "undertow.yaml"
    content = yaml.safe_load(sidecar.read_text())
    if whole:
        content = data.draw(YAMLISH)
    else:
        path = data.draw(st.sampled_from([p for p in _paths(content) if p]))
        target = content
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = data.draw(WEIRD)
    sidecar.write_text(yaml.safe_dump(content))
    log = outcome(read_log, bag)
    assert log is not None and len(log.imu) > 0  # the bag itself is intact: its data is kept
    density = log.metadata.get("water_density_kg_m3")
    assert density is None or (isinstance(density, int | float) and 0 < density < math.inf)


@SLOW_IO
@given(data=st.data())
def test_ros2_metadata_yaml(tmp_path, small_ros2_bag, data):
    bag = _copy(small_ros2_bag, tmp_path)
    meta = bag / "metadata.yaml"
    content = yaml.safe_load(meta.read_text())
    topics = content["rosbag2_bagfile_information"]["topics_with_message_count"]
    entry = data.draw(st.sampled_from(topics))["topic_metadata"]
    entry[data.draw(st.sampled_from(sorted(entry)))] = data.draw(WEIRD)
    meta.write_text(yaml.safe_dump(content))
    outcome(read_log, bag)


TUM_LINE = st.one_of(
    st.lists(st.floats(), min_size=8, max_size=8).map(lambda v: " ".join(map(repr, v))),
    st.lists(st.floats(), min_size=14, max_size=14).map(lambda v: " ".join(map(repr, v))),
    st.text(max_size=30),
    st.lists(st.integers(), min_size=1, max_size=9).map(lambda v: " ".join(map(str, v))),
)


@FAST
@given(lines=st.lists(TUM_LINE, max_size=12))
def test_tum_lines(tmp_path, lines):
    path = tmp_path / "poses.tum"
    text = "\n".join(lines) + "\n"
    path.write_text(text, encoding="utf-8", errors="replace")
    poses = outcome(read_tum, path)
    usable, width, bad_std = 0, None, False  # the first data line's count: 14 (with std) or 8
    for line in path.read_text(encoding="utf-8").splitlines():
        text = line.strip()
        fields = text.replace(",", " ").split()
        if not text or text.startswith("#"):
            continue
        width = width or (14 if len(fields) == 14 else 8)
        try:
            values = [float(f) for f in fields] if len(fields) == width else None
        except ValueError:
            values = None
        if values is not None:
            usable += math.isfinite(values[0])
            bad_std |= not all(math.isfinite(v) and v >= 0 for v in values[8:])
    assert (poses is None) == (usable == 0 or bad_std)  # a bad std is one error line
    if poses is not None:  # every well-formed pose with a finite time, in time order
        assert len(poses) == usable and np.all(np.diff(poses.t) >= 0)


@FAST
@given(data=st.data(), binary=st.booleans())
def test_ply_header_and_body(tmp_path, data, binary):
    path = tmp_path / "cloud.ply"
    pts = np.arange(30.0).reshape(10, 3)
    write_ply(path, pts, {"mean": np.ones(10)}, binary=binary)
    raw = bytearray(path.read_bytes())
    header_end = raw.index(b"end_header")
    if data.draw(st.booleans()):  # damage a header word
        lines = raw[:header_end].split(b"\n")
        i = data.draw(st.integers(0, len(lines) - 1))
        words = lines[i].split(b" ")
        j = data.draw(st.integers(0, len(words) - 1))
        words[j] = data.draw(st.sampled_from([b"", b"-1", b"99999999999999999999", b"list", b"x"]))
        lines[i] = b" ".join(words)
        raw = b"\n".join(lines) + raw[header_end:]
    else:
        raw = _bag_bytes(data, bytes(raw))
    path.write_bytes(bytes(raw))
    outcome(read_ply, path)


SETTINGS_KEYS = ("topics", "mounting", "localizer", "mapping")


@FAST
@given(data=st.data())
def test_settings_yaml(tmp_path, data):
    content = data.draw(
        st.one_of(YAMLISH, st.dictionaries(st.sampled_from(SETTINGS_KEYS), YAMLISH, max_size=3))
    )
    path = tmp_path / "settings.yaml"
    path.write_text(yaml.safe_dump(content))
    outcome(Settings.from_yaml, path)


@SLOW_IO
@given(data=st.data())
def test_scenario_yaml(tmp_path, data):
    base = load_scenario("calm").to_yaml_dict()
    path_in = data.draw(st.sampled_from([p for p in _paths(base) if p]))
    target = base
    for key in path_in[:-1]:
        target = target[key]
    target[path_in[-1]] = data.draw(WEIRD)
    content = data.draw(st.sampled_from([base, {"base": data.draw(WEIRD)}, data.draw(YAMLISH)]))
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(content))
    outcome(load_scenario, path)
