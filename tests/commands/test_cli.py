"""The command line: thin commands, one clear line for user errors, JSON that parses."""

import json
import shutil

import pytest
from conftest import REAL_DATA
from typer.testing import CliRunner

from undertow.cli import app

REAL = REAL_DATA
runner = CliRunner()


@pytest.mark.realdata
def test_info_json_on_the_real_ros1_bag():
    result = runner.invoke(app, ["info", str(REAL / "a50_ros1_circle.bag"), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    dvl = next(s for s in data["streams"] if s["name"] == "dvl")
    assert dvl["messages"] == 378


def test_missing_file_is_one_line_and_exit_1():
    result = runner.invoke(app, ["info", "/no/such/run.bag"])
    assert result.exit_code == 1
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "/no/such/run.bag" in lines[0]
    assert "Traceback" not in result.output


def test_help_has_examples():
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0 and "undertow simulate" in result.output


def test_localize_and_map_take_the_same_piece_options(monkeypatch):
    """--in-pieces / --whole and --piece-s on both commands; a piece length alone asks for the
    pieces, --whole wins over it (what reaches localize_file / map_file)."""
    import undertow.commands.localization as localization
    from undertow.errors import UndertowError

    monkeypatch.setenv("COLUMNS", "200")  # one option per line in the help
    for command in ("localize", "map"):
        out = runner.invoke(app, [command, "--help"]).output
        assert "--in-pieces" in out and "--whole" in out and "--piece-s" in out, out
    seen = []

    def localize_file(*args, **kwargs):
        seen.append(kwargs)
        raise UndertowError("stop here")

    monkeypatch.setattr(localization, "localize_file", localize_file)
    for extra in ([], ["--in-pieces"], ["--whole"], ["--piece-s", "30"],
                  ["--piece-s", "30", "--whole"]):  # fmt: skip
        runner.invoke(app, ["localize", "LOG", "--out", "o", "-q", *extra])
    got = [(kw["in_pieces"], kw.get("piece_s")) for kw in seen]
    assert got == [(None, None), (True, None), (False, None), (True, 30.0), (False, 30.0)]


@pytest.mark.slow
def test_simulate_localize_evaluate_map_end_to_end(tmp_path):
    """The README's workflow through the bag on disk, checked against the ground truth files:
    the DVL and the Ping convert with 1500 m/s in water of another sound speed, which the user
    gives (--sound-speed) to calibrate, localize and map alike."""
    run = tmp_path / "run"
    assert (
        runner.invoke(app, ["simulate", "wave-a0.05-f0.75", "--out", str(run), "-q"]).exit_code == 0
    )
    scenario = __import__("yaml").safe_load((run / "scenario.yaml").read_text())
    water = str(scenario["water"]["sound_speed_m_s"])
    cal = tmp_path / "cal.yaml"
    # the simulator's sound-speed error is c_set / c_true; calibration must find it, and find
    # nothing left once the water's sound speed is given
    expected = scenario["dvl"]["sound_speed_setting"] / scenario["water"]["sound_speed_m_s"]
    for extra, factor in (([], expected), (["--sound-speed", water], 1.0)):
        r = runner.invoke(app, ["calibrate", str(run / "log"), str(run / "ground_truth.tum"),
                                "--out", str(cal), *extra])  # fmt: skip
        assert r.exit_code == 0, r.output
        assert abs(json.loads(r.stdout)["dvl_scale_factor"] - factor) < 2e-3
    r = runner.invoke(app, ["localize", str(run / "log"), "--calibration", str(cal),
                            "--sound-speed", water, "--out", str(run / "est"), "-q"])  # fmt: skip
    assert r.exit_code == 0, r.output
    r = runner.invoke(
        app, ["evaluate", "trajectory", str(run / "est"), str(run / "ground_truth.tum"), "--json"]
    )
    assert r.exit_code == 0, r.output
    rmse = json.loads(r.stdout)["rmse"]
    assert rmse["x_m"] < 0.2 and rmse["y_m"] < 0.2 and rmse["z_m"] < 0.05
    scores = {}
    for name, extra in (("as recorded", []), ("water", ["--sound-speed", water])):
        out = run / f"map {name}"
        r = runner.invoke(app, ["map", str(run / "log"), "--trajectory", str(run / "est"),
                                "--out", str(out), "-q", *extra])  # fmt: skip
        assert r.exit_code == 0, r.output
        r = runner.invoke(app, ["evaluate", "map", str(out), str(run / "ground_truth.ply"),
                                "--json"])  # fmt: skip
        assert r.exit_code == 0, r.output
        scores[name] = json.loads(r.stdout)
    # the default (tpu) map's surface: the calm run's flat floor within a few cm, its std
    # covering most of it; from the ranges as recorded, 1.6 % too deep
    assert scores["water"]["surface_rmse_m"] < 0.05 and scores["water"]["within_2sigma"] > 0.5
    assert scores["as recorded"]["surface_bias_m"] > scores["water"]["surface_bias_m"] + 0.02
    config = __import__("yaml").safe_load((run / "map water" / "config.yaml").read_text())
    assert config["result"]["log"]["sound_speed"]["water_m_s"] == float(water)
    # the proposed filter carried the swell in its barometer's noise, so the map adds none to
    # the poses' depth (the filter's depth measurements, which it would need, are not taken)
    est = __import__("yaml").safe_load((run / "est" / "config.yaml").read_text())
    assert est["config"]["pressure_wave_noise"] is True and est["wave_noise"] is not None
    assert config["mapping"]["wave_depth_noise"] is True
    assert config["mapping"]["depth_noise"] is None


@pytest.mark.realdata
def test_bad_variant_and_missing_trajectory_are_one_line(tmp_path):
    r = runner.invoke(
        app, ["localize", str(REAL / "a50_ros1_circle.bag"), "--out", str(tmp_path / "x")]
    )
    assert r.exit_code == 1 and "imu" in r.output and "Traceback" not in r.output
    r = runner.invoke(
        app,
        [
            "map",
            str(REAL / "a50_ros1_circle.bag"),
            "--trajectory",
            str(tmp_path / "nope.npz"),
            "--out",
            str(tmp_path / "m"),
        ],
    )
    assert r.exit_code == 1 and "nope.npz" in r.output
    assert not (tmp_path / "x").exists() and not (tmp_path / "m").exists()


def test_simulate_list_names_every_builtin_with_its_description():
    from undertow.sim import list_scenarios

    result = runner.invoke(app, ["simulate", "--list"])
    assert result.exit_code == 0, result.output
    for name in list_scenarios():
        assert name in result.output
    assert "36.6 m" in result.output


def test_unknown_scenario_lists_the_builtins():
    result = runner.invoke(app, ["simulate", "nope", "--out", "/tmp/never"])
    assert result.exit_code == 1 and "wave-a0.10-f1.00" in result.output


@pytest.mark.slow
def test_characterize_writes_a_profile_that_localize_reads(tmp_path, simulated_run):
    calm, wave = simulated_run("calm", 2), simulated_run("wave-a0.10-f1.00", 2)
    profile = tmp_path / "profile.yaml"
    r = runner.invoke(
        app,
        ["characterize", str(calm / "log"), str(wave / "log"), "--out", str(profile), "--json"],
    )
    assert r.exit_code == 0, r.output
    rows = json.loads(r.stdout)["runs"]
    assert abs(rows[1]["amplitude_m"] - 0.10) < 0.005 and abs(rows[1]["frequency_hz"] - 1.0) < 0.01
    r = runner.invoke(
        app,
        ["localize", str(wave / "log"), "--profile", str(profile),
         "--wave-amplitude", "0.1", "--wave-frequency", "1.0", "--smooth",
         "--out", str(tmp_path / "est"), "-q"],
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    used = __import__("yaml").safe_load((tmp_path / "est" / "config.yaml").read_text())
    assert used["smoothed"] is True
    # the extra vx noise comes from the characterized profile (interpolated near its node)
    assert abs(used["wave_noise"]["dvl_std"][0] - rows[1]["dvl_extra_std_m_s"][0]) < 2e-3


def _one_error_line(result) -> str:
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 1 and "Traceback" not in result.output, result.output
    assert len(lines) == 1, result.output
    return lines[0]


@pytest.mark.slow
def test_outputs_never_clobber_a_folder_or_a_file(tmp_path, simulated_run):
    """calibrate/characterize --out on a run folder, localize --out on a non-empty folder or a
    file, simulate --out under a path that cannot exist: one line each, nothing touched."""
    run = shutil.copytree(simulated_run("calm"), tmp_path / "run")
    before = sorted(p.name for p in run.iterdir())
    gt = str(run / "ground_truth.tum")
    line = _one_error_line(
        runner.invoke(app, ["calibrate", str(run / "log"), gt, "--out", str(run)])
    )
    assert "is a directory" in line
    line = _one_error_line(
        runner.invoke(app, ["characterize", str(run / "log"), "--out", str(run)])
    )
    assert "is a directory" in line
    line = _one_error_line(runner.invoke(app, ["localize", str(run / "log"), "--out", str(run)]))
    assert "holds the input" in line
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    line = _one_error_line(runner.invoke(app, ["localize", str(run / "log"), "--out", str(other)]))
    assert "--overwrite" in line and (other / "notes.txt").read_text() == "mine"
    line = _one_error_line(runner.invoke(app, ["localize", str(run / "log"), "--out", gt]))
    assert "existing file" in line
    assert sorted(p.name for p in run.iterdir()) == before
    blocked = str(run / "ground_truth.ply" / "sub")
    _one_error_line(runner.invoke(app, ["simulate", "calm", "--out", blocked, "-q"]))


def test_errors_inside_long_work_are_still_one_line_without_quiet(tmp_path):
    """A failure while the progress bar would run (here: reading the log) prints the error
    line alone: no blank line from the bar in pipes and logs."""
    r = runner.invoke(app, ["localize", str(tmp_path / "nope.bag"), "--out", str(tmp_path / "o")])
    assert _one_error_line(r).startswith("error:") and r.output.startswith("error:")


def test_out_holding_the_input_is_refused_even_with_overwrite(tmp_path, simulated_run):
    run = shutil.copytree(simulated_run("calm"), tmp_path / "run")
    again = ["simulate", str(run / "scenario.yaml"), "--out", str(run), "--overwrite", "-q"]
    assert "holds the input" in _one_error_line(runner.invoke(app, again))
    assert (run / "log").is_dir() and (run / "scenario.yaml").is_file()
