"""Plotting: trajectories, covariance ellipses, maps, pose errors and NEES/NIS traces.

Needs matplotlib (``pip install "slamkit[plot]"``). Numerical packages never import this one;
every function draws on an ``Axes`` it is given and returns the artists it drew.
"""

try:
    import matplotlib as _matplotlib  # noqa: F401
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError(
        'slamkit.viz needs matplotlib; install it with: pip install "slamkit[plot]"'
    ) from exc

from slamkit.viz.graphs import plot_pose_graph, pose_graph_figure
from slamkit.viz.plots import (
    new_figure,
    plot_consistency,
    plot_covariance_ellipses,
    plot_landmark_estimates,
    plot_landmarks,
    plot_nis,
    plot_occupancy_grid,
    plot_particles,
    plot_pose_errors,
    plot_segments,
    plot_trajectories,
    plot_trajectory,
    save_figure,
)
from slamkit.viz.relations import plot_relation_errors

__all__ = [
    "new_figure",
    "plot_consistency",
    "plot_covariance_ellipses",
    "plot_landmark_estimates",
    "plot_landmarks",
    "plot_nis",
    "plot_occupancy_grid",
    "plot_particles",
    "plot_pose_errors",
    "plot_pose_graph",
    "plot_relation_errors",
    "plot_segments",
    "plot_trajectories",
    "plot_trajectory",
    "pose_graph_figure",
    "save_figure",
]
