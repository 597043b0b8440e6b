"""OccupancyMap: a flat floor from noiseless ranges, save/load, prior seeding, slices, PLY."""

import numpy as np
import pytest

from undertow.errors import ConfigError, ReaderError
from undertow.io.ply import write_map_ply
from undertow.log import Dvl, Log, SonarRange
from undertow.mapping.config import MappingConfig
from undertow.mapping.mappers import make_mapper, mapper_from_config
from undertow.mapping.samples import Samples, build_samples, samples_from_config
from undertow.occupancy import OccupancyMap
from undertow.robot import Mounting
from undertow.rotations import rpy_to_matrix
from undertow.trajectory import Trajectory

FLOOR, RES = 3.03, 0.1  # floor inside cell 30 (centre 3.05)


@pytest.fixture(scope="module")
def floor_survey():
    """A wavy track 1.5-2 m above a flat floor; ranges are exact intersections with it."""
    t = np.linspace(0, 60, 601)
    x = np.zeros((t.size, 18))
    x[:, 0], x[:, 1], x[:, 2] = 0.05 * t, 0.3 * np.sin(0.2 * t), 1.2
    x[:, 3], x[:, 4], x[:, 5] = (
        0.03 * np.sin(0.5 * t),
        0.02 * np.cos(0.4 * t),
        0.2 * np.sin(0.1 * t),
    )
    P = np.zeros((t.size, 18, 18))
    P[:, 0, 0], P[:, 1, 1], P[:, 2, 2] = 0.001 + 0.01 * t / 60, 0.001 + 0.005 * t / 60, 4e-4
    traj = Trajectory(t, x, P)
    tm, m = t[1:-1], Mounting()
    pos = x[1:-1, :3]
    R = rpy_to_matrix(x[1:-1, 3:6])
    units = Dvl.from_velocity(tm[:1], np.zeros((1, 3))).beam_unit[0]
    o = pos + R @ np.array(m.dvl.translation)
    v = np.einsum("nij,bj->nbi", R @ m.dvl.rotation_matrix(), units)
    r = (FLOOR - o[:, None, 2]) / v[:, :, 2]
    dvl = Dvl.from_velocity(tm, np.zeros((tm.size, 3)), beam_range=r, beam_valid=r > 0)
    o_s = pos + R @ np.array(m.sonar.translation)
    r_s = (FLOOR - o_s[:, 2]) / (R @ m.sonar.rotation_matrix())[:, 2, 2]
    log = Log(dvl=dvl, sonar=SonarRange(t=tm, range=r_s), mounting=m)
    return build_samples(log, traj), log, traj


@pytest.mark.parametrize("method", ["csm", "adaptive"])
def test_flat_floor_lands_within_half_a_cell(floor_survey, method):
    samples = floor_survey[0]
    np.testing.assert_allclose(samples.points[samples.label == 1, 2], FLOOR, atol=1e-9)
    mapper = make_mapper(method)
    mapper.integrate(samples)
    occ = mapper.occupancy().occupied()
    assert len(occ) > 200
    assert np.all(np.abs(occ.centres[:, 2] - FLOOR) <= RES / 2)
    top = occ.column_max()
    assert np.all(np.abs(top.centres[:, 2] - FLOOR) <= RES / 2)


def test_flat_floor_bki_max_mean_layer(floor_survey):
    # Isotropic l = 0.15 spreads hit mass to cells behind the floor that no free sample reaches
    # (a known BKI property); the max-mean cell per column is still the floor cell nearly always.
    mapper = make_mapper("bki")
    mapper.integrate(floor_survey[0])
    top = mapper.occupancy().occupied().column_max()
    assert np.mean(np.abs(top.centres[:, 2] - FLOOR) <= RES / 2) > 0.9


def test_config_factories_match_direct_calls(floor_survey):
    _, log, traj = floor_survey
    cfg = MappingConfig(method="bki", resolution=0.2)
    a = mapper_from_config(cfg)
    a.integrate(samples_from_config(log, traj, cfg))
    b = make_mapper("bki", resolution=0.2)
    b.integrate(build_samples(log, traj))
    np.testing.assert_array_equal(a.occupancy().alpha, b.occupancy().alpha)
    with pytest.raises(ConfigError, match="mapping.resolution"):
        MappingConfig.from_dict({"resolution": -1})
    with pytest.raises(ConfigError, match="l_min <= l_max"):
        MappingConfig.from_dict({"l_min": (0.2, 0.1, 0.05)})


def _random_samples(seed, n=2000):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-2, 2, (n, 3))
    return Samples.from_points(pts, (rng.random(n) < 0.3).astype(float), 0.9, rng.random((n, 3)))


def test_save_load_round_trip(tmp_path):
    m = make_mapper("adaptive", variance_bounds=((0, 0, 0), (1, 1, 1)))
    m.integrate(_random_samples(1))
    occ = m.occupancy()
    path = occ.save(tmp_path / "sub" / "map.npz")
    back = OccupancyMap.load(path)
    np.testing.assert_array_equal(back.cells, occ.cells)
    np.testing.assert_array_equal(back.alpha, occ.alpha)
    np.testing.assert_array_equal(back.beta, occ.beta)
    assert back.resolution == occ.resolution and back.alpha0 == occ.alpha0
    assert back.metadata["normalization"] == "fixed" and back.metadata["method"] == "adaptive"
    # atomic write: the folder holds the map and nothing else (no .map.npz.XXXX/ holder left)
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["map.npz"]
    with pytest.raises(ReaderError, match="no such map"):
        OccupancyMap.load(tmp_path / "missing.npz")


def test_prior_seeding_adds_evidence(tmp_path):
    s1, s2 = _random_samples(2), _random_samples(3)
    first = make_mapper("bki")
    first.integrate(s1)
    path = first.occupancy().save(tmp_path / "prior.npz")
    seeded = make_mapper("bki", prior=path)
    seeded.integrate(s2)
    both = make_mapper("bki")
    both.integrate(s1)
    both.integrate(s2)
    a, b = seeded.occupancy(), both.occupancy()
    oa, ob = np.lexsort(a.cells.T), np.lexsort(b.cells.T)
    np.testing.assert_array_equal(a.cells[oa], b.cells[ob])
    np.testing.assert_allclose(a.alpha[oa], b.alpha[ob], rtol=1e-5)
    np.testing.assert_allclose(a.beta[oa], b.beta[ob], rtol=1e-5)
    assert seeded.metadata()["seeded_from"] == str(path)
    with pytest.raises(ConfigError, match="resolution"):
        make_mapper("bki", resolution=0.2, prior=path)


def test_slices_and_points():
    m = make_mapper("csm")
    m.integrate(Samples.from_points([[0.05, 0.05, 0.05], [0.05, 0.05, 0.15], [0.25, 0.05, 0.15]],
                                    [1.0, 0.0, 1.0]))  # fmt: skip
    occ = m.occupancy()
    assert len(occ.slice(z_min=0.1, z_max=0.2)) == 2
    assert len(occ.slice(axis=0, index=2)) == 1
    np.testing.assert_allclose(np.sort(occ.points()[:, 0]), [0.05, 0.25])
    assert len(occ.occupied(threshold=0.99)) == 2 and len(occ.occupied(0.9999999999999)) == 0


def test_ply_written_with_mean_and_variance(tmp_path):
    m = make_mapper("bki")
    m.integrate(_random_samples(4, 300))
    occ = m.occupancy()
    path = write_map_ply(tmp_path / "map.ply", occ)
    data = path.read_bytes()
    head, body = data.split(b"end_header\n", 1)
    lines = head.decode().splitlines()
    assert "format binary_little_endian 1.0" in lines
    names = [ln.split()[-1] for ln in lines if ln.startswith("property")]
    assert names[:3] == ["x", "y", "z"] and {"mean", "variance"} <= set(names)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.ply"]
    kinds = {"double": "<f8", "float": "<f4"}
    dtype = [(ln.split()[2], kinds[ln.split()[1]]) for ln in lines if ln.startswith("property")]
    rows = np.frombuffer(body, dtype=dtype)
    k = occ.occupied()
    assert len(rows) == len(k)
    np.testing.assert_allclose(rows["z"], k.centres[:, 2], rtol=1e-6)
    np.testing.assert_allclose(rows["mean"], k.mean, rtol=1e-6)


def test_save_map_writes_the_result_folder_at_once(tmp_path):
    import yaml

    from undertow.io.results import save_map

    m = make_mapper("csm")
    m.integrate(Samples.from_points([[0.05, 0.05, 0.05], [0.05, 0.05, 0.15]], [1.0, 0.0]))
    occ = m.occupancy()
    out = save_map(occ, {"method": "csm"}, {"cells": 2}, tmp_path / "m", threshold=0.5)
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "map.npz", "map.ply"]
    doc = yaml.safe_load((out / "config.yaml").read_text())
    assert doc == {"mapping": {"method": "csm"}, "result": {"cells": 2}}
    np.testing.assert_array_equal(OccupancyMap.load(out).cells, occ.cells)
    with pytest.raises(ConfigError, match="not empty"):
        save_map(occ, {}, {}, out, threshold=0.5)
    save_map(occ, {}, {}, out, overwrite=True, threshold=0.5)
    assert yaml.safe_load((out / "config.yaml").read_text()) == {"mapping": {}, "result": {}}


def test_loading_another_kind_of_file_as_a_map_says_what_was_expected(tmp_path):
    """A PLY, TUM or YAML file given as a map: one line naming the file, what it looks like and
    what was expected (not numpy's message about pickled data)."""
    ply = tmp_path / "ground_truth.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nend_header\n")
    tum = tmp_path / "trajectory.tum"
    tum.write_text("0 0 0 0 0 0 0 1\n")
    for path, kind in ((ply, "a PLY point cloud"), (tum, "a TUM trajectory")):
        with pytest.raises(ReaderError) as info:
            OccupancyMap.load(path)
        assert str(info.value) == f"{path}: {kind}, expected a map.npz written by `undertow " \
            "map` (or its folder)"  # fmt: skip
