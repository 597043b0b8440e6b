"""TUM trajectories and PLY clouds: round trips, hand-written files, malformed input."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import DataError, ReaderError
from undertow.io import read_ply, read_tum, write_ply, write_tum
from undertow.io.tum import read_tum_poses
from undertow.log import GroundTruth
from undertow.rotations import rpy_to_quaternion


def test_tum_round_trip_and_format(tmp_path):
    rng = np.random.default_rng(1)
    t = 1.7e9 + np.cumsum(rng.uniform(0.01, 0.1, 20))
    pos = rng.normal(0, 10, (20, 3))
    rpy = np.column_stack([rng.uniform(-1, 1, (20, 2)), rng.uniform(-3, 3, 20)])
    path = write_tum(tmp_path / "traj.tum", t, pos, rpy)
    rows = np.loadtxt(path)  # plain numpy parse of the file: t tx ty tz qx qy qz qw
    np.testing.assert_array_equal(rows[:, 0], t)
    np.testing.assert_array_equal(rows[:, 1:4], pos)
    np.testing.assert_allclose(rows[:, 4:8], rpy_to_quaternion(rpy), atol=0)
    poses = read_tum(path)
    assert isinstance(poses, GroundTruth) and poses.velocity is None
    np.testing.assert_array_equal(poses.t, t)
    np.testing.assert_array_equal(poses.position, pos)
    np.testing.assert_allclose(poses.orientation, rpy, atol=1e-12)


def test_tum_malformed_line_skipped_and_counted(tmp_path):
    path = tmp_path / "bad.tum"
    path.write_text("# header\n0 0 0 0 0 0 0 1\n1 2 3\n2 1 1 1 0 0 0 1\nnan 1 1 1 0 0 0 1\n")
    with pytest.warns(UserWarning) as caught:
        poses = read_tum(path)
    text = [str(w.message) for w in caught]
    assert any("bad.tum: malformed TUM lines skipped: 1 (first: line 3" in t for t in text)
    assert any("non-finite time dropped: 1" in t for t in text)
    np.testing.assert_array_equal(poses.t, [0.0, 2.0])  # the good poses kept, NaN time dropped
    path.write_text("1 2 3\n")
    with pytest.raises(ReaderError, match=r"bad\.tum: no usable pose"):
        read_tum(path)


def test_extended_tum_round_trip_with_standard_deviations(tmp_path):
    rng = np.random.default_rng(5)
    t, pos = np.arange(12.0) + 0.5, rng.normal(0, 3, (12, 3))
    rpy = np.column_stack([rng.uniform(-1, 1, (12, 2)), rng.uniform(-3, 3, 12)])
    std = rng.uniform(0, 0.3, (12, 6))
    path = write_tum(tmp_path / "traj.tum", t, pos, rpy, std)
    assert path.read_text().splitlines()[0] == "# t tx ty tz qx qy qz qw sx sy sz sroll spitch syaw"
    rows = np.loadtxt(path)  # 14 plain columns
    np.testing.assert_array_equal(rows[:, 8:], std)
    poses = read_tum_poses(path)
    np.testing.assert_array_equal(poses.std, std)
    np.testing.assert_array_equal(poses.position, pos)
    np.testing.assert_allclose(poses.orientation, rpy, atol=1e-12)
    assert read_tum_poses(write_tum(tmp_path / "plain.tum", t, pos, rpy)).std is None
    np.testing.assert_array_equal(read_tum(path).t, t)  # ground truth from it: the poses


def test_extended_tum_bad_lines_and_bad_standard_deviations(tmp_path):
    path = tmp_path / "ext.tum"
    good = "0 0 0 0 0 0 0 1 0.1 0.1 0.1 0 0 0\n"
    path.write_text(good + "1 0 0 0 0 0 0 1\n2 0 0 nan 0 0 0 1 0.1 0.1 0.1 0 0 0\n" + good)
    with pytest.warns(UserWarning) as caught:
        poses = read_tum_poses(path)
    text = [str(w.message) for w in caught]
    assert any("line 2: 8 fields, expected 14 (t tx ty tz qx qy qz qw sx sy sz sroll" in x
               for x in text)  # fmt: skip
    assert len(poses) == 3 and np.isnan(poses.position[poses.t == 2, 2]).all()  # kept, as NaN
    for value in ("-0.1", "nan", "inf"):
        path.write_text(good + f"1 0 0 0 0 0 0 1 0.1 {value} 0.1 0 0 0\n")
        with pytest.raises(DataError) as error:
            read_tum_poses(path)
        assert str(error.value) == (
            f"{path}: line 2: standard deviations sx sy sz sroll spitch syaw must be finite and "
            f">= 0, got 0.1 {float(value):g} 0.1 0 0 0"
        )


@pytest.mark.parametrize("binary", [True, False])
def test_ply_round_trip(tmp_path, binary):
    rng = np.random.default_rng(2)
    pts = rng.normal(0, 3, (100, 3))
    prob = rng.uniform(0, 1, 100)
    path = write_ply(tmp_path / "map.ply", pts, {"probability": prob}, binary=binary)
    assert path.read_bytes().startswith(
        b"ply\nformat " + (b"binary_little" if binary else b"ascii")
    )
    pts2, props = read_ply(path)
    np.testing.assert_array_equal(pts2, pts.astype(np.float32))
    np.testing.assert_array_equal(props["probability"], prob.astype(np.float32))


def test_hand_written_ascii_ply_with_faces(tmp_path):
    path = tmp_path / "hand.ply"
    path.write_text(
        "ply\nformat ascii 1.0\ncomment by hand\nelement vertex 3\nproperty double x\n"
        "property double y\nproperty double z\nproperty uchar red\nelement face 1\n"
        "property list uchar int vertex_indices\nend_header\n"
        "0 0 0 255\n1.5 0 0 0\n0 2.25 -1 10\n3 0 1 2\n"
    )
    pts, props = read_ply(path)
    np.testing.assert_array_equal(pts, [[0, 0, 0], [1.5, 0, 0], [0, 2.25, -1]])
    np.testing.assert_array_equal(props["red"], [255, 0, 10])


def test_ply_not_a_ply(tmp_path):
    (tmp_path / "x.ply").write_text("hello\n")
    with pytest.raises(ReaderError, match=r"x\.ply: not a PLY"):
        read_ply(tmp_path / "x.ply")


@pytest.mark.parametrize("binary", [False, True])
def test_a_cloud_with_no_points_reads_as_empty(tmp_path, binary):
    """A map with no occupied cell is a valid PLY of 0 vertices, not a malformed file."""
    path = write_ply(tmp_path / "empty.ply", np.zeros((0, 3)), binary=binary)
    points, _ = read_ply(path)
    assert points.shape == (0, 3)
