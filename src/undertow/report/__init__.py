"""Report: tables, PNG figures mirroring the paper's figures, and one self-contained HTML page."""

from .figures import plot_disturbance, plot_kernel_shapes, plot_velocity
from .figures_map import plot_map_distance, plot_map_slice, plot_rock_map
from .figures_traj import plot_estimators, plot_trajectories, plot_trajectory_errors
from .figures_waves import plot_wave_estimate
from .html import markdown_to_html, write_report

__all__ = [
    "markdown_to_html",
    "plot_disturbance",
    "plot_estimators",
    "plot_kernel_shapes",
    "plot_map_distance",
    "plot_map_slice",
    "plot_rock_map",
    "plot_trajectories",
    "plot_trajectory_errors",
    "plot_velocity",
    "plot_wave_estimate",
    "write_report",
]
