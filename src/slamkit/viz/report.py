"""The standard figures of one run: map view, per-axis errors with ±3σ, NEES over time."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from slamkit.eval import GpsError, RelationError, chi2_bounds, nis_summary
from slamkit.geometry.alignment import Similarity
from slamkit.viz.maps import plot_map
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
)
from slamkit.viz.relations import plot_relation_errors

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from slamkit.datasets import Dataset, GroundTruth
    from slamkit.pipeline.evaluate import Evaluation
    from slamkit.pipeline.runner import Result

__all__ = ["gps_alignment", "plot_reference", "run_figures"]


def gps_alignment(evaluation: Evaluation) -> Similarity | None:
    """The similarity that maps the estimate into the GPS frame, if the run was scored
    against GPS."""
    gps = evaluation.scores.gps
    return gps.alignment if isinstance(gps, GpsError) else None


def plot_reference(ax: Axes, truth: GroundTruth, gps_alignment: Similarity | None = None) -> None:
    """What a data set knows of the world, under an estimate: its walls, its true landmarks
    and — given ``gps_alignment``, the similarity that maps the estimate into the GPS frame
    (:attr:`slamkit.eval.GpsError.alignment`) — the GPS track in the estimate's frame."""
    if truth.walls is not None:
        plot_segments(ax, truth.walls)
    if truth.landmarks is not None:
        plot_landmarks(ax, truth.landmarks, label="true landmarks")
    if truth.positions is not None and gps_alignment is not None:
        xy = gps_alignment.inverse().apply_to_points(truth.positions)
        ax.plot(xy[:, 0], xy[:, 1], ".", ms=1.5, color="0.55", label="GPS (aligned)", zorder=1)


def run_figures(
    result: Result, dataset: Dataset, evaluation: Evaluation, *, n_sigma: float = 3.0
) -> dict[str, Figure]:
    """Figures keyed by file name: ``trajectory.png`` always; ``errors.png`` and ``nees.png``
    when the data set has a true trajectory (and the estimator covariances); ``particles.png``
    when the estimator kept particle snapshots; ``nis.png`` when it logged innovations;
    ``map.png`` when it built an occupancy grid; ``relation_errors.png`` when it was scored
    against the data set's reference relations."""
    figs: dict[str, Figure] = {}
    fig = new_figure(figsize=(7.0, 6.0))
    ax = fig.add_subplot()
    plot_reference(ax, dataset.truth, gps_alignment(evaluation))
    plot_trajectories(ax, truth=dataset.truth.poses, estimate=result.poses, legend=False)
    if result.covariances is not None and len(result) > 1:
        every = max(1, len(result) // 25)
        plot_covariance_ellipses(
            ax,
            result.poses[:, :2],
            result.covariances[:, :2, :2],
            n_sigma=n_sigma,
            every=every,
            label=f"{n_sigma:g}σ position",
        )
    est_lm = result.output.landmarks
    if est_lm is not None:
        plot_landmark_estimates(ax, est_lm.landmarks.positions, est_lm.covariances, n_sigma=n_sigma)
    snaps = result.output.particle_snapshots
    if snaps:  # the last particle cloud over the map (FastSLAM: the poses behind the maps)
        cloud = plot_particles(ax, snaps[-1].particles, snaps[-1].weights)
        cloud[0].set_label(f"particles at t = {snaps[-1].t:.1f} s")
    ax.set_title(f"{result.estimator} on {result.dataset}")
    ax.legend(loc="best", fontsize="small")
    figs["trajectory.png"] = fig

    if evaluation.errors is not None and evaluation.matched_times is not None:
        fig = new_figure(figsize=(7.0, 6.0))
        axes = fig.subplots(3, 1, sharex=True)
        plot_pose_errors(
            axes, evaluation.matched_times, evaluation.errors, evaluation.sigmas, n_sigma
        )
        axes[0].set_title(f"estimate − truth with ±{n_sigma:g}σ")
        figs["errors.png"] = fig
    if evaluation.nees is not None and evaluation.matched_times is not None:
        ok = np.isfinite(evaluation.nees)
        if np.any(ok):
            fig = new_figure(figsize=(7.0, 3.5))
            ax = fig.add_subplot()
            lo, hi = chi2_bounds(3, 1, 0.95)
            plot_consistency(ax, evaluation.matched_times[ok], evaluation.nees[ok], (lo, hi))
            ax.set_yscale("log")
            ax.set_xlabel("time [s]")
            ax.set_title("NEES of the pose (3 dof) with the 95 % χ² band")
            figs["nees.png"] = fig
    if result.output.grid is not None:
        fig = new_figure(figsize=(7.0, 6.0))
        ax = fig.add_subplot()
        plot_map(ax, result.output.grid)
        plot_trajectories(ax, estimate=result.poses, legend=False)
        ax.set_title(f"{result.estimator} on {result.dataset}: occupancy grid")
        figs["map.png"] = fig
    if snaps:
        figs["particles.png"] = _particle_figure(result, dataset)
    log = result.output.innovations
    if log is not None and len(log) > 0:
        summary = nis_summary(log.times, log.nis, log.dof, window=50)
        fig = new_figure(figsize=(7.0, 3.5))
        ax = fig.add_subplot()
        plot_nis(ax, summary.window_start, summary.window_sums, summary.window_lower,
                 summary.window_upper)  # fmt: skip
        ax.set_xlabel("time [s]")
        ax.set_ylabel("NIS / band centre")
        ax.set_title(
            f"NIS over windows of {summary.window} updates: consistent for "
            f"{100 * summary.consistent_time_fraction:.0f} % of the run"
        )
        figs["nis.png"] = fig
    rel = evaluation.scores.relations
    if isinstance(rel, RelationError):
        fig = new_figure(figsize=(7.0, 5.0))
        axes = fig.subplots(2, 1, sharex=True)
        plot_relation_errors(axes, rel)
        axes[0].set_title(f"relation errors: {rel.summary()}")
        figs["relation_errors.png"] = fig
    return figs


def _particle_figure(result: Result, dataset: Dataset) -> Figure:
    """Up to six particle clouds side by side, with the map and the true pose."""
    snaps = result.output.particle_snapshots
    pick = np.unique(np.linspace(0, len(snaps) - 1, min(6, len(snaps))).round().astype(int))
    cols = min(3, pick.size)
    rows = int(np.ceil(pick.size / cols))
    fig = new_figure(figsize=(4.0 * cols, 3.6 * rows))
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    truth = dataset.truth
    for ax, i in zip(axes, pick, strict=False):
        snap = snaps[int(i)]
        if truth.walls is not None:
            plot_segments(ax, truth.walls)
        elif dataset.known_grid is not None:
            plot_occupancy_grid(ax, dataset.known_grid)
        if truth.landmarks is not None:
            plot_landmarks(ax, truth.landmarks)
        true_pose = None
        if truth.times is not None and truth.poses is not None and truth.times.size:
            k = int(np.argmin(np.abs(truth.times - snap.t)))
            true_pose = truth.poses[k]
        plot_particles(ax, snap.particles, snap.weights, true_pose=true_pose)
        ax.set_aspect("equal")
        ax.set_title(f"t = {snap.t:.1f} s, {snap.particles.shape[0]} particles", fontsize="small")
    for ax in axes[pick.size :]:
        ax.set_visible(False)
    return fig
