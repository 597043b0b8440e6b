"""The live pipeline's fast paths give what the general paths give: the recorder's CDR templates
are the bytes rosbags serializes, records_to_log's whole-column conversion the row-by-row one,
and a preview advanced by the new records only (or continued from a checkpoint) the fresh
preview over the whole buffer."""

from __future__ import annotations

import dataclasses
import json
import math
import warnings

import numpy as np
import pytest

from undertow.errors import DataError
from undertow.estimation.online import OnlineLocalizer
from undertow.io import read_log
from undertow.io.a50_json import velocity_report_line
from undertow.io.rosbag_write import (
    MessageBuilder,
    dead_reckoning_message,
    dvl_driver_message,
    imu_message,
    pressure_message,
)
from undertow.live.recorder import Recorder
from undertow.log import Dvl
from undertow.records import RECORD_FIELDS, Record, records_to_log
from undertow.sim import load_scenario, simulate

SPECIAL = [math.nan, math.inf, -math.inf, -0.0, 0.0, 1e308, -5e-324, 1.0]


def _value(rng) -> float:
    return float(rng.choice(SPECIAL)) if rng.random() < 0.2 else float(rng.normal() * 10.0)


def _vec(rng, n):
    return tuple(_value(rng) for _ in range(n))


@pytest.mark.parametrize("late", ["", "/undertow/late/"])
def test_cdr_templates_are_the_bytes_rosbags_writes(tmp_path, late):
    rng = np.random.default_rng(5)
    b = MessageBuilder()
    rec = Recorder(tmp_path / ("late" if late else "rec"))
    enc = rec.encoder  # the records' messages
    try:
        for parts in [(False, True), (True, True), (False, False), (True, False)]:
            enc._imu_parts = parts  # the session's IMU parts (fixed by its first record)
            for _ in range(200):
                t = float(rng.uniform(0.0, 2.0**31 - 1.0))
                if rng.random() < 0.1:  # stamps at the rounding edges of the nanoseconds
                    t = math.floor(t) + 1.0 - 1e-10 * rng.random()
                data = {"angular_velocity": _vec(rng, 3), "linear_acceleration": _vec(rng, 3),
                        "orientation": _vec(rng, 4)}  # fmt: skip
                _, [(topic, ns, msgtype, payload)] = enc._imu(t, Record("imu", t, data), late)
                has_a, has_q = parts if not late else (True, True)
                acc = data["linear_acceleration"] if has_a else (0.0,) * 3
                q = data["orientation"] if has_q else (0.0,) * 4
                ns_ref, msg = imu_message(b, t, enc._frame["imu"], data["angular_velocity"],
                                          acc, q, has_a, has_q)  # fmt: skip
                assert ns == ns_ref
                assert bytes(payload) == bytes(b.store.serialize_cdr(msg, msgtype))
        for _ in range(300):
            t, p = float(rng.uniform(0.0, 2.0**31 - 1.0)), _value(rng)
            record = Record("pressure", t, {"pressure": p})
            _, [(_, ns, msgtype, payload)] = enc._pressure(t, record, late)
            ns_ref, msg = pressure_message(b, t, enc._frame["barometer"], p)
            assert ns == ns_ref
            assert bytes(payload) == bytes(b.store.serialize_cdr(msg, msgtype))
        for _ in range(300):
            t = float(rng.uniform(0.0, 2.0**31 - 1.0))
            rpy = tuple(float(a) for a in rng.uniform(-3.2, 3.2, 3))
            if rng.random() < 0.1:  # NaN and infinite angles (numpy's path for the latter)
                rpy = (rpy[0], _value(rng), rpy[2])
            data = {"position": _vec(rng, 3), "orientation": rpy, "std": _value(rng)}
            record = Record("dead_reckoning", t, data)
            _, [(_, ns, msgtype, payload)] = enc._dead_reckoning(t, record, late)
            std = np.float64(data["std"])
            ns_ref, msg = dead_reckoning_message(b, t, data["position"], np.array(rpy), std)
            assert ns == ns_ref
            assert bytes(payload) == bytes(b.store.serialize_cdr(msg, msgtype))
        for _ in range(300):
            t = float(rng.uniform(0.0, 2.0**31 - 1.0))
            ok = tuple(bool(k) for k in rng.random(4) < 0.7)
            data = {"velocity": _vec(rng, 3), "valid": bool(rng.random() < 0.8),
                    "fom": _value(rng), "covariance": rng.normal(size=(3, 3)),
                    "altitude": _value(rng), "beam_range": _vec(rng, 4), "beam_valid": ok,
                    "beam_velocity": _vec(rng, 4)}  # fmt: skip
            for key in ("fom", "covariance", "beam_valid", "altitude"):
                if rng.random() < 0.1:
                    del data[key]
            sensor_time = t - 0.003 if rng.random() < 0.5 else math.nan
            record = Record("dvl", t, data, t, sensor_time)
            _, [(_, ns, msgtype, payload), (_, ns_j, type_j, text)] = enc._dvl(t, record, late)
            obj = json.loads(bytes(text)[8:-1])  # the report line in the std_msgs/String
            dvl = Dvl.from_velocity([t], [data["velocity"]])
            beams = ("beam_range", "beam_valid", "beam_velocity")
            dvl = dataclasses.replace(dvl, valid=np.array([data["valid"]]), **{
                k: np.array([data[k]]) for k in ("fom", "altitude", "covariance", *beams)
                if k in data})  # fmt: skip
            tov = sensor_time if math.isfinite(sensor_time) else t
            ns_ref, msg = dvl_driver_message(b, dvl, 0, enc._frame["dvl"], obj["time"])
            assert ns == ns_j == ns_ref
            assert bytes(payload) == bytes(b.store.serialize_cdr(msg, msgtype))
            line = velocity_report_line(dvl, 0, obj["time"], tov)
            string = b.T["std_msgs/msg/String"](data=line)
            assert bytes(text) == bytes(b.store.serialize_cdr(string, type_j))
        assert all(template is not None for template in enc._templates.values())
        assert enc._string_template  # the JSON lines' template reproduced rosbags' bytes
    finally:
        rec.abort()


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")  # cos/sin of an infinite angle
def test_pose_template_is_the_bytes_rosbags_writes(tmp_path):
    rng = np.random.default_rng(8)
    b = MessageBuilder()
    rec = Recorder(tmp_path / "rec")
    written = []
    write = rec._append
    rec._append = lambda conn, ns, data: (written.append((conn.topic, ns, bytes(data))),
                                          write(conn, ns, data))  # fmt: skip
    try:
        cases = []
        for _ in range(200):
            t = float(rng.uniform(0.0, 2.0**31 - 1.0))
            x = np.array([_value(rng) for _ in range(18)])
            P = rng.normal(size=(18, 18))
            P[rng.random((18, 18)) < 0.05] = math.nan
            rec.write_pose(t, x, P)
            cases.append((t, x, P))
        poses = [w for w in written if w[0] == "/undertow/pose"]
        assert len(poses) == len(cases)
        msgtype = "geometry_msgs/msg/PoseWithCovarianceStamped"
        for (t, x, P), (_, ns, data) in zip(cases, poses, strict=True):
            h, ns_ref = b.header(t, "world")
            cov = np.ascontiguousarray(P[:6, :6]).reshape(36)
            msg = b.T[msgtype](header=h, pose=b.pose_cov(x[0:3], x[3:6], cov))
            assert ns == ns_ref
            assert data == bytes(b.store.serialize_cdr(msg, msgtype))
        assert rec.encoder._templates[("/undertow/pose",)] is not None  # the template was used
    finally:
        rec.abort()


def _reference_column(records, key, shape, dtype):
    """Row by row: missing -> NaN (False for bool), None when no record has the field."""
    values = [r.data.get(key) for r in records]
    if all(v is None for v in values):
        return None
    out = np.empty((len(values), *shape), dtype)
    for i, v in enumerate(values):
        out[i] = (np.nan if dtype == np.float64 else False) if v is None else v
    return out


def test_records_to_log_columns_match_row_by_row():
    rng = np.random.default_rng(2)
    recs = []
    for k in range(60):
        data = {"velocity": tuple(rng.normal(size=3)), "valid": bool(k % 3),
                "covariance": rng.normal(size=(3, 3)), "beam_range": rng.normal(size=4),
                "beam_valid": rng.random(4) < 0.5, "fom": float(rng.random())}  # fmt: skip
        if k % 7 == 0:
            del data["fom"]  # a missing field: NaN in that row
        if k % 11 == 0:
            data["beam_range"] = list(data["beam_range"])  # any sequence of numbers
        recs.append(Record("dvl", float(k) * 0.1, data))
    log = records_to_log(recs)
    shapes = {"velocity": ((3,), np.float64), "valid": ((), np.bool_), "fom": ((), np.float64),
              "covariance": ((3, 3), np.float64), "beam_range": ((4,), np.float64),
              "beam_valid": ((4,), np.bool_)}  # fmt: skip
    for key, (shape, dtype) in shapes.items():
        ref = _reference_column(recs, key, shape, dtype)
        got = getattr(log.dvl, key)
        assert got.dtype == ref.dtype and np.array_equal(got, ref, equal_nan=True), key
    imu = [Record("imu", 0.01 * k, {"angular_velocity": (1.0, 2.0, float(k))}) for k in range(5)]
    assert records_to_log(imu).imu.linear_acceleration is None
    assert set(RECORD_FIELDS["dvl"]) >= set(shapes)


def test_records_to_log_streams_are_the_checked_constructors_streams():
    """records_to_log builds its streams without the constructors' checks and copies: every
    field equal (dtype, shape, values) to the stream the checked constructor makes of the same
    columns, read-only as those are; a non-finite time is still the one-line error."""
    recs = list(_sim_records(2.0)[0])
    recs += [Record("sonar", 0.05 * k, {"range": 2.0 + 0.01 * k, "confidence": 0.9,
                                        "max_range": 30.0}) for k in range(20)]  # fmt: skip
    log = records_to_log(recs)
    for name, stream in log.streams().items():
        fields = {f.name: getattr(stream, f.name) for f in dataclasses.fields(stream)}
        checked = type(stream)(**fields)
        for key, value in fields.items():
            ref = getattr(checked, key)
            if isinstance(ref, np.ndarray):
                assert value.dtype == ref.dtype and value.shape == ref.shape, (name, key)
                assert np.array_equal(value, ref, equal_nan=True), (name, key)
                assert not value.flags.writeable, (name, key)
            else:
                assert value == ref, (name, key)
    assert log.sonar.max_range == 30.0 and len(log.sonar) == 20
    with pytest.raises(DataError, match=r"^imu\.t: non-finite timestamps$"):
        records_to_log([*recs[:3], Record("imu", math.nan, {"angular_velocity": (0.0,) * 3})])


def _sim_records(span_s: float):
    log = simulate(load_scenario("calm"), seed=3).log
    recs = []
    for name in ("imu", "dvl", "dead_reckoning", "pressure"):
        s = getattr(log, name)
        fields = {f: getattr(s, f) for f in RECORD_FIELDS[name] if getattr(s, f, None) is not None}
        recs += [Record(name, float(s.t[i]), {f: v[i] for f, v in fields.items()})
                 for i in range(len(s)) if s.t[i] < span_s]  # fmt: skip
    recs.sort(key=lambda r: r.t)
    return recs, log.mounting


def test_appended_messages_are_the_file_rosbags_writes(tmp_path):
    """The recorder's MessageAppender against rosbags' own Writer.write: the same records
    (every stream, a late one, estimates; enough bytes for rosbags to close chunks of 1 MiB by
    itself) give the same .mcap and metadata.yaml, byte for byte."""
    recs, mounting = _sim_records(math.inf)
    recs.append(Record("sonar", recs[-1].t + 0.01, {"range": 2.5, "confidence": 90.0}))
    x, P = np.arange(18.0), np.eye(18)
    bags = {}
    for fast in (True, False):
        rec = Recorder(tmp_path / f"bag_{fast}" / "rec", mounting, flush_every_s=1e9)
        assert rec._append.__self__.fast  # rosbags' MCAP storage: the fast path applies
        rec._append.__self__.fast = fast
        for i, record in enumerate(recs):
            rec.write_record(record)
            if i % 50 == 0:
                rec.write_pose(record.t, x, P)
        rec.write_late(recs[3])
        chunks = len(rec._writer.storage.chunks)
        bags[fast] = rec.close()
    assert chunks >= 1  # one closed by size during the writes (the last one by close)
    for name in ("rec.mcap", "metadata.yaml"):
        assert (bags[True] / name).read_bytes() == (bags[False] / name).read_bytes(), name
    assert read_log(bags[True]).imu is not None


def test_a_resumed_preview_is_the_fresh_preview():
    """Chunks released behind a horizon 0.25 s back, a preview every 0.125 s: advancing the
    last preview by the new records gives bit for bit the committed filter run over the whole
    buffer (no depth is rejected in this run, so the depth-rate check agrees)."""
    recs, mounting = _sim_records(12.0)
    t = np.array([r.t for r in recs])
    kw = dict(wave=(0.1, 1.0), mounting=mounting, expected={"imu", "dvl", "pressure"})
    fresh, resumed = OnlineLocalizer("proposed", **kw), OnlineLocalizer("proposed", **kw)
    released = seen = compared = 0
    started = False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for now in np.arange(0.125, t[-1], 0.125):
            i = int(np.searchsorted(t, now - 0.25))
            if i > released:
                for online in (fresh, resumed):
                    online.push(records_to_log(recs[released:i]))
                released = i
            j = int(np.searchsorted(t, now))
            new, seen = recs[seen:j], j
            if not fresh.ready or j == released:
                continue
            a = fresh.peek(records_to_log(recs[released:j]))
            b = resumed.peek(records_to_log(recs[released:j] if not started else new),
                             resume=started)  # fmt: skip
            started = True
            if a is None or b is None:
                continue
            assert a.t[-1] == b.t[-1]
            assert np.array_equal(a.x[-1], b.x[-1]) and np.array_equal(a.P[-1], b.P[-1])
            compared += 1
    assert compared > 50


@pytest.mark.parametrize(("commit_every", "taken_at_least"), [(0.5, 0.8), (0.1, 0.3)])
def test_a_preview_from_a_checkpoint_is_the_fresh_preview(commit_every, taken_at_least):
    """DVL reports arrive 30 ms after their time (the A50 stamps the time of validity) and
    dead-reckoning reports 150 ms after (later than the preview before them), IMU and pressure
    on time; a preview at every DVL arrival continues from the newest checkpoint the arrivals
    left valid (PreviewCheckpoints) over the buffered records after it, and gives bit for bit
    the committed filter run over the whole buffer. The commits release up to a preview's end
    behind the horizon, as the pipeline's, and take the previews' states: the committed
    trajectory is bit for bit the one without previews taken. Most previews continue, and the
    late reports invalidate some checkpoints. With commits every 0.5 s (the pipeline's default)
    most rows are taken from previews; every 0.1 s (shorter than the buffer: a late report
    often leaves no preview to commit up to) fewer."""
    from undertow.live.preview import PreviewCheckpoints

    recs, mounting = _sim_records(12.0)
    lag = {"dvl": 0.03, "dead_reckoning": 0.15}
    arrival = np.array([r.t + lag.get(r.stream, 0.0) for r in recs])
    order = np.argsort(arrival, kind="stable")
    kw = dict(wave=(0.1, 1.0), mounting=mounting, expected={"imu", "dvl", "pressure"})
    fresh, cont = OnlineLocalizer("proposed", **kw), OnlineLocalizer("proposed", **kw)
    plain = OnlineLocalizer("proposed", **kw)  # pushed the same chunks, never peeked
    checkpoints = PreviewCheckpoints()
    buffered: list = []
    horizon, next_commit = -math.inf, -math.inf
    compared, continued, dropped = 0, 0, 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for k in order:
            record, now = recs[k], arrival[k]
            boundary = checkpoints.boundary(now - 0.25)
            wait = boundary is None and checkpoints.start() is not None  # (as the pipeline)
            if now - 0.25 >= next_commit and not wait:  # 0.25 s behind
                next_commit = now - 0.25 + commit_every
                h = now - 0.25 if boundary is None else math.nextafter(boundary, math.inf)
                horizon = max(horizon, h)
                out = [r for r in buffered if r.t < horizon]
                buffered = [r for r in buffered if r.t >= horizon]
                if out:
                    out.sort(key=lambda r: r.t)
                    for online in (fresh, cont, plain):
                        online.push(records_to_log(out))
                checkpoints.released(horizon, continued=cont.at_preview)
            kept = len(checkpoints._kept)
            checkpoints.arrived(record.t)
            dropped += kept - len(checkpoints._kept)
            assert record.t >= horizon  # (no record is late here)
            buffered.append(record)
            if record.stream != "dvl" or not fresh.ready:
                continue
            pending = sorted(buffered, key=lambda r: r.t)
            start = checkpoints.start()
            after = -math.inf if start is None else start[0]
            mine = [r for r in pending if r.t > after]
            a = fresh.peek(records_to_log(pending))
            b = cont.peek(records_to_log(mine), start=None if start is None else start[1])
            checkpoints.reached(mine[-1].t, cont.preview_state, fresh=start is None)
            continued += start is not None
            if a is None or b is None:
                continue
            assert a.t[-1] == b.t[-1]
            assert np.array_equal(a.x[-1], b.x[-1]) and np.array_equal(a.P[-1], b.P[-1])
            compared += 1
        for online in (fresh, cont, plain):
            online.push(records_to_log(sorted(buffered, key=lambda r: r.t)))
    assert compared > 50 and continued > 20 and dropped > 0
    ref, got = plain.trajectory(), cont.trajectory()
    assert np.array_equal(got.t, ref.t) and np.array_equal(got.x, ref.x)
    assert np.array_equal(got.P, ref.P) and got.metadata["counts"] == ref.metadata["counts"]
    assert ref.metadata["online"]["rows_from_previews"] == 0
    taken = got.metadata["online"]["rows_from_previews"]
    assert taken > taken_at_least * sum(v["total"] for v in got.metadata["sensors"].values())


def test_preview_checkpoints_rules():
    from undertow.live.preview import PreviewCheckpoints

    c = PreviewCheckpoints()
    assert c.start() is None and c.boundary(100.0) is None
    c.reached(10.0, "s10", fresh=True)
    c.reached(10.2, "s10.2", fresh=False)
    c.reached(10.4, "s10.4", fresh=False)
    assert c.start() == (10.4, "s10.4")
    assert c.boundary(10.4) == 10.2 and c.boundary(10.41) == 10.4 and c.boundary(10.0) is None
    c.arrived(10.3)  # a record at 10.3 arrived after the previews that reached 10.4
    assert c.start() == (10.2, "s10.2")
    c.arrived(10.2)  # at the time reached: not taken by that preview either
    assert c.start() == (10.0, "s10")
    c.reached(10.5, "s10.5", fresh=False)
    c.released(10.3, continued=True)  # records before 10.3 left: 10.0 cannot be continued
    assert c.start() == (10.5, "s10.5")
    c.reached(11.2, "s11.2", fresh=False)
    c.released(10.6, continued=False)  # the committed state is no preview's: start afresh
    assert c.start() is None
    c.reached(11.3, "s11.3", fresh=False)
    c.reached(11.4, "s11.4", fresh=True)  # a fresh preview: those before cannot lead to it
    assert c.start() == (11.4, "s11.4") and len(c._kept) == 1


def test_latency_counts_from_the_links_receipt():
    """A DVL report's latency starts when the link's thread received it (its arrival on the
    session's clock, scaled by the replay rate), not when the loop decoded it; without an
    arrival (or a clock ahead of the queueing) it starts when it was queued."""
    import time

    from undertow._util.clocks import ScaledClock
    from undertow.live.pipeline import received_at

    for scale in (1.0, 20.0):
        clock = ScaledClock(scale)
        arrival = clock() - scale * 0.030  # received 30 ms (wall) ago
        queued = time.perf_counter()
        got = received_at(clock, arrival, queued)
        assert abs((queued - got) - 0.030) < 0.005
    assert received_at(clock, math.nan, queued) == queued
    assert received_at(clock, clock() + 10.0, queued) == queued  # an arrival in the future


def test_a_commit_waits_for_a_preview_at_most_max_wait():
    """A preview that reached a time far ahead (a record stamped ahead of the others) must not
    hold the commits back for ever: the buffer, and the session's memory, would grow. The wait
    counts from the first commit that waited, not from the last release (commits come every
    commit_every_s, longer than the buffer: counted from the release, every wait would end at
    once)."""
    from undertow.live.preview import PreviewCheckpoints

    c = PreviewCheckpoints()
    assert c.commit_to(10.0, 2.0) == (10.0, False)  # none kept: up to the horizon
    c.reached(9.7, "s9.7", fresh=True)
    at, forced = c.commit_to(10.0, 2.0)
    assert at == math.nextafter(9.7, math.inf) and not forced  # to the preview's end
    c.released(at, continued=True)
    c.reached(500.0, "far", fresh=False)  # far ahead of every horizon to come
    assert c.commit_to(10.5, 2.0) == (None, False)  # waits, from 10.5 on
    assert c.commit_to(12.5, 2.0) == (None, False)  # 2 s: still waits
    assert c.commit_to(12.51, 2.0) == (12.51, True)  # then commits without it
    assert c.start() is None  # and the next preview starts afresh
    c.reached(13.0, "s13", fresh=True)
    assert c.commit_to(12.9, 2.0) == (None, False)  # a new wait starts afresh
    assert c.commit_to(13.5, 2.0) == (math.nextafter(13.0, math.inf), False)  # ends it
    c.released(math.nextafter(13.0, math.inf), continued=True)
    c.reached(600.0, "far", fresh=False)
    assert c.commit_to(14.0, 2.0) == (None, False)  # counted from 14.0, not from 12.9
    assert c.commit_to(15.9, 2.0) == (None, False)
