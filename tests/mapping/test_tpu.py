"""The tpu mapper (mapping/tpu.py) and its evidence surface, against closed forms."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from undertow.mapping.config import MappingConfig
from undertow.mapping.kernels import sparse_kernel
from undertow.mapping.mappers import TpuBkiMapper, make_mapper, mapper_from_config
from undertow.mapping.samples import SENSOR_DVL, SENSOR_SONAR, Samples
from undertow.mapping.surface import evidence_surface, map_surface
from undertow.mapping.tpu import (
    KERNEL_STD,
    hit_sigmas,
    lattice_weights,
    log_wave,
    trajectory_wave,
    wave_range_std,
    with_wave,
)
from undertow.sim.waves import wavenumber
from undertow.trajectory import Trajectory

RES = 0.1


def _hit(z=2.0, var=(0.0, 0.0, 0.0), sensor=SENSOR_DVL, origin_z=0.0, x=0.33, y=-0.41):
    """One hit straight below its origin."""
    return Samples(np.array([[x, y, z]]), np.ones(1), np.array([0.9]), np.array([var]),
                   np.zeros(1, np.int64), np.array([sensor], np.int8),
                   np.array([[x, y, origin_z]]))  # fmt: skip


def test_kernel_std_is_the_sparse_kernels_second_moment():
    d = np.linspace(-1.0, 1.0, 400001)
    k = sparse_kernel(d, 1.0)
    assert KERNEL_STD == pytest.approx(np.sqrt(np.sum(d * d * k) / np.sum(k)), rel=1e-6)


@pytest.mark.parametrize("z", [2.0, 2.04, 2.05, 2.0999, 1.731, -0.26])
@pytest.mark.parametrize("sigma", [0.0, 0.01, 0.03])
def test_lattice_weights_keep_the_mass_the_depth_and_the_variance(z, sigma):
    centres, w = lattice_weights(np.array([z]), np.array([sigma]), RES)
    assert np.all(w >= 0) and w.sum() == pytest.approx(1.0, abs=1e-12)
    mean = np.sum(w * centres)
    assert mean == pytest.approx(z, abs=1e-12)
    u = (z - centres[0, 1]) / RES
    least = abs(u) * (1 - abs(u)) * RES**2
    assert np.sum(w * (centres - mean) ** 2) == pytest.approx(least + sigma**2, abs=1e-12)


def test_lattice_weights_cap_a_spread_the_three_cells_cannot_hold():
    centres, w = lattice_weights(np.array([2.05]), np.array([1.0]), RES)
    assert np.all(w >= 0) and w.sum() == pytest.approx(1.0)
    assert np.sum(w * centres) == pytest.approx(2.05, abs=1e-12)  # the depth is still kept


def test_the_evidence_surface_of_one_hit_is_its_depth_and_its_vertical_std():
    """d = z_i exactly; s = sigma_v = sqrt(s_z^2 + s_r^2) (the least lattice variance removed)."""
    for z, var_z in ((2.013, 0.0), (2.05, 1e-4), (1.97, 4e-4)):
        mapper = make_mapper("tpu")
        mapper.integrate(_hit(z, (0.0, 0.0, var_z)))
        surface = evidence_surface(mapper.occupancy())
        j, i = np.nonzero(surface.coverage)
        s_r = MappingConfig().range_std_dvl
        assert np.allclose(surface.depth[j, i], z, atol=1e-12)
        assert np.allclose(surface.std[j, i], math.sqrt(var_z + s_r**2), rtol=1e-9)


def test_a_hit_spread_by_its_pose_keeps_its_mass():
    """The pose widens the kernel across the floor but not the hit's evidence: the total hit
    mass of a hit with a 0.3 m horizontal std is that of a perfectly placed one (the sum of a
    wide kernel over cell centres is its integral; of the base kernel, about it)."""
    masses = []
    for var in ((0.0, 0.0, 0.0), (0.09, 0.09, 0.0), (0.04, 0.25, 0.0)):
        mapper = make_mapper("tpu")
        mapper.integrate(_hit(var=var, x=0.05, y=0.05))
        occupancy = mapper.occupancy()
        masses.append((occupancy.alpha - occupancy.alpha0).sum())
    base_integral = (2 / 3) ** 2  # int k(d; l0) dd = 2 l0 / 3 per axis, over cells of l0
    assert masses[0] == pytest.approx(0.9 * 1.0, rel=1e-6)  # a hit on a centre: k(0)^2
    assert masses[1] == pytest.approx(0.9 * base_integral, rel=0.03)
    assert masses[2] == pytest.approx(0.9 * base_integral, rel=0.03)


def test_the_kernel_lengths_follow_the_pose_std_within_their_bounds():
    config = MappingConfig(method="tpu")
    sx, sy, sv, s_r, _ = hit_sigmas(_hit(var=(0.04, 0.09, 1e-4)), (0.005, 0.01, 0.01), 0.005)
    assert sx[0] == pytest.approx(0.2) and sy[0] == pytest.approx(0.3)
    assert s_r[0] == pytest.approx(0.005) and sv[0] == pytest.approx(math.sqrt(1e-4 + 0.005**2))
    assert config.base_length <= 0.3 / KERNEL_STD <= config.max_length


def _slant_hit(r, theta, phi, var=(0.0, 0.0, 0.0), origin=(1.2, -0.7, 0.4)):
    """One DVL hit at range r along a beam theta from the vertical (z down), at azimuth phi."""
    v = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                  math.cos(theta)])  # fmt: skip
    o = np.array(origin)
    return Samples(
        (o + r * v)[None],
        np.ones(1),
        np.array([0.9]),
        np.array([var]),
        np.zeros(1, np.int64),
        np.array([SENSOR_DVL], np.int8),
        o[None],
    ), v


@pytest.mark.parametrize(
    ("theta", "phi"),
    [
        (math.radians(22.5), math.radians(45.0)),
        (math.radians(60.0), math.radians(-90.0)),
        (math.radians(35.0), math.radians(170.0)),
    ],
)
def test_a_slant_beams_range_noise_lies_along_the_beam(theta, phi):
    """A range error n ~ N(0, s_r^2) moves the hit o + (r + n) v along v: s_r^2 v_x^2 and
    s_r^2 v_y^2 join the horizontal variances, s_r^2 v_z^2 = s_r^2 cos^2 theta the vertical one
    (checked against the spread of hits drawn with that range noise)."""
    s0, var = 0.005, (0.01, 0.02, 1e-4)
    samples, v = _slant_hit(2.6, theta, phi, var)
    sx, sy, sv, s_r, _ = hit_sigmas(samples, (s0, 0.01, 0.01), 0.005)
    draws = samples.points[0] + np.random.default_rng(3).normal(0.0, s0, (200000, 1)) * v
    spread = draws.var(axis=0)
    assert sx[0] ** 2 - var[0] == pytest.approx(spread[0], rel=0.02, abs=1e-9)
    assert sy[0] ** 2 - var[1] == pytest.approx(spread[1], rel=0.02, abs=1e-9)
    assert sv[0] ** 2 - var[2] == pytest.approx(spread[2], rel=0.02)
    assert s_r[0] == pytest.approx(s0 * math.cos(theta), rel=1e-12)
    mapper = make_mapper("tpu")  # the surface of that one hit: its depth and vertical std
    mapper.integrate(_slant_hit(2.6, theta, phi, (0.0, 0.0, var[2]))[0])
    surface = evidence_surface(mapper.occupancy())
    j, i = np.nonzero(surface.coverage)
    assert np.allclose(surface.std[j, i], math.sqrt(var[2] + (s0 * math.cos(theta)) ** 2))


def test_a_wide_beams_footprint_adds_to_the_horizontal_std():
    """A first return in a cone of full angle b at range r: a disk of radius r tan(b / 2),
    per-axis std R / 2; the sonar's range noise is s_0 + f r."""
    r, b = 2.0, 25.0
    sx, sy, _, s_r, _ = hit_sigmas(_hit(z=r, var=(0.01, 0.0, 0.0), sensor=SENSOR_SONAR),
                                (0.005, 0.01, 0.01), 0.005, b)  # fmt: skip
    foot = r * math.tan(math.radians(b / 2)) / 2
    assert sx[0] == pytest.approx(math.sqrt(0.01 + foot**2))
    assert sy[0] == pytest.approx(foot)
    assert s_r[0] == pytest.approx(0.01 + 0.005 * r)
    dvl = hit_sigmas(_hit(z=r), (0.005, 0.01, 0.01), 0.005, b)
    assert dvl[0][0] == 0.0  # a narrow DVL beam has no footprint term


def test_a_wide_beams_first_return_falls_short_of_the_floor_on_its_axis():
    """s_d = r (sec(b / 2) - 1): the nearest floor in a cone of full angle b over a plane of
    slope b / 2 (found by brute force over the cone's rays) is that much shallower than the
    floor on the axis; on gentler slopes it is less. It enters sigma_v (the DVL's does not)."""
    b, h = 25.0, 2.5  # full beam angle (deg); the floor's depth under the sensor on the axis
    half = math.radians(b / 2)
    polar = np.linspace(0.0, half, 401)[:, None]
    azimuth = np.linspace(0.0, 2 * np.pi, 721)[None, :]
    ux, uz = np.sin(polar) * np.cos(azimuth), np.cos(polar) + 0 * azimuth
    first = {}
    for slope in (half, half / 2, 0.0):  # the plane z = h + x tan(slope), z down
        with np.errstate(divide="ignore"):
            along = h / (uz - ux * math.tan(slope))  # range to the plane along each ray
        first[slope] = along[along > 0].min()  # the first return
    r = first[half]
    assert h - r == pytest.approx(r * (1 / math.cos(half) - 1), abs=1e-6)
    assert 0 < h - first[half / 2] < h - r and h - first[0.0] == pytest.approx(0.0, abs=1e-12)
    _, _, sv, s_r, _ = hit_sigmas(_hit(z=r, var=(0.0, 0.0, 1e-4), sensor=SENSOR_SONAR),
                               (0.005, 0.01, 0.01), 0.005, b)  # fmt: skip
    s_d = h - r  # the shortfall on that plane, r (sec(b / 2) - 1)
    assert sv[0] == pytest.approx(math.sqrt(1e-4 + s_r[0] ** 2 + s_d**2))
    dvl = hit_sigmas(_hit(z=r, var=(0.0, 0.0, 1e-4)), (0.005, 0.01, 0.01), 0.005, b)
    assert dvl[2][0] == pytest.approx(math.sqrt(1e-4 + 0.005**2))


def test_the_waves_range_noise_is_the_orbital_displacement_between_sensor_and_floor():
    """s_w = a K_s(d) / sqrt 2, K_s = sinh(k (h - d)) / sinh(k h): a at the surface (d = 0),
    0 on the floor (d = h), with k from the dispersion relation in depth h."""
    a, f, h = 0.2, 0.3, 4.0
    k = float(wavenumber(2 * np.pi * f, h))
    for d in (0.0, 1.0, 3.0, 4.0):
        s_w = wave_range_std(_hit(z=h, origin_z=d), np.array([0]), (a, f), RES)[0]
        assert s_w == pytest.approx(a * math.sinh(k * (h - d)) / math.sinh(k * h) / math.sqrt(2))
    free = _hit(z=h)
    free = Samples(free.points, np.zeros(1), free.sigma0, free.pose_variance, free.ray,
                   free.sensor, free.origins)  # fmt: skip
    assert hit_sigmas(free, (0.005, 0.01, 0.01), 0.005, 0.0, (a, f))[0].size == 0  # hits only
    assert wave_range_std(_hit(z=h), np.array([0]), None, RES)[0] == 0.0


def test_the_trajectorys_wave_is_read_from_its_metadata():
    t = np.arange(3.0)
    traj = Trajectory(t, np.zeros((3, 18)), np.zeros((3, 18, 18)))
    assert trajectory_wave(traj) is None
    traj.metadata["wave_noise"] = {"amplitude_m": 0.1, "frequency_hz": 0.5}
    assert trajectory_wave(traj) == (0.1, 0.5)
    traj.metadata["wave_track"] = {"t": [0, 1], "amplitude_m": [0.3, 0.4],
                                   "frequency_hz": [0.2, 0.4]}  # fmt: skip
    assert trajectory_wave(traj) == pytest.approx((math.sqrt((0.09 + 0.16) / 2), 0.3))
    traj.metadata["wave_track"] = {"t": [0], "amplitude_m": [0.0], "frequency_hz": [0.0]}
    traj.metadata.pop("wave_noise")
    assert trajectory_wave(traj) is None  # calm


def test_a_trajectory_made_elsewhere_takes_the_waves_the_log_records():
    """A TUM trajectory says no wave: the log's recorded one (a condition, or a track reduced as
    a trajectory's is) gives the range noise, in one warning; the settings and a trajectory
    that says one win; a calm or unreadable record gives none."""
    t = np.arange(3.0)
    traj = Trajectory(t, np.zeros((3, 18)), np.zeros((3, 18, 18)))
    log = SimpleNamespace(metadata={"wave": {"amplitude_m": 0.15, "frequency_hz": 0.33}})
    with pytest.warns(RuntimeWarning, match="the waves the log records"):
        assert with_wave(MappingConfig(), traj, log).wave == (0.15, 0.33)
    assert log_wave(SimpleNamespace(metadata={"wave": {"t": [0, 9], "amplitude_m": [0.3, 0.4],
                                                       "frequency_hz": [0.2, 0.4]}})) == (
        pytest.approx((math.sqrt((0.09 + 0.16) / 2), 0.3)))  # fmt: skip
    assert with_wave(MappingConfig(wave=(0.2, 0.3)), traj, log).wave == (0.2, 0.3)
    traj.metadata["wave_noise"] = {"amplitude_m": 0.1, "frequency_hz": 0.5}
    assert with_wave(MappingConfig(), traj, log).wave == (0.1, 0.5)
    for wave in ({"amplitude_m": 0.0, "frequency_hz": None}, {"amplitude_m": "x"}, "calm"):
        assert log_wave(SimpleNamespace(metadata={"wave": wave})) is None
    assert log_wave(SimpleNamespace(metadata={})) is None


def test_the_wave_is_resolved_once_into_the_settings():
    """with_wave: the settings' wave wins, else the trajectory's (tpu with a wave term only),
    so a tiled map's tasks, which see only the settings, map with the same wave; likewise the
    depth measurements the filter fused (its depth_std_m, its pressure updates over its span)."""
    t = np.arange(3.0)
    traj = Trajectory(t, np.zeros((3, 18)), np.zeros((3, 18, 18)))
    traj.metadata["wave_noise"] = {"amplitude_m": 0.1, "frequency_hz": 0.5}
    assert with_wave(MappingConfig(), traj).wave == (0.1, 0.5)
    assert with_wave(MappingConfig(wave=(0.2, 0.3)), traj).wave == (0.2, 0.3)
    assert with_wave(MappingConfig(wave_range_noise=False), traj).wave == (0.1, 0.5)
    quiet = MappingConfig(wave_range_noise=False, wave_depth_noise=False)
    assert with_wave(quiet, traj).wave is None
    assert with_wave(MappingConfig(), traj).depth_noise is None  # the trajectory does not say
    traj.metadata["config"] = {"depth_std_m": 0.01}
    traj.metadata["sensors"] = {"pressure": {"used": 21}}
    assert with_wave(MappingConfig(), traj).depth_noise == (0.01, 0.1)  # 2 s over 20 intervals
    given = MappingConfig(depth_noise=(0.002, 0.05))
    assert with_wave(given, traj).depth_noise == (0.002, 0.05)
    assert mapper_from_config(with_wave(MappingConfig(), traj)).depth_wave == (0.1, 0.5, 0.01, 0.1)
    assert (
        mapper_from_config(with_wave(MappingConfig(wave_depth_noise=False), traj)).depth_wave
        is None
    )
    assert with_wave(MappingConfig(method="adaptive"), traj).wave is None
    config = with_wave(MappingConfig(), traj)
    assert mapper_from_config(config).wave == (0.1, 0.5)
    assert mapper_from_config(config.model_copy(update={"wave_range_noise": False})).wave is None


def test_tpu_is_the_default_mapper_and_reads_back_with_the_evidence_surface():
    assert MappingConfig().method == "tpu"
    assert isinstance(mapper_from_config(MappingConfig()), TpuBkiMapper)
    mapper = make_mapper("tpu")
    mapper.integrate(_hit(2.013))
    occupancy = mapper.occupancy()
    assert occupancy.metadata["method"] == "tpu"
    by_default = map_surface(occupancy)
    first = map_surface(occupancy, estimator="first-occupied")
    j, i = np.nonzero(by_default.coverage)
    assert np.allclose(by_default.depth[j, i], 2.013)
    assert not np.allclose(first.depth[j, i], 2.013)  # the cell-centre expectation
    with pytest.raises(Exception, match="surface estimator 'mean'"):
        map_surface(occupancy, estimator="mean")


def test_tpu_settings_are_checked():
    from undertow.errors import ConfigError

    with pytest.raises(ConfigError, match="base_length 3.0 m exceeds max_length 2.0 m"):
        MappingConfig.from_dict({"method": "tpu", "base_length": 3.0})
    with pytest.raises(ConfigError, match="range_std_dvl"):
        MappingConfig.from_dict({"range_std_dvl": 0})
    for bad in ([0.0, 0.1], [0.01, -1.0], [0.01], [0.01, float("nan")]):
        with pytest.raises(ConfigError, match=r"depth_noise"):
            MappingConfig.from_dict({"depth_noise": bad})
