"""Mappers (CSM, BKI, adaptive BKI): scatter sums against independent numpy sums, hand counts,
invariants, and OctoMap as a peer for the counting model's hit cells."""

import numpy as np
import pytest

from undertow.errors import ConfigError, DataError
from undertow.mapping.kernels import product_kernel, sparse_kernel
from undertow.mapping.mappers import AdaptiveBkiMapper, make_mapper
from undertow.mapping.samples import Samples

RES = 0.1


def _cells_around(p, half=4):
    """Every cell within +-half cells of p, with centres (independent enumeration)."""
    base = np.floor(np.asarray(p) / RES).astype(int)
    r = np.arange(-half, half + 1)
    off = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)
    cells = base + off
    return cells, (cells + 0.5) * RES


def _mass_by_cell(occ):
    return {
        tuple(c): (a - occ.alpha0, b - occ.beta0)
        for c, a, b in zip(occ.cells, occ.alpha, occ.beta, strict=True)
    }


@pytest.mark.parametrize("method", ["bki", "adaptive"])
def test_single_sample_mass_equals_kernel_at_cell_centres(method):
    rng = np.random.default_rng(7)
    for _ in range(5):
        p = rng.uniform(-1, 1, 3)
        var = rng.uniform(0, 1, 3)
        mapper = make_mapper(method, variance_bounds=((0, 0, 0), (1, 1, 1)))
        mapper.integrate(Samples.from_points(p[None], [1.0], 0.9, var[None]))
        cells, centres = _cells_around(p)
        if method == "bki":
            k = sparse_kernel(np.linalg.norm(centres - p, axis=1), 0.15, 0.9)
        else:
            lengths = var * (np.array([0.18, 0.18, 0.08]) - [0.1, 0.1, 0.05]) + [0.1, 0.1, 0.05]
            k = product_kernel(centres - p, lengths, 0.9)
        got = _mass_by_cell(mapper.occupancy())
        assert set(got) == {tuple(c) for c in cells[k > 0]}
        for c, kk in zip(cells[k > 0], k[k > 0], strict=True):
            assert got[tuple(c)][0] == pytest.approx(kk, rel=1e-6)
            assert got[tuple(c)][1] == 0.0
        total = sum(a for a, _ in got.values())
        assert total == pytest.approx(k.sum(), rel=1e-6)


def test_adaptive_kernel_along_axes_is_1d_kernel_and_factorizes():
    p = np.array([[0.05, 0.05, 0.05]])  # centre of cell (0, 0, 0)
    l_min = l_max = (0.18, 0.14, 0.08)
    m = make_mapper("adaptive", l_min=l_min, l_max=l_max)
    m.integrate(Samples.from_points(p, [1.0], 0.9))
    got = _mass_by_cell(m.occupancy())
    for j, l in enumerate(l_min):
        for n in range(1, 3):
            cell = [0, 0, 0]
            cell[j] = n
            expect = float(sparse_kernel(n * RES, l, 0.9))
            assert got.get(tuple(cell), (0.0, 0.0))[0] == pytest.approx(expect, rel=1e-6, abs=1e-12)
    # off-axis: sigma0 k_x k_y (sigma0 once), and not the radial kernel of `bki`
    kx, ky = sparse_kernel(0.1, 0.18), sparse_kernel(0.1, 0.14)
    assert got[(1, 1, 0)][0] == pytest.approx(0.9 * kx * ky, rel=1e-6)
    b = make_mapper("bki", length_scale=0.15)
    b.integrate(Samples.from_points(p, [1.0], 0.9))
    assert _mass_by_cell(b.occupancy())[(1, 1, 0)][0] != pytest.approx(got[(1, 1, 0)][0])


def _adaptive(variance_bounds):
    """The constructor takes every value explicitly (checked by MappingConfig, no defaults)."""
    return AdaptiveBkiMapper(l_min=(0.1, 0.1, 0.05), l_max=(0.18, 0.18, 0.08),
                             variance_bounds=variance_bounds, resolution=RES, alpha0=1e-10,
                             beta0=1e-10, max_memory_gb=None)  # fmt: skip


def test_adaptive_length_scales_from_normalized_variance():
    m = _adaptive(None)
    var = np.array([[1.0, 2.0, 5.0], [3.0, 2.0, 5.0], [2.0, 2.0, 5.0]])
    ls = m.length_scales(var)
    np.testing.assert_allclose(ls[:, 0], [0.10, 0.18, 0.14])  # min, max, midpoint
    np.testing.assert_allclose(ls[:, 1:], [[0.1, 0.05]] * 3)  # max == min on y, z: l_min
    fixed = _adaptive(((0, 0, 0), (1, 1, 1)))
    np.testing.assert_allclose(fixed.length_scales([[2.0, -1.0, 0.5]]), [[0.18, 0.10, 0.065]])
    assert fixed.normalization == "fixed" and m.normalization == "session"
    assert m.metadata()["normalization"] == "session"


def test_adaptive_with_equal_bounds_ignores_pose_variance():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1, 1, (300, 3))
    y = (rng.random(300) < 0.5).astype(float)
    maps = []
    for var in (rng.uniform(0, 1, (300, 3)), rng.uniform(0, 50, (300, 3))):
        m = make_mapper("adaptive", l_min=(0.15, 0.15, 0.06), l_max=(0.15, 0.15, 0.06))
        m.integrate(Samples.from_points(pts, y, 0.9, var))
        maps.append(m.occupancy())
    np.testing.assert_array_equal(maps[0].cells, maps[1].cells)
    np.testing.assert_array_equal(maps[0].alpha, maps[1].alpha)


def test_csm_equals_hand_counts():
    pts = [[0.01, 0.02, 0.03], [0.09, 0.09, 0.09], [0.05, 0.05, 0.05],  # 3 hits in (0, 0, 0)
           [0.02, 0.08, 0.01], [0.07, 0.01, 0.02],  # 2 free in (0, 0, 0)
           [-0.05, 0.0, 0.25]]  # 1 free in (-1, 0, 2)  # fmt: skip
    y = [1, 1, 1, 0, 0, 0]
    m = make_mapper("csm")
    m.integrate(Samples.from_points(pts, y, 0.6))
    occ = m.occupancy()
    got = _mass_by_cell(occ)
    assert got == {(0, 0, 0): (3.0, 2.0), (-1, 0, 2): (0.0, 1.0)}
    i = {tuple(c): n for n, c in enumerate(occ.cells)}[(0, 0, 0)]
    assert occ.mean[i] == pytest.approx(0.6)
    assert occ.variance[i] == pytest.approx(3 * 2 / (25 * 6))  # eq:mean_var
    np.testing.assert_allclose(occ.points(), [[0.05, 0.05, 0.05]])


def test_integrate_is_additive_and_grows_storage():
    rng = np.random.default_rng(5)
    pts = rng.uniform(-20, 20, (4000, 3))  # many chunks: forces several grow/rehash rounds
    y = (rng.random(4000) < 0.4).astype(float)
    whole = make_mapper("bki")
    whole.integrate(Samples.from_points(pts, y, 0.9))
    parts = make_mapper("bki")
    for k in range(4):
        parts.integrate(Samples.from_points(pts[k::4], y[k::4], 0.9))
    a, b = whole.occupancy(), parts.occupancy()
    oa, ob = np.lexsort(a.cells.T), np.lexsort(b.cells.T)
    np.testing.assert_array_equal(a.cells[oa], b.cells[ob])
    np.testing.assert_allclose(a.alpha[oa], b.alpha[ob], rtol=1e-5)
    assert whole.grid.n_chunks > 64


def test_csm_hit_cells_match_octomap():
    octomap = pytest.importorskip("octomap")
    rng = np.random.default_rng(11)
    cols = rng.choice(400, 60, replace=False)
    xy = (np.stack([cols // 20, cols % 20], 1) + rng.uniform(0.1, 0.9, (60, 2))) * RES
    hits = np.column_stack([xy, rng.uniform(1.51, 1.89, 60)])
    tree = octomap.OcTree(RES)
    m = make_mapper("csm")
    for h in hits:  # vertical rays from z = 0, one per xy cell
        tree.insertPointCloud(h[None], np.array([h[0], h[1], 0.0]))
        s = np.arange(0.0, h[2] - RES + 1e-9, RES)
        free = np.column_stack([np.full_like(s, h[0]), np.full_like(s, h[1]), s])
        m.integrate(Samples.from_points(np.vstack([h, free]), [1.0] + [0.0] * len(s)))
    ours = {tuple(np.round(c, 3)) for c in m.occupancy().points()}
    peer = set()
    for leaf in tree.begin_leafs():
        if tree.isNodeOccupied(leaf):
            peer.add(tuple(np.round(leaf.getCoordinate(), 3)))
    assert ours == peer and len(ours) == 60


def test_invalid_inputs_rejected_with_clear_message():
    """make_mapper checks its settings in MappingConfig (the one place they are checked)."""
    with pytest.raises(ConfigError, match="mapping.resolution: Input should be greater than 0"):
        make_mapper("bki", resolution=-0.1)
    with pytest.raises(ConfigError, match=r"need 0 < l_min <= l_max per axis, got \(0.2, "):
        make_mapper("adaptive", l_min=(0.2, 0.1, 0.05), l_max=(0.18, 0.18, 0.08))
    with pytest.raises(ConfigError, match=r"mapping.l_max: .*expected three values \(x, y, z\)"):
        make_mapper("adaptive", l_max=(0.18, 0.18))
    with pytest.raises(
        ConfigError, match="mapping.method: Input should be 'csm', 'bki', 'adaptive' or 'tpu'"
    ):
        make_mapper("octree")
    with pytest.raises(ConfigError, match="variance_bounds need 0 <= min <= max"):
        make_mapper("adaptive", variance_bounds=((1, 1, 1), (0, 0, 0)))
    for name, value in (("alpha0", float("inf")), ("l_max", (0.18, 0.18, float("inf"))),
                        ("max_memory_gb", float("nan")), ("length_scale", float("inf")),
                        ("variance_bounds", ((0, 0, 0), (1, 1, float("nan")))),
                        ("max_memory_gb", 0)):  # fmt: skip
        with pytest.raises(ConfigError, match=f"mapping.{name}"):
            make_mapper("adaptive", **{name: value})
    with pytest.raises(TypeError, match="required keyword-only"):
        AdaptiveBkiMapper()  # constructors hold no defaults of their own
    with pytest.raises(DataError, match="expected \\(N, 3\\)"):
        Samples.from_points(np.zeros((4, 2)), np.zeros(4))
    with pytest.raises(DataError, match="label: shape"):
        Samples.from_points(np.zeros((4, 3)), np.zeros(3))
    with pytest.raises(DataError, match="non-finite"):
        Samples.from_points([[0, 0, np.nan]], [1.0])
    with pytest.raises(DataError, match="needs Samples"):
        make_mapper("csm").integrate(np.zeros((3, 3)))
    with pytest.raises(DataError, match="beyond"):  # would alias chunk keys
        make_mapper("bki").integrate(Samples.from_points([[1e6, 0.0, 0.0]], [1.0]))


def test_numpy_arrays_are_accepted_as_settings():
    bounds = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    m = make_mapper("adaptive", l_min=np.array([0.1, 0.1, 0.05]), variance_bounds=bounds)
    np.testing.assert_array_equal(m.l_min, [0.1, 0.1, 0.05])
    np.testing.assert_array_equal(np.array(m.variance_bounds), bounds)


@pytest.mark.parametrize("method", ["csm", "bki", "adaptive"])
def test_chunk_count_matches_the_chunks_the_scatter_creates(method):
    """The memory estimate counts the distinct chunks the supports touch without storing them:
    the same number the scatter then allocates."""
    from undertow.mapping.kernels import count_chunks

    rng = np.random.default_rng(3)
    points = rng.uniform(-2, 2, (500, 3))
    samples = Samples.from_points(
        points, rng.integers(0, 2, 500), 0.9, rng.uniform(0, 1e-3, (500, 3))
    )
    mapper = make_mapper(method, resolution=0.05)
    if method == "adaptive":
        lo, hi, bounds = mapper.l_min, mapper.l_max, mapper._bounds(samples.pose_variance)
    else:
        lo = hi = np.full(3, 0.15 if method == "bki" else 0.0)
        bounds = (np.zeros(3), np.zeros(3))
    mode = {"csm": 2, "bki": 1, "adaptive": 0}[method]
    table = np.full(1 << 16, -1, np.int64)
    n = count_chunks(mode, samples.points, samples.pose_variance, *bounds, lo, hi, 0.05, table,
                      0, 10**6)  # fmt: skip
    mapper.integrate(samples)
    assert n == mapper.grid.n_chunks


def test_memory_limit_and_out_of_memory_are_one_line_errors(monkeypatch):
    samples = Samples.from_points(np.random.default_rng(0).uniform(0, 5, (2000, 3)), 1.0)
    mapper = make_mapper("adaptive", max_memory_gb=0.001)
    with pytest.raises(ConfigError, match=r"would need an estimated .* GB or more \(limit 0.001"):
        mapper.integrate(samples)
    assert mapper.grid.n_chunks == 0  # refused before any storage was allocated
    big = make_mapper("adaptive", max_memory_gb=100)

    def no_memory(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(big.grid, "scatter", no_memory)
    with pytest.raises(ConfigError, match="ran out of memory at resolution 0.1 m"):
        big.integrate(samples)


def test_length_scales_must_exceed_a_tenth_of_the_resolution():
    from undertow.mapping.config import MappingConfig

    with pytest.raises(ConfigError, match="length_scale 0.15 m is not above resolution / 10"):
        make_mapper("bki", resolution=2.0)
    with pytest.raises(ConfigError, match="l_min"):
        make_mapper("adaptive", resolution=1.0)
    make_mapper("csm", resolution=2.0)  # no length scale
    with pytest.raises(ConfigError, match="not above resolution / 10"):
        MappingConfig.from_dict({"method": "bki", "resolution": 2.0})
    with pytest.raises(ConfigError, match="both false in the config"):
        MappingConfig.from_dict({"use_dvl": False, "use_sonar": False})
    with pytest.raises(ConfigError, match="mapping.resolution"):
        MappingConfig.from_dict({"resolution": float("inf")})
