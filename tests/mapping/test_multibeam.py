"""DVL geometry presets and the multibeam echosounder: beam vectors in closed form, the A50
default unchanged, multibeam ranges over a flat floor against h / cos(theta) and the noise
model's formula, PointCloud2 round trip, mapping a tilted plane, `undertow info`."""

import json

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from undertow.cli import app
from undertow.errors import ConfigError, DataError
from undertow.io import read_log, write_log
from undertow.io.msgdefs import dvl_typestore
from undertow.io.rosbag_streams import cloud_points
from undertow.io.rosbag_write import MessageBuilder, multibeam_message
from undertow.log import GroundTruth, Log, Multibeam
from undertow.mapping.config import MappingConfig
from undertow.mapping.mappers import mapper_from_config
from undertow.mapping.run import map_log
from undertow.mapping.samples import SENSOR_MULTIBEAM, build_samples
from undertow.mapping.surface import map_surface
from undertow.robot import (
    DVL_PRESETS,
    DvlGeometry,
    Mounting,
    SensorMount,
    a50_beam_units,
    dvl_preset,
)
from undertow.rotations import rpy_to_matrix
from undertow.sim import Scenario, load_scenario, simulate
from undertow.sim.scenario.sensors import MultibeamModel
from undertow.sim.sensors.multibeam import range_sigma
from undertow.trajectory import Trajectory

runner = CliRunner()

# -- DVL geometry -------------------------------------------------------------------------------

DATASHEET_TILTS = {"a50": 22.5, "dvl1000": 25.0, "pathfinder": 30.0}


def test_pathfinder_beam_numbering_follows_the_guide():
    """The Pathfinder DVL Guide's PD4 convention, mounted beam 3 forward: X velocity positive
    moving toward beam 2, Y positive moving toward beam 3, so with y to starboard here beam 2
    points to starboard, beam 1 to port, beam 4 aft."""
    units = dvl_preset("pathfinder").units()
    horizontal = units[:, :2] / np.linalg.norm(units[:, :2], axis=1, keepdims=True)
    np.testing.assert_allclose(horizontal, [[0, -1], [0, 1], [1, 0], [-1, 0]], atol=1e-15)


@pytest.mark.parametrize("name", sorted(DATASHEET_TILTS))
def test_presets_give_the_beam_vectors_of_their_tilt_and_azimuths(name):
    """b_i = Rz(az_i) Ry(tilt) e_z: the datasheet tilt from the vertical, the azimuth about z."""
    g = dvl_preset(name)
    assert g.tilt_deg == DATASHEET_TILTS[name] and g.beams == 4
    units = g.units()
    for b, az in zip(units, g.azimuths_deg, strict=True):
        want = Rotation.from_euler("ZY", [az, g.tilt_deg], degrees=True).apply([0.0, 0.0, 1.0])
        np.testing.assert_allclose(b, want, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(units, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(np.degrees(np.arccos(units[:, 2])), g.tilt_deg, atol=1e-12)
    # a Janus head: opposite beams pair up, the horizontal parts cancel
    np.testing.assert_allclose(units[:, :2].sum(axis=0), 0.0, atol=1e-15)


def test_the_a50_default_is_unchanged():
    """The A50 numbers of its documentation (horizontal 0.383, vertical 0.924, transducer 1 at
    +135 deg), the preset equal to a50_beam_units bit for bit, and the scenario's default DVL."""
    b = a50_beam_units()
    np.testing.assert_allclose(np.hypot(b[:, 0], b[:, 1]), 0.383, atol=5e-4)
    np.testing.assert_allclose(b[:, 2], 0.924, atol=5e-4)
    assert b[0, 0] < 0 < b[0, 1]  # +135 deg: backwards and to starboard
    assert np.array_equal(DVL_PRESETS["a50"].units(), b)
    s = load_scenario("calm")
    assert s.dvl.model == "a50" and s.dvl.geometry() == DVL_PRESETS["a50"]


def test_scenario_dvl_model_sets_geometry_and_given_fields_override():
    base = _short_scenario()
    s = Scenario.model_validate({**base, "dvl": {"model": "pathfinder"}})
    assert s.dvl.beam_tilt_deg == 30.0 and s.dvl.geometry() == DVL_PRESETS["pathfinder"]
    s = Scenario.model_validate({**base, "dvl": {"model": "dvl1000", "beam_tilt_deg": 20.0}})
    assert s.dvl.geometry().tilt_deg == 20.0
    assert s.dvl.geometry().azimuths_deg == DVL_PRESETS["dvl1000"].azimuths_deg
    with pytest.raises(ConfigError, match="dvl.model"):
        load_scenario_dict({**base, "dvl": {"model": "dvl9000"}})
    with pytest.raises(ConfigError, match="beam_azimuths_deg"):
        load_scenario_dict({**base, "dvl": {"beam_azimuths_deg": [0, 90, 180]}})
    with pytest.raises(ConfigError, match="tilt"):
        DvlGeometry("x", 95.0, (0, 90, 180, 270))


def test_simulator_and_readers_use_the_configured_geometry(tmp_path):
    """A Pathfinder run: beam vectors are the preset's, the least-squares velocity over them
    matches the truth, and the A50 driver bag (no beam vectors in its messages) reads them
    back from the recorded geometry."""
    base = _short_scenario()
    r = simulate(Scenario.model_validate({**base, "dvl": {"model": "pathfinder"}}), seed=1)
    d = r.log.dvl
    assert np.array_equal(d.beam_unit[0], DVL_PRESETS["pathfinder"].units())
    ok = d.beam_valid.all(axis=1)
    # ranges along 30 deg beams over the flat floor: altitude / cos(30 deg) to the noise
    vertical = d.beam_range[ok] * d.beam_unit[ok][..., 2]
    assert np.abs(vertical - d.altitude[ok][:, None]).max() < 0.05
    gt = r.log.ground_truth
    _, rpy, v_world = gt.interpolate(d.t, gt.velocity)
    R_wd = rpy_to_matrix(rpy) @ r.log.mounting.dvl.rotation_matrix()
    v_dvl = np.einsum("nji,nj->ni", R_wd, v_world)
    good = d.valid
    assert good.mean() > 0.9
    assert np.abs(d.velocity[good] - v_dvl[good]).max() < 0.02  # sigma_b 2 mm/s per beam
    back = read_log(write_log(r.log, tmp_path / "bag"))
    assert np.array_equal(back.dvl.beam_unit, d.beam_unit)
    assert back.metadata["dvl_geometry"]["name"] == "pathfinder"
    # a malformed recorded geometry: one warning line, the A50 beams of the driver message
    side = tmp_path / "bag" / "undertow.yaml"
    data = yaml.safe_load(side.read_text())
    data["metadata"]["dvl_geometry"]["azimuths_deg"] = [0.0, 90.0]
    side.write_text(yaml.safe_dump(data))
    with pytest.warns(UserWarning, match="dvl_geometry unusable"):
        again = read_log(tmp_path / "bag")
    assert np.array_equal(again.dvl.beam_unit[0], a50_beam_units())
    with pytest.raises(DataError, match="3 beams"):
        d.with_geometry(DvlGeometry("three", 20.0, (0.0, 120.0, 240.0)))


def load_scenario_dict(data):
    from undertow._util.validate import validate

    return validate(Scenario, data, "scenario: field ")


def _short_scenario(**extra) -> dict:
    s = load_scenario("calm").to_yaml_dict()
    s["motion"]["carriage"]["run_length_m"] = 2.0
    s["motion"]["carriage"]["hold_before_s"] = 1.0
    s["motion"]["carriage"]["hold_after_s"] = 1.0
    s["ground_truth"]["rate_hz"] = 100.0
    s.update(extra)
    return s


# -- multibeam in the simulator -----------------------------------------------------------------


def _flat_pings(seconds=10.0, **multibeam):
    """A calm station-keeping run over the flat tank floor (widened: no wall in the swath)."""
    s = _short_scenario()
    s["motion"]["carriage"].update(run_length_m=0.0, hold_before_s=seconds, hold_after_s=0.0)
    s["tank"]["width_m"] = 60.0
    s["multibeam"] = {"rate_hz": 20.0, "beams": 96, "swath_deg": 120.0, **multibeam}
    r = simulate(Scenario.model_validate(s), seed=3)
    return r, MultibeamModel(**s["multibeam"])


def _expected_flat(r):
    """Closed form over the flat floor z = h: r_j = (h - o_z) / (R_ws u_j)_z, o the head."""
    log, h = r.log, r.scenario.water.depth_m
    mb, gt, mount = log.multibeam, log.ground_truth, log.mounting.multibeam
    pos, rpy, _ = gt.interpolate(mb.t)
    R = rpy_to_matrix(rpy)
    origin = pos + R @ np.asarray(mount.translation)
    theta = np.linspace(-1, 1, mb.beams) * np.deg2rad(r.scenario.multibeam.swath_deg) / 2
    u = np.stack([np.zeros_like(theta), np.sin(theta), np.cos(theta)], axis=1)
    dirs = np.einsum("nij,kj->nki", R @ mount.rotation_matrix(), u)
    return (h - origin[:, 2])[:, None] / dirs[..., 2], dirs[..., 2]


def test_a_ping_over_a_flat_floor_gives_h_over_cos_theta_within_the_noise():
    r, config = _flat_pings(seconds=4.0)
    mb = r.log.multibeam
    assert mb.beams == 96 and abs(mb.rate_hz - 20.0) < 1e-6 and mb.valid.all()
    want, cos_g = _expected_flat(r)
    sigma = range_sigma(config, want, cos_g)
    z = (mb.range - want) / sigma
    assert np.abs(z).max() < 5.5  # ~7700 draws of N(0, 1)
    # the nadir beam (theta ~ 0) and the outer one (60 deg): h and 2h over a level floor
    assert np.all(np.abs(cos_g[:, 0] - 0.5) < 0.01)
    np.testing.assert_allclose(np.median(mb.range[:, 0] / want[:, 0]), 1.0, atol=0.01)
    # detections lie in the sensor's y-z plane, at the beam's across-track angle
    np.testing.assert_allclose(mb.points[..., 0], 0.0, atol=1e-12)
    theta = np.linspace(-60.0, 60.0, 96)
    np.testing.assert_allclose(np.degrees(mb.across_angle), np.tile(theta, (len(mb), 1)),
                               atol=1e-9)  # fmt: skip


def test_range_noise_std_follows_its_formula_over_many_pings():
    """std over pings of each beam's range error against sigma = sqrt(a^2 + (b r cos g)^2) /
    cos g: within 12 % per beam (400 pings), and it grows from nadir to the swath edge."""
    r, config = _flat_pings(seconds=20.0, range_sigma_a_m=0.01, range_sigma_b=0.01)
    want, cos_g = _expected_flat(r)
    err = r.log.multibeam.range - want
    std = err.std(axis=0, ddof=1)
    formula = range_sigma(config, want, cos_g).mean(axis=0)
    np.testing.assert_allclose(std / formula, 1.0, atol=0.12)
    assert abs(err.mean()) < 3 * formula.mean() / np.sqrt(err.size)
    edge, nadir = formula[[0, -1]].mean(), formula[47:49].mean()
    assert edge > 1.9 * nadir and std[[0, -1]].mean() > 1.6 * std[47:49].mean()


def test_multibeam_section_is_checked():
    with pytest.raises(ConfigError, match="multibeam.beams"):
        load_scenario_dict(_short_scenario(multibeam={"beams": 1}))
    with pytest.raises(ConfigError, match="multibeam.swath_deg"):
        load_scenario_dict(_short_scenario(multibeam={"swath_deg": 190}))


# -- readers and writer: sensor_msgs/PointCloud2 --------------------------------------------------


def _multibeam_log(n=6, beams=5, seed=0) -> Log:
    rng = np.random.default_rng(seed)
    t = 100.0 + 0.05 * np.arange(n)
    points = rng.normal(0.0, 1.0, (n, beams, 3)) + [0.0, 0.0, 4.0]
    points[1, 2] = np.nan  # a beam without a detection
    intensity = rng.uniform(0, 100, (n, beams))
    mb = Multibeam(t=t, points=points, intensity=intensity, min_range=0.3, max_range=60.0)
    mount = Mounting(multibeam=SensorMount((0.3, -0.05, 0.25), (0.0, 0.1, 0.02)))
    return Log(multibeam=mb, mounting=mount, source="test")


def test_pointcloud2_written_and_read_back_equal(tmp_path):
    log = _multibeam_log()
    back = read_log(write_log(log, tmp_path / "bag"))
    a, b = log.multibeam, back.multibeam
    assert np.array_equal(a.points, b.points, equal_nan=True)
    assert np.array_equal(a.intensity, b.intensity)
    np.testing.assert_allclose(b.t, a.t, rtol=0, atol=1e-9)  # header stamps: whole ns
    assert (b.min_range, b.max_range) == (0.3, 60.0)
    assert back.mounting.multibeam == log.mounting.multibeam
    (tmp_path / "bag" / "undertow.yaml").unlink()  # /tf_static alone keeps the mounting
    bare = read_log(tmp_path / "bag")
    np.testing.assert_allclose(bare.mounting.multibeam.translation, (0.3, -0.05, 0.25), atol=1e-15)
    np.testing.assert_allclose(bare.mounting.multibeam.rotation, (0.0, 0.1, 0.02), atol=1e-12)
    assert np.array_equal(bare.multibeam.points, a.points, equal_nan=True)


def test_a_driver_cloud_of_float32_detections_decodes():
    """What MBES drivers publish: only the beams with a detection, x y z FLOAT32, plus other
    fields; a second row (height 2) with row padding. Decoded by the layout, not assumed."""
    store = dvl_typestore()
    T = store.types
    pts = np.array([[0.0, -1.0, 3.0], [0.0, 0.5, 2.5], [0.1, 2.0, 3.5], [0.0, 0.0, 2.0]])
    rec = np.zeros(4, dtype=[("ring", "<u2"), ("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    rec["x"], rec["y"], rec["z"] = pts.T
    raw = rec.view(np.uint8).reshape(2, -1)  # two rows of two points (14 bytes each)
    data = np.concatenate([raw, np.zeros((2, 4), np.uint8)], axis=1).reshape(-1)  # 4 pad bytes
    field = T["sensor_msgs/msg/PointField"]
    fields = [field(name="ring", offset=0, datatype=4, count=1)] + [
        field(name=n, offset=2 + 4 * k, datatype=7, count=1) for k, n in enumerate("xyz")
    ]
    b = MessageBuilder()
    h, _ = b.header(1.0, "mbes_link")
    msg = T["sensor_msgs/msg/PointCloud2"](header=h, height=2, width=2, fields=fields,
                                           is_bigendian=False, point_step=14, row_step=32,
                                           data=data, is_dense=True)  # fmt: skip
    got, intensity = cloud_points(msg)
    np.testing.assert_array_equal(got, pts.astype(np.float32).astype(np.float64))
    assert intensity is None
    # the writer's message decodes to its input
    _, mine = multibeam_message(b, 1.0, "mbes_link", pts, np.arange(4.0))
    got, intensity = cloud_points(mine)
    assert np.array_equal(got, pts) and np.array_equal(intensity, np.arange(4.0))
    bad = T["sensor_msgs/msg/PointCloud2"](header=h, height=1, width=9, fields=fields[1:],
                                           is_bigendian=False, point_step=14, row_step=126,
                                           data=data, is_dense=True)  # fmt: skip
    with pytest.raises(ValueError, match="layout"):
        cloud_points(bad)


def test_undertow_info_lists_the_multibeam_stream(tmp_path):
    path = write_log(_multibeam_log(n=8), tmp_path / "bag")
    result = runner.invoke(app, ["info", str(path), "--json"])
    assert result.exit_code == 0, result.output
    streams = {s["name"]: s for s in json.loads(result.output)["streams"]}
    assert streams["multibeam"]["messages"] == 8
    assert streams["multibeam"]["missing_detail"] == {"beams_without_detection": 1}
    table = runner.invoke(app, ["info", str(path)])
    assert table.exit_code == 0 and "multibeam" in table.output


# -- mapping --------------------------------------------------------------------------------------

PLANE = (6.0, 0.05, 0.12)  # z = c0 + cx x + cy y: a plane tilted about both axes


def _plane_z(x, y):
    c0, cx, cy = PLANE
    return c0 + cx * x + cy * y


def _tilted_plane_survey(beams=64, swath_deg=120.0):
    """Pings from a level head moving along x at 2 m depth over the plane: closed-form ranges
    r_j = (c0 + n_h . o_h - o_z) / (u_z - n_h . u_h) for the ray o + r u (n_h = (cx, cy))."""
    t = np.arange(0.0, 20.0, 0.1)
    pos = np.stack([0.5 * t, np.zeros_like(t), np.full_like(t, 2.0)], axis=1)
    mount = SensorMount((0.25, 0.0, 0.3), (0.0, 0.0, 0.0))
    theta = np.linspace(-1, 1, beams) * np.deg2rad(swath_deg) / 2
    u = np.stack([np.zeros_like(theta), np.sin(theta), np.cos(theta)], axis=1)
    o = pos + mount.translation
    c0, cx, cy = PLANE
    r = (c0 + cx * o[:, :1] + cy * o[:, 1:2] - o[:, 2:]) / (u[:, 2] - cx * u[:, 0] - cy * u[:, 1])
    mb = Multibeam(t=t, points=r[..., None] * u, min_range=0.2, max_range=100.0)
    gt = GroundTruth(t=t, position=pos, orientation=np.zeros_like(pos))
    x = np.zeros((t.size, 18))
    x[:, :3] = pos
    traj = Trajectory(t, x, np.zeros((t.size, 18, 18)) + np.eye(18) * 1e-4)
    return Log(multibeam=mb, ground_truth=gt, mounting=Mounting(multibeam=mount)), traj


def test_multibeam_samples_are_hits_on_the_plane_plus_free_samples_along_the_beams():
    log, traj = _tilted_plane_survey()
    s = build_samples(log, traj, use_dvl=False, use_sonar=False, use_multibeam=True)
    hits = s.points[s.label == 1]
    assert len(hits) == log.multibeam.points[..., 0].size
    np.testing.assert_allclose(hits[:, 2], _plane_z(hits[:, 0], hits[:, 1]), atol=1e-9)
    free = s.points[s.label == 0]
    assert len(free) > 10 * len(hits) and np.all(free[:, 2] < _plane_z(free[:, 0], free[:, 1]))
    assert np.all(s.sensor == SENSOR_MULTIBEAM)
    assert np.all(s.sigma0 == MappingConfig().sigma0_multibeam)
    off = build_samples(log, traj, use_dvl=False, use_sonar=False, use_multibeam=True,
                        sigma0_multibeam=0.3)  # fmt: skip
    assert np.all(off.sigma0 == 0.3)
    with pytest.raises(ConfigError, match="both false"):
        MappingConfig.from_dict({"use_dvl": False, "use_sonar": False, "use_multibeam": False})


def test_the_mapper_maps_a_multibeam_survey_of_a_tilted_plane_onto_the_plane():
    log, traj = _tilted_plane_survey()
    config = MappingConfig(method="adaptive", use_dvl=False, use_sonar=False, use_multibeam=True)
    samples = build_samples(log, traj, **config.model_dump(include={"use_dvl", "use_sonar",
                                                                    "use_multibeam"}))  # fmt: skip
    mapper = mapper_from_config(config)
    mapper.integrate(samples)
    occupied = mapper.occupancy().occupied(config.occupied_threshold)
    c = occupied.centres
    dz = c[:, 2] - _plane_z(c[:, 0], c[:, 1])
    assert len(occupied) > 1000
    # occupied cells sit on the plane: within a cell and a half, nearly all within one cell
    assert np.abs(dz).max() < 1.5 * config.resolution + 1e-9
    assert np.mean(np.abs(dz) <= config.resolution) > 0.95
    # the swath is covered: occupied cells across the plane's width under the track
    assert np.ptp(c[:, 1]) > 6.0


def test_the_tpu_surface_of_a_multibeam_survey_of_a_tilted_plane_is_the_plane():
    """The default mapper's surface (depth per column) lies on the plane to within a fraction
    of a cell, unbiased, and its standard deviation covers the plane's depth."""
    log, traj = _tilted_plane_survey()
    config = MappingConfig(method="tpu", use_dvl=False, use_sonar=False, use_multibeam=True)
    occupancy = map_log(log, traj, config).map
    surface = map_surface(occupancy)
    p = surface.points()
    j, i = np.nonzero(surface.coverage)
    error = p[:, 2] - _plane_z(p[:, 0], p[:, 1])
    assert len(p) > 1000 and np.ptp(p[:, 1]) > 6.0
    assert np.sqrt(np.mean(error**2)) < 0.25 * config.resolution
    assert abs(np.mean(error)) < 0.05 * config.resolution
    assert np.mean(np.abs(error) <= 2 * surface.std[j, i] + 1e-9) > 0.9


# -- the built-in survey --------------------------------------------------------------------------


@pytest.mark.slow
def test_multibeam_survey_detections_lie_on_the_seabed():
    """`multibeam-survey`: every detection, placed in the world with the true pose and the
    mounting, lies on the scenario's seabed to within its range noise; the swath is ~27 m."""
    from undertow.sim.simulate import build_tank

    r = simulate(load_scenario("multibeam-survey"))
    log, s = r.log, r.scenario
    mb, mount = log.multibeam, log.mounting.multibeam
    assert mb.beams == 256 and log.time_span[1] > 150.0 and mb.valid.mean() > 0.99
    rows = np.arange(0, len(mb), 7)  # every 7th ping: ~140k detections
    pos, rpy, _ = log.ground_truth.interpolate(mb.t[rows])
    R = rpy_to_matrix(rpy)
    origin = pos + R @ np.asarray(mount.translation)
    world = origin[:, None, :] + np.einsum("nij,nkj->nki", R @ mount.rotation_matrix(),
                                           mb.points[rows])  # fmt: skip
    ok = mb.valid[rows]
    p = world[ok]
    floor = build_tank(s).floor_depth(p[:, 0], p[:, 1])
    cos_g = np.einsum("nij,kj->nki", R @ mount.rotation_matrix(),
                      mb.beam_unit[rows][0])[..., 2][ok]  # fmt: skip
    sigma = range_sigma(s.multibeam, mb.range[rows][ok], cos_g)
    z = (p[:, 2] - floor) / (sigma * cos_g)  # a range error dr moves the point dr cos g in z
    assert np.mean(np.abs(z) < 4.0) > 0.999
    across = p[:, 1] - np.repeat(origin[:, 1], ok.sum(axis=1))
    assert np.ptp(across) > 24.0
