"""The XYZ reader on good files, on damaged ones, and on hypothesis-made bytes: it returns the
good points (counting the rest in one warning) or raises one ReaderError line, nothing else."""

from __future__ import annotations

import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir

from undertow.errors import DataError, ReaderError
from undertow.io.xyz import read_xyz

set_hypothesis_home_dir(Path(tempfile.gettempdir()) / "undertow-hypothesis")
FAST = hsettings(max_examples=60, deadline=None, database=None)


def _write(tmp: Path, content: bytes | str, name: str = "f.xyz") -> Path:
    path = tmp / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


def test_spaces_commas_comments_and_a_bom(tmp_path):
    text = "\ufeff# survey\n1 2 3\n4,5,6  # a comment\n\n  7\t8 , 9\n-1e2 0.5 +2.5e-1\n"
    points = read_xyz(_write(tmp_path, text))
    np.testing.assert_array_equal(points, [[1, 2, 3], [4, 5, 6], [7, 8, 9], [-100, 0.5, 0.25]])


def test_malformed_lines_are_skipped_and_counted_in_one_warning(tmp_path):
    text = "x y z\n1 2 3\n1 2\n4 5 6\n1 2 3 4\nnan 1 2\n1e999 0 0\n7 8 9\n"
    with pytest.warns(UserWarning) as caught:
        points = read_xyz(_write(tmp_path, text))
    np.testing.assert_array_equal(points, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    assert len(caught) == 1
    message = str(caught[0].message)
    assert "malformed XYZ lines skipped: 5" in message and "line 1 'x y z'" in message


@pytest.mark.parametrize("content", ["", "# only a comment\n\n", "a b c\n1 2\n", b"\x00\xff\x01"])
def test_no_usable_point_is_one_error_line(tmp_path, content):
    path = _write(tmp_path, content)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the error says it all: no warning before it
        with pytest.raises(ReaderError) as info:
            read_xyz(path)
    message = str(info.value)
    assert message.startswith(f"{path}: no usable x y z point") and "\n" not in message


def test_a_missing_file_and_a_folder_are_one_error_line(tmp_path):
    for path in (tmp_path / "none.xyz", tmp_path):
        with pytest.raises(ReaderError, match=str(path)):
            read_xyz(path)


def _outcome(path: Path):
    """read_xyz's points, or None after a one-line ReaderError/DataError; any other exception
    or a non-UserWarning warning fails."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result = read_xyz(path)
        except (ReaderError, DataError) as exc:
            assert str(exc) and "\n" not in str(exc)
            result = None
    assert all(issubclass(w.category, UserWarning) for w in caught), [str(w) for w in caught]
    return result


@FAST
@given(st.binary(max_size=400))
def test_random_bytes_give_points_or_one_error(data):
    with tempfile.TemporaryDirectory() as tmp:
        points = _outcome(_write(Path(tmp), data))
    if points is not None:
        assert points.ndim == 2 and points.shape[1] == 3 and np.isfinite(points).all()


NUMBER = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**400), 10**400).map(str),
    st.sampled_from(["", "-", "1e", "1e999", "0x10", "1_0", ",", "#", "\t", "nan", "1.5.2"]),
)


@FAST
@given(
    st.lists(st.lists(NUMBER, min_size=0, max_size=5), max_size=20),
    st.sampled_from([" ", ",", "\t", " , "]),
    st.integers(0, 200),
)
def test_damaged_and_truncated_lines_keep_every_good_point(rows, sep, cut):
    """Lines of hypothesis-made fields, the file cut at a random byte: every point the reader
    returns is one of the whole, good lines, in order, and each good line before the cut is kept."""
    lines = [sep.join(fields) for fields in rows]
    text = "\n".join(lines)[: max(cut, 0) or None]
    with tempfile.TemporaryDirectory() as tmp:
        points = _outcome(_write(Path(tmp), text))
    kept_lines = text.split("\n")
    expected = []
    for line in kept_lines:
        fields = line.split("#", 1)[0].replace(",", " ").split()
        try:
            values = [float(v) for v in fields]
        except ValueError:
            continue
        if len(values) == 3 and np.isfinite(values).all():
            expected.append(values)
    if not expected:
        assert points is None
    else:
        np.testing.assert_array_equal(points, np.array(expected))
