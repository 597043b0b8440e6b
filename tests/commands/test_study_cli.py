"""`undertow reproduce` / `demo` argument errors (checked before any work: one line, at once) and
`undertow characterize` without ground truth at the command line."""

import json
import socket
import time

import pytest
from conftest import one_error_line as _one_error_line
from typer.testing import CliRunner

from undertow.cli import app

runner = CliRunner()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--seeds", "2", "--scheduler", "bogus"], "unknown scheduler 'bogus'"),
        (["--seeds", "1", "--scheduler", "bogus"], "unknown scheduler 'bogus'"),
        (["--seeds", "0"], "--seeds must be at least 1"),
        (["--first-seed", "-1"], "--first-seed must be >= 0, got -1"),
        (["--peer-time-cap", "-1"], "--peer-time-cap must be >= 0 s, got -1"),
        (["--peer-scenarios", "rock-survey,nope"], "--peer-scenarios: unknown scenario(s) nope"),
        (["--seeds", "2", "--scheduler", "tcp://127.0.0.1:{port}"], "cannot reach the Dask"),
    ],
)
def test_reproduce_argument_errors_fail_at_once(tmp_path, args, message):
    args = [a.format(port=_free_port()) for a in args]
    start = time.perf_counter()
    line = _one_error_line(runner.invoke(app, ["reproduce", "--out", str(tmp_path / "r"), *args]))
    assert message in line
    assert time.perf_counter() - start < 5.0  # before any simulation (a seed takes ~10 s)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("command", ["reproduce", "demo"])
def test_an_output_folder_that_is_a_file_is_one_line(tmp_path, command):
    target = tmp_path / "a_file"
    target.write_text("keep me\n")
    line = _one_error_line(runner.invoke(app, [command, "--out", str(target)]))
    assert line == f"error: {target}: output folder is an existing file"
    assert target.read_text() == "keep me\n"


def test_one_seed_says_the_scheduler_is_not_used(tmp_path, monkeypatch):
    """With one seed there is nothing for the scheduler to run: a warning, not silence. The
    study itself is replaced by a seed that fails, which must be one line too."""
    import undertow.study.runner

    monkeypatch.setattr(
        undertow.study.runner,
        "_first_seed",
        lambda seeds, settings, note: ({}, {s: "RuntimeError: stopped by the test" for s in seeds},
                                       None, []),
    )  # fmt: skip
    r = runner.invoke(app, ["reproduce", "--out", str(tmp_path / "r"), "--scheduler", "threads"])
    assert r.exit_code == 1, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert lines[0].startswith("warning: scheduler 'threads' not used: with one seed")
    assert lines[1] == "error: every seed failed; seed 0: RuntimeError: stopped by the test"


@pytest.fixture(scope="module")
def runs(tmp_path_factory, simulated_run):
    root = tmp_path_factory.mktemp("cli_characterize")
    for name in ("calm", "wave-a0.10-f0.75"):
        (root / name).symlink_to(simulated_run(name, 2))
    (root / "no_gt.yaml").write_text("ground_truth: [/not/recorded]\n")
    return root


@pytest.mark.slow
def test_characterize_without_ground_truth_prints_its_notes_and_agrees(runs):
    """A topic map that hides the ground truth: the calm run is still calm (no 13 Hz wave), the
    DVL noise comes from the DVL itself within sampling error of the ground-truth numbers, the
    barometer noise is measured, and every note is a warning line."""
    logs = [str(runs / n / "log") for n in ("calm", "wave-a0.10-f0.75")]
    with_gt = runner.invoke(app, ["characterize", *logs, "--json"])
    without = runner.invoke(
        app, ["characterize", *logs, "--json", "--topics", str(runs / "no_gt.yaml")]
    )
    assert with_gt.exit_code == without.exit_code == 0, without.output
    a, b = json.loads(with_gt.stdout)["runs"], json.loads(without.stdout)["runs"]
    assert [r["calm"] for r in b] == [True, False] and b[0]["frequency_hz"] is None
    for ra, rb in zip(a, b, strict=True):
        n = min(ra["samples"], rb["samples"])
        rel = 3 / (2 * (n - 1)) ** 0.5
        assert rb["dvl_std_m_s"] == pytest.approx(ra["dvl_std_m_s"], rel=rel)
        assert rb["depth_std_m"] == pytest.approx(ra["depth_std_m"], rel=0.05)
    warnings = [ln for ln in without.stderr.splitlines() if ln.startswith("warning:")]
    assert sum("no ground_truth stream" in w for w in warnings) == 2
    assert any("calm run" in w for w in warnings)


@pytest.mark.slow
def test_characterize_without_a_calm_run_warns_through_the_warning_line(runs):
    r = runner.invoke(app, ["characterize", str(runs / "wave-a0.10-f0.75" / "log"), "--json"])
    assert r.exit_code == 0, r.output
    assert "warning: no calm run among the logs: the profile holds total, not extra, noise" in (
        r.stderr.splitlines()
    )


@pytest.mark.realdata
def test_characterize_a_circle_says_there_is_no_constant_speed_segment():
    """The real circle run has 303 valid DVL samples but turns all the time: the error names
    the missing constant-speed segment, not a shortage of samples."""
    from conftest import REAL_DATA
    from conftest import one_error_line as _one_error_line

    bag = REAL_DATA / "a50_ros1_circle.bag"
    if not bag.exists():
        pytest.skip(f"real recording not found: {bag}")
    line = _one_error_line(runner.invoke(app, ["characterize", str(bag)]))
    assert "no constant-speed segment" in line and "303 valid DVL samples" in line
    assert "fewer than 10" not in line


@pytest.mark.parametrize("command", ["map", "characterize", "reproduce"])
def test_quiet_has_help(command):
    r = runner.invoke(app, [command, "--help"])
    assert r.exit_code == 0
    text = " ".join(r.output.replace("│", " ").split())  # rich wraps help inside a box
    assert "--quiet" in text and "No progress or summary on stderr." in text


@pytest.mark.slow
def test_characterize_from_python_gives_what_the_command_prints(runs, tmp_path):
    """`characterize_files` is the command without the printing: the same rows and profile,
    the same warnings (the command prints each as one `warning:` line), the same file."""
    from undertow._util.plain import json_safe
    from undertow.commands.study import characterize_files

    logs = [str(runs / n / "log") for n in ("calm", "wave-a0.10-f0.75")]
    topics = str(runs / "no_gt.yaml")
    result = characterize_files(logs, topics=topics, out=tmp_path / "python.yaml")
    cli = runner.invoke(
        app,
        ["characterize", *logs, "--json", "--topics", topics, "--out", str(tmp_path / "c.yaml")],
    )
    assert cli.exit_code == 0, cli.output
    assert json.loads(cli.stdout) == json.loads(
        json.dumps(json_safe(result.to_dict()), default=float)
    )
    printed = [ln for ln in cli.stderr.splitlines() if ln.startswith("warning:")]
    assert printed == [f"warning: {w}" for w in result.warnings] and len(printed) >= 3
    assert result.profile_path.read_text() == (tmp_path / "c.yaml").read_text()


def test_reproduce_from_python_checks_its_arguments_as_the_command_does(tmp_path):
    from undertow.commands import study
    from undertow.errors import UndertowError

    with pytest.raises(UndertowError, match="--seeds must be at least 1"):
        study.reproduce(tmp_path / "r", seeds=0)
    with pytest.raises(UndertowError, match="--first-seed must be >= 0, got -1"):
        study.reproduce(tmp_path / "r", first_seed=-1)
    assert not (tmp_path / "r").exists()
