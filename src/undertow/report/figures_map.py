"""Map figures (paper Figs. 4, 5 and 6): map points coloured by their distance to the
ground-truth cloud, a vertical slice comparing mappers, the rock survey over the true rock, and
the top view of a map's implied seafloor coloured by its depth error.

Distances are the C2C distances of :mod:`undertow.evaluation.cloud` (nearest ground-truth
point); colours run blue (close) to red (far), clipped at the 95th percentile. The surface error
is e = d - z_true of :mod:`undertow.evaluation.surface` (z down: e > 0 the map is too deep).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..errors import DataError
from ..evaluation.surface import truth_heightfield
from ..mapping.surface import Surface
from ..occupancy import OccupancyMap
from .figures import DISTANCE_CMAP, cloud, new_figure, save_figure, subsample

_GT_POINTS = 30_000


def _distance_scale(*distances: np.ndarray) -> float:
    """Colour-scale top: max(95th percentile, 2 x median), so the typical point sits at most
    mid-scale (a grid map's half-cell offsets would otherwise all be "red")."""
    d = np.concatenate([np.ravel(x) for x in distances]) if distances else np.zeros(0)
    if not d.size:
        return 1.0
    return max(float(np.percentile(d, 95)), 2.0 * float(np.median(d)), 1e-3)


def _cell_boxes(ax, x, z, res, values, cmap, vmin, vmax):
    """Draw one res x res square per cell centre (x, z), coloured by ``values``."""
    from matplotlib.collections import PolyCollection

    h = res / 2.0
    corners = np.array([(-h, -h), (h, -h), (h, h), (-h, h)])
    verts = np.stack([np.asarray(x, float), np.asarray(z, float)], axis=1)[:, None, :] + corners
    boxes = PolyCollection(verts, array=np.asarray(values), cmap=cmap, edgecolors="none")
    boxes.set_clim(vmin, vmax)
    ax.add_collection(boxes)
    return boxes


def plot_map_distance(path, map_points, ground_truth_cloud, vmax: float | None = None) -> Path:
    """Paper Fig. 4: map points (occupied cell centres) coloured by distance to the ground-truth
    cloud (blue low, red high; colour bar in m) over the subsampled ground truth (grey); side
    view (x-z, depth down) and top view (x-y). ``vmax`` (m) fixes the top of the colour scale."""
    mp = cloud("map_points", map_points)
    gt = cloud("ground_truth_cloud", ground_truth_cloud)
    if len(gt) == 0:
        raise DataError("plot_map_distance: empty ground-truth cloud")
    dist = cKDTree(gt).query(mp, k=1)[0] if len(mp) else np.zeros(0)
    vmax = _distance_scale(dist) if vmax is None else float(vmax)
    gts = subsample(gt, _GT_POINTS)
    fig, axes = new_figure(11, 7, nrows=2, sharex=True)
    order = np.argsort(dist)  # far points drawn last, on top
    sc = None
    for ax, j, name in ((axes[0], 2, "depth z (m, down)"), (axes[1], 1, "y (m)")):
        ax.scatter(gts[:, 0], gts[:, j], s=1.0, c="0.45", alpha=0.5, lw=0,
                   label="ground-truth scan (subsampled)", rasterized=True)  # fmt: skip
        sc = ax.scatter(mp[order, 0], mp[order, j], s=5, c=dist[order], cmap=DISTANCE_CMAP,
                        vmin=0.0, vmax=vmax, lw=0, label=f"map points ({len(mp)})")  # fmt: skip
        ax.set(ylabel=name)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", markerscale=4, fontsize=8)
    axes[0].invert_yaxis()
    axes[0].set_title("Map points coloured by distance to the ground truth, side view (Fig. 4)")
    axes[1].set(xlabel="x (m)", title="Top view")
    fig.colorbar(sc, ax=axes, label="distance to ground truth (m)", extend="max", shrink=0.9)
    return save_figure(fig, path)


def plot_map_slice(
    path,
    maps: dict[str, OccupancyMap],
    ground_truth_cloud,
    y_range: tuple[float, float],
    x_range: tuple[float, float] | None = None,
    threshold: float = 0.5,
) -> Path:
    """Paper Fig. 6: a vertical x-z slice (cells with centre y in ``y_range``) near the floor,
    one row per map (e.g. adaptive vs BKI): occupied cells as squares coloured by distance to
    the ground truth, ground-truth points of the same y band in grey."""
    if not maps:
        raise DataError("plot_map_slice: no maps given")
    y0, y1 = sorted(float(v) for v in y_range)
    gt = cloud("ground_truth_cloud", ground_truth_cloud)
    if len(gt) == 0:
        raise DataError("plot_map_slice: empty ground-truth cloud")
    tree = cKDTree(gt)
    band = gt[(gt[:, 1] >= y0) & (gt[:, 1] <= y1)]
    slices = {}
    for name, m in maps.items():
        c = m.points(threshold)
        c = c[(c[:, 1] >= y0) & (c[:, 1] <= y1)]
        if x_range is not None:
            c = c[(c[:, 0] >= min(x_range)) & (c[:, 0] <= max(x_range))]
        slices[name] = (c, tree.query(c, k=1)[0] if len(c) else np.zeros(0), m.resolution)
    vmax = _distance_scale(*(d for _, d, _ in slices.values()))
    fig, axes = new_figure(11, 1.2 + 2.2 * len(maps), nrows=len(maps), sharex=True, sharey=True)
    axes = np.atleast_1d(axes)
    boxes = None
    if x_range is not None:
        band = band[(band[:, 0] >= min(x_range)) & (band[:, 0] <= max(x_range))]
    band = subsample(band, _GT_POINTS)
    for ax, (name, (c, d, res)) in zip(axes, slices.items(), strict=True):
        ax.scatter(band[:, 0], band[:, 2], s=2, c="0.45", lw=0, label="ground truth",
                   rasterized=True, zorder=3)  # fmt: skip
        boxes = _cell_boxes(ax, c[:, 0], c[:, 2], res, d, DISTANCE_CMAP, 0.0, vmax)
        ax.plot([], [], "s", color="0.7", label=f"occupied cells ({len(c)}), colour = distance")
        ax.set(ylabel="depth z (m, down)", title=f"{name}: slice {y0:.2f} <= y <= {y1:.2f} m")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    zs = np.concatenate([band[:, 2]] + [c[:, 2] for c, _, _ in slices.values()])
    xs = np.concatenate([band[:, 0]] + [c[:, 0] for c, _, _ in slices.values()])
    if zs.size:
        axes[0].set_ylim(zs.max() + 0.25, zs.min() - 0.25)  # depth down
        axes[0].set_xlim(xs.min() - 0.2, xs.max() + 0.2)
    axes[-1].set_xlabel("x (m)")
    fig.colorbar(boxes, ax=axes, label="distance to ground truth (m)", extend="max", shrink=0.9)
    fig.suptitle("Map slice near the floor (paper Fig. 6)")
    return save_figure(fig, path)


def _rock_tuple(rock) -> tuple[float, float, float, float, float]:
    if hasattr(rock, "center_x_m"):
        rock = (rock.center_x_m, rock.center_y_m, rock.length_m, rock.width_m, rock.height_m)
    values = tuple(float(v) for v in rock)
    if len(values) != 5:
        raise DataError("rock: expected (center_x, center_y, length, width, height) in m")
    return values


def plot_rock_map(path, occupancy_map: OccupancyMap, rock, floor_depth: float,
                  threshold: float = 0.5) -> Path:  # fmt: skip
    """Paper Fig. 5: the rock-survey map over the rock's true outline.

    Left: top view, per x-y column the shallowest occupied cell, coloured by its height above
    the floor (floor_depth - z), with the rock's footprint. Right: x-z slice of the cells within
    one cell of the rock's centre line y = center_y, with the true rock profile and floor.
    ``rock`` is (center_x, center_y, length, width, height) in m (or a ``RockModel``).
    """
    cx, cy, length, width, height = _rock_tuple(rock)
    occ = occupancy_map.occupied(threshold)
    res = occupancy_map.resolution
    c = occ.centres
    fig, (top, side) = new_figure(12, 5, ncols=2)
    from matplotlib.patches import Rectangle

    if len(c):
        order = np.lexsort((c[:, 2], c[:, 1], c[:, 0]))  # shallowest first per column
        cells = occ.cells[order]
        first = np.ones(len(order), bool)
        first[1:] = np.any(cells[1:, :2] != cells[:-1, :2], axis=1)
        col = c[order][first]
        boxes = _cell_boxes(top, col[:, 0], col[:, 1], res, floor_depth - col[:, 2], "viridis",
                            min(0.0, float((floor_depth - col[:, 2]).min())),
                            max(height * 1.2, 0.1))  # fmt: skip
        fig.colorbar(boxes, ax=top, label="height above floor (m)", shrink=0.9)
        top.set_xlim(col[:, 0].min() - res, col[:, 0].max() + res)
        top.set_ylim(col[:, 1].min() - res, col[:, 1].max() + res)
    top.add_patch(Rectangle((cx - length / 2, cy - width / 2), length, width, fill=False,
                            ec="red", lw=2, label="true rock outline"))  # fmt: skip
    top.set(xlabel="x (m)", ylabel="y (m)", title="Top view: shallowest occupied cell",
            aspect="equal")  # fmt: skip
    top.legend(loc="upper center", bbox_to_anchor=(0.5, -0.26), fontsize=8)
    strip = occ.select(np.abs(c[:, 1] - cy) <= res) if len(c) else occ
    sc = strip.centres
    lo_x, hi_x = cx - 2.5 * length, cx + 2.5 * length
    keep = (sc[:, 0] >= lo_x) & (sc[:, 0] <= hi_x)
    slice_boxes = _cell_boxes(side, sc[keep, 0], sc[keep, 2], res, strip.mean[keep], "Blues",
                              0.5, 1.0)  # fmt: skip
    fig.colorbar(slice_boxes, ax=side, label="occupancy mean", shrink=0.9)
    side.plot([lo_x, hi_x], [floor_depth, floor_depth], color="0.5", lw=1.5, label="true floor")
    side.add_patch(Rectangle((cx - length / 2, floor_depth - height), length, height, fill=False,
                             ec="red", lw=2, label="true rock profile"))  # fmt: skip
    side.plot([], [], "s", color="tab:blue", label=f"occupied cells ({int(keep.sum())})")
    side.set(xlim=(lo_x, hi_x), ylim=(floor_depth + 0.4, floor_depth - height - 0.4),
             xlabel="x (m)", ylabel="depth z (m, down)",
             title=f"Side slice |y - {cy:.2f}| <= {res:.2f} m")  # fmt: skip
    side.grid(alpha=0.3)
    side.legend(loc="lower right", fontsize=8)
    fig.suptitle("Rock survey map against the true rock (paper Fig. 5)")
    return save_figure(fig, path)


def _surface_error(surface: Surface, height) -> np.ndarray:
    """e = d - z_true at every cell centre (NaN where the map or the truth has no depth)."""
    x, y = surface.centres()
    with np.errstate(invalid="ignore"):
        return surface.depth - np.asarray(height(x, y), dtype=float)


def plot_surface_error(path, surfaces: dict[str, Surface], truth, title: str = "") -> Path:
    """Top view (x-y) of each map's implied seafloor (:func:`undertow.mapping.surface.
    map_surface`), one row per map, every column coloured by its depth error e = d - z_true
    (red: too deep, blue: too shallow; a shared scale clipped at the 95th percentile of |e|),
    with the RMSE and bias of e in each row's title. ``truth``: a heightfield z(x, y) or the
    ground-truth cloud (N, 3)."""
    if not surfaces:
        raise DataError("plot_surface_error: no maps given")
    height = truth_heightfield(truth)
    errors = {name: _surface_error(s, height) for name, s in surfaces.items()}
    finite = np.concatenate([e[np.isfinite(e)] for e in errors.values()])
    vmax = max(float(np.percentile(np.abs(finite), 95)), 1e-3) if finite.size else 0.1
    fig, axes = new_figure(11, 1.0 + 2.4 * len(surfaces), nrows=len(surfaces), sharex=True,
                           sharey=True)  # fmt: skip
    axes = np.atleast_1d(axes)
    mesh = None
    for ax, (name, s) in zip(axes, surfaces.items(), strict=True):
        e = errors[name]
        ny, nx = s.shape
        xe = s.x0 + s.resolution * (np.arange(nx + 1) - 0.5)
        ye = s.y0 + s.resolution * (np.arange(ny + 1) - 0.5)
        mesh = ax.pcolormesh(xe, ye, np.ma.masked_invalid(e), cmap="RdBu_r", vmin=-vmax,
                             vmax=vmax, shading="flat", rasterized=True)  # fmt: skip
        ok = e[np.isfinite(e)]
        stats = (f"RMSE {np.sqrt(np.mean(ok**2)):.3f} m, bias {np.mean(ok):+.3f} m, "
                 f"{ok.size} columns") if ok.size else "no data"  # fmt: skip
        ax.set(ylabel="y (m)", title=f"{name}: {stats}")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("x (m)")
    fig.colorbar(mesh, ax=axes, label="surface error d - z_true (m, + too deep)", extend="both",
                 shrink=0.9)  # fmt: skip
    fig.suptitle(title or "Map surface coloured by its depth error (top view)")
    return save_figure(fig, path)
