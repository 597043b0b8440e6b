"""Online filter and mapper (issue 12): a log pushed in chunks gives the offline results.

The reference is the offline path on the whole log (Localizer.run, map_log), an independent
run of the same model: the online one feeds the numba loop piece by piece from a saved state,
builds rows per chunk and judges depths incrementally."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from scipy.spatial import cKDTree

from undertow.errors import ConfigError
from undertow.estimation import Localizer
from undertow.estimation.online import OnlineLocalizer
from undertow.log import G0
from undertow.mapping.config import MappingConfig
from undertow.mapping.online import OnlineMapper
from undertow.mapping.run import map_log
from undertow.mapping.samples import samples_from_config
from undertow.records import RECORD_FIELDS, Record, records_to_log
from undertow.sim import load_scenario, simulate
from undertow.wavetrack import WaveTrack

WAVE = (0.1, 1.0)
# the start waits for these, so that x0 (first DR attitude, first depth) is the offline one
EXPECTED = {"imu", "dvl", "dead_reckoning", "pressure"}
U32 = 2.0**-24  # unit roundoff of the float32 evidence sums (mapping.grid)


def _records(log) -> list[Record]:
    recs = []
    for name, fields in RECORD_FIELDS.items():
        stream = getattr(log, name)
        if stream is None:
            continue
        columns = {f: getattr(stream, f) for f in fields if getattr(stream, f, None) is not None}
        for i in range(len(stream)):
            recs.append(Record(name, float(stream.t[i]), {f: v[i] for f, v in columns.items()}))
    recs.sort(key=lambda r: r.t)  # time order, as the pipeline releases them
    return recs


@pytest.fixture(scope="module")
def session():
    """A 48.6 s simulated run (IMU 100 Hz, DVL, DR, pressure 10 Hz, sonar: many equal times
    across streams) whose pressure has a spike at 10 s and a 6 m plateau from 20 to 25 s: the
    depth-rate check rejects them, and its verdict on a depth changes as later depths arrive
    (the online filter must then rewind)."""
    log = simulate(load_scenario("calm"), seed=11).log
    p = log.pressure
    rho = log.metadata.get("water_density_kg_m3", 997.0)
    pressure = np.array(p.pressure)
    pressure[np.argmin(np.abs(p.t - 10.0))] += 6.0 * rho * G0
    pressure[(p.t >= 20.0) & (p.t < 25.0)] += 6.0 * rho * G0
    log = log.replace(pressure=dataclasses.replace(p, pressure=pressure))
    return _records(log), log.mounting


def _whole(recs, mounting):
    return records_to_log(recs).replace(mounting=mounting)


def _push_all(online: OnlineLocalizer, recs, cuts):
    """Push the chunks between ``cuts``; the states returned, revisions applied."""
    t, x, P, revised = [], [], [], 0
    k = 0
    for c in [*cuts, len(recs)]:
        out = online.push(records_to_log(recs[k:c]))
        k = c
        if online.revised:
            revised += online.revised
            del t[-online.revised :], x[-online.revised :], P[-online.revised :]
        if out is not None:
            t.extend(out.t), x.extend(out.x), P.extend(out.P)
    return np.array(t), np.array(x), np.array(P), revised


def _assert_same(traj, ref):
    assert np.array_equal(traj.t, ref.t)
    assert np.array_equal(traj.x, ref.x)
    assert np.array_equal(traj.P, ref.P)
    assert traj.metadata["counts"] == ref.metadata["counts"]


def _cuts(recs, how: str, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if how == "equal-times":  # every chunk boundary between two records of the same time
        t = np.array([r.t for r in recs])
        same = np.flatnonzero(t[1:] == t[:-1]) + 1
        return np.sort(rng.choice(same, size=300, replace=False))
    return np.sort(rng.choice(np.arange(1, len(recs)), size=int(how), replace=False))


@pytest.mark.parametrize("variant", ["proposed", "baseline", "adaptive-r"])
@pytest.mark.parametrize(("how", "seed"), [("1500", 0), ("40", 1), ("equal-times", 2)])
def test_chunked_filter_is_bit_identical(session, variant, how, seed):
    recs, mounting = session
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ref = Localizer(variant, wave=WAVE).run(_whole(recs, mounting))
        online = OnlineLocalizer(variant, wave=WAVE, mounting=mounting, expected=EXPECTED)
        t, x, P, revised = _push_all(online, recs, _cuts(recs, how, seed))
    traj = online.trajectory()
    _assert_same(traj, ref)
    assert traj.metadata["sensors"] == ref.metadata["sensors"]
    assert traj.metadata["nis"] == ref.metadata["nis"]
    assert ref.metadata["counts"]["rejected_pressure_rate"] > 0  # the spike and the plateau
    # what push returned, later revisions applied, is the trajectory
    assert np.array_equal(t, ref.t) and np.array_equal(x, ref.x) and np.array_equal(P, ref.P)
    if how == "1500":
        assert revised > 0  # a depth's verdict changed after its state was returned
    assert traj.metadata["online"]["final_states"] <= len(traj)
    if variant == "adaptive-r":
        assert traj.metadata["adaptive_r"] == ref.metadata["adaptive_r"]


def test_outputs_in_blocks_are_one_array(monkeypatch):
    """The online filter's states are stored in blocks: appends in any pieces, across block
    boundaries, with rewinds (n set back), read back as one array would hold them."""
    from undertow.estimation.online_run import OutputBlocks

    monkeypatch.setattr(OutputBlocks, "BLOCK", 7)
    rng = np.random.default_rng(4)
    out, ref = OutputBlocks(), np.zeros((0, 1 + 18 + 18 * 18))
    for _ in range(60):
        if rng.random() < 0.2 and out.n:  # a rewind
            out.n = int(rng.integers(0, out.n + 1))
            ref = ref[: out.n]
        k = int(rng.integers(0, 12))
        rows = rng.normal(size=(k, ref.shape[1]))
        out.append(rows[:, 0], rows[:, 1:19], rows[:, 19:].reshape(k, 18, 18))
        ref = np.concatenate([ref, rows])
        n0 = int(rng.integers(0, out.n + 1))
        t, x, P = out.view(n0, out.n)
        got = np.concatenate([t[:, None], x, P.reshape(-1, 18 * 18)], axis=1)
        assert np.array_equal(got, ref[n0:])
    t, x, _ = out.view(out.n - 2, out.n)  # within a block: views of the storage
    if (out.n - 2) // 7 == (out.n - 1) // 7:
        assert t.base is not None and x.base is not None


def test_committed_since_is_the_tail_of_the_trajectory(session):
    recs, mounting = session
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        online = OnlineLocalizer("proposed", wave=WAVE, mounting=mounting, expected=EXPECTED)
        _push_all(online, recs, _cuts(recs, "40", 0))
    whole = online.trajectory()
    for since in (0, 1, 2047, 2048, 2049, len(whole) - 1, len(whole), len(whole) + 5):
        tail = online.committed(since)
        first = min(since, len(whole))
        assert tail.metadata["online"]["first_state"] == first
        assert tail.metadata["online"]["final_states"] == whole.metadata["online"]["final_states"]
        assert np.array_equal(tail.t, whole.t[first:]) and np.array_equal(tail.P, whole.P[first:])


def test_one_record_chunks(session):
    recs, mounting = session
    part = [r for r in recs if r.t < 12.0]  # through the spike at 10 s
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ref = Localizer("proposed", wave=WAVE).run(_whole(part, mounting))
        online = OnlineLocalizer("proposed", wave=WAVE, mounting=mounting, expected=EXPECTED)
        _push_all(online, part, np.arange(1, len(part)))
    _assert_same(online.trajectory(), ref)


def test_waits_for_the_expected_streams(session):
    recs, mounting = session
    late = [r for r in recs if r.stream != "pressure" or r.t >= 2.0]  # the barometer from 2 s
    online = OnlineLocalizer("proposed", wave=WAVE, mounting=mounting, expected=EXPECTED)
    first_p = next(i for i, r in enumerate(late) if r.stream == "pressure")
    assert online.push(records_to_log(late[:first_p])) is None
    assert not online.ready
    assert [m.split(":")[0] for m in online.missing] == ["pressure"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out = online.push(records_to_log(late[first_p : first_p + 1]))
        assert online.ready and online.missing == []
        assert out is not None and out.t[0] == late[0].t  # everything released so far
        _push_all(online, late[first_p + 1 :], [])
        ref = Localizer("proposed", wave=WAVE).run(_whole(late, mounting))
    _assert_same(online.trajectory(), ref)


def test_starts_after_the_timeout_without_an_expected_stream(session):
    recs, mounting = session
    no_p = [r for r in recs if r.stream != "pressure"]
    online = OnlineLocalizer("be", mounting=mounting, expected={"pressure"}, start_timeout_s=3.0)
    cut = next(i for i, r in enumerate(no_p) if r.t >= 3.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        assert online.push(records_to_log(no_p[: cut - 1])) is None
        assert online.missing == ["pressure: expected, no data yet"]
        assert online.push(records_to_log(no_p[cut - 1 : cut + 1])) is not None
        assert online.trajectory().metadata["online"]["started_without"] == ["pressure"]
        _push_all(online, no_p[cut + 1 :], np.arange(100, len(no_p) - cut - 1, 100))
        ref = Localizer("be").run(_whole(no_p, mounting))
    _assert_same(online.trajectory(), ref)


def test_never_starts_without_an_orientation_source(session):
    recs, mounting = session
    dvl_only = [r for r in recs if r.stream == "dvl"]
    online = OnlineLocalizer("proposed", mounting=mounting, start_timeout_s=1.0)
    assert online.push(records_to_log(dvl_only)) is None
    assert not online.ready and len(online.missing) == 1
    assert online.missing[0].startswith("orientation")


def test_set_wave_applies_to_later_rows(session):
    """A step of the wave condition between two rows it adds noise to (DVL, DR, barometer) is
    exactly a two-node WaveTrack (interpolation returns the node value at and beyond a node). A
    preview made before the step (its DVL rows with the old noise) is not taken by the push
    after it."""
    recs, mounting = session
    k = next(i for i, r in enumerate(recs) if r.t >= 30.0)
    noisy = [r.t for r in recs if r.stream in ("dvl", "dead_reckoning", "pressure")]
    before = max(t for t in noisy if t < recs[k].t)
    after = min(t for t in noisy if t >= recs[k].t)
    track = WaveTrack(t=np.array([before, after]), amplitude_m=np.array([0.1, 0.05]),
                      frequency_hz=np.array([1.0, 0.75]))  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ref = Localizer("proposed", wave=track).run(_whole(recs, mounting))
        online = OnlineLocalizer("proposed", wave=(0.1, 1.0), mounting=mounting, expected=EXPECTED)
        _push_all(online, recs[:k], np.arange(50, k, 50))
        assert any(r.stream == "dvl" for r in recs[k : k + 50])
        online.peek(records_to_log(recs[k : k + 50]))  # the old noise: not to be taken
        online.set_wave("wave-a0.05-f0.75")
        _push_all(online, recs[k:], np.arange(50, len(recs) - k, 50))
        constant = Localizer("proposed", wave=WAVE).run(_whole(recs, mounting))
    traj = online.trajectory()
    _assert_same(traj, ref)
    assert traj.metadata["online"]["wave_changes"][0]["amplitude_m"] == 0.05
    assert not np.array_equal(traj.x, constant.x)  # the step matters


def _evidence_counts(samples, cells, resolution, method, config) -> np.ndarray:
    """Upper bound on the samples adding mass to each cell: those within the kernel's support
    (BKI: distance < length_scale; adaptive: |d_j| < l_max_j per axis)."""
    centres = (cells + 0.5) * resolution
    if method == "bki":
        tree = cKDTree(samples.points)
        return tree.query_ball_point(centres, config.length_scale, return_length=True)
    scale = np.asarray(config.l_max, float)
    tree = cKDTree(samples.points / scale)
    return tree.query_ball_point(centres / scale, 1.0, p=np.inf, return_length=True)


def _sorted(occupancy):
    order = np.lexsort(occupancy.cells.T[::-1])
    return occupancy.cells[order], occupancy.alpha[order], occupancy.beta[order]


@pytest.mark.parametrize("method", ["csm", "bki", "adaptive"])
def test_online_map_equals_the_offline_map(session, method):
    recs, mounting = session
    bounds = ((0.0, 0.0, 0.0), (0.01, 0.01, 0.01)) if method == "adaptive" else None
    config = MappingConfig(method=method, variance_bounds=bounds)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        whole = _whole(recs, mounting)
        online = OnlineLocalizer("proposed", wave=WAVE, mounting=mounting, expected=EXPECTED)
        mapper = OnlineMapper(config, mounting=mounting)
        cuts = _cuts(recs, "300", 3)
        integrated, k, held = 0, 0, []
        for c in [*cuts, len(recs)]:
            chunk = records_to_log(recs[k:c])
            k = c
            online.push(chunk)
            integrated += mapper.push(chunk, online.trajectory())
            held.append(mapper.poses.held)
        final = online.trajectory()
        assert integrated > 0  # the map grows during the run
        # the map keeps a window of states, not the run's (and the map is the same)
        assert mapper.poses.base > 0 and max(held) < 0.5 * len(final)
        integrated += mapper.finish(final)
        offline = map_log(whole, final, config)
    cells, alpha, beta = _sorted(mapper.occupancy())
    cells_ref, alpha_ref, beta_ref = _sorted(offline.map)
    assert np.array_equal(cells, cells_ref)
    meta = mapper.metadata()
    assert meta["samples"] == offline.metadata["samples"]
    assert integrated == meta["ranges_integrated"] and meta["ranges_waiting"] == 0
    if method == "csm":  # unit counts: any order of the sums is exact
        assert np.array_equal(alpha, alpha_ref) and np.array_equal(beta, beta_ref)
        return
    # the same kernel terms summed in another order into float32 (mapping.grid): a sum of n
    # positive terms differs between two orders by at most 2 (n - 1) u times the sum
    samples = samples_from_config(whole, final, config)
    n = _evidence_counts(samples, cells, config.resolution, method, config)
    for got, ref, prior in ((alpha, alpha_ref, config.alpha0), (beta, beta_ref, config.beta0)):
        bound = 2.0 * np.maximum(n - 1, 0) * U32 * (ref - prior) * (1 + 1e-6) + 4e-16 * ref
        assert np.all(np.abs(got - ref) <= bound)


def test_refusals_are_one_line(session):
    _, mounting = session
    for make in (
        lambda: OnlineLocalizer("proposed", wave="auto"),
        lambda: OnlineLocalizer("proposed", output_rate_hz=10.0),
        lambda: OnlineLocalizer("proposed", expected={"sonar", "laser"}),
        lambda: OnlineMapper(MappingConfig(method="adaptive")),
    ):
        with pytest.raises(ConfigError) as info:
            make()
        assert "\n" not in str(info.value)


def test_depth_rate_median_is_numpys_nanmedian():
    """The depth-rate check's window median (health._window_median, fast enough to run per
    chunk) equals numpy.nanmedian on windows padded with NaN, ties and even counts included."""
    from undertow.estimation.health import _window_median

    rng = np.random.default_rng(5)
    for trial in range(300):
        d = rng.normal(0.0, [1e-3, 1.0, 100.0][trial % 3], int(rng.integers(3, 30)))
        if trial % 2:
            d = np.round(d, 1) + 1e3  # ties
        pad = np.concatenate([np.full(5, np.nan), d, np.full(5, np.nan)])
        windows = np.lib.stride_tricks.sliding_window_view(pad, 11)
        assert np.array_equal(_window_median(windows), np.nanmedian(windows, axis=1))


def test_peek_previews_a_push_without_changing_the_filter(session):
    """peek(chunk) gives the states push(chunk) then gives (when push revises nothing), and
    leaves the filter as it was: the run with peeks is still the offline one."""
    recs, mounting = session
    t = np.array([r.t for r in recs])
    cuts = np.searchsorted(t, np.arange(0.25, t[-1], 0.25))  # chunks split between times
    online = OnlineLocalizer("proposed", wave=WAVE, mounting=mounting, expected=EXPECTED)
    compared = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        k = 0
        for c in [*cuts, len(recs)]:
            chunk = records_to_log(recs[k:c])
            k = c
            preview = online.peek(chunk)
            out = online.push(chunk)
            if preview is not None and online.revised == 0:
                assert np.array_equal(preview.t, out.t) and np.array_equal(preview.x, out.x)
                assert np.array_equal(preview.P, out.P)
                compared += 1
            assert online.latest().t[0] == online.trajectory().t[-1]
        ref = Localizer("proposed", wave=WAVE).run(_whole(recs, mounting))
    assert compared > 100
    _assert_same(online.trajectory(), ref)


@pytest.mark.parametrize("variant", ["proposed", "adaptive-r"])
def test_pushes_that_take_the_previews_states_are_the_offline_run(session, variant):
    """The live pipeline's protocol: a preview at every DVL record, continued from the last
    (PreviewCheckpoints), commits every 0.5 s up to the latest preview's end 0.25 s behind. The
    pushes take most rows' states from the previews; with the depth spike and plateau (the
    previews judge those depths on fewer neighbours, and the pushes revise states after a
    verdict changes, rewinding to a checkpoint before a preview taken) the trajectory is still
    bit for bit the offline one."""
    import math

    from undertow.live.preview import PreviewCheckpoints

    recs, mounting = session
    online = OnlineLocalizer(variant, wave=WAVE, mounting=mounting, expected=EXPECTED)
    checkpoints = PreviewCheckpoints()
    buffered, horizon, next_commit, revised = [], -math.inf, -math.inf, 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for record in recs:
            now = record.t
            boundary = checkpoints.boundary(now - 0.25)
            if now - 0.25 >= next_commit and (boundary is not None or not checkpoints._kept):
                next_commit = now - 0.25 + 0.5
                h = now - 0.25 if boundary is None else math.nextafter(boundary, math.inf)
                horizon = max(horizon, h)
                out = [r for r in buffered if r.t < horizon]
                buffered = [r for r in buffered if r.t >= horizon]
                if out:
                    online.push(records_to_log(out))
                    revised += online.revised
                checkpoints.released(horizon, continued=online.at_preview)
            checkpoints.arrived(record.t)
            buffered.append(record)
            if record.stream != "dvl" or not online.ready:
                continue
            start = checkpoints.start()
            mine = [r for r in buffered if start is None or r.t > start[0]]
            if mine:
                online.peek(records_to_log(mine), start=None if start is None else start[1])
                checkpoints.reached(mine[-1].t, online.preview_state, fresh=start is None)
        online.push(records_to_log(buffered))
        ref = Localizer(variant, wave=WAVE).run(_whole(recs, mounting))
    traj = online.trajectory()
    _assert_same(traj, ref)
    assert traj.metadata["nis"] == ref.metadata["nis"]
    assert traj.metadata["sensors"] == ref.metadata["sensors"]
    if variant == "adaptive-r":
        assert traj.metadata["adaptive_r"] == ref.metadata["adaptive_r"]
    rows = sum(v["total"] for v in traj.metadata["sensors"].values())
    assert traj.metadata["online"]["rows_from_previews"] > 0.8 * rows
    assert revised > 0


def test_depth_rate_verdicts_are_those_of_the_whole_history():
    """DepthRateCheck (the online depth-rate check) against depth_jumps over every depth so far:
    depths added in random pieces (a spike, a plateau, noise), each piece first peeked (its
    verdicts as if the log ended with it), then added; the verdicts in use once everything is
    in, and every peek, are those of the whole history cut where it was."""
    from undertow.estimation.config import LocalizerConfig
    from undertow.estimation.health import depth_jumps
    from undertow.estimation.online_run import DepthRateCheck

    cfg = LocalizerConfig()
    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(0.05, 0.15, 400))
    d = 2.0 + 0.02 * rng.standard_normal(400)
    d[50] += 3.0
    d[200:204] += 4.0
    d[300:330] += 2.0
    rate = DepthRateCheck(cfg)
    k = 0
    for n in rng.integers(1, 9, 200):
        part = slice(k, min(k + int(n), t.size))
        whole = depth_jumps(t[: part.stop], d[: part.stop], cfg)
        assert np.array_equal(rate.peek(t[part], d[part]), whole[part])
        rate.add(t[part], d[part])
        rate.trim()
        k = part.stop
        if k == t.size:
            break
    whole = depth_jumps(t, d, cfg)
    assert whole.sum() > 3 and rate.rejected() == int(whole.sum())


def test_released_states_are_freed_and_the_rest_unchanged(session):
    """A consumer that takes the final states and releases them keeps a window: the states
    after the release are bit for bit those of a run that kept everything, and asking for a
    released one is refused."""
    recs, mounting = session
    cuts = [*_cuts(recs, "200", 5), len(recs)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ref = Localizer("proposed", wave=WAVE).run(_whole(recs, mounting))
        online = OnlineLocalizer("proposed", wave=WAVE, mounting=mounting, expected=EXPECTED)
        taken, t, x, P, k = 0, [], [], [], 0
        for c in cuts:
            online.push(records_to_log(recs[k:c]))
            k = c
            part = online.committed(taken)
            final = part.metadata["online"]["final_states"]
            t.append(part.t[: final - taken])
            x.append(part.x[: final - taken])
            P.append(part.P[: final - taken].copy())
            taken = final
            freed = online.release(taken)
        rest = online.trajectory(since=taken)
    assert 0 < freed <= taken
    got_t = np.concatenate([*t, rest.t])
    assert np.array_equal(got_t, ref.t)
    assert np.array_equal(np.concatenate([*x, rest.x]), ref.x)
    assert np.array_equal(np.concatenate([*P, rest.P]), ref.P)
    with pytest.raises(ValueError, match="released"):
        online.committed(0)
