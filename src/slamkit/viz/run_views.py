"""The figures of a run beyond the map view: the occupancy map it built, the pose graph's
accepted loop closures over that map, and the particle clouds zoomed to where they are."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, cast

import numpy as np
from matplotlib.collections import LineCollection, PathCollection

from slamkit.optim.data import loop_closures
from slamkit.viz.layout import (
    add_scale_bar,
    legend_outside,
    map_box,
    reference_box,
    set_box,
    union_box,
)
from slamkit.viz.maps import plot_map
from slamkit.viz.plots import (
    new_figure,
    plot_landmark_estimates,
    plot_landmarks,
    plot_occupancy_grid,
    plot_particles,
    plot_segments,
    plot_trajectory,
    plot_truth,
)
from slamkit.viz.reference import plot_estimate_over_truth, reference_extent

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from slamkit.datasets import Dataset
    from slamkit.pipeline.runner import Result

__all__ = ["loop_closures", "loop_figure", "map_figure", "particle_figure"]

PARTICLE_PANELS = 6
PARTICLES_DRAWN = 3000
"""At most this many particles per panel (a deterministic stride over the cloud)."""


def map_figure(result: Result, dataset: Dataset) -> Figure:
    """The occupancy grid the run built, cropped to its observed cells, with the estimate
    and the true path, start and end, and a scale bar."""
    grid = result.output.grid
    assert grid is not None
    fig = new_figure(figsize=(9.0, 6.5))
    ax = fig.add_subplot()
    plot_map(ax, grid, scale_bar=False)
    plot_estimate_over_truth(ax, result, dataset)
    set_box(ax, union_box(map_box(grid), reference_extent(result, dataset, grid)), pad=0.02)
    add_scale_bar(ax)
    ax.set_title(f"{result.estimator} on {result.dataset}: occupancy grid")
    legend_outside(ax)
    return fig


def loop_figure(result: Result, dataset: Dataset) -> Figure:
    """The map with the optimised keyframe path and the accepted loop closures (the graph's
    non-consecutive edges) drawn between the keyframes they join."""
    graph = result.output.graph
    assert graph is not None
    fig = new_figure(figsize=(9.0, 6.5))
    ax = fig.add_subplot()
    grid = result.output.grid
    if grid is not None:
        plot_map(ax, grid, scale_bar=False, alpha=0.8)
    elif dataset.truth.walls is not None:
        plot_segments(ax, dataset.truth.walls, color="0.4", linewidth=1.0)
    kf = graph.poses[:, :2]
    plot_trajectory(
        ax,
        graph.poses[:, :3],
        label=f"keyframes ({kf.shape[0]})",
        color="tab:blue",
        linewidth=1.2,
        marker=".",
        ms=3,
        zorder=3,
    )
    loops = loop_closures(graph)
    if loops.shape[0]:
        segs = np.stack([kf[loops[:, 0]], kf[loops[:, 1]]], axis=1)
        ax.add_collection(
            LineCollection(
                cast(Any, segs),
                colors="tab:red",
                linewidths=1.4,
                zorder=4,
                label=f"loop closures ({loops.shape[0]})",
            )
        )
        ends = np.unique(loops.ravel())
        ax.plot(kf[ends, 0], kf[ends, 1], "o", ms=4, mfc="none", mec="tab:red", zorder=5)
    if dataset.truth.poses is not None:
        plot_truth(ax, dataset.truth.poses, linewidth=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    box = union_box(reference_box([kf]), None if grid is None else map_box(grid))
    set_box(ax, box, pad=0.02)
    add_scale_bar(ax)
    ax.set_title(f"{result.estimator} on {result.dataset}: {loops.shape[0]} accepted loop closures")
    legend_outside(ax)
    return fig


def particle_figure(result: Result, dataset: Dataset) -> Figure:
    """Up to six particle clouds, each panel zoomed to its cloud (at least a fifth of the
    whole scene across): the particles, the estimated path so far, the true pose and path
    so far, and the map — the walls or known grid, the true landmarks, the landmarks the
    run mapped — with a legend beside the first panel."""
    snaps = result.output.particle_snapshots
    pick = np.unique(
        np.linspace(0, len(snaps) - 1, min(PARTICLE_PANELS, len(snaps))).round().astype(int)
    )
    cols = min(3, pick.size)
    rows = int(np.ceil(pick.size / cols))
    fig = new_figure(figsize=(4.8 * cols + 1.8, 4.4 * rows))
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    truth = dataset.truth
    scene = reference_extent(result, dataset, dataset.known_grid)
    min_span = 1.0 if scene is None else 0.3 * max(scene[1] - scene[0], scene[3] - scene[2])
    t0 = float(result.times[0]) if len(result) else 0.0
    mapped = result.output.landmarks
    for n, (ax, i) in enumerate(zip(axes, pick, strict=False)):
        snap = snaps[int(i)]
        if truth.walls is not None:
            plot_segments(ax, truth.walls, linewidth=1.0)
        elif dataset.known_grid is not None:
            plot_occupancy_grid(ax, dataset.known_grid)
        if truth.landmarks is not None:
            plot_landmarks(ax, truth.landmarks, label="true landmarks", s=40, zorder=2)
        if mapped is not None and len(mapped.landmarks.positions):
            plot_landmark_estimates(ax, mapped.landmarks.positions, label="mapped landmarks (end)")
        upto = int(np.searchsorted(result.times, snap.t, side="right"))
        plot_trajectory(
            ax,
            result.poses[:upto],
            label="estimate so far",
            color="tab:blue",
            linewidth=1.2,
            zorder=3,
        )
        true_pose = None
        if truth.times is not None and truth.poses is not None and truth.times.size:
            k = int(np.argmin(np.abs(truth.times - snap.t)))
            true_pose = truth.poses[k]
            plot_truth(
                ax, truth.poses[: k + 1], label="ground truth so far", linewidth=0.8, zorder=3
            )
        cloud = plot_particles(
            ax, snap.particles, snap.weights, true_pose=true_pose, max_points=PARTICLES_DRAWN
        )
        cast(PathCollection, cloud[0]).set_sizes([6.0])
        cloud[0].set_zorder(4)
        cloud[0].set_label(f"particles (≤ {PARTICLES_DRAWN} drawn)")
        box = reference_box([snap.particles[:, :2]], quantile=0.01)
        if true_pose is not None:
            box = union_box(box, (true_pose[0], true_pose[0], true_pose[1], true_pose[1]))
        set_box(ax, box, pad=0.15, min_span=min_span)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(
            f"t = {snap.t - t0:.1f} s, {snap.particles.shape[0]} particles", fontsize="small"
        )
        if n == 0:
            handles, labels = ax.get_legend_handles_labels()
            fig.legend(handles, labels, loc="outside right upper", fontsize="small")
    for ax in axes[pick.size :]:
        ax.set_visible(False)
    return fig
