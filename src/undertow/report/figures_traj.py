"""Trajectory figures (paper Fig. 3): estimated vs ground-truth path, and the error along it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import DataError
from ..log import GroundTruth
from ..rotations import wrap_angle
from ..trajectory import Trajectory
from .figures import GROUND_TRUTH_COLOR, new_figure, save_figure, variant_color

_MAX_LINE_POINTS = 5000


def _thin(n: int) -> slice:
    return slice(None, None, max(1, n // _MAX_LINE_POINTS))


def _check(ground_truth: GroundTruth | None, trajectories: dict) -> None:
    if ground_truth is None or len(ground_truth) < 2:
        raise DataError("trajectory figures need a ground truth with at least 2 poses")
    if not trajectories:
        raise DataError("trajectory figures need at least one trajectory")


def plot_trajectories(path, ground_truth: GroundTruth, trajectories: dict[str, Trajectory]) -> Path:
    """Paper Fig. 3a: top view (x-y) and side view (x-z, depth down) of the ground truth (green)
    against each estimate (proposed blue, baseline red, others from the colour cycle)."""
    _check(ground_truth, trajectories)
    fig, (top, side) = new_figure(10, 7, nrows=2, sharex=True)
    gp = ground_truth.position[_thin(len(ground_truth))]
    for ax, j in ((top, 1), (side, 2)):
        ax.plot(gp[:, 0], gp[:, j], color=GROUND_TRUTH_COLOR, lw=2.5, label="ground truth")
        for i, (name, traj) in enumerate(trajectories.items()):
            p = traj.position[_thin(len(traj))]
            style = "--" if name == "baseline" else "-"
            ax.plot(p[:, 0], p[:, j], color=variant_color(name, i), ls=style, lw=1.3, label=name)
        ax.grid(alpha=0.3)
        ax.legend(loc="best")
    top.set(ylabel="y (m)", title="Trajectory, top view (paper Fig. 3a)")
    side.set(xlabel="x (m)", ylabel="depth z (m, down)", title="Trajectory, side view")
    side.invert_yaxis()
    return save_figure(fig, path)


def _errors(gt: GroundTruth, traj: Trajectory):
    """Times, errors (x, y, yaw) and their 2-sigma bounds from P, inside the GT time span."""
    inside = (traj.t >= gt.t[0]) & (traj.t <= gt.t[-1])
    t = traj.t[inside]
    pos, rpy, _ = gt.interpolate(t)
    x = traj.x[inside]
    err = np.stack([x[:, 0] - pos[:, 0], x[:, 1] - pos[:, 1],
                    wrap_angle(x[:, 5] - rpy[:, 2])], axis=1)  # fmt: skip
    var = np.stack([traj.P[inside, i, i] for i in (0, 1, 5)], axis=1)
    return t, err, 2.0 * np.sqrt(np.clip(var, 0.0, None))


def plot_trajectory_errors(
    path, ground_truth: GroundTruth, trajectories: dict[str, Trajectory]
) -> Path:
    """Paper Fig. 3b: error of x, y and yaw against the ground truth over time; the baseline
    dashed, the proposed solid, with the proposed filter's own +-2 sigma band (from P)."""
    _check(ground_truth, trajectories)
    fig, axes = new_figure(10, 7.5, nrows=3, sharex=True)
    labels = ("x error (m)", "y error (m)", "yaw error (deg)")
    scale = (1.0, 1.0, 180.0 / np.pi)
    for i, (name, traj) in enumerate(trajectories.items()):
        t, err, two_sigma = _errors(ground_truth, traj)
        if len(t) == 0:
            raise DataError(f"trajectory {name!r} does not overlap the ground truth in time")
        color = variant_color(name, i)
        style = "--" if name == "baseline" else "-"
        for k, ax in enumerate(axes):
            if name == "proposed":
                ax.fill_between(t, -two_sigma[:, k] * scale[k], two_sigma[:, k] * scale[k],
                                color=color, alpha=0.15, lw=0,
                                label="proposed +-2 sigma (from P)")  # fmt: skip
            ax.plot(t, err[:, k] * scale[k], color=color, ls=style, lw=1.3, label=name)
    for ax, label in zip(axes, labels, strict=True):
        ax.axhline(0.0, color="0.4", lw=0.8)
        ax.set(ylabel=label)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=9)
    axes[0].set_title("Error along the trajectory (paper Fig. 3b)")
    axes[-1].set_xlabel("time (s)")
    return save_figure(fig, path)


def plot_estimators(path, ground_truth: GroundTruth, trajectories: dict[str, Trajectory],
                    title: str = "") -> Path:  # fmt: skip
    """Several estimators of one run together (the style of paper Fig. 3): the top view (x-y)
    against the ground truth (green), then the horizontal position error
    sqrt(e_x^2 + e_y^2) and the yaw error over time, one colour per estimator (the UKF's solid,
    the others dashed)."""
    _check(ground_truth, trajectories)
    fig, (top, horizontal, yaw) = new_figure(10, 10, nrows=3)
    gp = ground_truth.position[_thin(len(ground_truth))]
    top.plot(gp[:, 0], gp[:, 1], color=GROUND_TRUTH_COLOR, lw=2.5, label="ground truth")
    for i, (name, traj) in enumerate(trajectories.items()):
        color = variant_color(name, i)
        style = "-" if name.startswith(("baseline", "proposed")) else "--"
        p = traj.position[_thin(len(traj))]
        top.plot(p[:, 0], p[:, 1], color=color, ls=style, lw=1.2, label=name)
        t, err, _ = _errors(ground_truth, traj)
        if len(t) == 0:
            raise DataError(f"trajectory {name!r} does not overlap the ground truth in time")
        horizontal.plot(t, np.hypot(err[:, 0], err[:, 1]), color=color, ls=style, lw=1.2,
                        label=name)  # fmt: skip
        yaw.plot(t, np.degrees(err[:, 2]), color=color, ls=style, lw=1.2, label=name)
    top.set(xlabel="x (m)", ylabel="y (m)", title=title or "Estimators, top view")
    horizontal.set(ylabel="horizontal error (m)")
    yaw.set(xlabel="time (s)", ylabel="yaw error (deg)")
    yaw.axhline(0.0, color="0.4", lw=0.8)
    for ax in (top, horizontal, yaw):
        ax.grid(alpha=0.3)
    top.legend(loc="best", fontsize=8)
    return save_figure(fig, path)
