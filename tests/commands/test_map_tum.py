"""`undertow map --trajectory FILE.tum`: a trajectory made elsewhere maps as undertow's own
trajectory.npz does when it states the same diagonal covariance, an ENU file is detected from
the log's depth and gives the same map, and every input mistake is one line naming the file and
the option."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from undertow.cli import app
from undertow.commands.mapping import map_file
from undertow.io.tum import write_tum
from undertow.occupancy import OccupancyMap
from undertow.trajectory import Trajectory

runner = CliRunner()


@pytest.fixture(scope="module")
def run(tmp_path_factory, simulation, simulated_run):
    """A simulated calm run, its ground truth as a trajectory.npz whose covariance is a diagonal
    growing along the run (different per axis), and the same poses and standard deviations as
    an extended TUM file (NED), as an ENU TUM file written from the closed form (x east = y,
    y north = x, z up = -z; roll, -pitch, pi/2 - yaw; sx and sy swapped) and as a plain TUM
    file."""
    root = tmp_path_factory.mktemp("map_tum")
    log = simulated_run("calm", 0) / "log"
    gt = simulation("calm", 0).log.ground_truth
    keep = slice(None, None, 20)
    t, p, rpy = gt.t[keep], gt.position[keep], gt.orientation[keep]
    grow = (t - t[0]) / (t[-1] - t[0])
    std = np.column_stack([0.01 + 0.03 * grow, 0.02 + 0.01 * grow, 0.005 + 0.002 * grow,
                           np.full((t.size, 3), 0.01)])  # fmt: skip
    x = np.zeros((t.size, 18))
    x[:, :3], x[:, 3:6] = p, rpy
    P = np.zeros((t.size, 18, 18))
    P[:, np.arange(6), np.arange(6)] = std**2
    Trajectory(t, x, P).save_npz(root / "est.npz")
    write_tum(root / "est.tum", t, p, rpy, std)
    enu = np.column_stack([p[:, 1], p[:, 0], -p[:, 2]])
    enu_rpy = np.column_stack([rpy[:, 0], -rpy[:, 1], np.pi / 2 - rpy[:, 2]])
    write_tum(root / "enu.txt", t, enu, enu_rpy, std[:, [1, 0, 2, 3, 4, 5]])
    write_tum(root / "plain.tum", t, p, rpy)
    write_tum(root / "shifted.tum", t + 1e4, p, rpy, std)
    return root, log


def _same_map(a: OccupancyMap, b: OccupancyMap, tol: float) -> None:
    """The evidence (alpha - alpha_0, beta - beta_0) of every cell of either map agrees within
    ``tol`` of the largest (a cell one map lacks has none): rounding in the poses moves a sample
    by ~1e-16 m, which may give a cell at the edge of a kernel's support a mass of ~1e-20."""
    cells = np.unique(np.concatenate([a.cells, b.cells]), axis=0)
    evidence = []
    for m in (a, b):
        at = np.zeros((len(cells), 2))
        rows = {tuple(c): i for i, c in enumerate(m.cells)}
        idx = np.array([rows.get(tuple(c), -1) for c in cells])
        has = idx >= 0
        at[has] = np.column_stack([m.alpha[idx[has]] - m.alpha0, m.beta[idx[has]] - m.beta0])
        evidence.append(at)
    scale = np.abs(evidence[0]).max()
    assert scale > 0
    np.testing.assert_allclose(evidence[0], evidence[1], rtol=0, atol=tol * scale)


def test_a_tum_file_with_the_same_diagonal_maps_as_the_npz(run, tmp_path):
    root, log = run
    npz = map_file(log, root / "est.npz", method="adaptive")
    tum = map_file(log, root / "est.tum", out_dir=tmp_path / "m", method="adaptive")
    # positions and std round-trip exactly through the text, the angles through a quaternion
    _same_map(tum.map, npz.map, tol=1e-12)
    np.testing.assert_allclose(tum.metadata["mapper"]["variance_bounds"],
                               npz.metadata["mapper"]["variance_bounds"], rtol=1e-12)  # fmt: skip
    assert tum.warnings == []
    record = yaml.safe_load((tmp_path / "m" / "config.yaml").read_text())["result"]["trajectory"]
    assert record["file"] == str(root / "est.tum")
    assert record["format"] == "TUM, 14 columns"
    assert record["frame"] == "ned" and record["frame_source"].startswith("detected: z = depth")
    assert record["covariance"] == "the file's columns sx sy sz sroll spitch syaw"
    assert npz.metadata["trajectory"]["format"] == "trajectory.npz (undertow localize)"


def test_an_enu_file_is_detected_from_the_depth_and_maps_the_same(run):
    root, log = run
    ned = map_file(log, root / "est.tum")
    enu = map_file(log, root / "enu.txt")
    record = enu.metadata["trajectory"]
    assert record["frame"] == "enu" and record["frame_source"].startswith("detected: z = -depth")
    _same_map(enu.map, ned.map, tol=1e-12)
    assert enu.warnings == []
    # stating the frame wins; a statement the depth contradicts is warned of
    forced = map_file(log, root / "enu.txt", trajectory_frame="ned", method="csm")
    assert forced.metadata["trajectory"]["frame_source"] == "stated"
    assert len(forced.warnings) == 1
    assert "frame ned as stated, but the log's depth says enu" in forced.warnings[0]


def _map(log, out, *extra):
    return runner.invoke(app, ["map", str(log), "--out", str(out), *extra])


def _one_error_line(result):
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 1, result.output
    assert len(lines) == 1 and lines[0].startswith("error:"), result.output
    return lines[0]


def test_a_stated_std_on_the_command_line_and_the_line_that_states_the_choices(run, tmp_path):
    root, log = run
    r = _map(log, tmp_path / "m", "--trajectory", str(root / "plain.tum"), "--pose-std",
             "0.02,0.02,0.01", "--method", "csm")  # fmt: skip
    assert r.exit_code == 0, r.output
    said = [ln for ln in r.output.splitlines() if ln.startswith("trajectory:")]
    assert said == [
        f"trajectory: {root / 'plain.tum'} (TUM, 8 columns); frame ned (detected: z = depth "
        + said[0].split("(detected: z = depth ", 1)[1]
    ]
    assert said[0].endswith(
        "covariance: --pose-std 0.02,0.02,0.01 (constant); orientation not stated (the map does "
        "not use it)"
    )
    settings = tmp_path / "settings.yaml"
    settings.write_text("trajectory: {position_std_m: [0.02, 0.02, 0.01], frame: ned}\n")
    r = _map(log, tmp_path / "s", "--trajectory", str(root / "plain.tum"), "--config",
             str(settings), "--method", "csm", "-q")  # fmt: skip
    assert r.exit_code == 0, r.output
    record = yaml.safe_load((tmp_path / "s" / "config.yaml").read_text())["result"]["trajectory"]
    assert record["frame_source"] == "stated"
    assert record["covariance"].startswith("settings trajectory.position_std_m 0.02,0.02,0.01")
    # the same stated std from the command line and from the settings: the same map
    assert np.array_equal(OccupancyMap.load(tmp_path / "m").alpha,
                          OccupancyMap.load(tmp_path / "s").alpha)  # fmt: skip


def test_a_constant_std_under_session_normalization_is_warned_of(run):
    root, log = run
    result = map_file(log, root / "plain.tum", pose_std=(0.02, 0.02, 0.01), method="adaptive")
    assert len(result.warnings) == 1 and "the same adaptive kernel (l_min)" in result.warnings[0]
    fixed = map_file(log, root / "plain.tum", pose_std=(0.02, 0.02, 0.01), method="adaptive",
                     variance_bounds=((0, 0, 0), (1e-3, 1e-3, 1e-3)))  # fmt: skip
    assert fixed.warnings == []


def test_no_depth_in_the_log_assumes_ned_and_says_so(run, tmp_path):
    root, log = run
    topics = tmp_path / "topics.yaml"
    topics.write_text("pressure: []\n")
    r = _map(log, tmp_path / "m", "--trajectory", str(root / "est.tum"), "--topics", str(topics),
             "--method", "csm", "-q")  # fmt: skip
    assert r.exit_code == 0, r.output
    warnings = [ln for ln in r.output.splitlines() if ln.startswith("warning:")]
    assert warnings == [
        f"warning: {root / 'est.tum'}: frame not detected (the log has no pressure or depth "
        "stream): read as NED (z down); add --trajectory-frame enu if its z points up"
    ]
    record = yaml.safe_load((tmp_path / "m" / "config.yaml").read_text())["result"]["trajectory"]
    assert record["frame"] == "ned" and record["frame_source"].startswith("assumed, not detected")


def test_input_mistakes_are_one_line(run, tmp_path):
    root, log = run
    plain, est = root / "plain.tum", root / "est.tum"
    line = _one_error_line(_map(log, tmp_path / "a", "--trajectory", str(plain)))
    assert line == (
        f"error: {plain}: a TUM file without std columns needs the pose's uncertainty: add "
        "--pose-std SX,SY,SZ[,SROLL,SPITCH,SYAW] (m, rad) or the settings' trajectory: "
        "{position_std_m: [SX, SY, SZ]}"
    )
    mistakes = {"1,2": "expected 3 or 6 comma-separated numbers",
                "1,-1,1": "must be finite and >= 0", "1,nan,1": "must be finite"}  # fmt: skip
    for bad, why in mistakes.items():
        line = _one_error_line(_map(log, tmp_path / "b", "--trajectory", str(plain),
                                    "--pose-std", bad))  # fmt: skip
        assert line.startswith("error: --pose-std: ") and why in line
    line = _one_error_line(_map(log, tmp_path / "c", "--trajectory", str(est),
                                "--trajectory-frame", "up"))  # fmt: skip
    assert line == "error: --trajectory-frame: expected ned or enu (or auto), got 'up'"
    line = _one_error_line(_map(log, tmp_path / "d", "--trajectory", str(root / "est.npz"),
                                "--pose-std", "1,1,1"))  # fmt: skip
    assert line.startswith("error: pose_std and trajectory_frame (--pose-std, "
                           "--trajectory-frame) apply to a TUM trajectory; ")  # fmt: skip
    shifted = root / "shifted.tum"
    line = _one_error_line(_map(log, tmp_path / "e", "--trajectory", str(shifted)))
    assert line.startswith(f"error: {shifted}: its poses (10000.000 .. ")
    assert "do not overlap the log's ranges (0.000 .. " in line
    bad = tmp_path / "bad.tum"
    bad.write_text("0 0 0 0 0 0 0 1 0.1 0.1 0.1 0 0 0\n1 0 0 0 0 0 0 1 0.1 0.1 -1 0 0 0\n")
    line = _one_error_line(_map(log, tmp_path / "f", "--trajectory", str(bad)))
    assert line == (
        f"error: {bad}: line 2: standard deviations sx sy sz sroll spitch syaw must be finite "
        "and >= 0, got 0.1 0.1 -1 0 0 0"
    )
    notes = tmp_path / "notes.txt"
    notes.write_text("not a trajectory\n")
    line = _one_error_line(_map(log, tmp_path / "g", "--trajectory", str(notes)))
    assert line.startswith(f"error: {notes}: no usable pose in TUM file")
    for out in "abcdefg":
        assert not (tmp_path / out).exists()


def test_a_tum_trajectory_maps_with_the_waves_the_log_records(simulated_run, tmp_path):
    """The ground truth as a TUM file says no wave; the bag's sidecar records the run's, which
    the default mapper takes for its range noise, in one line, and config.yaml records."""
    run_dir = simulated_run("wave-a0.10-f1.00", 0)
    r = _map(run_dir / "log", tmp_path / "m", "--trajectory", str(run_dir / "ground_truth.tum"),
             "--pose-std", "0.02,0.02,0.01")  # fmt: skip
    assert r.exit_code == 0, r.output
    said = [ln for ln in r.output.splitlines() if "the waves the log records" in ln]
    assert len(said) == 1 and "a = 0.1 m, f = 1 Hz" in said[0], r.output
    config = yaml.safe_load((tmp_path / "m" / "config.yaml").read_text())
    assert config["mapping"]["wave"] == [0.1, 1.0]
