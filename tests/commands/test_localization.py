"""localize / calibrate / evaluate trajectory on wrong inputs: one line and exit 1, or one warning
line and the good data kept; never a traceback, never a quiet exit 0 with defaults."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from undertow.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def run(tmp_path_factory, simulated_run):
    """The calm carriage run, localized once (no smoothing)."""
    root = tmp_path_factory.mktemp("calm")
    (root / "run").symlink_to(simulated_run("calm", 0))  # `undertow simulate calm`'s folder
    r = runner.invoke(
        app, ["localize", str(root / "run" / "log"), "--out", str(root / "est"), "-q"]
    )
    assert r.exit_code == 0, r.output
    return root


def _error_line(result) -> str:
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 1 and "Traceback" not in result.output, result.output
    assert len(lines) == 1, result.output
    return lines[0]


def _localize(run, *args):
    return runner.invoke(
        app, ["localize", str(run / "run" / "log"), "--out", str(run / "x"), "-q", *args]
    )


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("dr_bias_drift_rad_s: [.nan, 0, 0]\n", "dr_bias_drift_rad_s.0"),
        ("[1, 2]\n", "not a calibration file"),
        ("name: paper\nconditions: []\n", "unknown keys conditions, name"),
    ],
    ids=["nan", "list", "noise-profile"],
)
def test_wrong_calibration_file_is_one_line(run, tmp_path, text, message):
    cal = tmp_path / "cal.yaml"
    cal.write_text(text)
    assert message in _error_line(_localize(run, "--calibration", str(cal)))
    assert not (run / "x").exists()


def test_invalid_settings_value_is_one_line(run, tmp_path):
    settings = tmp_path / "s.yaml"
    settings.write_text("localizer: {beta: .nan, accel_density: [0.01, 0.01, 0.01]}\n")
    assert "localizer.beta: Input should be a finite number" in _error_line(
        _localize(run, "--config", str(settings))
    )


@pytest.mark.slow
def test_gate_option_reaches_the_filter(run):
    r = _localize(run, "--gate", "0.999", "--output-rate", "5")
    assert r.exit_code == 0, r.output
    used = yaml.safe_load((run / "x" / "config.yaml").read_text())
    assert used["config"]["gate_probability"] == 0.999
    c = used["counts"]
    # chi-square 0.999 gates about 1 in 1000 innovations of a consistent sensor; not most
    gated = sum(c[f"gated_{k}"] for k in ("imu", "dvl", "dead_reckoning", "pressure"))
    assert gated < 0.05 * sum(c[f"used_{k}"] for k in ("imu", "dvl", "dead_reckoning", "pressure"))
    assert "wave condition" not in r.output  # -q: no info line
    line = _error_line(_localize(run, "--gate", "1.5", "--overwrite"))
    assert "gate_probability: Input should be less than 1" in line


def _npz(run, tmp_path, name, change):
    data = dict(np.load(run / "est" / "trajectory.npz"))
    change(data)
    path = tmp_path / name
    np.savez(path, **data)
    return str(path)


@pytest.mark.slow
def test_evaluate_refuses_empty_or_nan_time_trajectories(run, tmp_path):
    gt = str(run / "run" / "ground_truth.tum")

    def empty(d):
        d.update(t=d["t"][:0], x=d["x"][:0], P=d["P"][:0])

    def nan_time(d):
        d["t"][5] = np.nan

    line = _error_line(
        runner.invoke(app, ["evaluate", "trajectory", _npz(run, tmp_path, "e.npz", empty), gt])
    )
    assert "no samples" in line
    line = _error_line(
        runner.invoke(app, ["evaluate", "trajectory", _npz(run, tmp_path, "n.npz", nan_time), gt])
    )
    assert "non-finite times" in line


def test_evaluate_zero_covariance_warns_and_reports_no_nees(run, tmp_path):
    def zero(d):
        d["P"][:] = 0.0

    path = _npz(run, tmp_path, "z.npz", zero)
    gt = str(run / "run" / "ground_truth.tum")
    r = runner.invoke(app, ["evaluate", "trajectory", path, gt, "--json"])
    assert r.exit_code == 0, r.output
    assert "not positive definite" in r.output and "Traceback" not in r.output
    data = json.loads(r.stdout)
    assert data["nees_mean"] is None and data["nees_samples"] == 0
    assert data["rmse"]["z_m"] < 0.05


@pytest.mark.slow
def test_rounded_ground_truth_times_warn_and_give_the_same_answer(run, tmp_path):
    """Ground truth rounded to 0.01 s (20 repeats per time at 2000 Hz): one warning line; RMSE
    and calibration as with the original file (what moves in 5 ms at 0.8 m/s is 4 mm)."""
    gt = run / "run" / "ground_truth.tum"
    rows = np.loadtxt(gt)
    rows[:, 0] = np.round(rows[:, 0], 2)
    rounded = tmp_path / "rounded.tum"
    np.savetxt(rounded, rows, fmt="%.9f")
    est = str(run / "est")
    ref = json.loads(runner.invoke(app, ["evaluate", "trajectory", est, str(gt), "--json"]).stdout)
    r = runner.invoke(app, ["evaluate", "trajectory", est, str(rounded), "--json"])
    assert r.exit_code == 0, r.output
    assert "repeats" in r.output and "Traceback" not in r.output
    rmse = json.loads(r.stdout)["rmse"]
    for key in ("x_m", "y_m", "z_m", "yaw_rad"):
        assert rmse[key] == pytest.approx(ref["rmse"][key], abs=5e-3)
    log = str(run / "run" / "log")
    r = runner.invoke(app, ["calibrate", log, str(rounded), "--out", str(tmp_path / "c.yaml")])
    assert r.exit_code == 0, r.output
    assert "repeats" in r.output
    scenario = yaml.safe_load((run / "run" / "scenario.yaml").read_text())
    expected = scenario["dvl"]["sound_speed_setting"] / scenario["water"]["sound_speed_m_s"]
    assert json.loads(r.stdout)["dvl_scale_factor"] == pytest.approx(expected, abs=2e-3)


def test_calibrate_with_a_four_pose_ground_truth_is_one_line(run, tmp_path):
    gt = tmp_path / "gt4.tum"
    lines = (run / "run" / "ground_truth.tum").read_text().splitlines()
    gt.write_text("\n".join(lines[:5]) + "\n")  # header + 4 poses (2 ms)
    out = tmp_path / "cal.yaml"
    line = _error_line(runner.invoke(app, ["calibrate", str(run / "run" / "log"), str(gt),
                                           "--out", str(out)]))  # fmt: skip
    assert "need at least 20" in line
    assert not out.exists()


def _warnings(output: str) -> list[str]:
    return [ln for ln in output.splitlines() if ln.startswith("warning:")]


@pytest.mark.slow
def test_calibrate_without_the_imu_says_so_and_localize_does_not_pretend(run, tmp_path):
    """A topic map hiding the IMU: the gyro bias keeps its default with one warning line, the
    YAML records what was estimated, and localize --calibration names what it did not get."""
    topics = tmp_path / "topics.yaml"
    topics.write_text("imu: [/nothing]\n")
    cal = tmp_path / "cal.yaml"
    log, gt = str(run / "run" / "log"), str(run / "run" / "ground_truth.tum")
    r = runner.invoke(app, ["calibrate", log, gt, "--topics", str(topics), "--out", str(cal)])
    assert r.exit_code == 0, r.output
    lines = [w for w in _warnings(r.output) if "calibrate:" in w]
    assert lines == [
        "warning: calibrate: gyro_bias_rad_s left at the default [0, 0, 0]: the log has "
        "no imu stream"
    ]
    saved = yaml.safe_load(cal.read_text())
    assert saved["estimated"] == ["dr_bias_drift_rad_s", "dvl_scale_factor", "depth_std_m"]
    assert saved["left_at_default"] == {"gyro_bias_rad_s": "the log has no imu stream"}
    out = run / "cal_est"
    r = runner.invoke(app, ["localize", log, "--out", str(out), "--calibration", str(cal)])
    assert r.exit_code == 0, r.output
    assert any("not estimated" in w and "gyro_bias_rad_s" in w for w in _warnings(r.output))
    # the wave condition comes from the bag's sidecar, and says so (one line, not with -q)
    assert "wave condition: calm (from the bag's sidecar undertow.yaml" in r.output
    used = yaml.safe_load((out / "config.yaml").read_text())
    assert used["wave_condition_source"] == "the bag's sidecar undertow.yaml"
    assert used["calibration"]["estimated"] == saved["estimated"]


@pytest.mark.slow
def test_a_bare_bag_file_is_localized_as_calm_and_says_so(run, tmp_path):
    bare = tmp_path / "bare"
    bare.mkdir()
    (bare / "log.mcap").write_bytes((run / "run" / "log" / "log.mcap").read_bytes())
    out = tmp_path / "est"
    r = runner.invoke(
        app, ["localize", str(bare / "log.mcap"), "--out", str(out), "--variant", "baseline"]
    )
    assert r.exit_code == 0, r.output
    info = [ln for ln in r.output.splitlines() if ln.startswith("wave condition:")]
    assert len(info) == 1 and info[0].startswith("wave condition: calm (default")
    assert yaml.safe_load((out / "config.yaml").read_text())["wave_condition_source"] == "default"


def _help(command: str) -> str:
    r = runner.invoke(app, [command, "--help"], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    return " ".join(r.output.replace("│", " ").split())


def test_help_documents_quiet_and_the_default_wave():
    for command in ("localize", "calibrate"):
        assert "No progress or summary on stderr." in _help(command), command
    assert "undertow.yaml, else calm" in _help("localize")


def test_conflicting_wave_options_and_smooth_with_output_rate_are_refused_up_front(run, tmp_path):
    line = _error_line(_localize(run, "--wave", "calm", "--wave-amplitude", "0.1",
                                 "--wave-frequency", "1"))  # fmt: skip
    assert "--wave and --wave-amplitude / --wave-frequency conflict" in line
    # before reading the log: a missing log would be the error otherwise
    r = runner.invoke(app, ["localize", str(run / "missing"), "--out", str(run / "y"),
                            "--output-rate", "1", "--smooth"])  # fmt: skip
    line = _error_line(r)
    assert "smoothing (--smooth) needs the filter output at every measurement" in line
    assert "output_rate_hz=1.0 (--output-rate" in line
    assert not (run / "y").exists()
    settings = tmp_path / "s.yaml"  # the same clash from the settings file
    settings.write_text("localizer: {output_rate_hz: 2.0}\n")
    r = runner.invoke(app, ["localize", str(run / "missing"), "--out", str(run / "y"),
                            "--config", str(settings), "--smooth"])  # fmt: skip
    assert "output_rate_hz=2.0" in _error_line(r)
    assert not (run / "y").exists()


@pytest.mark.slow
def test_a_python_user_gets_what_the_commands_print(run, tmp_path):
    """calibrate_file, localize_file and evaluate_trajectory_file (what the commands call)
    from Python: the same calibration, trajectory, wave condition and warnings as the CLI."""
    from undertow.commands.localization import (
        calibrate_file,
        evaluate_trajectory_file,
        localize_file,
    )

    topics = tmp_path / "topics.yaml"
    topics.write_text("imu: [/nothing]\n")  # calibrate warns: no gyro bias; localize warns too
    log, gt = run / "run" / "log", run / "run" / "ground_truth.tum"
    cli = runner.invoke(app, ["calibrate", str(log), str(gt), "--topics", str(topics),
                              "--out", str(tmp_path / "cli.yaml")])  # fmt: skip
    assert cli.exit_code == 0, cli.output
    py = calibrate_file(log, gt, topics=topics, out=tmp_path / "py.yaml")
    assert [f"warning: {w}" for w in py.warnings] == _warnings(cli.output) != []
    assert (tmp_path / "py.yaml").read_text() == (tmp_path / "cli.yaml").read_text()
    assert py.calibration.to_dict() == json.loads(cli.stdout)

    cli = runner.invoke(app, ["localize", str(log), "--variant", "be", "--out",
                              str(tmp_path / "cli"), "--calibration", str(tmp_path / "cli.yaml")]
                        )  # fmt: skip
    assert cli.exit_code == 0, cli.output
    py = localize_file(log, variant="be", calibration=tmp_path / "py.yaml",
                       out_dir=tmp_path / "py")  # fmt: skip
    assert [f"warning: {w}" for w in py.warnings] == _warnings(cli.output) != []
    assert f"wave condition: {py.wave} (from {py.wave_source}; --wave overrides; the be " in (
        cli.output
    )
    assert not py.wave_noise_added and py.counts["used_dvl"] > 0
    on_disk = np.load(tmp_path / "cli" / "trajectory.npz")
    for key in ("t", "x", "P"):
        np.testing.assert_array_equal(getattr(py.trajectory, key), on_disk[key])
    for name in ("trajectory.tum", "config.yaml"):
        cli_text = (tmp_path / "cli" / name).read_text().replace("cli.yaml", "py.yaml")
        assert (tmp_path / "py" / name).read_text() == cli_text

    cli = runner.invoke(app, ["evaluate", "trajectory", str(tmp_path / "cli"), str(gt), "--json"])
    assert cli.exit_code == 0, cli.output
    assert evaluate_trajectory_file(py.out_dir, gt).to_dict() == json.loads(cli.stdout)


def test_evaluate_against_a_ground_truth_covering_little_of_the_run(run, tmp_path):
    rows = (run / "run" / "ground_truth.tum").read_text().splitlines()
    est = str(run / "est")
    tiny, short = tmp_path / "tiny.tum", tmp_path / "short.tum"
    tiny.write_text("\n".join(rows[:4]) + "\n")  # header + 3 poses (1 ms): one sample
    short.write_text("\n".join(rows[:4001]) + "\n")  # 2 s of 2000 Hz
    line = _error_line(runner.invoke(app, ["evaluate", "trajectory", est, str(tiny)]))
    assert "only 1 of" in line and "need at least 10" in line
    r = runner.invoke(app, ["evaluate", "trajectory", est, str(short)])
    assert r.exit_code == 0, r.output
    (warning,) = _warnings(r.output)
    assert "outside the ground truth" in warning and "are dropped" in warning
    result = json.loads(
        runner.invoke(app, ["evaluate", "trajectory", est, str(short), "--json"]).stdout
    )
    used, dropped = result["samples"], result["dropped_outside_ground_truth"]
    assert f"samples: {used} used, {dropped} outside the ground truth (dropped)" in r.output


@pytest.mark.slow
def test_wrong_files_are_one_line_naming_what_they_should_be(run, tmp_path):
    gt = str(run / "run" / "ground_truth.tum")
    line = _error_line(runner.invoke(app, ["evaluate", "trajectory", gt, gt]))
    assert "not a trajectory.npz written by `undertow localize`" in line and "TUM" in line
    profile = tmp_path / "profile.yaml"
    profile.write_text("name: mine\nconditions: [{amplitude_m: 0.1, frequency_hz: 1.0}]\n")
    line = _error_line(_localize(run, "--profile", str(profile), "--overwrite"))
    assert f"{profile}: noise profile field conditions.0.dvl_std: Field required" in line
    assert "KeyError" not in line


@pytest.mark.slow
def test_a_log_localized_on_disk_gives_the_files_map_and_metrics_of_one_in_memory(run, tmp_path):
    """localize --smooth with the states on disk (chunked) writes the TUM and config.yaml bytes
    and the npz arrays of the in-memory run, leaves no store behind; `map` (which now reads the
    poses chunk by chunk) gives the map of map_log on the whole loaded Trajectory, and
    `evaluate trajectory` the same metrics, from either folder."""
    from undertow.commands.common import load_log
    from undertow.commands.localization import evaluate_trajectory_file, localize_file
    from undertow.commands.mapping import map_file
    from undertow.mapping.config import MappingConfig
    from undertow.mapping.run import map_log
    from undertow.trajectory import Trajectory
    from undertow.trajectory_chunks import NpzTrajectory

    log, gt = run / "run" / "log", run / "run" / "ground_truth.tum"
    mem = localize_file(log, smooth=True, out_dir=tmp_path / "mem", chunked=False)
    disk = localize_file(log, smooth=True, out_dir=tmp_path / "disk", chunked=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["disk", "mem"]  # no store left
    assert isinstance(disk.trajectory, NpzTrajectory) and disk.warnings == mem.warnings
    assert disk.trajectory.metadata == Trajectory.load_npz(tmp_path / "mem").metadata
    assert disk.counts == mem.counts and disk.consistency == mem.consistency
    for name in ("trajectory.tum", "config.yaml"):
        assert (tmp_path / "disk" / name).read_bytes() == (tmp_path / "mem" / name).read_bytes()
    a, b = (np.load(tmp_path / f / "trajectory.npz") for f in ("mem", "disk"))
    assert a.files == b.files
    for key in a.files:
        np.testing.assert_array_equal(a[key], b[key])
    cheap = MappingConfig(method="csm", resolution=0.2)
    today = map_log(load_log(log), Trajectory.load_npz(tmp_path / "mem"), cheap).map
    for folder in ("mem", "disk"):
        got = map_file(log, tmp_path / folder, method="csm", resolution=0.2).map
        assert len(got) == len(today) > 0
        for key in ("cells", "alpha", "beta"):
            np.testing.assert_array_equal(getattr(got, key), getattr(today, key))
    assert (evaluate_trajectory_file(tmp_path / "disk", gt).to_dict()
            == evaluate_trajectory_file(tmp_path / "mem", gt).to_dict())  # fmt: skip


def test_chunked_without_a_folder_or_with_an_output_rate_is_refused_before_reading(tmp_path):
    from undertow.commands.localization import localize_file
    from undertow.errors import ConfigError

    missing = tmp_path / "no-such-log"  # not read: the options fail first
    with pytest.raises(ConfigError, match="chunked: needs an output folder"):
        localize_file(missing, chunked=True)
    with pytest.raises(ConfigError, match="no output rate"):
        localize_file(missing, chunked=True, out_dir=tmp_path / "o", output_rate_hz=10.0)


def test_a_bag_too_long_to_read_whole_is_read_in_pieces_says_so_and_records_it(run, monkeypatch):
    """With the limit below the calm run's 48 s, `localize` reads it in pieces by itself: one
    line says so, config.yaml records it (``read_in_pieces``) and is otherwise the whole
    read's, as are the states (a log of under an hour: the same choices); --whole gives the
    whole read's files byte for byte, with one line."""
    import undertow.io

    monkeypatch.setattr(undertow.io, "PIECES_ABOVE_S", 10.0)
    today = run / "est"  # localized by default before the patch: read whole, nothing recorded
    auto = _localize(run, "--out", str(run / "auto"))
    said = [ln for ln in auto.output.splitlines() if "pieces" in ln]
    assert auto.exit_code == 0 and len(said) == 1, auto.output
    assert "read in 600 s pieces" in said[0] and "--whole reads it at once" in said[0]
    doc = yaml.safe_load((run / "auto" / "config.yaml").read_text())
    assert doc.pop("read_in_pieces")["policy"] == "auto"
    assert doc == yaml.safe_load((today / "config.yaml").read_text())
    assert (run / "auto" / "trajectory.tum").read_bytes() == (today / "trajectory.tum").read_bytes()
    whole = _localize(run, "--out", str(run / "whole"), "--whole")
    assert whole.exit_code == 0 and "read whole as asked (--whole" in whole.output, whole.output
    for name in ("trajectory.tum", "config.yaml", "trajectory.npz"):
        assert (run / "whole" / name).read_bytes() == (today / name).read_bytes()
