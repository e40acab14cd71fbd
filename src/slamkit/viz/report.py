"""The standard figures of one run: map view, per-axis errors (with ±3σ when the estimator
has a covariance, else after the ATE's alignment), NEES over time.

Every picture is made to be read: axis limits from the trajectories and the map, not from
covariance ellipses or a lost start (:mod:`slamkit.viz.layout`); the map the run localizes
or maps in drawn under it; the truth dashed over the estimate; start and end marked;
legends beside the axes; times counted from the start of the run.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from slamkit.eval import (
    ConvergenceReport,
    GpsError,
    RelationError,
    chi2_bounds,
    nis_summary,
)
from slamkit.geometry.alignment import Similarity
from slamkit.optim.data import loop_closures
from slamkit.viz.layout import (
    legend_outside,
    plot_start_end,
    robust_abs_limit,
    set_box,
)
from slamkit.viz.maps import plot_map
from slamkit.viz.plots import (
    new_figure,
    plot_closures,
    plot_consistency,
    plot_covariance_ellipses,
    plot_landmark_estimates,
    plot_nis,
    plot_particles,
    plot_path_by_time,
    plot_pose_errors,
)
from slamkit.viz.reference import (
    POINT_ESTIMATORS,
    map_under,
    plot_estimate_over_truth,
    plot_reference,
    reference_extent,
)
from slamkit.viz.relations import plot_relation_errors
from slamkit.viz.run_views import loop_figure, map_figure, particle_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from slamkit.datasets import Dataset
    from slamkit.pipeline.evaluate import Evaluation
    from slamkit.pipeline.runner import Result

__all__ = ["FIGURE_DPI", "gps_alignment", "run_figures"]

FIGURE_DPI = 150.0
"""Resolution of the PNGs a run writes (a 9 × 6.5 in figure: 1350 × 975 pixels)."""


def gps_alignment(evaluation: Evaluation) -> Similarity | None:
    """The similarity that maps the estimate into the GPS frame, if the run was scored
    against GPS."""
    gps = evaluation.scores.gps
    return gps.alignment if isinstance(gps, GpsError) else None


def run_figures(
    result: Result, dataset: Dataset, evaluation: Evaluation, *, n_sigma: float = 3.0
) -> dict[str, Figure]:
    """Figures keyed by file name: ``trajectory.png`` always (over the map the run built or
    localized in); ``errors.png`` and ``nees.png`` when the data set has a true trajectory
    (and the estimator covariances); ``particles.png`` when the estimator kept particle
    snapshots; ``nis.png`` when it logged innovations; ``map.png`` when it built an occupancy
    grid; ``loops.png`` when it built a pose graph with loop closures;
    ``relation_errors.png`` when it was scored against the data set's reference relations."""
    figs: dict[str, Figure] = {
        "trajectory.png": _trajectory_figure(result, dataset, evaluation, n_sigma)
    }
    t0 = float(result.times[0]) if len(result) else 0.0
    if evaluation.errors is not None and evaluation.matched_times is not None:
        figs["errors.png"] = _error_figure(result, evaluation, n_sigma, t0)
    if evaluation.nees is not None and evaluation.matched_times is not None:
        ok = np.isfinite(evaluation.nees)
        if np.any(ok):
            fig = new_figure(figsize=(9.0, 4.0))
            ax = fig.add_subplot()
            lo, hi = chi2_bounds(3, 1, 0.95)
            plot_consistency(ax, evaluation.matched_times[ok] - t0, evaluation.nees[ok], (lo, hi))
            ax.set_yscale("log")
            ax.set_xlabel("time since the start [s]")
            ax.set_title("NEES of the pose (3 dof) with the 95 % χ² band")
            legend_outside(ax)
            figs["nees.png"] = fig
    if result.output.grid is not None:
        figs["map.png"] = map_figure(result, dataset)
    graph = result.output.graph
    if graph is not None and graph.dim == 2 and len(graph.poses) > 1:
        figs["loops.png"] = loop_figure(result, dataset)
    if result.output.particle_snapshots:
        figs["particles.png"] = particle_figure(result, dataset)
    log = result.output.innovations
    if log is not None and len(log) > 0:
        summary = nis_summary(log.times, log.nis, log.dof, window=50)
        fig = new_figure(figsize=(9.0, 4.0))
        ax = fig.add_subplot()
        plot_nis(
            ax,
            summary.window_start - t0,
            summary.window_sums,
            summary.window_lower,
            summary.window_upper,
        )
        ax.set_xlabel("time since the start [s]")
        ax.set_ylabel("NIS / band centre")
        ax.set_title(
            f"NIS over windows of {summary.window} updates: consistent for "
            f"{100 * summary.consistent_time_fraction:.0f} % of the run"
        )
        legend_outside(ax)
        figs["nis.png"] = fig
    rel = evaluation.scores.relations
    if isinstance(rel, RelationError):
        fig = new_figure(figsize=(9.0, 5.5))
        axes = fig.subplots(2, 1, sharex=True)
        plot_relation_errors(axes, rel)
        axes[0].set_title(f"relation errors: {rel.summary()}")
        figs["relation_errors.png"] = fig
    return figs


def _trajectory_figure(
    result: Result, dataset: Dataset, evaluation: Evaluation, n_sigma: float
) -> Figure:
    fig = new_figure(figsize=(9.0, 6.5))
    ax = fig.add_subplot()
    grid = map_under(result, dataset)
    if grid is not None:
        plot_map(ax, grid, scale_bar=False)
    plot_reference(ax, dataset.truth, gps_alignment(evaluation))
    own_data = dataset.truth.poses is None and dataset.truth.positions is None
    if own_data and result.estimator not in POINT_ESTIMATORS and len(result) > 1:
        # Nothing to draw the path against: when the robot was where, and the closures.
        plot_path_by_time(ax, result.times, result.poses)
        plot_start_end(ax, result.poses)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    else:
        plot_estimate_over_truth(ax, result, dataset)
    graph = result.output.graph
    if graph is not None and graph.dim == 2:
        plot_closures(ax, graph.poses, loop_closures(graph))
    if result.covariances is not None and len(result) > 1:
        every = max(1, len(result) // 25)
        plot_covariance_ellipses(
            ax,
            result.poses[:, :2],
            result.covariances[:, :2, :2],
            n_sigma=n_sigma,
            every=every,
            label=f"{n_sigma:g}σ position",
            linewidth=0.6,
            alpha=0.7,
        )
    est_lm = result.output.landmarks
    if est_lm is not None:
        plot_landmark_estimates(ax, est_lm.landmarks.positions, est_lm.covariances, n_sigma=n_sigma)
    snaps = result.output.particle_snapshots
    if snaps:  # the last particle cloud over the map (FastSLAM: the poses behind the maps)
        cloud = plot_particles(ax, snaps[-1].particles, snaps[-1].weights, max_points=3000)
        cloud[0].set_label(f"particles at t = {snaps[-1].t - result.times[0]:.1f} s")
        cloud[0].set_zorder(5)
    set_box(ax, reference_extent(result, dataset, grid))
    if grid is not None:
        from slamkit.viz.layout import add_scale_bar

        add_scale_bar(ax)
    ax.set_title(f"{result.estimator} on {result.dataset}")
    legend_outside(ax)
    return fig


def _error_figure(result: Result, evaluation: Evaluation, n_sigma: float, t0: float) -> Figure:
    """x, y, heading errors against the time since the start, each axis limited to what the
    run shows after its first transient (convergence, when the run was scored for it).

    With the estimator's covariance: the errors as they are (no alignment, as the NEES
    reads them) with the ``±n_sigma·σ`` band. Without: the errors after the SE(2)
    alignment of the headline ATE, and no band; the title says which."""
    assert evaluation.errors is not None and evaluation.matched_times is not None
    t = evaluation.matched_times - t0
    fig = new_figure(figsize=(9.0, 6.5))
    axes = fig.subplots(3, 1, sharex=True)
    errors, sigmas = evaluation.errors, evaluation.sigmas
    if sigmas is not None:
        title = f"estimate − truth (no alignment) with the estimator's ±{n_sigma:g}σ"
    elif evaluation.aligned_errors is not None:
        errors = evaluation.aligned_errors
        title = "estimate − truth after the SE(2) alignment of the ATE (no covariance: no σ band)"
    else:
        title = "estimate − truth (no alignment; no covariance: no σ band)"
    plot_pose_errors(axes, t, errors, sigmas, n_sigma)
    conv = evaluation.scores.convergence
    settle = conv.time if isinstance(conv, ConvergenceReport) and conv.time is not None else None
    # after convergence; without a convergence score, after the first 5 % of the run
    first = settle if settle is not None else float(t[0] + 0.05 * (t[-1] - t[0]))
    after = t >= first
    if not np.any(after):
        after = np.ones_like(t, dtype=bool)
    unit = np.array([1.0, 1.0, np.degrees(1.0)])
    err = errors.copy()
    err[:, 2] = (err[:, 2] + np.pi) % (2 * np.pi) - np.pi
    for i, ax in enumerate(axes):
        half = robust_abs_limit(err[after, i] * unit[i], quantile=1.0)
        if sigmas is not None:
            half = max(half, robust_abs_limit(n_sigma * sigmas[after, i] * unit[i], quantile=0.95))
        half = 1.25 * half if half > 0 else 1.0
        ax.set_ylim(-half, half)
        ax.axhline(0.0, color="0.6", linewidth=0.6, zorder=0)
        if settle is not None and settle > 0:
            ax.axvspan(
                float(t[0]),
                settle,
                color="0.85",
                zorder=0,
                label="before convergence" if i == 0 else None,
            )
    axes[-1].set_xlabel("time since the start [s]")
    axes[0].set_title(title)
    legend_outside(axes[0])
    return fig
