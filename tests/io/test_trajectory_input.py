"""A trajectory made elsewhere (TUM) for mapping: the frame change against its closed form, the
covariance the mapper reads, which standard deviations apply, the frame told from the log's
depth (hydrostatic pressure built here from a chosen depth), the time overlap."""

from __future__ import annotations

import numpy as np
import pytest

from undertow.errors import ConfigError, DataError
from undertow.io.trajectory_input import (
    TrajectoryOptions,
    check_overlap,
    detect_frame,
    enu_to_ned,
    read_tum_input,
    trajectory_from_poses,
)
from undertow.io.tum import write_tum
from undertow.log import FRESH_WATER_DENSITY, G0, P_ATM, Depth, Log, Pressure, SonarRange
from undertow.rotations import rpy_to_matrix, wrap_angle


def _rpy(rng, n):
    return np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-1.4, 1.4, n),
                            rng.uniform(-3, 3, n)])  # fmt: skip


def test_enu_to_ned_is_the_closed_form_and_its_own_inverse():
    rng = np.random.default_rng(3)
    p, rpy = rng.normal(0, 5, (50, 3)), _rpy(rng, 50)
    p2, rpy2 = enu_to_ned(p, rpy)
    # x north = y of ENU, y east = x of ENU, z down = -z up
    np.testing.assert_array_equal(p2, np.column_stack([p[:, 1], p[:, 0], -p[:, 2]]))
    # the angles (derivation: C = Rz(pi/2) Rx(pi), B = Rx(pi), Rx(pi) Rz(a) = Rz(-a) Rx(pi))
    expected = np.column_stack([rpy[:, 0], -rpy[:, 1], np.pi / 2 - rpy[:, 2]])
    np.testing.assert_allclose(wrap_angle(rpy2 - expected), 0, atol=1e-12)
    # the body's forward axis points the same way in the world, its left axis is the NED body's -y
    R, R2 = rpy_to_matrix(rpy), rpy_to_matrix(rpy2)
    enu_to_ned_world = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]])
    np.testing.assert_allclose(R2[:, :, 0], R[:, :, 0] @ enu_to_ned_world.T, atol=1e-12)
    np.testing.assert_allclose(R2[:, :, 1], -(R[:, :, 1] @ enu_to_ned_world.T), atol=1e-12)
    back = enu_to_ned(p2, rpy2)
    np.testing.assert_allclose(back[0], p, atol=0)
    np.testing.assert_allclose(wrap_angle(back[1] - rpy), 0, atol=1e-12)


def test_trajectory_from_poses_carries_the_stated_diagonal_and_nothing_else():
    rng = np.random.default_rng(4)
    t = np.arange(10.0)
    p, rpy = rng.normal(size=(10, 3)), _rpy(rng, 10)
    std = rng.uniform(0.01, 0.2, (10, 3))
    traj = trajectory_from_poses(t, p, rpy, std, (0.01, 0.02, 0.03))
    np.testing.assert_array_equal(traj.position, p)
    np.testing.assert_array_equal(traj.orientation, rpy)
    np.testing.assert_allclose(traj.position_variance, std**2, rtol=1e-15)
    block = traj.P[:, :6, :6]
    np.testing.assert_allclose(np.einsum("nii->ni", block)[:, 3:], [[1e-4, 4e-4, 9e-4]] * 10)
    assert np.all(block - np.einsum("ni,ij->nij", np.einsum("nii->ni", block), np.eye(6)) == 0)
    # velocities and biases are unknown: NaN, as are their covariances
    assert np.isnan(traj.x[:, 6:]).all() and np.isnan(traj.P[:, 6:, :]).all()
    # orientation std not stated: unknown
    assert np.isnan(trajectory_from_poses(t, p, rpy, (0.1, 0.1, 0.1)).P[:, 3:6, 3:6]).all()
    for bad in ((0.1, np.nan, 0.1), (0.1, -0.1, 0.1)):
        with pytest.raises(DataError, match="finite and >= 0"):
            trajectory_from_poses(t, p, rpy, bad)


def test_stated_options_are_checked_in_one_line():
    assert TrajectoryOptions.stated() is None
    opts = TrajectoryOptions.stated([0.1, 0.2, 0.3, 0.01, 0.02, 0.03], "enu")
    assert opts.position_std_m == (0.1, 0.2, 0.3) and opts.orientation_std_rad == (0.01, 0.02, 0.03)
    assert TrajectoryOptions.stated((0.1, 0.2, 0.3)).orientation_std_rad is None
    with pytest.raises(ConfigError, match="expected 3 or 6 values"):
        TrajectoryOptions.stated([0.1, 0.2])
    with pytest.raises(ConfigError, match=r"position_std_m\.1: .*greater than or equal to 0"):
        TrajectoryOptions.stated([0.1, -0.2, 0.3])
    with pytest.raises(ConfigError, match="position_std_m.0"):
        TrajectoryOptions.stated([float("inf"), 0.2, 0.3])
    with pytest.raises(ConfigError, match="frame"):
        TrajectoryOptions.stated(None, "up")


def test_which_standard_deviations_apply(tmp_path):
    t, p, rpy = np.arange(3.0), np.zeros((3, 3)), np.zeros((3, 3))
    plain = write_tum(tmp_path / "plain.tum", t, p, rpy)
    cols = np.array([[0.1, 0.2, 0.3, 0.01, 0.02, 0.03]] * 3)
    extended = write_tum(tmp_path / "ext.tum", t, p, rpy, cols)
    settings = TrajectoryOptions(position_std_m=(1, 1, 1))
    stated = TrajectoryOptions.stated((2, 2, 2))
    # the file's columns win over the settings, the command line over both
    got = read_tum_input(extended, settings)
    np.testing.assert_array_equal(got.position_std, cols[:, :3])
    assert not got.constant and got.covariance.startswith("the file's columns sx sy sz")
    got = read_tum_input(extended, settings, stated)
    np.testing.assert_array_equal(got.position_std, [2, 2, 2])
    assert got.constant and "replacing the file's std columns" in got.covariance
    got = read_tum_input(plain, settings)
    np.testing.assert_array_equal(got.position_std, [1, 1, 1])
    assert got.covariance == "settings trajectory.position_std_m 1,1,1 (constant)"
    with pytest.raises(DataError) as caught:
        read_tum_input(plain)
    assert str(caught.value) == (
        f"{plain}: a TUM file without std columns needs the pose's uncertainty: add --pose-std "
        "SX,SY,SZ[,SROLL,SPITCH,SYAW] (m, rad) or the settings' trajectory: {position_std_m: "
        "[SX, SY, SZ]}"
    )


def test_poses_that_are_not_finite_are_dropped_with_a_warning(tmp_path):
    path = tmp_path / "nan.tum"
    path.write_text("0 0 0 0 0 0 0 1\n1 0 nan 0 0 0 0 1\n2 0 0 0 0 0 0 0\n3 1 1 1 0 0 0 1\n")
    with pytest.warns(UserWarning, match=r"nan\.tum: 2 poses with a non-finite position or q"):
        got = read_tum_input(path, stated=TrajectoryOptions.stated((0.1, 0.1, 0.1)))
    np.testing.assert_array_equal(got.poses.t, [0.0, 3.0])
    path.write_text("1 0 nan 0 0 0 0 1\n")
    with pytest.raises(DataError, match="no pose with a finite position and quaternion"):
        read_tum_input(path, stated=TrajectoryOptions.stated((0.1, 0.1, 0.1)))


def _log_with_depth(t, depth, stream="pressure"):
    """A log whose pressure is the hydrostatic p = p_atm + rho g d of the given depth (the
    default references: fresh water, one atmosphere), or a depth stream of it."""
    if stream == "pressure":
        pressure = P_ATM + FRESH_WATER_DENSITY * G0 * np.asarray(depth)
        return Log(pressure=Pressure(t=t, pressure=pressure))
    return Log(depth=Depth(t=t, depth=np.asarray(depth)))


@pytest.mark.parametrize("stream", ["pressure", "depth"])
def test_the_frame_is_told_from_the_logs_depth(stream):
    t = np.linspace(0, 60, 601)
    varying = 2.0 + 0.5 * np.sin(t / 5)
    log = _log_with_depth(t, varying, stream)
    # a varying depth: the correlation, whatever the trajectory's origin
    for z, frame in ((varying, "ned"), (-varying, "enu"), (varying - 2.3, "ned"),
                     (2.3 - varying, "enu")):  # fmt: skip
        found, why = detect_frame(t, z, log)
        assert found == frame, why
        assert "correlation" in why and stream in why
    # a constant depth: the levels tell z = depth from z = -depth ...
    flat = _log_with_depth(t, np.full(t.size, 0.5), stream)
    assert detect_frame(t, np.full(t.size, 0.5), flat)[0] == "ned"
    assert detect_frame(t, np.full(t.size, -0.5), flat)[0] == "enu"
    # ... but not a trajectory whose origin is at the start (z = 0 = -0)
    found, why = detect_frame(t, np.zeros(t.size), flat)
    assert found is None and "neither follows nor mirrors" in why
    # at the surface z = depth = -depth
    assert (
        detect_frame(t, np.zeros(t.size), _log_with_depth(t, np.zeros(t.size), stream))[0] is None
    )


def test_no_depth_to_compare_with_says_why():
    t = np.linspace(0, 10, 11)
    assert detect_frame(t, t, Log()) == (None, "the log has no pressure or depth stream")
    log = _log_with_depth(t + 100, np.full(11, 1.0))
    assert detect_frame(t, t, log) == (None, "no pressure sample within the trajectory's time span")


def test_poses_outside_the_logs_ranges_name_the_file(tmp_path):
    t = np.linspace(0, 10, 11)
    log = Log(sonar=SonarRange(t=t, range=np.ones(11)))
    check_overlap(tmp_path / "a.tum", np.array([5.0, 50.0]), log)  # overlaps: fine
    with pytest.raises(DataError) as caught:
        check_overlap(tmp_path / "a.tum", np.array([1e9, 1e9 + 10]), log)
    assert str(caught.value).startswith(
        f"{tmp_path / 'a.tum'}: its poses (1000000000.000 .. 1000000010.000 s) do not overlap "
        "the log's ranges (0.000 .. 10.000 s)"
    )
