"""Pose graphs on an ``Axes``: the trajectory through the poses, the other relative-pose edges
(loop closures) as faint lines under it, and landmarks; and the before/after figure that
``slamkit optimize`` writes.

Positions are ``(N, 2)`` x-y rows in trajectory order (for a 3D graph the caller passes the
x-y projection and says so in the title); edges are ``(E, 2)`` integer rows into them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, cast

import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from numpy.typing import ArrayLike

from slamkit._validation import as_array
from slamkit.errors import InputError, ShapeError
from slamkit.viz.plots import new_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["plot_pose_graph", "pose_graph_figure"]


def _edge_rows(edges: ArrayLike, n: int) -> np.ndarray:
    e = np.asarray(edges)
    if e.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if e.ndim != 2 or e.shape[1] != 2:
        raise ShapeError(f"edges: expected shape (E, 2), got {e.shape}")
    if e.dtype.kind not in "iu":
        raise InputError(f"edges: expected integer rows, got dtype {e.dtype}")
    if e.min() < 0 or e.max() >= n:
        raise InputError(f"edges: expected rows in [0, {n}), got {int(e.min())}..{int(e.max())}")
    return e.astype(np.int64)


def plot_pose_graph(
    ax: Axes,
    positions: ArrayLike,
    *,
    edges: ArrayLike | None = None,
    landmarks: ArrayLike | None = None,
    label: str | None = None,
    color: str = "tab:blue",
    edge_color: str = "0.8",
    landmark_color: str = "tab:orange",
    **style: Any,
) -> dict[str, Artist]:
    """Draw the poses ``positions (N, 2)`` as one line in row order, the ``edges (E, 2)``
    between rows that are not consecutive (loop closures; consecutive ones lie under the
    line) as one thin :class:`~matplotlib.collections.LineCollection` underneath, and
    ``landmarks (L, 2)`` as crosses. Equal axis scales, metre labels.

    ``style`` goes to the trajectory line. Returns the artists keyed ``"trajectory"``,
    ``"edges"``, ``"landmarks"`` (those drawn).
    """
    p = as_array(positions, "positions", (None, 2))
    drawn: dict[str, Artist] = {}
    if edges is not None:
        e = _edge_rows(edges, p.shape[0])
        e = e[np.abs(e[:, 0] - e[:, 1]) != 1]
        if e.shape[0]:
            segments = np.stack([p[e[:, 0]], p[e[:, 1]]], axis=1)  # (E, 2 ends, xy)
            # An (E, 2, 2) array takes matplotlib's vectorised path; its stubs want a Sequence.
            coll = LineCollection(
                cast(Any, segments), colors=edge_color, linewidths=0.5, zorder=1,
                label="loop closures",
            )  # fmt: skip
            ax.add_collection(coll)
            drawn["edges"] = coll
    kw: dict[str, Any] = {"color": color, "linewidth": 1.0, "zorder": 2, **style}
    (line,) = ax.plot(p[:, 0], p[:, 1], label=label, **kw)
    drawn["trajectory"] = line
    if landmarks is not None:
        lm = as_array(landmarks, "landmarks", (None, 2))
        if lm.shape[0]:
            drawn["landmarks"] = ax.scatter(
                lm[:, 0], lm[:, 1], marker="+", s=30, color=landmark_color, zorder=3,
                label="landmarks",
            )  # fmt: skip
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return drawn


def pose_graph_figure(
    initial: ArrayLike,
    optimized: ArrayLike,
    *,
    edges: ArrayLike | None = None,
    initial_landmarks: ArrayLike | None = None,
    optimized_landmarks: ArrayLike | None = None,
    titles: tuple[str, str] = ("initial", "optimised"),
    suptitle: str | None = None,
) -> Figure:
    """Two panels side by side: the graph at its initial values (grey) and optimised (blue),
    each with its own scale (an odometry start can be far larger than the optimum)."""
    fig = new_figure(figsize=(11.0, 5.5))
    ax0, ax1 = fig.subplots(1, 2)
    plot_pose_graph(ax0, initial, edges=edges, landmarks=initial_landmarks, color="0.35")
    plot_pose_graph(ax1, optimized, edges=edges, landmarks=optimized_landmarks)
    ax0.set_title(titles[0], fontsize="medium")
    ax1.set_title(titles[1], fontsize="medium")
    if suptitle:
        fig.suptitle(suptitle)
    return fig
