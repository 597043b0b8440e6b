"""write_simulation: the run folder reads back (bag, TUM at the carriage rate, PLY, scenario)."""

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.io import read_log
from undertow.io.ply import read_ply
from undertow.io.tum import read_tum
from undertow.sim import Scenario, load_scenario, simulate, write_simulation


@pytest.mark.slow
def test_write_simulation_round_trip(tmp_path):
    s = load_scenario("wave-a0.05-f0.75").to_yaml_dict()
    s["motion"]["carriage"]["run_length_m"] = 3.0
    s["floor_cloud"]["spacing_m"] = 0.1
    result = simulate(Scenario.model_validate(s), seed=11)
    out = write_simulation(result, tmp_path / "run")
    assert sorted(p.name for p in out.iterdir()) == [
        "ground_truth.ply", "ground_truth.tum", "log", "scenario.yaml",
    ]  # fmt: skip
    tum = read_tum(out / "ground_truth.tum")
    t, pos = tum.t, tum.position
    gt = result.log.ground_truth
    assert t.size == len(gt) and np.median(np.diff(t)) == pytest.approx(1 / 2000.0)
    np.testing.assert_allclose(pos, gt.position, atol=1e-9)
    points, _ = read_ply(out / "ground_truth.ply")
    np.testing.assert_allclose(points, result.floor_cloud, atol=1e-5)
    again = load_scenario(out / "scenario.yaml")
    assert again == result.scenario and again.seed == 11
    log = read_log(out / "log")
    assert len(log.dvl) == len(result.log.dvl) and len(log.imu) == len(result.log.imu)
    with pytest.raises(ConfigError, match="not empty"):
        write_simulation(result, out)
    write_simulation(result, out, overwrite=True)
    assert (out / "log").is_dir()
