"""`undertow simulate` and `info` on the command line: seeds that reproduce a run, and user
mistakes that give one line and exit status 1 (never a traceback)."""

import numpy as np
import pytest
from typer.testing import CliRunner

from undertow.cli import app
from undertow.io import read_log
from undertow.sim import load_scenario

#: reads the shared real recordings (conftest.py: a missing folder fails)
pytestmark = pytest.mark.realdata

runner = CliRunner()

SHORT = """\
base: wave-a0.05-f0.75
name: short
seed: 3
motion: {carriage: {run_length_m: 2.0, hold_before_s: 1.0, hold_after_s: 1.0}}
floor_cloud: {spacing_m: 0.1}
"""


def _simulate(*args):
    return runner.invoke(app, ["simulate", *map(str, args), "-q"])


def _one_error_line(result, *needles):
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), result.output
    for needle in needles:
        assert needle in lines[0], lines[0]


def _noise(log):
    return {
        "imu": log.imu.angular_velocity,
        "dvl": log.dvl.velocity,
        "beam_range": log.dvl.beam_range,
        "pressure": log.pressure.pressure,
        "sonar": log.sonar.range,
        "wave_probe": log.wave_probe.elevation,
        "dead_reckoning": log.dead_reckoning.orientation,
    }


@pytest.mark.slow
def test_a_written_scenario_yaml_reproduces_its_run_and_an_explicit_seed_wins(tmp_path):
    (tmp_path / "short.yaml").write_text(SHORT)
    s3 = tmp_path / "s3"
    assert _simulate(tmp_path / "short.yaml", "--out", s3).exit_code == 0
    assert load_scenario(s3 / "scenario.yaml").seed == 3  # no --seed: the file's own
    again = tmp_path / "s3b"
    assert _simulate(s3 / "scenario.yaml", "--out", again).exit_code == 0
    for name in ("ground_truth.tum", "ground_truth.ply", "scenario.yaml"):
        assert (again / name).read_bytes() == (s3 / name).read_bytes(), name
    first, second = _noise(read_log(s3 / "log")), _noise(read_log(again / "log"))
    for name, values in first.items():
        np.testing.assert_array_equal(second[name], values, err_msg=name)
    # the seed matters (the noise differs) and a given --seed wins over the file's
    other = tmp_path / "s0"
    assert _simulate(s3 / "scenario.yaml", "--out", other, "--seed", 0).exit_code == 0
    assert load_scenario(other / "scenario.yaml").seed == 0
    assert not np.array_equal(_noise(read_log(other / "log"))["imu"], first["imu"])


@pytest.mark.parametrize(
    ("content", "needles"),
    [
        (b"", ["empty.yaml", "empty scenario file"]),
        (b"ply\nformat binary_little_endian 1.0\nend_header\n\x00\xff\x89", ["not a scenario"]),
        (b"base: calm\nmotion: {carriage: {depth_m: 5.0}}\n", ["motion.carriage.depth_m", "floor"]),
        (b"base: calm\nmotion: {carriage: {start_x_m: 100}}\n", ["start_x_m", "110 m"]),
        (b"base: calm\ndvl: {min_range: 60}\n", ["dvl.min_range", "dvl.max_range = 50"]),
        (b"base: calm\nwave: {amplitude_m: 0.3}\n", ["wave.amplitude_m", "1/7"]),
    ],
)
def test_scenario_mistakes_are_one_line(tmp_path, content, needles):
    name = "scan.ply" if b"ply" in content else "empty.yaml" if not content else "mine.yaml"
    (tmp_path / name).write_bytes(content)
    result = _simulate(tmp_path / name, "--out", tmp_path / "out")
    _one_error_line(result, name, *needles)
    assert not (tmp_path / "out").exists()


def test_negative_seed_is_one_line(tmp_path):
    _one_error_line(_simulate("calm", "--out", tmp_path / "o", "--seed", -1), "--seed -1")


def test_info_warns_about_a_topic_of_the_users_file_that_the_bag_lacks(tmp_path):
    from conftest import REAL_DATA

    topics = tmp_path / "topics.yaml"
    topics.write_text("imu: /mavros/imu/data\n")
    bag = REAL_DATA / "a50_ros1_circle.bag"
    result = runner.invoke(app, ["info", str(bag), "--json", "--topics", str(topics)])
    assert result.exit_code == 0, result.output
    warned = [ln for ln in result.stderr.splitlines() if "topic map" in ln]
    assert len(warned) == 1 and "imu" in warned[0] and "/mavros/imu/data" in warned[0]


@pytest.mark.slow
def test_the_library_functions_give_what_the_commands_print(tmp_path, simulated_run):
    """`undertow simulate calm --seed 0` writes the same files as the library (the session's
    shared run is written by it), and `undertow info --json` prints `info_file(...).to_dict()`,
    warnings included (a topic of the user's map that the bag lacks)."""
    import json

    from undertow.commands.data import RUN_FILES, info_file, simulate_to_folder

    cli = tmp_path / "cli"
    result = runner.invoke(app, ["simulate", "calm", "--seed", "0", "--out", str(cli)])
    assert result.exit_code == 0, result.output
    assert " ".join(result.stderr.split()) == f"wrote {cli}/{', '.join(RUN_FILES)}"
    lib = simulated_run("calm", 0)
    for name in ("ground_truth.tum", "ground_truth.ply", "scenario.yaml", "log/log.mcap"):
        assert (cli / name).read_bytes() == (lib / name).read_bytes(), name
    labels = []
    again = simulate_to_folder(lib / "scenario.yaml", tmp_path / "py", on_start=labels.append)
    assert labels == ["simulating calm (seed 0)"] and again.seed == 0
    assert sorted(p.name for p in again.out_dir.iterdir()) == sorted(RUN_FILES)
    assert (again.out_dir / "log/log.mcap").read_bytes() == (lib / "log/log.mcap").read_bytes()

    printed = runner.invoke(app, ["info", str(cli / "log"), "--json"])
    assert printed.exit_code == 0, printed.output
    assert json.loads(printed.stdout) == json.loads(json.dumps(info_file(cli / "log").to_dict()))

    from conftest import REAL_DATA

    topics = tmp_path / "topics.yaml"
    topics.write_text("imu: /mavros/imu/data\n")
    bag = REAL_DATA / "a50_ros1_circle.bag"
    printed = runner.invoke(app, ["info", str(bag), "--json", "--topics", str(topics)])
    with pytest.warns(UserWarning, match="/mavros/imu/data"):
        info = info_file(bag, topics=topics)
    assert json.loads(printed.stdout) == info.to_dict()
    assert [w for w in info.warnings if "/mavros/imu/data" in w]
    assert all(f"warning: {w}" in printed.stderr for w in info.warnings)


def test_info_settings_file_topics_and_the_table(tmp_path):
    """`--config` reads the topic names from the settings file (as `--topics` does); the table
    has one row per stream."""
    from conftest import REAL_DATA

    from undertow.cli.data import summary_table
    from undertow.commands.data import info_file
    from undertow.settings import Settings

    settings = tmp_path / "settings.yaml"
    settings.write_text("topics: {imu: [/mavros/imu/data]}\n")
    bag = REAL_DATA / "a50_ros1_circle.bag"
    printed = runner.invoke(app, ["info", str(bag), "--config", str(settings)])
    assert printed.exit_code == 0, printed.output
    assert "/mavros/imu/data" in printed.stderr
    with pytest.warns(UserWarning, match="/mavros/imu/data"):
        info = info_file(bag, settings=Settings.from_yaml(settings))
    table = summary_table(info.summary)
    assert table.row_count == len(info.summary.streams) == 1
    assert "dvl" in printed.stdout and "378" in printed.stdout
