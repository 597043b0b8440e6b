"""Seabeds: heightfield forms against closed forms, the ray caster against the heightfield it
casts on, bathymetry files (GeoTIFF written here with rasterio, XYZ, PLY), walls and beach, the
ground-truth cloud, and the new scenarios."""

import numpy as np
import pytest

from undertow.errors import ConfigError
from undertow.robot import a50_beam_units
from undertow.sim import Scenario, list_scenarios, load_scenario, simulate
from undertow.sim.scenario.model import FloorModel
from undertow.sim.seabed import (
    Heightfield,
    procedural_heightfield,
    random_field,
    scenario_heightfield,
    uses_heightfield,
)
from undertow.sim.simulate import build_tank
from undertow.sim.tank import Tank

DOMAIN = (0.0, 20.0, -5.0, 5.0)


def _tank(hf: Heightfield, depth=3.0, walls=True, length=20.0, width=10.0) -> Tank:
    return Tank(length, width, depth, 10.0, 0.0, 1.0, 1.0, 0.1, 0.0, walls=walls, heightfield=hf)


def _procedural(**floor) -> Heightfield:
    return procedural_heightfield(FloorModel(kind="procedural", **floor), 3.0, DOMAIN)


def test_tilted_plane_vertical_and_slanted_rays_hit_the_closed_form_plane():
    alpha, psi = 4.0, 30.0  # deg: deepens toward 30 deg from +x
    hf = _procedural(slope={"gradient_deg": alpha, "downslope_deg": psi, "reference_x_m": 8.0,
                            "reference_y_m": 1.0})  # fmt: skip
    e = np.array([np.cos(np.deg2rad(psi)), np.sin(np.deg2rad(psi))])
    t = np.tan(np.deg2rad(alpha))

    def plane(x, y):
        return 3.0 + t * ((x - 8.0) * e[0] + (y - 1.0) * e[1])

    rng = np.random.default_rng(0)
    o = np.column_stack(
        [rng.uniform(3, 17, 200), rng.uniform(-3, 3, 200), rng.uniform(0.2, 1, 200)]
    )
    tank = _tank(hf)
    np.testing.assert_allclose(tank.floor_depth(o[:, 0], o[:, 1]), plane(o[:, 0], o[:, 1]),
                               atol=1e-12)  # fmt: skip
    r = tank.cast_rays(o, np.tile([0.0, 0.0, 1.0], (200, 1)))
    np.testing.assert_allclose(r, plane(o[:, 0], o[:, 1]) - o[:, 2], atol=1e-5)
    # slanted A50 beams: o_z + s u_z = plane(o + s u)  ->  s = (plane(o) - o_z) / (u_z - t u_h.e)
    B = a50_beam_units()
    oo = np.repeat(o[:20], 4, axis=0)
    u = np.tile(B, (20, 1))
    s = (plane(oo[:, 0], oo[:, 1]) - oo[:, 2]) / (u[:, 2] - t * (u[:, :2] @ e))
    np.testing.assert_allclose(tank.cast_rays(oo, u), s, atol=1e-5)


def test_ripples_crests_and_troughs():
    lam, H, crest = 0.6, 0.05, 30.0
    hf = _procedural(ripples={"wavelength_m": lam, "height_m": H, "crest_deg": crest},
                     resolution_m=0.01)  # fmt: skip
    c = np.deg2rad(crest)
    normal = np.array([-np.sin(c), np.cos(c)])  # n = -x sin c + y cos c across the crests
    along = np.array([np.cos(c), np.sin(c)])
    k = np.arange(-2, 5)
    p0 = 5.0 * along  # on the crest line n = 0 (phase 0)
    for n, expected in ((k * lam, 3.0 - H / 2), ((k + 0.5) * lam, 3.0 + H / 2)):
        p = p0 + n[:, None] * normal - 0.37 * along
        # a crest line crosses grid cells: bilinear error <= (dx^2 / 8) |z''| = pi^2 H dx^2 / lam^2
        bound = np.pi**2 * H * 0.01**2 / lam**2
        np.testing.assert_allclose(hf.sample(p[:, 0], p[:, 1]), expected, atol=bound)
    # along a crest line the height does not change
    line = p0 + np.linspace(-3, 3, 50)[:, None] * along
    assert np.ptp(hf.sample(line[:, 0], line[:, 1])) <= bound


def _radial_spectrum(f, d):
    """Radially averaged periodogram |F|^2 of a square field f of spacing d: (K, P)."""
    n = f.shape[0]
    P = np.abs(np.fft.fft2(f - f.mean())) ** 2
    k = 2 * np.pi * np.fft.fftfreq(n, d)
    K = np.hypot(k[:, None], k[None, :])
    edges = np.geomspace(2 * np.pi / 4.0, 2 * np.pi / 0.2, 16)
    idx = np.digitize(K.ravel(), edges)
    mids, power = [], []
    for b in range(1, edges.size):
        sel = idx == b
        if sel.any():
            mids.append(np.sqrt(edges[b - 1] * edges[b]))
            power.append(P.ravel()[sel].mean())
    return np.array(mids), np.array(power)


def test_random_field_rms_and_spectral_slope_within_sampling_error():
    n, d, rms, gamma = 256, 0.05, 0.02, 3.0
    var, slopes = [], []
    for seed in range(8):
        f = random_field(n, n, d, d, rms, gamma, 0.1, 4.0, np.random.default_rng(seed))
        var.append(np.mean(f**2))
        K, P = _radial_spectrum(f, d)
        slopes.append(np.polyfit(np.log(K), np.log(P), 1)[0])
    var = np.array(var)
    # E[var] = rms^2: the sample mean over seeds within 3 standard errors
    assert abs(var.mean() - rms**2) <= 3 * var.std(ddof=1) / np.sqrt(var.size)
    # periodogram ~ K^-gamma over the band
    assert np.mean(slopes) == pytest.approx(-gamma, abs=0.15)
    assert not np.array_equal(random_field(8, 8, d, d, rms, gamma, 0.1, 4.0,
                                           np.random.default_rng(1)),
                              random_field(8, 8, d, d, rms, gamma, 0.1, 4.0,
                                           np.random.default_rng(2)))  # fmt: skip


def _rough() -> Heightfield:
    return _procedural(
        resolution_m=0.02, seed=3,
        slope={"gradient_deg": 2.0, "downslope_deg": 90.0},
        ripples={"wavelength_m": 0.5, "height_m": 0.05, "crest_deg": 70.0},
        roughness={"rms_m": 0.03, "spectral_slope": 3.0, "min_wavelength_m": 0.05},
        rocks=[
            {"kind": "boulder", "center_x_m": 10.0, "center_y_m": 0.5, "length_m": 1.2,
             "width_m": 0.8, "height_m": 0.6, "yaw_deg": 30.0},
            {"kind": "box", "center_x_m": 12.0, "center_y_m": -1.0, "length_m": 1.0,
             "width_m": 0.8, "height_m": 0.4, "edge_radius_m": 0.05},
        ],
    )  # fmt: skip


def test_rays_hit_the_heightfield_they_sample_and_nothing_before():
    hf = _rough()
    tank = _tank(hf)
    rng = np.random.default_rng(5)
    n = 400
    o = np.column_stack([rng.uniform(8, 14, n), rng.uniform(-2, 2, n), rng.uniform(0.3, 1.5, n)])
    u = rng.normal(size=(n, 3))
    u[:, 2] = np.abs(u[:, 2]) + 0.3
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = tank.cast_rays(o, u)
    assert np.isfinite(r).all()
    p = o + r[:, None] * u
    inside = (np.abs(p[:, 1]) < 4.99) & (p[:, 0] > 0.01) & (p[:, 0] < 19.99)
    np.testing.assert_allclose(p[inside, 2], hf.sample(p[inside, 0], p[inside, 1]), atol=1e-5)
    # the first hit: every point along the ray before it is in the water
    s = np.linspace(0.0, 1.0, 2000)[None, :] * (r[:, None] - 1e-4)
    q = o[:, None, :] + s[..., None] * u[:, None, :]
    assert np.all(q[..., 2] < hf.sample(q[..., 0], q[..., 1]))
    # the rocks stand on the floor: the boulder's top at its centre is 0.6 m above the floor
    base = _procedural(resolution_m=0.02, seed=3,
                       slope={"gradient_deg": 2.0, "downslope_deg": 90.0},
                       ripples={"wavelength_m": 0.5, "height_m": 0.05, "crest_deg": 70.0},
                       roughness={"rms_m": 0.03, "spectral_slope": 3.0,
                                  "min_wavelength_m": 0.05})  # fmt: skip
    assert hf.sample(10.0, 0.5) == pytest.approx(base.sample(10.0, 0.5) - 0.6, abs=1e-9)


def test_rays_against_walls_and_beach():
    hf = procedural_heightfield(FloorModel(kind="procedural"), 3.0, DOMAIN)
    from undertow.sim.seabed import apply_beach

    z = hf.z.copy()
    xs, _ = hf.nodes()
    apply_beach(z, xs, 3.0, 6.0)  # 1:2 beach from x = 6 m up to the still-water line at x = 0
    tank = _tank(Heightfield(hf.x0, hf.y0, hf.dx, hf.dy, z))
    o = np.array([[10.0, 1.0, 2.0], [10.0, 1.0, 2.0], [10.0, 1.0, 1.0], [3.0, 0.0, 0.5],
                  [10.0, 0.0, 1.0]])  # fmt: skip
    u = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0],
                  [0.0, -0.6, -0.8]])  # fmt: skip
    r = tank.cast_rays(o, u)
    assert r[0] == pytest.approx(5.0 - 1.0, abs=1e-5)  # side wall y = W/2
    assert r[1] == pytest.approx(20.0 - 10.0, abs=1e-5)  # end wall x = L
    assert r[2] == pytest.approx(10.0 - 1.0 * 6.0 / 3.0, abs=1e-5)  # beach: h x / l_b = 1 m
    assert r[3] == pytest.approx(3.0 * 3.0 / 6.0 - 0.5, abs=1e-5)  # vertical ray onto the beach
    assert np.isnan(r[4])  # up and out of the water (1.25 m) before the wall (5 / 0.6 m)
    # without walls the floor's edge continues and a horizontal ray finds nothing
    open_sea = _tank(hf, walls=False)
    r = open_sea.cast_rays([[10.0, 1.0, 2.0], [30.0, 9.0, 1.0]], [[0, 1, 0], [0, 0, 1]], 40.0)
    assert np.isnan(r[0]) and r[1] == pytest.approx(2.0, abs=1e-5)


def test_flat_heightfield_equals_the_closed_form_tank():
    """A flat floor with the rock platform as a heightfield (e.g. with a beach) has the original
    tank's floor at its nodes."""
    s = load_scenario("calm").to_yaml_dict()
    legacy = build_tank(Scenario.model_validate(s))
    assert legacy.heightfield is None
    s["tank"]["beach"] = {"length_m": 8.0}
    grid = build_tank(Scenario.model_validate(s))
    xs, ys = grid.heightfield.nodes()
    sel = (xs > 40) & (xs < 56)
    X, Y = np.meshgrid(xs[sel], ys, indexing="ij")
    np.testing.assert_allclose(grid.floor_depth(X, Y), legacy.floor_depth(X, Y), atol=1e-12)
    o = np.column_stack([np.linspace(20, 90, 50), np.zeros(50), np.full(50, 0.5)])
    B = a50_beam_units()
    oo, u = np.repeat(o, 4, axis=0), np.tile(B, (50, 1))
    far = np.abs(oo[:, 0] - 48.0) > 2.0  # away from the rock's faces (vertical vs one node)
    np.testing.assert_allclose(grid.cast_rays(oo, u)[far], legacy.cast_rays(oo, u)[far],
                               atol=1e-5)  # fmt: skip


def test_builtins_before_this_change_keep_the_closed_form_tank():
    new = {"mhl-basin", "field-survey", "multibeam-survey"}
    assert new <= set(list_scenarios())
    for name in set(list_scenarios()) - new:
        assert not uses_heightfield(load_scenario(name)), name


def _write_geotiff(path, a, b, c, x0=2.0, y0=-3.0, res=0.5, nx=20, ny=14):
    """A north-up GeoTIFF of elevation = -(a + b x + c y) at the pixel centres."""
    import rasterio
    from rasterio.transform import Affine

    transform = Affine(res, 0.0, x0, 0.0, -res, y0 + ny * res)  # top-left corner, rows go -y
    cols, rows = np.meshgrid(np.arange(nx), np.arange(ny))
    x = x0 + (cols + 0.5) * res
    y = y0 + ny * res - (rows + 0.5) * res
    elev = -(a + b * x + c * y)
    with rasterio.open(path, "w", driver="GTiff", height=ny, width=nx, count=1,
                       dtype="float64", transform=transform) as dst:  # fmt: skip
        dst.write(elev, 1)


def _file_scenario(tmp_path, floor: dict) -> Scenario:
    f = tmp_path / "scenario.yaml"
    import yaml

    f.write_text(yaml.safe_dump({
        "tank": {"length_m": 20.0, "width_m": 8.0, "rock": {"center_x_m": 17.0}},
        "wave_probe": {"x_m": 5.0},
        "motion": {"carriage": {"start_x_m": 4.0, "run_length_m": 8.0}},
        "floor": floor,
    }))  # fmt: skip
    return load_scenario(f)


def test_geotiff_floor_is_the_plane_written(tmp_path):
    _write_geotiff(tmp_path / "bathy.tif", 2.5, 0.02, -0.03)
    s = _file_scenario(tmp_path, {"file": "bathy.tif"})  # relative to the scenario file
    assert s.floor.kind == "file"
    tank = build_tank(s)
    x, y = np.array([4.0, 8.0, 11.0]), np.array([-2.0, 0.0, 2.5])
    np.testing.assert_allclose(tank.floor_depth(x, y), 2.5 + 0.02 * x - 0.03 * y, atol=1e-9)
    # placed by a 90 deg rotation and an offset: (x, y) = R (x_f, y_f) + o, z = o_z - elevation
    s = _file_scenario(tmp_path, {"file": str(tmp_path / "bathy.tif"), "rotation_deg": 90.0,
                                  "offset_m": [10.0, -4.0, 0.2]})  # fmt: skip
    x, y = np.array([7.0, 9.0, 12.0]), np.array([-1.0, 0.5, 3.0])  # inside the raster
    xf, yf = y - (-4.0), -(x - 10.0)
    np.testing.assert_allclose(build_tank(s).floor_depth(x, y),
                               0.2 + 2.5 + 0.02 * xf - 0.03 * yf, atol=1e-9)  # fmt: skip
    r = build_tank(s).cast_rays([[8.0, 1.0, 0.5]], [[0, 0, 1]])[0]  # (x_f, y_f) = (5, 2)
    assert r == pytest.approx(0.2 + 2.5 + 0.02 * 5.0 - 0.03 * 2.0 - 0.5, abs=1e-5)


def test_xyz_and_ply_floors_are_the_plane_given(tmp_path):
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(-1, 21, 400), rng.uniform(-5, 5, 400)])
    depth = 3.1 - 0.01 * pts[:, 0] + 0.04 * pts[:, 1]
    f = tmp_path / "survey.xyz"
    f.write_text(
        "# x y depth\n"
        + "\n".join(
            f"{x:.9f}, {y:.9f}, {z:.9f}"
            for x, y, z in zip(pts[:, 0], pts[:, 1], depth, strict=True)
        )
    )
    s = _file_scenario(tmp_path, {"file": str(f), "values": "depth"})
    x, y = np.array([3.0, 9.0, 14.0]), np.array([-1.0, 0.5, 2.0])
    np.testing.assert_allclose(build_tank(s).floor_depth(x, y), 3.1 - 0.01 * x + 0.04 * y,
                               atol=1e-6)  # fmt: skip
    # over a built-in: the file replaces the base's procedural floor (no field merging)
    (tmp_path / "mine.yaml").write_text(
        "base: mhl-basin\nfloor: {file: survey.xyz, values: depth}\n"
    )
    s = load_scenario(tmp_path / "mine.yaml")
    assert s.floor.kind == "file" and s.floor.roughness.rms_m == 0.0
    xb = np.array([13.0, 16.0, 20.0])  # past mhl-basin's 12 m beach
    np.testing.assert_allclose(build_tank(s).floor_depth(xb, y), 3.1 - 0.01 * xb + 0.04 * y,
                               atol=1e-6)  # fmt: skip
    from undertow.io.ply import write_ply

    write_ply(tmp_path / "survey.ply", np.column_stack([pts, -depth]))
    s = _file_scenario(tmp_path, {"file": str(tmp_path / "survey.ply")})
    np.testing.assert_allclose(build_tank(s).floor_depth(x, y), 3.1 - 0.01 * x + 0.04 * y,
                               atol=1e-6)  # fmt: skip


@pytest.mark.parametrize(
    ("name", "content"),
    [("bad.tif", b"not a tiff at all"), ("bad.xyz", b"1 2 3\nfour five six\n"),
     ("bad.ply", b"ply\nformat nonsense\n"), ("missing.xyz", None)],
)  # fmt: skip
def test_bad_bathymetry_file_is_one_line_naming_it(tmp_path, name, content):
    if content is not None:
        (tmp_path / name).write_bytes(content)
    with pytest.raises(ConfigError) as info:
        _file_scenario(tmp_path, {"file": name})
    message = str(info.value)
    assert "\n" not in message and name in message and "field floor.file" in message


def test_floor_fields_are_checked(tmp_path):
    for floor, field in (
        ({"kind": "file"}, "floor"),
        ({"kind": "flat", "rocks": [{"kind": "boulder", "center_x_m": 5, "center_y_m": 0,
                                     "length_m": 1, "width_m": 1, "height_m": 0.3}]}, "floor"),
        ({"ripples": {"wavelength_m": 0.2, "height_m": 0.1}}, "floor.ripples"),
        ({"kind": "procedural", "resolution_m": 0.001}, "floor.resolution_m"),
        ({"rocks": [{"kind": "boulder", "center_x_m": 30, "center_y_m": 0, "length_m": 1,
                     "width_m": 1, "height_m": 0.3}]}, "floor.rocks.0.center_x_m"),
        ({"rocks": [{"kind": "boulder", "center_x_m": 8, "center_y_m": 0, "length_m": 1,
                     "width_m": 1, "height_m": 3.5}]}, "floor.rocks.0.height_m"),
    ):  # fmt: skip
        with pytest.raises(ConfigError, match=rf"field {field}\b"):
            _file_scenario(tmp_path, floor)


def test_ground_truth_cloud_lies_on_the_heightfield_with_the_wall_strips():
    s = load_scenario("mhl-basin").to_yaml_dict()
    s["motion"]["carriage"].update(run_length_m=3.0, hold_before_s=1.0, hold_after_s=1.0)
    s["ground_truth"]["rate_hz"] = 100.0
    s["floor_cloud"].update(margin_m=4.0, spacing_m=0.05)  # reaches both side walls
    r = simulate(Scenario.model_validate(s), seed=0)
    tank = build_tank(r.scenario)
    cloud = r.floor_cloud
    W = r.scenario.tank.width_m
    wall = np.abs(np.abs(cloud[:, 1]) - W / 2) < 1e-9
    floor = cloud[~wall]
    np.testing.assert_allclose(floor[:, 2], tank.floor_depth(floor[:, 0], floor[:, 1]),
                               atol=1e-12)  # fmt: skip
    strips = cloud[wall]
    assert {-W / 2, W / 2} == set(np.round(strips[:, 1], 9))
    assert strips[:, 2].min() == 0.0
    assert np.all(strips[:, 2] <= tank.floor_depth(strips[:, 0], strips[:, 1]) + 1e-12)
    # the DVL's ranges are the ray caster's on the same floor: altitude ~ floor under the DVL
    assert np.nanmax(r.log.dvl.altitude) < tank.floor_depth(cloud[:, 0], cloud[:, 1]).max()


def test_new_scenarios_mhl_basin_and_field_survey():
    basin = load_scenario("mhl-basin")
    paper = load_scenario("wave-a0.10-f1.00")
    assert basin.motion == paper.motion and basin.wave == paper.wave
    assert basin.tank.walls and basin.tank.beach.length_m > 0 and basin.floor.kind == "procedural"
    hf = scenario_heightfield(basin)
    xs, _ = hf.nodes()
    mean_floor = float(hf.z[(xs > 30) & (xs < 70)].mean())
    cells = mean_floor / 0.1
    assert 0.2 <= abs(cells - round(cells)) * 2 <= 0.8  # off the 0.1 m cells' faces and centres
    field = load_scenario("field-survey")
    assert field.motion.kind == "waypoints" and not field.tank.walls
    assert field.floor.roughness.rms_m > 0 and len(field.floor.rocks) >= 5
    pts = np.asarray(field.motion.waypoints.points)
    legs = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert legs.sum() / field.motion.waypoints.speed_m_s >= 600.0  # >= 10 min of passes
    assert field.tank.length_m * field.tank.width_m > 10 * 110 * 6.7 / 6  # a field, not the tank


@pytest.mark.slow
def test_field_survey_simulates_over_its_seabed(simulation):
    r = simulation("field-survey", 0)
    tank = build_tank(r.scenario)
    gt = r.log.ground_truth
    assert gt.t[-1] >= 600.0
    # sonar first returns: the floor at most its range below the sonar, never above it
    assert np.isfinite(r.log.sonar.range).mean() > 0.99
    cloud = r.floor_cloud
    np.testing.assert_allclose(cloud[:, 2], tank.floor_depth(cloud[:, 0], cloud[:, 1]))
