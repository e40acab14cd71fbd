"""The figure of a landmark graph with GPS: the path, the landmark map and the fixes, fused
and held out (``slamkit landmark-graph``'s ``graph.png``)."""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from numpy.typing import ArrayLike

from slamkit.viz.plots import plot_landmarks, plot_trajectory

__all__ = ["plot_gps_fusion"]


def plot_gps_fusion(
    ax: Axes,
    poses: ArrayLike,
    landmarks: ArrayLike,
    fixes: ArrayLike | None = None,
    held_out: ArrayLike | None = None,
    *,
    label: str = "graph",
) -> None:
    """Draw the path ``poses (N, 3)``, the map ``landmarks (L, 2)`` and, when given, the GPS
    ``fixes (M, 2)`` (grey; those where ``held_out (M,)`` is true in red) on ``ax``."""
    if fixes is not None:
        xy = np.asarray(fixes, dtype=float)
        held = np.zeros(xy.shape[0], dtype=bool) if held_out is None else np.asarray(held_out)
        ax.scatter(xy[~held, 0], xy[~held, 1], s=2, color="0.6", label="GPS fixes (fused)")
        if held.any():
            ax.scatter(xy[held, 0], xy[held, 1], s=6, color="tab:red", label="GPS (held out)")
    plot_trajectory(ax, poses, label=label, color="tab:blue", lw=0.8)
    plot_landmarks(ax, landmarks, label="landmarks")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best", fontsize=8)
