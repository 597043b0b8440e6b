"""Map evaluation: C2C against closed forms (a plane offset by a known distance)."""

import numpy as np
import pytest

from undertow.errors import DataError
from undertow.evaluation.cloud import evaluate_map


def _plane(x0, x1, y0, y1, step, z=0.0):
    x, y = np.meshgrid(np.arange(x0, x1, step), np.arange(y0, y1, step), indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z)])


def test_plane_offset_gives_c2c_equal_to_offset():
    d = 0.037
    gt = _plane(0, 2, 0, 1, 0.1)
    far = _plane(10, 12, 0, 1, 0.1)  # ground truth outside the mapped footprint
    mp = _plane(0, 2, 0, 1, 0.1, z=d)
    ev = evaluate_map(mp, np.vstack([gt, far]))
    assert ev.c2c_mean_m == pytest.approx(d)
    assert ev.c2c_median_m == pytest.approx(d)
    assert ev.c2c_rmse_m == pytest.approx(d)
    assert ev.coverage_mean_m == pytest.approx(d)  # the far patch is outside the footprint
    assert ev.ground_truth_in_footprint == len(gt)
    assert ev.occupied_cells == len(mp)
    assert set(ev.to_dict()) >= {"c2c_mean_m", "coverage_mean_m", "occupied_cells"}


def test_c2c_against_dense_plane_with_two_offsets():
    # half the points at d1, half at d2 above a dense plane: mean (d1+d2)/2, rmse sqrt mean sq.
    rng = np.random.default_rng(0)
    gt = _plane(-0.1, 2.1, -0.1, 2.1, 0.003)
    xy = rng.uniform(0, 2, (400, 2))
    z = np.where(np.arange(400) < 200, 0.05, 0.2)
    ev = evaluate_map(np.column_stack([xy, z]), gt)
    assert ev.c2c_mean_m == pytest.approx(0.125, abs=5e-5)
    assert ev.c2c_rmse_m == pytest.approx(np.sqrt((0.05**2 + 0.2**2) / 2), abs=5e-5)


def test_bad_clouds_rejected():
    with pytest.raises(DataError, match="expected \\(N, 3\\)"):
        evaluate_map(np.zeros((3, 2)), np.zeros((3, 3)))
    with pytest.raises(DataError, match="non-finite"):
        evaluate_map(np.zeros((3, 3)), [[0, 0, np.nan]])
    assert evaluate_map(np.zeros((0, 3)), np.zeros((3, 3))).occupied_cells == 0
