"""`undertow waves` and `undertow localize --wave auto` on the command line: the estimate per
window against the simulated truth, the figure, the records in config.yaml and trajectory.npz,
and one-line errors for wrong options (checked before the log is read)."""

import json

import numpy as np
import pytest
import yaml
from conftest import REAL_DATA
from conftest import one_error_line as _one_error_line
from typer.testing import CliRunner

from undertow.cli import app
from undertow.trajectory import Trajectory

runner = CliRunner()


def test_waves_json_against_the_simulated_truth(simulated_run, tmp_path):
    run = simulated_run("wave-a0.10-f1.00")
    plot = tmp_path / "waves.png"
    r = runner.invoke(app, ["waves", str(run / "log"), "--json", "--plot", str(plot)])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    truth = doc["truth"]
    assert truth["source"] == "scenario"
    a_true, f_true = truth["amplitude_m"][0], truth["frequency_hz"][0]
    windows = doc["estimate"]["windows"]
    assert windows, doc
    for w in windows:  # the accuracy: 15 % in amplitude, 5 % in frequency
        assert w["amplitude_m"] == pytest.approx(a_true, rel=0.15)
        assert w["frequency_hz"] == pytest.approx(f_true, rel=0.05)
    assert plot.stat().st_size > 1000 and plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_waves_table_names_the_truth(simulated_run):
    r = runner.invoke(app, ["waves", str(simulated_run("wave-a0.10-f1.00") / "log")])
    assert r.exit_code == 0, r.output
    assert "true: scenario" in r.output and "rigid" in r.output


@pytest.mark.parametrize(
    "args, message",
    [
        (["--platform", "boat"], "--platform must be one of auto, rigid, free"),
        (["--plot", "waves.txt"], "PNG"),
    ],
)
def test_wrong_options_fail_at_once_in_one_line(tmp_path, args, message):
    missing = tmp_path / "no_such_log"  # options are checked before the log is looked at
    assert message in _one_error_line(runner.invoke(app, ["waves", str(missing), *args]))


@pytest.mark.realdata
def test_the_real_dvl_only_recording_gives_a_result_or_one_line():
    bag = REAL_DATA / "a50_ros1_circle.bag"
    if not bag.is_file():
        pytest.skip(f"real recording not found: {bag}")
    r = runner.invoke(app, ["waves", str(bag), "--json"])
    assert "Traceback" not in r.output
    if r.exit_code == 0:
        doc = json.loads(r.stdout)
        assert doc["truth"] is None  # a real tank recording: nothing to compare with
    else:
        _one_error_line(r)


@pytest.mark.slow
def test_localize_wave_auto_records_the_followed_condition(simulated_run, tmp_path):
    run = simulated_run("wave-a0.10-f1.00")
    out = tmp_path / "auto"
    r = runner.invoke(app, ["localize", str(run / "log"), "--wave", "auto", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert "--wave auto" in r.output
    config = yaml.safe_load((out / "config.yaml").read_text())
    track = config["wave_track"]
    assert track["source"] == "estimated" and len(track["t"]) >= 1
    assert track["amplitude_m"][0] == pytest.approx(0.1, rel=0.15)
    with np.load(out / "trajectory.npz") as data:
        np.testing.assert_allclose(data["wave_amplitude_m"], track["amplitude_m"])
    assert Trajectory.load_npz(out).metadata["wave_condition_source"].startswith("estimated")
