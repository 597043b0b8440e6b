"""Atomic outputs: all or nothing, permissions from the umask."""

import os

import pytest

from undertow._atomic import atomic_path


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
