"""Atomic outputs: all or nothing, permissions from the umask."""

import os

import pytest

from undertow._util.atomic import atomic_path


def test_file_appears_only_on_success(tmp_path):
    target = tmp_path / "a.txt"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert not target.exists() and os.listdir(tmp_path) == []
    with atomic_path(target) as tmp:
        tmp.write_text("whole")
    assert target.read_text() == "whole"
    assert os.listdir(tmp_path) == ["a.txt"]


def test_directory_is_replaced_as_a_whole_with_umask_modes(tmp_path):
    target = tmp_path / "out"
    target.mkdir()
    (target / "stale").write_text("x")
    old = os.umask(0o022)
    try:
        with atomic_path(target, directory=True) as tmp:
            (tmp / "new").write_text("y")
    finally:
        os.umask(old)
    assert sorted(os.listdir(target)) == ["new"]
    assert (target.stat().st_mode & 0o777) == 0o755


def test_a_file_write_never_replaces_a_directory(tmp_path):
    """Writing a file where a run folder stands is a user mistake, not a reason to delete it."""
    from undertow.errors import ConfigError

    run = tmp_path / "run"
    run.mkdir()
    (run / "log.mcap").write_text("precious")
    with pytest.raises(ConfigError, match="is a directory"):
        with atomic_path(run) as tmp:
            tmp.write_text("calibration")
    assert (run / "log.mcap").read_text() == "precious"


def test_output_folder_refuses_a_file_and_a_non_empty_folder_unless_overwrite(tmp_path):
    from undertow._util.atomic import output_folder
    from undertow.errors import ConfigError

    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(ConfigError, match="existing file"):
        with output_folder(afile):
            pass
    full = tmp_path / "full"
    full.mkdir()
    (full / "old").write_text("x")
    with pytest.raises(ConfigError, match="--overwrite"):
        with output_folder(full):
            pass
    assert (full / "old").exists()
    with output_folder(full, overwrite=True) as tmp:
        (tmp / "new").write_text("y")
    assert sorted(os.listdir(full)) == ["new"]


def test_output_folder_never_holds_an_input_and_is_probed_before_the_work(tmp_path):
    """--out on the log's own folder (or a parent of it) would delete the input even with
    --overwrite; a place that cannot be written fails before any work, naming the path given."""
    from undertow._util.atomic import check_output_folder
    from undertow.errors import ConfigError

    run = tmp_path / "run"
    (run / "log").mkdir(parents=True)
    (run / "log" / "log.mcap").write_text("bag")
    for out in (run / "log", run):
        with pytest.raises(ConfigError, match="holds the input"):
            check_output_folder(out, overwrite=True, inputs=[run / "log"])
    assert check_output_folder(run / "est", inputs=[run / "log"]) == run / "est"
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    with pytest.raises(ConfigError, match="cannot write here"):
        check_output_folder(blocker / "sub" / "out")
    assert not (tmp_path / "afile" / "sub").exists()
