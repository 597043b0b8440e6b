"""The peers table (undertow.study.peers, peer_claims, peer_tables): common evaluation times,
the paired verdicts, a missing gtsam and the time cap as one line each, and one short run of
every estimator (slow)."""

import math
import types

import numpy as np
import pytest
from scipy import stats

from undertow.log import Log
from undertow.study import peers
from undertow.study.peer_claims import verdict
from undertow.study.peer_tables import build_peers, peers_markdown
from undertow.study.report import peer_figures, peer_notes
from undertow.trajectory import Trajectory


def _traj(t):
    n = len(t)
    x = np.arange(n * 18.0).reshape(n, 18)
    return Trajectory(np.asarray(t, float), x, np.zeros((n, 18, 18)))


def test_at_times_takes_the_last_row_at_each_time_and_drops_times_without_one():
    traj = _traj([0.0, 0.5, 1.0, 1.0, 1.5, 2.0])
    sub = peers.at_times(traj, np.array([1.0, 1.25, 2.0]))
    assert sub.t.tolist() == [1.0, 2.0]
    assert sub.x[0, 0] == traj.x[3, 0]  # the second row at t = 1.0 (after its update)


def _result(seed, ukf, peer, metric="horizontal_rmse_m"):
    est = {"proposed": {metric: ukf}, "isam2": {metric: peer}}
    return {"seed": seed, "peers": {"s": {"duration_s": 10.0, "estimators": est}}}


def test_verdict_is_the_paired_students_t_interval_of_the_difference():
    ukf = [1.0, 1.1, 0.9, 1.05, 0.95]
    d = [0.20, 0.25, 0.15, 0.22, 0.18]  # the peer is worse in every seed
    results = [_result(i, u, u + x) for i, (u, x) in enumerate(zip(ukf, d, strict=True))]
    v = verdict(results, "s", "proposed", "isam2", "horizontal_rmse_m")
    half = stats.t.ppf(0.975, 4) * np.std(d, ddof=1) / math.sqrt(5)
    assert v.difference["ci95_low"] == pytest.approx(np.mean(d) - half)
    assert (v.verdict, v.holds, v.n) == ("undertow ahead", 5, 5)
    mixed = [_result(i, 1.0, 1.0 + x) for i, x in enumerate([0.1, -0.1, 0.05, -0.05])]
    assert verdict(mixed, "s", "proposed", "isam2", "horizontal_rmse_m").verdict.startswith("tie")
    worse = [_result(i, 1.0 + x, 1.0) for i, x in enumerate([0.3, 0.2, 0.25])]
    assert verdict(worse, "s", "proposed", "isam2", "horizontal_rmse_m").verdict == "peer ahead"


def test_a_missing_gtsam_is_one_line_of_the_table(monkeypatch):
    monkeypatch.setattr(peers, "gtsam_available", lambda: False)
    settings = peers.PeerSettings()
    status = {e: peers.run_one(e, None, settings)[1] for e in peers.GTSAM_PEERS}
    assert all("gtsam is not installed" in s["status"] for s in status.values())
    ran = {"rmse": {a: 0.1 for a in ("x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "yaw_rad",
                                     "vx_m_s", "vy_m_s", "vz_m_s")},
           "horizontal_rmse_m": 0.14, "nees_mean": 6.0, "cpu_s_per_hour": 1.0}  # fmt: skip
    result = {"seed": 0, "peers": {"s": {"duration_s": 10.0,
                                         "estimators": {"proposed": ran, **status}}}}  # fmt: skip
    text = peers_markdown(build_peers([result]), "s")
    lines = [ln for ln in text.splitlines() if "gtsam" in ln]
    assert len(lines) == 1 and "factor-graph, isam2" in lines[0]


def test_the_time_cap_stops_the_child_interpreter(monkeypatch):
    monkeypatch.setattr(peers, "CHILD_START_S", 0.0)
    run = peers.PeerRun("empty", Log(), {}, 1.0)
    with pytest.raises(peers.CapExceeded, match="time cap"):
        peers.run_capped("factor-graph", run, 0.01)  # killed long before its imports end
    _, record = peers.run_one("factor-graph", run, peers.PeerSettings(time_cap_s={
        "factor-graph": 0.0}))  # fmt: skip
    assert record == {"status": "skipped (time cap 0 s)"}


@pytest.mark.slow
def test_every_estimator_on_a_short_run(simulation, tmp_path):
    sim = simulation("wave-a0.10-f1.00", 0)
    short = types.SimpleNamespace(log=peers.log_head(sim.log, 12.0))
    art = types.SimpleNamespace(simulations={"wave-a0.10-f1.00": short}, peers={})
    study = {"waves": {"wave-a0.10-f1.00": (0.1, 1.0)}, "profile": None, "calibration": None}
    settings = peers.PeerSettings(scenarios=("wave-a0.10-f1.00",))
    out = peers.run_peers(0, settings, study, art)["wave-a0.10-f1.00"]["estimators"]
    expected = set(peers.ESTIMATORS) if peers.gtsam_available() else (
        set(peers.ESTIMATORS) - set(peers.GTSAM_PEERS))  # fmt: skip
    ran = {e for e, m in out.items() if "status" not in m}
    assert ran == expected
    # every estimator is evaluated at the same instants: the valid DVL reports
    assert len({out[e]["samples"] for e in ran}) == 1
    gt = short.log.ground_truth
    t_last = peers.dvl_times(short.log)[-1]
    for e in ran:  # the final drift, from the trajectory and the ground truth directly
        traj = peers.at_times(art.peers[("wave-a0.10-f1.00", e)], np.array([t_last]))
        truth = [np.interp(t_last, gt.t, gt.position[:, i]) for i in (0, 1)]
        drift = math.hypot(traj.x[0, 0] - truth[0], traj.x[0, 1] - truth[1])
        assert out[e]["final_drift_m"] == pytest.approx(drift, rel=1e-6, abs=1e-9)
    tables = build_peers([{"seed": 0, "peers": {"wave-a0.10-f1.00": {
        "duration_s": 12.0, "estimators": out}}}])  # fmt: skip
    text = peers_markdown(tables, "wave-a0.10-f1.00")
    assert "InEKF" in text and "(1 seed, no interval)" in text
    # the report: one figure of every estimator together, one note per comparison
    figures = peer_figures(tmp_path, art)
    assert [p.name for _, p in figures] == ["peers_wave-a0.10-f1.00.png"]
    assert figures[0][1].read_bytes()[:4] == b"\x89PNG"
    assert len(peer_notes(tables)) == (3 if peers.gtsam_available() else 1)
