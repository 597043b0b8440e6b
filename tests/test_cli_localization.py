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
def run(tmp_path_factory):
    """The calm carriage run, localized once (no smoothing)."""
    root = tmp_path_factory.mktemp("calm")
    r = runner.invoke(app, ["simulate", "calm", "--out", str(root / "run"), "-q"])
    assert r.exit_code == 0, r.output
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
        ("dead_reckoning_drift_rad_per_s: [.nan, 0, 0]\n", "dead_reckoning_drift_rad_per_s.0"),
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


def test_gate_option_reaches_the_filter(run):
    r = _localize(run, "--gate", "0.999", "--output-rate", "5")
    assert r.exit_code == 0, r.output
    used = yaml.safe_load((run / "x" / "config.yaml").read_text())
    assert used["config"]["gate_probability"] == 0.999
    c = used["counts"]
    # chi-square 0.999 gates about 1 in 1000 innovations of a consistent sensor; not most
    gated = sum(c[f"gated_{k}"] for k in ("imu", "dvl", "dead_reckoning", "pressure"))
    assert gated < 0.05 * sum(c[f"used_{k}"] for k in ("imu", "dvl", "dead_reckoning", "pressure"))
    line = _error_line(_localize(run, "--gate", "1.5", "--overwrite"))
    assert "gate_probability: Input should be less than 1" in line


def _npz(run, tmp_path, name, change):
    data = dict(np.load(run / "est" / "trajectory.npz"))
    change(data)
    path = tmp_path / name
    np.savez(path, **data)
    return str(path)


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
