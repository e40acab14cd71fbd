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

__all__ = ["plot_pose_graph", "pose_graph_figure", "principal_plane"]


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
                cast(Any, segments),
                colors=edge_color,
                linewidths=0.5,
                zorder=1,
                label="loop closures",
            )
            ax.add_collection(coll)
            drawn["edges"] = coll
    kw: dict[str, Any] = {"color": color, "linewidth": 1.0, "zorder": 2, **style}
    (line,) = ax.plot(p[:, 0], p[:, 1], label=label, **kw)
    drawn["trajectory"] = line
    if landmarks is not None:
        lm = as_array(landmarks, "landmarks", (None, 2))
        if lm.shape[0]:
            drawn["landmarks"] = ax.scatter(
                lm[:, 0],
                lm[:, 1],
                marker="+",
                s=30,
                color=landmark_color,
                zorder=3,
                label="landmarks",
            )
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return drawn


def principal_plane(
    initial: ArrayLike, optimized: ArrayLike
) -> tuple[np.ndarray, np.ndarray, tuple[str, str]]:
    """Positions ``(N, 3)`` of a 3D graph before and after, projected onto the plane of the
    two largest principal axes of the optimised positions (the plane the trajectory mostly
    lies in: for a car, the ground; for a sphere of poses, a great circle's plane), both
    about the optimised centroid. Returns the two ``(N, 2)`` projections and axis labels."""
    p0 = as_array(initial, "initial", (None, 3))
    p1 = as_array(optimized, "optimized", (None, 3))
    if p1.shape[0] < 3:
        return p0[:, :2], p1[:, :2], ("x [m]", "y [m]")
    centre = p1.mean(axis=0)
    vt = np.linalg.svd(p1 - centre, full_matrices=False)[2]
    basis = vt[:2].T  # (3, 2): the two directions of largest spread
    # name each axis by the world axis it is closest to
    names = [
        f"principal axis {k + 1} (≈{'xyz'[int(np.argmax(np.abs(basis[:, k])))]}) [m]"
        for k in range(2)
    ]
    return (p0 - centre) @ basis, (p1 - centre) @ basis, (names[0], names[1])


def pose_graph_figure(
    initial: ArrayLike,
    optimized: ArrayLike,
    *,
    edges: ArrayLike | None = None,
    initial_landmarks: ArrayLike | None = None,
    optimized_landmarks: ArrayLike | None = None,
    titles: tuple[str, str] = ("initial", "optimised"),
    suptitle: str | None = None,
    axis_labels: tuple[str, str] = ("x [m]", "y [m]"),
    same_scale: bool = True,
) -> Figure:
    """Two panels side by side: the graph at its initial values (grey) and optimised (blue),
    on one scale (``same_scale``: shared limits round both, so the change is seen as it
    is), or each on its own."""
    fig = new_figure(figsize=(13.0, 6.0))
    ax0, ax1 = fig.subplots(1, 2, sharex=same_scale, sharey=same_scale)
    plot_pose_graph(ax0, initial, edges=edges, landmarks=initial_landmarks, color="0.35")
    plot_pose_graph(ax1, optimized, edges=edges, landmarks=optimized_landmarks)
    for ax, title in zip((ax0, ax1), titles, strict=True):
        if same_scale:  # shared axes keep their aspect by the box, not the limits
            ax.set_aspect("equal", adjustable="box")
        ax.set_title(title, fontsize="medium")
        ax.set_xlabel(axis_labels[0])
        ax.set_ylabel(axis_labels[1])
    if same_scale:
        from slamkit.viz.layout import reference_box, set_box

        set_box(ax0, reference_box([initial, optimized, initial_landmarks, optimized_landmarks]))
        ax1.set_autoscale_on(False)
    if suptitle:
        fig.suptitle(suptitle)
    return fig
