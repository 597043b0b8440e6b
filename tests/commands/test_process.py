"""How the process behaves: bugs become a crash report and exit 70, options fail before any data
is read, SIGTERM removes temporary output and exits 143, and temporary folders left by killed
runs are removed by the next write there (only ours, only of dead processes)."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from undertow.cli import app

runner = CliRunner()
UNDERTOW = Path(sys.executable).with_name("undertow")


def _one_error_line(result) -> str:
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    assert "Traceback" not in result.output
    return lines[0]


# ---- bugs ------------------------------------------------------------------------------------


def _raise_bug(*args, **kwargs):
    return {}["a key that is not there"]  # a genuine bug: KeyError, not an UndertowError


def test_a_bug_is_one_line_naming_a_crash_report_and_exit_70(tmp_path, monkeypatch):
    import undertow.commands.data

    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    monkeypatch.delenv("UNDERTOW_DEBUG", raising=False)
    monkeypatch.setattr(undertow.commands.data, "info_file", _raise_bug)
    result = runner.invoke(app, ["info", "some.bag"])
    assert result.exit_code == 70  # EX_SOFTWARE, distinct from user (1) and usage (2) errors
    line = _one_error_line(result)
    assert "bug in undertow" in line and "KeyError" in line
    reports = list((tmp_path / "state" / "undertow").glob("undertow-crash-*.txt"))
    assert len(reports) == 1 and str(reports[0]) in line.replace("\n", "")
    text = reports[0].read_text()
    assert "Traceback" in text and "_raise_bug" in text  # the traceback of the bug itself
    assert "numpy " + np.__version__ in text and "python " in text
    assert "command line:" in text


def test_the_crash_report_falls_back_to_the_temporary_folder(tmp_path, monkeypatch):
    import tempfile

    import undertow.commands.data

    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")  # XDG_STATE_HOME under a file: cannot be created
    monkeypatch.setenv("XDG_STATE_HOME", str(blocker / "state"))
    monkeypatch.setattr(tempfile, "gettempdir", lambda: str(tmp_path))
    monkeypatch.setattr(undertow.commands.data, "info_file", _raise_bug)
    result = runner.invoke(app, ["info", "some.bag"])
    assert result.exit_code == 70
    assert len(list(tmp_path.glob("undertow-crash-*.txt"))) == 1


def test_user_and_usage_errors_keep_their_exit_codes(tmp_path, monkeypatch):
    import typer

    import undertow.commands.data

    assert runner.invoke(app, ["info", str(tmp_path / "missing.bag")]).exit_code == 1
    assert runner.invoke(app, ["info", "--no-such-option", "x"]).exit_code == 2

    def leave(*args, **kwargs):
        raise typer.Exit(5)  # typer's own exits are not bugs

    monkeypatch.setattr(undertow.commands.data, "info_file", leave)
    assert runner.invoke(app, ["info", "x.bag"]).exit_code == 5


# ---- options before data ---------------------------------------------------------------------

# the log does not exist: an option error must come first, naming the option's problem
LOCALIZE_OPTIONS = [
    (["--calibration", "{tmp}/missing_cal.yaml"], "missing_cal.yaml"),
    (["--profile", "{tmp}/missing_profile.yaml"], "missing_profile.yaml"),
    (["--wave", "heavy-seas"], "heavy-seas"),
    (["--variant", "fancy"], "variant"),
    (["--gate", "1.5"], "gate"),
    (["--initial-position", "1,2"], "--initial-position"),
    (["--smooth", "--output-rate", "10"], "smooth"),
]


@pytest.mark.parametrize("args, message", LOCALIZE_OPTIONS)
def test_localize_checks_its_options_before_reading_the_log(tmp_path, args, message):
    args = [a.format(tmp=tmp_path) for a in args]
    log = tmp_path / "missing_log"
    result = runner.invoke(app, ["localize", str(log), "--out", str(tmp_path / "o"), *args])
    line = _one_error_line(result)
    assert result.exit_code == 1 and message in line and "missing_log" not in line, line


def test_localize_checks_a_calibration_file_s_content_first(tmp_path):
    calibration = tmp_path / "cal.yaml"
    calibration.write_text("dvl_scale_factor: a lot\n")
    args = ["--out", str(tmp_path / "o"), "--calibration", str(calibration)]
    result = runner.invoke(app, ["localize", str(tmp_path / "missing_log"), *args])
    line = _one_error_line(result)
    assert "cal.yaml" in line and "missing_log" not in line


@pytest.mark.slow  # a subprocess: about 3 s
@pytest.mark.skipif(not hasattr(os, "mkfifo") or not UNDERTOW.exists(), reason="POSIX, script")
def test_a_bad_option_with_a_named_pipe_as_log_fails_at_once(tmp_path):
    """A FIFO blocks whoever opens it: the option error must come before the log is touched."""
    fifo = tmp_path / "pipe_log"
    os.mkfifo(fifo)
    done = subprocess.run(
        [str(UNDERTOW), "localize", str(fifo), "--out", str(tmp_path / "o"), "--calibration",
         str(tmp_path / "missing_cal.yaml")],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 1 and "missing_cal.yaml" in done.stderr, done.stderr


@pytest.mark.parametrize(
    "command, message",
    [
        (
            [
                "map",
                "{tmp}/log",
                "--trajectory",
                "{tmp}/t",
                "--out",
                "{tmp}/m",
                "--method",
                "csm",
                "--length-scale",
                "0.2",
            ],
            "length_scale",
        ),  # fmt: skip
        (
            [
                "map",
                "{tmp}/log",
                "--trajectory",
                "{tmp}/t",
                "--out",
                "{tmp}/m",
                "--resolution",
                "-1",
            ],
            "resolution",
        ),  # fmt: skip
        (["calibrate", "{tmp}/log", "--out", "{tmp}"], "is a directory"),
        (["characterize", "{tmp}/log", "--out", "{tmp}"], "is a directory"),
        (["evaluate", "trajectory", "{tmp}/est", "{tmp}/gt.tum", "--align", "best"], "align"),
        (["evaluate", "map", "{tmp}/map.npz", "{tmp}/gt.ply", "--threshold", "2"], "threshold"),
    ],
)
def test_other_commands_check_their_options_before_their_files(tmp_path, command, message):
    command = [a.format(tmp=tmp_path) for a in command]
    result = runner.invoke(app, command)
    line = _one_error_line(result)
    assert result.exit_code == 1 and message in line, line


def test_map_reads_the_prior_before_the_log(tmp_path):
    from undertow.trajectory import STATE_NAMES, Trajectory

    n = len(STATE_NAMES)
    Trajectory(np.arange(3.0), np.zeros((3, n)), np.tile(np.eye(n), (3, 1, 1))).save_npz(
        tmp_path / "trajectory.npz"
    )
    prior = tmp_path / "prior.npz"
    np.savez(prior, something=np.zeros(3))  # an npz, but not a map
    result = runner.invoke(app, ["map", str(tmp_path / "missing_log"), "--trajectory",
                                 str(tmp_path), "--prior", str(prior), "--out",
                                 str(tmp_path / "m")])  # fmt: skip
    line = _one_error_line(result)
    assert "prior.npz" in line and "missing_log" not in line, line


# ---- signals and leftovers -------------------------------------------------------------------


def test_sigterm_raises_terminated_and_the_temporary_output_goes(tmp_path):
    from undertow._util.atomic import atomic_path
    from undertow.cli._crash import sigterm_as_exception
    from undertow.errors import Terminated

    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Terminated):
        with sigterm_as_exception(), atomic_path(tmp_path / "out", directory=True) as tmp:
            (tmp / "partial").write_bytes(b"x" * 1000)
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)  # the handler interrupts this
    assert os.listdir(tmp_path) == []
    assert signal.getsignal(signal.SIGTERM) == before


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def _holder(folder: Path, name: str, pid: int, host: str | None = None) -> Path:
    from undertow._util import atomic

    path = folder / f".{name}.undertow-{pid}-{host or atomic._HOST}-abcd_123"
    (path / name).mkdir(parents=True)
    (path / name / "partial.mcap").write_bytes(b"x" * 100)
    return path


def _another_host() -> str:
    from undertow._util import atomic

    return "000000" if atomic._HOST != "000000" else "111111"


def test_stale_temporaries_of_dead_runs_go_and_nothing_else(tmp_path):
    from undertow._util.atomic import atomic_path

    dead = _holder(tmp_path, "run", _dead_pid())
    live = _holder(tmp_path, "run2", os.getpid())
    other_host = _holder(tmp_path, "run3", _dead_pid(), host=_another_host())
    not_ours = [tmp_path / ".run.abcd1234", tmp_path / ".run.undertow-1-zz-abcd1234"]
    for path in not_ours:
        path.mkdir()
    stale_file = tmp_path / f".x.undertow-{_dead_pid()}-000000-abcdefgh"
    stale_file.write_text("a file, not our folder")
    with atomic_path(tmp_path / "result.txt") as tmp:
        tmp.write_text("new")
    left = set(os.listdir(tmp_path))
    assert dead.name not in left
    assert {live.name, other_host.name, *(p.name for p in not_ours), stale_file.name,
            "result.txt"} == left  # fmt: skip


def _start_simulate(out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [str(UNDERTOW), "simulate", "calm", "--out", str(out), "-q"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def _wait_for_the_write(proc: subprocess.Popen, folder: Path, pattern: str) -> None:
    """Return once a temporary folder of ``proc``'s naming holds a partial file."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        holders = [p for p in folder.iterdir() if re.fullmatch(pattern, p.name)]
        if holders and any(f.is_file() for f in holders[0].rglob("*")):
            return
        time.sleep(0.02)
    proc.kill()
    pytest.fail("the run finished or timed out before its write could be interrupted")


@pytest.mark.slow
@pytest.mark.skipif(not UNDERTOW.exists(), reason="needs the console script")
def test_sigterm_during_a_write_leaves_nothing_and_exits_143(tmp_path):
    proc = _start_simulate(tmp_path / "run")
    _wait_for_the_write(proc, tmp_path, rf"\.run\.undertow-{proc.pid}-.*")
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 143, stderr
    assert "terminated" in stderr and "Traceback" not in stderr
    assert os.listdir(tmp_path) == []


@pytest.mark.slow
@pytest.mark.skipif(not UNDERTOW.exists(), reason="needs the console script")
def test_what_a_killed_run_leaves_is_removed_by_the_next_write_there(tmp_path):
    from undertow._util.atomic import atomic_path  # what every writer goes through

    proc = _start_simulate(tmp_path / "run")
    pattern = rf"\.run\.undertow-{proc.pid}-.*"
    _wait_for_the_write(proc, tmp_path, pattern)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    assert [p for p in os.listdir(tmp_path) if re.fullmatch(pattern, p)]  # the leftover
    live = _holder(tmp_path, "other", os.getpid())  # a run still writing here
    with atomic_path(tmp_path / "calibration.yaml") as tmp:
        tmp.write_text("dvl_scale_factor: 1.0\n")
    assert sorted(os.listdir(tmp_path)) == sorted([live.name, "calibration.yaml"])
