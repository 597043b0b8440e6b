"""Report figures drawn from a real pipeline run: simulate the rock survey, localize, map.

Each figure must be a valid PNG of exactly figsize x dpi pixels (read back with matplotlib),
written atomically (no temporary files left behind), and reject bad input with a clear error.
"""

import dataclasses

import numpy as np
import pytest
from matplotlib.image import imread

from undertow.errors import DataError
from undertow.estimation import localize
from undertow.mapping.config import MappingConfig
from undertow.mapping.mappers import make_mapper
from undertow.mapping.run import map_log
from undertow.report import figures, figures_map, figures_traj
from undertow.report.figures import DPI

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run(simulation):
    sim = simulation("rock-survey", 0)
    trajs = {v: localize(sim.log, variant=v) for v in ("baseline", "proposed")}
    maps = {
        m: map_log(sim.log, trajs["proposed"], MappingConfig(method=m)).map
        for m in ("adaptive", "bki")
    }
    return sim, trajs, maps


def check_png(path, width_in, height_in):
    assert path.is_file()
    assert path.read_bytes()[:8] == PNG_MAGIC
    image = imread(path)
    assert image.shape[:2] == (round(height_in * DPI), round(width_in * DPI))
    assert image[..., :3].std() > 0.01  # not a blank canvas
    leftovers = [p for p in path.parent.iterdir() if p.name.startswith(".")]
    assert leftovers == []  # atomic write cleaned up


@pytest.mark.slow
def test_trajectories_png(run, tmp_path):
    sim, trajs, _ = run
    out = figures_traj.plot_trajectories(tmp_path / "traj.png", sim.log.ground_truth, trajs)
    check_png(out, 10, 7)


@pytest.mark.slow
def test_trajectory_errors_png(run, tmp_path):
    sim, trajs, _ = run
    out = figures_traj.plot_trajectory_errors(tmp_path / "err.png", sim.log.ground_truth, trajs)
    check_png(out, 10, 7.5)


@pytest.mark.slow
def test_estimators_png(run, tmp_path):
    sim, trajs, _ = run
    trajs = {**trajs, "inekf": trajs["proposed"]}  # a third, dashed line
    out = figures_traj.plot_estimators(tmp_path / "est.png", sim.log.ground_truth, trajs, "t")
    check_png(out, 10, 10)


def test_estimators_reject_trajectory_outside_ground_truth(run, tmp_path):
    sim, trajs, _ = run
    late = dataclasses.replace(trajs["proposed"], t=trajs["proposed"].t + 1e4)
    with pytest.raises(DataError, match="overlap"):
        figures_traj.plot_estimators(tmp_path / "e.png", sim.log.ground_truth, {"late": late})
    assert not (tmp_path / "e.png").exists()


def test_trajectory_errors_reject_trajectory_outside_ground_truth(run, tmp_path):
    sim, trajs, _ = run
    late = dataclasses.replace(trajs["proposed"], t=trajs["proposed"].t + 1e4)
    with pytest.raises(DataError, match="overlap"):
        figures_traj.plot_trajectory_errors(
            tmp_path / "e.png", sim.log.ground_truth, {"late": late}
        )
    assert not (tmp_path / "e.png").exists()


@pytest.mark.slow
def test_map_distance_png(run, tmp_path):
    sim, _, maps = run
    out = figures_map.plot_map_distance(
        tmp_path / "d.png", maps["adaptive"].points(), sim.floor_cloud
    )
    check_png(out, 11, 7)


def test_map_distance_rejects_bad_cloud(tmp_path):
    with pytest.raises(DataError, match=r"\(N, 3\)"):
        figures_map.plot_map_distance(tmp_path / "d.png", np.zeros((4, 2)), np.zeros((4, 3)))


@pytest.mark.slow
def test_map_slice_png(run, tmp_path):
    sim, _, maps = run
    rock = sim.scenario.tank.rock
    y = (rock.center_y_m - 0.1, rock.center_y_m + 0.1)
    out = figures_map.plot_map_slice(tmp_path / "s.png", maps, sim.floor_cloud, y)
    check_png(out, 11, 1.2 + 2.2 * len(maps))


def test_velocity_png(run, tmp_path):
    sim, trajs, _ = run
    check_png(figures.plot_velocity(tmp_path / "v.png", sim.log, trajs["proposed"]), 10, 4)


def test_dvl_body_velocity_matches_ground_truth(run):
    """The DVL reading rotated to body axes tracks the true body velocity (independent
    check of the frame handling used by the velocity figures): median |error| < 5 cm/s."""
    sim, _, _ = run
    t, v = figures.dvl_body_velocity(sim.log)
    truth = sim.log.ground_truth.body_velocity(t)
    assert np.median(np.abs(v[:, 0] - truth[:, 0])) < 0.05


@pytest.mark.slow
def test_disturbance_png(run, tmp_path):
    sim, _, _ = run
    check_png(figures.plot_disturbance(tmp_path / "w.png", sim.log), 10, 7)


@pytest.mark.slow
def test_kernel_shapes_png(run, tmp_path):
    _, trajs, _ = run
    ls = make_mapper("adaptive").length_scales(trajs["proposed"].position_variance)
    out = figures.plot_kernel_shapes(tmp_path / "k.png", ls.min(axis=0), ls.max(axis=0))
    check_png(out, 10, 7.5)


def test_kernel_shapes_reject_non_positive_length(tmp_path):
    with pytest.raises(DataError, match="positive"):
        figures.plot_kernel_shapes(tmp_path / "k.png", 0.1, (0.2, 0.0, 0.1))


@pytest.mark.slow
def test_rock_map_png_from_tuple_and_model(run, tmp_path):
    sim, _, maps = run
    rock = sim.scenario.tank.rock
    as_tuple = (rock.center_x_m, rock.center_y_m, rock.length_m, rock.width_m, rock.height_m)
    depth = sim.scenario.water.depth_m
    check_png(
        figures_map.plot_rock_map(tmp_path / "r.png", maps["adaptive"], as_tuple, depth), 12, 5
    )
    check_png(figures_map.plot_rock_map(tmp_path / "r2.png", maps["adaptive"], rock, depth), 12, 5)


def test_the_report_package_exports_every_figure_from_its_module():
    import undertow.report as report

    assert report.plot_trajectories is figures_traj.plot_trajectories
    assert report.plot_map_slice is figures_map.plot_map_slice
    assert report.plot_velocity is figures.plot_velocity
    assert not hasattr(figures, "plot_trajectories")  # no re-export shim in figures.py
