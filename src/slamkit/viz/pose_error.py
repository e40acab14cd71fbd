"""Figures of ``slamkit eval ape`` / ``rpe`` (:class:`slamkit.eval.pose_error.PoseErrorResult`):
the two trajectories from above after alignment, and the errors against time, each drawn on
given axes."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from slamkit.errors import ShapeError
from slamkit.eval.pose_error import PoseErrorResult, describe_alignment
from slamkit.viz.plots import new_figure

__all__ = ["plot_aligned_trajectories", "plot_pose_errors_over_time", "pose_error_figures"]


def plot_aligned_trajectories(ax: Axes, result: PoseErrorResult) -> list[Artist]:
    """The reference (dashed, on top) and the aligned estimate in the x-y plane [m], with
    start (circle) and end (square) markers; equal axes."""
    ref, est = result.reference[:, :2, 3], result.estimate[:, :2, 3]
    drawn: list[Artist] = []
    (line_e,) = ax.plot(est[:, 0], est[:, 1], color="tab:blue", lw=1.2,
                        label=f"estimate ({describe_alignment(result.alignment)})")  # fmt: skip
    (line_r,) = ax.plot(ref[:, 0], ref[:, 1], color="black", lw=1.0, ls="--", label="reference",
                        zorder=3)  # fmt: skip
    drawn += [line_e, line_r]
    drawn.append(ax.scatter(*ref[0], marker="o", color="tab:green", zorder=4, label="start"))
    drawn.append(ax.scatter(*ref[-1], marker="s", color="tab:red", zorder=4, label="end"))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best", fontsize="small", framealpha=0.8)
    return drawn


def plot_pose_errors_over_time(
    axes: Sequence[Axes], result: PoseErrorResult, kind: str = "ape"
) -> list[Artist]:
    """APE (``kind="ape"``) or RPE (``"rpe"``) translation [m] and rotation [deg] on two axes,
    against time from the first pair [s] (pair index for files without stamps), with the
    RMSE as a dashed line."""
    if len(axes) != 2:
        raise ShapeError(f"axes: expected 2 axes (translation, rotation), got {len(axes)}")
    if kind == "ape":
        idx = np.arange(result.matched)
        values = (result.ape_translation, np.degrees(result.ape_rotation))
    elif kind == "rpe":
        idx = result.rpe_pairs[:, 1]
        values = (result.rpe_translation, np.degrees(result.rpe_rotation))
    else:
        raise ShapeError(f"kind: expected 'ape' or 'rpe', got {kind!r}")
    if result.times is not None:
        x, xlabel = result.times[idx] - result.times[0], "time from the start [s]"
    else:
        x, xlabel = idx.astype(float), "pose index"
    drawn: list[Artist] = []
    for ax, v, name in zip(axes, values, ("translation [m]", "rotation [deg]"), strict=True):
        (line,) = ax.plot(x, v, lw=0.9, color="tab:blue", label=f"{kind.upper()} {name}")
        rmse = float(np.sqrt(np.mean(v * v)))
        ref = ax.axhline(rmse, color="black", ls="--", lw=1.0, label=f"RMSE {rmse:.4g}")
        drawn += [line, ref]
        ax.set_ylabel(f"{kind.upper()} {name}")
        ax.set_ylim(bottom=0.0)
        ax.legend(loc="upper left", fontsize="small", framealpha=0.8)
    axes[-1].set_xlabel(xlabel)
    return drawn


def pose_error_figures(result: PoseErrorResult, kind: str) -> dict[str, Figure]:
    """The figures of one evaluation: ``trajectories.png`` and ``{kind}.png``."""
    top = new_figure(figsize=(7.0, 6.0), dpi=130)
    plot_aligned_trajectories(top.add_subplot(), result)
    errors = new_figure(figsize=(8.0, 5.5), dpi=130)
    plot_pose_errors_over_time(errors.subplots(2, 1, sharex=True), result, kind)
    errors.suptitle(f"{kind.upper()}, {describe_alignment(result.alignment)}", fontsize="medium")
    return {"trajectories.png": top, f"{kind}.png": errors}
