"""Drift against a reference without ground truth (undertow.evaluation.drift): closed forms on
synthetic straight runs (a linear drift injected into the reference is recovered exactly, its
along/cross split, a known rotation removed by the yaw alignment), sparse GPS fixes, and the
command on a simulated run with the DVL's own dead reckoning."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
from typer.testing import CliRunner

from undertow.errors import ConfigError, DataError, MissingStreamError
from undertow.evaluation.drift import (
    ReferenceTrack,
    least_squares_yaw,
    reference_track,
    trajectory_drift,
)
from undertow.log import Dvl, GpsFix, Log
from undertow.trajectory import Trajectory

runner = CliRunner()


def _trajectory(t: np.ndarray, position: np.ndarray) -> Trajectory:
    x = np.zeros((t.size, 18))
    x[:, :3] = position
    return Trajectory(t, x, np.tile(np.eye(18) * 1e-4, (t.size, 1, 1)))


def _straight(heading_rad: float = 0.0, speed: float = 0.5, duration: float = 200.0):
    """A straight run from (3, -2, 1) at ``speed`` along ``heading_rad`` (x north, y east):
    the estimate at 10 Hz, its path length s(t) = speed t."""
    t = np.arange(0.0, duration + 1e-9, 0.1)
    u = np.array([math.cos(heading_rad), math.sin(heading_rad), 0.0])
    return t, np.array([3.0, -2.0, 1.0]) + speed * t[:, None] * u, u


def _reference(name, t, position, fixes=False):
    return ReferenceTrack(name, t, position, fixes=fixes, source="synthetic")


@pytest.mark.parametrize("heading_deg", [0.0, 35.0, -120.0])
def test_linear_drift_is_recovered_exactly(heading_deg):
    """The estimate runs ahead of a 5 Hz reference by c s along the track and right of it by
    k s: drift = sqrt(c^2 + k^2) s, so drift % = 100 sqrt(c^2 + k^2) at every checkpoint, the
    components 100 c and 100 k, and the growth the same (whatever the heading)."""
    c, k = 0.02, -0.015  # 2 % ahead, 1.5 % to the left
    t, p, u = _straight(math.radians(heading_deg))
    right = np.array([-u[1], u[0], 0.0])
    t_ref = np.arange(0.0, 200.0 + 1e-9, 0.2)
    s_ref = 0.5 * t_ref
    p_ref = (
        np.array([3.0, -2.0, 1.0])
        + s_ref[:, None] * u
        - (c * s_ref)[:, None] * u
        - (k * s_ref)[:, None] * right
        + [100.0, 50.0, -0.3]  # the reference's own frame: translated
    )
    result = trajectory_drift(_trajectory(t, p), _reference("dvl-dr", t_ref, p_ref))
    assert len(result.checkpoints) == 10
    assert result.distance_m == pytest.approx(100.0)
    for i, cp in enumerate(result.checkpoints, start=1):
        assert cp.distance_m == pytest.approx(10.0 * i)
        assert cp.drift_percent == pytest.approx(100 * math.hypot(c, k), rel=1e-9)
        assert cp.along_track_m == pytest.approx(c * cp.distance_m, abs=1e-9)
        assert cp.cross_track_m == pytest.approx(k * cp.distance_m, abs=1e-9)
        assert cp.vertical_m == pytest.approx(0.0, abs=1e-9)
    assert result.growth_percent == pytest.approx(100 * math.hypot(c, k), rel=1e-9)
    assert result.along_growth_percent == pytest.approx(100 * c, rel=1e-9)
    assert result.cross_growth_percent == pytest.approx(100 * k, rel=1e-9)
    assert result.final_drift_percent == pytest.approx(100 * math.hypot(c, k), rel=1e-9)
    # the alignment moved the reference's start onto the estimate's
    assert result.alignment.translation_m == pytest.approx((-100.0, -50.0, 0.3))
    assert result.alignment.t_s == 0.0 and result.alignment.yaw_rad == 0.0


def test_constant_offset_splits_into_along_and_cross_track():
    """A reference 3 m behind and 4 m to the left of the estimate, without alignment: along
    +3 m, cross +4 m (estimate to the right), drift 5 m at every checkpoint."""
    t, p, u = _straight(math.radians(60.0))
    right = np.array([-u[1], u[0], 0.0])
    p_ref = p - 3.0 * u - 4.0 * right
    result = trajectory_drift(_trajectory(t, p), _reference("autopilot", t, p_ref), align="none")
    for cp in result.checkpoints:
        assert cp.drift_m == pytest.approx(5.0)
        assert cp.along_track_m == pytest.approx(3.0)
        assert cp.cross_track_m == pytest.approx(4.0)
    assert result.alignment.method == "none" and "as they are" in result.alignment_text()


def test_yaw_alignment_removes_a_known_rotation():
    """The reference is the path turned by 20 deg about its start (a frame rotated by 20 deg):
    translated only, a straight run shows the chord 2 sin(10 deg) s, i.e. 34.7 % of distance;
    with the yaw alignment the rotation (-20 deg) is found and the drift vanishes."""
    theta = math.radians(20.0)
    t, p, _ = _straight(math.radians(10.0))
    rel = p - p[0]
    c, s = math.cos(theta), math.sin(theta)
    p_ref = np.c_[c * rel[:, 0] - s * rel[:, 1], s * rel[:, 0] + c * rel[:, 1], rel[:, 2]]
    ref = _reference("dvl-dr", t, p_ref)
    start = trajectory_drift(_trajectory(t, p), ref)
    for cp in start.checkpoints:
        assert cp.drift_percent == pytest.approx(200 * math.sin(theta / 2), rel=1e-9)
    yaw = trajectory_drift(_trajectory(t, p), ref, align="yaw")
    assert yaw.alignment.yaw_rad == pytest.approx(-theta, abs=1e-12)
    assert yaw.alignment.segment_m == pytest.approx(10.0)  # 10 % of 100 m
    assert max(cp.drift_m for cp in yaw.checkpoints) < 1e-9
    assert "-20.00 deg" in yaw.alignment_text()


def test_least_squares_yaw_is_umeyamas_rotation():
    """On noisy points, the yaw equals the rotation of the SVD (Kabsch/Umeyama) solution."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(50, 2))
    theta = 0.7
    R = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    b = a @ R.T + rng.normal(scale=0.05, size=a.shape)
    U, _, Vt = np.linalg.svd(b.T @ a)
    R_svd = U @ np.diag([1.0, np.linalg.det(U @ Vt)]) @ Vt
    assert least_squares_yaw(a, b) == pytest.approx(math.atan2(R_svd[1, 0], R_svd[0, 0]))


def test_sparse_gps_fixes_checkpoint_at_each_surfacing():
    """Three surfacings of 1 Hz fixes (0-5 s, 80-85 s, 160-165 s) on a run drifting 3 % along
    the track: the first fix aligns, the next surfacings' first fixes are the checkpoints, each
    at 3 %; GPS has no vertical."""
    t, p, u = _straight(duration=170.0)
    fix_t = np.r_[np.arange(0.0, 5.5), np.arange(80.0, 85.5), np.arange(160.0, 165.5)]
    s = 0.5 * fix_t
    ned = (np.array([3.0, -2.0, 1.0]) + (0.97 * s)[:, None] * u) - [3.0, -2.0, 0.0]
    gps = GpsFix(t=fix_t, position=ned, origin=(42.0, -83.0, 250.0))
    log = Log(gps=gps, source="synthetic.bag")
    result = trajectory_drift(_trajectory(t, p), reference_track(log, "gps"))
    assert [cp.t_s for cp in result.checkpoints] == [80.0, 160.0]
    for cp in result.checkpoints:
        assert cp.drift_percent == pytest.approx(3.0, rel=1e-9)
        assert cp.along_track_m == pytest.approx(0.03 * cp.distance_m)
        assert cp.vertical_m is None
    assert "surfacing" in result.checkpoint_rule and result.reference_samples == fix_t.size


def test_gps_fixed_all_along_is_a_continuous_reference():
    t, p, _ = _straight(duration=100.0)
    gps = GpsFix(t=t[::10], position=p[::10])  # 1 Hz, no gap
    ref = reference_track(Log(gps=gps), "gps")
    result = trajectory_drift(_trajectory(t, p), ref, checkpoints=5)
    assert len(result.checkpoints) == 5 and "evenly spaced in distance" in result.checkpoint_rule
    assert result.final_drift_m == pytest.approx(0.0, abs=1e-9)


def test_a_reference_the_log_lacks_names_the_log_and_its_streams():
    log = Log(dvl=Dvl.from_velocity(np.arange(3.0), np.zeros((3, 3))), source="run.mcap")
    with pytest.raises(MissingStreamError) as info:
        reference_track(log, "dvl-dr")
    assert str(info.value) == (
        "run.mcap has no dead_reckoning stream (the DVL's dead reckoning) for --reference "
        "dvl-dr; it has: dvl"
    )
    with pytest.raises(ConfigError, match="one of gps, dvl-dr, autopilot"):
        reference_track(log, "ins")


def test_no_overlap_and_no_distance():
    t, p, _ = _straight(duration=10.0)
    later = _reference("dvl-dr", t + 100.0, p)
    with pytest.raises(DataError, match="need 2"):
        trajectory_drift(_trajectory(t, p), later)
    still = np.tile(p[:1], (t.size, 1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = trajectory_drift(_trajectory(t, still), _reference("dvl-dr", t, still + 0.1))
    assert any("no drift in % of distance" in str(w.message) for w in caught)
    assert all(cp.drift_percent is None for cp in result.checkpoints)
    assert result.growth_percent is None and result.final_drift_percent is None
    with pytest.raises(ConfigError, match="start, yaw, none"):
        trajectory_drift(_trajectory(t, p), _reference("dvl-dr", t, p), align="origin")


def test_nonfinite_reference_rows_are_dropped_with_one_warning():
    t, p, _ = _straight(duration=50.0)
    p_ref = p.copy()
    p_ref[7] = np.nan
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = trajectory_drift(_trajectory(t, p), _reference("autopilot", t, p_ref))
    assert [str(w.message) for w in caught] == [
        "synthetic: autopilot: dropped 1 of 501 samples (non-finite, or a repeated time)"
    ]
    assert result.final_drift_m == pytest.approx(0.0, abs=1e-9)


@pytest.fixture(scope="module")
def localized(tmp_path_factory, simulated_run):
    """The calm run (it has the DVL's dead reckoning), localized once."""
    from undertow.cli import app

    root = tmp_path_factory.mktemp("drift")
    log = simulated_run("calm", 0) / "log"
    r = runner.invoke(app, ["localize", str(log), "--out", str(root / "est"), "-q"])
    assert r.exit_code == 0, r.output
    return log, root / "est"


def test_evaluate_against_the_dvl_dead_reckoning(localized):
    """The drift table is printed; --json gives the same numbers as the library and the final
    drift computed here from the files (the estimate's and the DR's displacement from the first
    common time)."""
    from undertow.cli import app
    from undertow.commands.localization import evaluate_trajectory_file
    from undertow.io import read_log

    log, est = localized
    r = runner.invoke(app, ["evaluate", "trajectory", str(est), str(log), "--reference", "dvl-dr"])
    assert r.exit_code == 0, r.output
    assert "Drift of" in r.output and "drift %" in r.output and "along m" in r.output
    assert "alignment: the reference translated by" in r.output
    assert "growth:" in r.output and "Consistency of the filter's innovations" in r.output
    j = runner.invoke(
        app, ["evaluate", "trajectory", str(est), str(log), "--reference", "dvl-dr", "--json"]
    )
    assert j.exit_code == 0, j.output
    data = json.loads(j.stdout)
    assert data == json.loads(json.dumps(evaluate_trajectory_file(est, log, reference="dvl-dr")
                                         .to_dict()))  # fmt: skip
    assert len(data["checkpoints"]) == 10 and data["reference"] == "dvl-dr"
    assert set(data["consistency"]["sensors"]) == {"imu", "dvl", "dead_reckoning", "pressure"}
    # independent: the end of the comparison, from the files themselves
    dr = read_log(log).dead_reckoning
    traj = Trajectory.load_npz(est)
    assert data["final_drift_m"] == pytest.approx(_end_drift(traj, dr.t, dr.position), rel=1e-6)
    assert data["distance_m"] == pytest.approx(36.6, rel=0.05)  # the carriage run's length


def test_a_reference_kind_the_log_lacks_is_one_line(localized):
    from conftest import one_error_line

    from undertow.cli import app

    log, est = localized
    line = one_error_line(
        runner.invoke(app, ["evaluate", "trajectory", str(est), str(log), "--reference", "gps"])
    )
    assert str(log) in line and "has no gps stream (GPS fixes)" in line
    assert "it has: imu, dvl, dead_reckoning, pressure" in line
    line = one_error_line(runner.invoke(app, ["evaluate", "trajectory", str(est), str(log)]))
    assert "is a log, not a ground-truth TUM file" in line and "--reference" in line


def _real(name: str):
    """A shared real recording (the tests using it carry the realdata marker: a missing folder
    fails them, see conftest.py)."""
    from conftest import REAL_DATA

    return REAL_DATA / name


def _end_drift(traj: Trajectory, t_ref: np.ndarray, p_ref: np.ndarray) -> float:
    """|displacement of the estimate - displacement of the reference| (horizontal) between the
    first and last reference samples inside the trajectory's span."""
    inside = (t_ref >= traj.t[0]) & (t_ref <= traj.t[-1])
    t0, t1 = t_ref[inside][0], t_ref[inside][-1]

    def at(t, tp, p):
        return np.array([np.interp(t, tp, p[:, i]) for i in range(2)])

    moved_est = at(t1, traj.t, traj.position) - at(t0, traj.t, traj.position)
    moved_ref = at(t1, t_ref, p_ref) - at(t0, t_ref, p_ref)
    return float(np.linalg.norm(moved_est - moved_ref))


@pytest.mark.realdata
def test_the_real_auv_against_its_a50_dead_reckoning(tmp_path):
    """The shared AUV recording, localized with the default settings: the drift table against
    the A50's own dead reckoning, its final drift as recomputed here from the files."""
    from undertow.cli import app
    from undertow.io import read_log

    bag = _real("coug_a50_imu_ros2")
    r = runner.invoke(app, ["localize", str(bag), "--out", str(tmp_path / "est"), "-q"])
    assert r.exit_code == 0, r.output
    args = ["evaluate", "trajectory", str(tmp_path / "est"), str(bag), "--reference", "dvl-dr"]
    r = runner.invoke(app, args)
    assert r.exit_code == 0 and "Traceback" not in r.output, r.output
    assert "Drift of" in r.output and "growth:" in r.output
    data = json.loads(runner.invoke(app, [*args, "--json"]).stdout)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dr = read_log(bag).dead_reckoning
    traj = Trajectory.load_npz(tmp_path / "est")
    assert data["final_drift_m"] == pytest.approx(_end_drift(traj, dr.t, dr.position), rel=1e-6)
    assert 5.0 < data["distance_m"] < 50.0  # a small AUV over about 15 s


@pytest.mark.realdata
def test_the_autopilot_of_a_real_dataflash_log_is_a_reference(tmp_path):
    """ardusub_small.BIN's EKF (XKF1, a vehicle on the bench): a trajectory 3 m north and 4 m
    east of it drifts 5 m without alignment and 0 with it; it travels too little for a %."""
    from undertow.cli import app
    from undertow.io import read_log

    path = _real("ardusub_small.BIN")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ekf = read_log(path).autopilot
    _trajectory(ekf.t, ekf.position + [3.0, 4.0, 0.0]).save_npz(tmp_path / "t.npz")
    base = ["evaluate", "trajectory", str(tmp_path / "t.npz"), str(path), "--reference"]
    r = runner.invoke(app, [*base, "autopilot", "--align", "none", "--json"])
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    assert [c["drift_m"] for c in data["checkpoints"]] == pytest.approx([5.0] * 10)
    assert data["final_drift_percent"] is None and "no drift in % of distance" in r.output
    r = runner.invoke(app, [*base, "autopilot", "--json"])
    assert max(c["drift_m"] for c in json.loads(r.stdout)["checkpoints"]) < 1e-9
