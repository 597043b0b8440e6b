"""`undertow localize --estimator`: the peers write the UKF's outputs with the estimator recorded;
wrong combinations are one line before anything runs."""

import importlib.util

import numpy as np
import pytest
import yaml
from conftest import one_error_line
from typer.testing import CliRunner

from undertow.cli import app
from undertow.commands.localization import localize_file
from undertow.errors import ConfigError
from undertow.evaluation.trajectory import trajectory_rmse
from undertow.io.tum import read_tum
from undertow.peers import ESTIMATORS, resolve, run_estimator
from undertow.trajectory import Trajectory

runner = CliRunner()


def test_the_registry_names_the_ukf_and_the_peers():
    assert set(ESTIMATORS) == {"ukf", "factor-graph", "isam2", "inekf"}
    from undertow.estimation.localizer import localize

    assert resolve("ukf") is localize
    with pytest.raises(ConfigError, match="unknown"):
        resolve("kalman")


def test_smooth_with_a_peer_is_one_line(tmp_path):
    args = ["--estimator", "isam2", "--smooth"]
    result = runner.invoke(app, ["localize", str(tmp_path / "missing"), "--out",
                                 str(tmp_path / "o"), *args])  # fmt: skip
    assert "--smooth" in one_error_line(result)


def test_an_unknown_estimator_is_one_line(tmp_path):
    result = runner.invoke(app, ["localize", str(tmp_path / "missing"), "--out",
                                 str(tmp_path / "o"), "--estimator", "ekf"])  # fmt: skip
    assert "ekf" in one_error_line(result)


@pytest.mark.skipif(importlib.util.find_spec("undertow.peers.inekf") is not None,
                    reason="the InEKF is importable")  # fmt: skip
def test_an_estimator_not_importable_is_one_line(tmp_path):
    result = runner.invoke(app, ["localize", str(tmp_path / "missing"), "--out",
                                 str(tmp_path / "o"), "--estimator", "inekf"])  # fmt: skip
    assert "inekf" in one_error_line(result)


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["factor-graph", "isam2"])
def test_a_peer_localizes_a_simulated_run_like_the_ukf(simulated_run, tmp_path, estimator):
    """The peer's trajectory files are the UKF's (TUM, npz, config.yaml with the estimator), and
    its errors against the ground truth are of the UKF's order on the same run."""
    pytest.importorskip("gtsam")
    run = simulated_run("calm")
    out = tmp_path / estimator
    result = localize_file(run / "log", out_dir=out, estimator=estimator)
    ukf = localize_file(run / "log")
    for name in ("trajectory.tum", "trajectory.npz", "config.yaml"):
        assert (out / name).is_file()
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["estimator"] == estimator and config["accelerometer"] is True
    assert ukf.trajectory.metadata["estimator"] == "ukf"
    loaded = Trajectory.load_npz(out)
    assert np.all(np.isfinite(loaded.x)) and np.all(np.isfinite(loaded.P))
    assert result.trajectory.metadata["online"] is (estimator == "isam2")
    gt = read_tum(run / "ground_truth.tum")
    peer_rmse = trajectory_rmse(loaded, gt).rmse
    ukf_rmse = trajectory_rmse(ukf.trajectory, gt).rmse
    for axis in ("x_m", "y_m", "z_m"):
        assert peer_rmse[axis] < 2 * ukf_rmse[axis] + 0.02, (axis, peer_rmse, ukf_rmse)


@pytest.mark.slow
def test_run_estimator_runs_the_ukf_by_name(simulation):
    traj = run_estimator("ukf", simulation("calm").log, variant="baseline")
    assert traj.variant == "baseline"
