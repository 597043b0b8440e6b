"""Report figures: one function per paper figure, each drawing one PNG and returning its path.

Figures are drawn on a bare :class:`matplotlib.figure.Figure` with the Agg canvas (no pyplot,
no global state) and written atomically (temp file, then rename). Depth is z DOWN, as in the
rest of the library, so side views put the surface at the top.

This module holds the shared helpers and the sensor and kernel figures; the trajectory figures
live in :mod:`.figures_traj` and the map figures in :mod:`.figures_map`. Every figure is
importable from :mod:`undertow.report`.

- :func:`plot_velocity` -- paper Fig. 8 (DVL x velocity vs estimate vs ground truth).
- :func:`plot_disturbance` -- paper Fig. 2b (wave elevation, DVL altitude, DVL x velocity).
- :func:`plot_kernel_shapes` -- paper Fig. 7 kernel figure (small vs large length scales).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._util.atomic import atomic_path
from ..errors import DataError
from ..log import Log
from ..mapping.kernels import product_kernel, sparse_kernel
from ..trajectory import Trajectory

DPI = 120
GROUND_TRUTH_COLOR = "tab:green"
VARIANT_COLORS = {"proposed": "tab:blue", "baseline": "tab:red"}
DISTANCE_CMAP = "turbo"  # blue = close to the ground truth, red = far


def new_figure(width_in: float, height_in: float, nrows: int = 1, ncols: int = 1, **kw):
    """A constrained-layout Figure with an Agg canvas and its axes (squeezed like pyplot)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - matplotlib is a dependency
        raise ImportError("figures need matplotlib: pip install 'matplotlib>=3.8'") from exc
    fig = Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=True, **kw)
    return fig, axes


def save_figure(fig, path: str | Path) -> Path:
    """Write ``fig`` as PNG at :data:`DPI` (atomic), at exactly figsize * DPI pixels."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=DPI)
    return path


def variant_color(name: str, index: int) -> str:
    """Paper colours: proposed blue, baseline red; other variants from the default cycle."""
    others = ("tab:purple", "tab:orange", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
    return VARIANT_COLORS.get(name, others[index % len(others)])


def subsample(points: np.ndarray, n_max: int, seed: int = 0) -> np.ndarray:
    """At most ``n_max`` rows of ``points``, chosen at random (fixed seed, order kept)."""
    points = np.asarray(points)
    if len(points) <= n_max:
        return points
    idx = np.sort(np.random.default_rng(seed).choice(len(points), n_max, replace=False))
    return points[idx]


def cloud(name: str, points) -> np.ndarray:
    """``points`` as a finite (N, 3) float array, else a clear :class:`DataError`."""
    arr = np.asarray(points, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise DataError(f"{name}: shape {arr.shape}, expected (N, 3)")
    return arr[np.all(np.isfinite(arr), axis=1)]


def dvl_body_velocity(log: Log) -> tuple[np.ndarray, np.ndarray]:
    """Times and valid DVL velocities rotated from the DVL frame to body axes (N, 3).

    v^B = R_dvl^B v^DVL; the lever-arm term omega x r is left out (the DVL's own reading).
    """
    dvl = log.dvl
    ok = dvl.valid & np.all(np.isfinite(dvl.velocity), axis=1)
    rot = log.mounting.dvl.rotation_matrix()
    return dvl.t[ok], dvl.velocity[ok] @ rot.T


def plot_velocity(path, log: Log, trajectory: Trajectory) -> Path:
    """Paper Fig. 8: body x velocity u -- ground truth (green), estimate (blue), DVL (red).

    The DVL reading is rotated to body axes; the ground truth is the differentiated, smoothed
    ground-truth position expressed in the body frame (as :mod:`undertow.evaluation`).
    """
    log.require("dvl", stage="plot_velocity")
    fig, ax = new_figure(10, 4)
    t_dvl, v_dvl = dvl_body_velocity(log)
    ax.plot(t_dvl, v_dvl[:, 0], color="tab:red", lw=0.8, alpha=0.8, label="DVL measurement")
    ax.plot(trajectory.t, trajectory.x[:, 6], color="tab:blue", lw=1.4,
            label=f"estimate ({trajectory.variant or 'UKF'})")  # fmt: skip
    gt = log.ground_truth
    if gt is not None and len(gt) >= 3:
        t = np.linspace(gt.t[0], gt.t[-1], min(len(gt), 4000))
        ax.plot(t, gt.body_velocity(t)[:, 0], color=GROUND_TRUTH_COLOR, lw=1.4,
                label="ground truth")  # fmt: skip
    ax.set(xlabel="time (s)", ylabel="body x velocity u (m/s)",
           title="Velocity in x: ground truth, estimate and DVL (paper Fig. 8)")  # fmt: skip
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    return save_figure(fig, path)


def plot_disturbance(path, log: Log) -> Path:
    """Paper Fig. 2b: wave elevation at the probe, DVL altitude and DVL x velocity over time."""
    log.require("wave_probe", "dvl", stage="plot_disturbance")
    fig, axes = new_figure(10, 7, nrows=3, sharex=True)
    wp = log.wave_probe
    axes[0].plot(wp.t, wp.elevation, color="tab:cyan", lw=0.8,
                 label=f"wave probe at x = {wp.x:.1f} m")  # fmt: skip
    axes[0].set(ylabel="elevation (m, up)", title="Wave disturbance on the DVL (paper Fig. 2b)")
    dvl = log.dvl
    axes[1].plot(dvl.t, dvl.altitude, color="tab:purple", lw=0.8, label="DVL altitude")
    axes[1].set(ylabel="altitude (m)")
    t_dvl, v_dvl = dvl_body_velocity(log)
    axes[2].plot(t_dvl, v_dvl[:, 0], color="tab:red", lw=0.8, label="DVL x velocity (body)")
    axes[2].set(ylabel="x velocity (m/s)", xlabel="time (s)")
    for ax in axes:
        lo, hi = ax.get_ylim()
        ax.set_ylim(lo, hi + 0.3 * (hi - lo))  # headroom for the legend
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right")
    return save_figure(fig, path)


def plot_kernel_shapes(path, l_small, l_large, sigma0: float = 1.0) -> Path:
    """Paper Fig. 7 (kernel figure): the adaptive product kernel for small and large pose
    uncertainty.

    ``l_small`` / ``l_large`` are length scales (x, y, z) in m (a scalar means all axes), e.g.
    ``AdaptiveBkiMapper.length_scales`` of the least and most uncertain samples. Top row: 1-D
    profiles k(d) of ``eq:kernel`` along x and along z; bottom row: the 2-D x-z heat map of
    ``eq:decom_kernel`` (y = 0) for each.
    """
    ls = {"small uncertainty": np.broadcast_to(np.asarray(l_small, float), 3),
          "large uncertainty": np.broadcast_to(np.asarray(l_large, float), 3)}  # fmt: skip
    if any(np.any(v <= 0) or not np.all(np.isfinite(v)) for v in ls.values()):
        raise DataError("plot_kernel_shapes: length scales must be positive and finite")
    reach = 1.15 * max(float(v.max()) for v in ls.values())
    d = np.linspace(-reach, reach, 401)
    fig, axes = new_figure(10, 7.5, nrows=2, ncols=2)
    styles = {"small uncertainty": ("tab:blue", "-"), "large uncertainty": ("tab:red", "--")}
    for col, (axis_name, j) in enumerate((("x", 0), ("z", 2))):
        ax = axes[0, col]
        for name, lv in ls.items():
            color, style = styles[name]
            ax.plot(d, sigma0 * sparse_kernel(d, lv[j]), color=color, ls=style,
                    label=f"{name}: l_{axis_name} = {lv[j]:.3f} m")  # fmt: skip
        ax.set(xlabel=f"offset d_{axis_name} (m)", ylabel="k(d)",
               title=f"Kernel profile along {axis_name}")  # fmt: skip
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    gx, gz = np.meshgrid(d, d)
    delta = np.stack([gx, np.zeros_like(gx), gz], axis=-1)
    image = None
    for col, (name, lv) in enumerate(ls.items()):
        ax = axes[1, col]
        k = product_kernel(delta, lv, sigma0)
        image = ax.imshow(k, origin="lower", extent=(-reach, reach, -reach, reach),
                          cmap="viridis", vmin=0.0, vmax=sigma0, aspect="equal")  # fmt: skip
        ax.set(xlabel="offset x (m)", ylabel="offset z (m)",
               title=f"{name}: l = ({lv[0]:.2f}, {lv[1]:.2f}, {lv[2]:.2f}) m")  # fmt: skip
    fig.colorbar(image, ax=axes[1, :], label="kernel weight k(m*, m_i)", shrink=0.9)
    fig.suptitle("Adaptive sparse kernel for small and large pose uncertainty (paper Fig. 7)")
    return save_figure(fig, path)
