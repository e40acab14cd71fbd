"""What a run is drawn over: the data set's reference (walls, true landmarks, the GPS track,
the true path), the box a map view shows, and the grid under it. Shared by the run's
figures (:mod:`slamkit.viz.report`), its map, loop and particle views
(:mod:`slamkit.viz.run_views`) and its animation (:mod:`slamkit.viz.animation`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from slamkit.viz.layout import Box, map_box, plot_start_end, reference_box, union_box
from slamkit.viz.plots import plot_landmarks, plot_segments, plot_trajectory, plot_truth

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from slamkit.datasets import Dataset, GroundTruth
    from slamkit.geometry.alignment import Similarity
    from slamkit.maps import OccupancyGrid
    from slamkit.pipeline.runner import Result

__all__ = [
    "MANY_LANDMARKS",
    "POINT_ESTIMATORS",
    "map_under",
    "plot_estimate_over_truth",
    "plot_reference",
    "reference_extent",
]

POINT_ESTIMATORS = frozenset({"least-squares"})
"""Estimators whose estimates are independent fixes, drawn as points rather than a path."""

MANY_LANDMARKS = 60
"""Above this many true landmarks the stars are drawn small, so they do not bury the rest."""


def plot_reference(ax: Axes, truth: GroundTruth, gps_alignment: Similarity | None = None) -> None:
    """What a data set knows of the world, under an estimate: its walls, its true landmarks
    and — given ``gps_alignment``, the similarity that maps the estimate into the GPS frame
    (:attr:`slamkit.eval.GpsError.alignment`) — the GPS track in the estimate's frame."""
    if truth.walls is not None:
        plot_segments(ax, truth.walls)
    if truth.landmarks is not None:
        many = len(truth.landmarks.positions) > MANY_LANDMARKS
        plot_landmarks(
            ax,
            truth.landmarks,
            label="true landmarks",
            s=18 if many else 80,
            alpha=0.6 if many else 1.0,
        )
    if truth.positions is not None and gps_alignment is not None:
        xy = gps_alignment.inverse().apply_to_points(truth.positions)
        ax.plot(xy[:, 0], xy[:, 1], ".", ms=1.5, color="0.55", label="GPS (aligned)", zorder=1)


def reference_extent(
    result: Result, dataset: Dataset, grid: OccupancyGrid | None = None
) -> Box | None:
    """The box a run's map view should show: the true path, walls, true landmarks, the known
    cells of ``grid``, the landmarks the run mapped, and the estimate between its 2 % and
    98 % quantiles when there is a reference (0.5 %–99.5 % without one) — never the
    covariance ellipses, and not a lost start's first wild estimates."""
    truth = dataset.truth
    parts = [
        None if truth.poses is None else truth.poses[:, :2],
        None if truth.walls is None else truth.walls.segments.reshape(-1, 2),
        None if truth.landmarks is None else truth.landmarks.positions,
    ]
    ref = union_box(reference_box(parts), None if grid is None else map_box(grid))
    est = reference_box([result.poses[:, :2]], quantile=0.02 if ref is not None else 0.005)
    mapped = result.output.landmarks
    lm = None
    if mapped is not None and len(mapped.landmarks.positions):
        lm = reference_box([mapped.landmarks.positions], quantile=0.0 if ref else 0.01)
    return union_box(ref, est, lm)


def plot_estimate_over_truth(
    ax: Axes, result: Result, dataset: Dataset, *, markers: bool = True
) -> None:
    """The estimate (blue; independent fixes as dots) under the true path (black, dashed),
    with start and end markers on the estimate."""
    if result.estimator in POINT_ESTIMATORS:
        ax.plot(
            result.poses[:, 0],
            result.poses[:, 1],
            ".",
            ms=3,
            color="tab:blue",
            label="least-squares fixes",
            zorder=2,
        )
    else:
        plot_trajectory(
            ax, result.poses, label="estimate", color="tab:blue", linewidth=1.6, zorder=2
        )
    if dataset.truth.poses is not None:
        plot_truth(ax, dataset.truth.poses)
    if markers and result.estimator not in POINT_ESTIMATORS:
        plot_start_end(ax, result.poses)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def map_under(result: Result, dataset: Dataset) -> OccupancyGrid | None:
    """The occupancy grid a run's map view is drawn on: the one it built, else the one it
    localized in."""
    return result.output.grid if result.output.grid is not None else dataset.known_grid
