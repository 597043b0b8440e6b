"""A tpu map of a flat floor with two survey patches whose depth stds are known in closed form,
for the tests of the IHO order (tests/mapping/test_iho.py, tests/commands/test_iho_order.py)."""

from __future__ import annotations

import numpy as np

from undertow.mapping import make_mapper
from undertow.mapping.samples import SENSOR_DVL, expand
from undertow.occupancy import OccupancyMap

RES = 0.1
FLOOR = 2.0  # m, z down
S_R = 0.005  # the DVL's range noise (MappingConfig.range_std_dvl)
GOOD, POOR = 0.05, 0.30  # the two patches' pose depth std, m
BASE = 0.10  # the tpu mapper's base length (MappingConfig.base_length)
REACH = 0.75  # the column sums' reach, in kernel lengths (undertow.mapping.columns.SUPPORT)


def two_patches() -> OccupancyMap:
    """DVL beams straight down from 0.5 m onto a floor FLOOR deep: a 1 x 0.6 m patch whose
    poses' depth std is GOOD and, 3 m further along x, one whose is POOR (horizontal std 1 mm,
    so the kernels are the base one and the patches do not touch). Without waves each column's
    propagated std is :func:`expected_std` of its patch (a flat floor: no slope term)."""
    x, y = patch_hits()
    origin = np.concatenate([np.stack([x, y, np.full(x.size, 0.5)], axis=1),
                             np.stack([x + 3.0, y, np.full(x.size, 0.5)], axis=1)])  # fmt: skip
    n = len(origin)
    var = np.full((n, 3), 1e-6)
    var[: x.size, 2], var[x.size :, 2] = GOOD**2, POOR**2
    samples = expand(origin, np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, FLOOR - 0.5), var,
                     np.full(n, 0.6), np.full(n, SENSOR_DVL), 0.1, {})  # fmt: skip
    mapper = make_mapper("tpu", resolution=RES, wave_range_noise=False)
    mapper.integrate(samples)
    return mapper.occupancy()


def patch_hits() -> tuple[np.ndarray, np.ndarray]:
    """The (x, y) of the first patch's hits (the second's are 3 m further along x)."""
    xs, ys = np.meshgrid(np.arange(0.0, 1.0, 0.05), np.arange(0.0, 0.6, 0.05))
    return xs.ravel(), ys.ravel()


def sparse_kernel(d, l):
    """The sparse kernel of Melkumyan and Ramos (2009) at distances d >= 0, length l."""
    r = np.minimum(np.asarray(d, float) / l, 1.0)
    return (2.0 + np.cos(2.0 * np.pi * r)) * (1.0 - r) / 3.0 + np.sin(2.0 * np.pi * r) / (
        2.0 * np.pi
    )


def expected_std(cx, cy, s_z: float, length: float = BASE) -> np.ndarray:
    """The closed form of a column centred at (cx, cy) of the first patch: sqrt(s_z^2 + S_R^2
    sum_i k_i^2 / (sum_i k_i)^2), k_i the product kernel of hit i at the column's centre (the
    hits of a patch weigh alike; the shared pose error s_z is not averaged, the range noise
    is, over the hits within 0.75 l along each axis, where the column sums reach)."""
    x, y = patch_hits()
    dx = np.abs(np.asarray(cx, float)[..., None] - x)
    dy = np.abs(np.asarray(cy, float)[..., None] - y)
    k = np.where((dx <= REACH * length) & (dy <= REACH * length),
                 sparse_kernel(dx, length) * sparse_kernel(dy, length), 0.0)  # fmt: skip
    return np.sqrt(s_z**2 + S_R**2 * (k * k).sum(-1) / k.sum(-1) ** 2)
