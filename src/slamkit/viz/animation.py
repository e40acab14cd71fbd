"""An animated GIF of a run: the estimate growing over time, from the runner's frames.

Each frame of :attr:`slamkit.pipeline.Result.frames` becomes one image: the path estimated so
far, the current pose with its ``n_sigma`` position ellipse, the estimator's map at that
moment (landmarks with their ellipses) and its particles, over the true trajectory and
landmarks (or the GPS track) where the data set has them. The axes are fixed to the extent
of the whole run, so the picture does not jump.
"""

from __future__ import annotations

import os
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter

from slamkit.errors import InputError
from slamkit.geometry.alignment import Similarity
from slamkit.viz.plots import (
    new_figure,
    plot_covariance_ellipses,
    plot_landmark_estimates,
    plot_trajectory,
)
from slamkit.viz.report import plot_reference

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes

    from slamkit.datasets import Dataset
    from slamkit.pipeline.runner import Result

__all__ = ["save_animation"]


def save_animation(
    result: Result,
    dataset: Dataset,
    path: str | os.PathLike[str],
    *,
    fps: int = 8,
    n_sigma: float = 3.0,
    gps_alignment: Similarity | None = None,
) -> Path:
    """Write the frames of ``result`` as an animated GIF to ``path`` (atomically: a reader
    never sees a half-written file) and return the path.

    ``gps_alignment`` is the similarity that maps the estimate into the GPS frame (the
    ``alignment`` of an evaluation's :class:`~slamkit.eval.GpsError`); with it the GPS track
    is drawn in the estimate's frame. Raises :class:`~slamkit.errors.InputError` when the
    run kept no frames.
    """
    frames = result.frames
    if not frames:
        raise InputError("save_animation: the run kept no frames (run it with frames > 0)")
    target = Path(path)
    fig = new_figure(figsize=(6.4, 5.6), dpi=80.0)
    ax = fig.add_subplot()
    truth = dataset.truth
    plot_reference(ax, truth, gps_alignment)
    if truth.poses is not None:
        plot_trajectory(ax, truth.poses, label="ground truth", color="black", linewidth=1.0)
    _fix_limits(ax, result, dataset)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    (path_line,) = ax.plot([], [], color="tab:blue", linewidth=1.2, label="estimate")
    ax.legend(loc="upper right", fontsize="x-small")
    title = ax.set_title("")
    dynamic: list[Artist] = []

    def draw(i: int) -> list[Artist]:
        for artist in dynamic:
            artist.remove()
        dynamic.clear()
        f = frames[i]
        upto = int(np.searchsorted(result.times, f.t, side="right"))
        path_line.set_data(result.poses[:upto, 0], result.poses[:upto, 1])
        if f.particles is not None and f.particles.size:
            dynamic.append(
                ax.scatter(f.particles[:, 0], f.particles[:, 1], s=2, color="tab:red", alpha=0.3)
            )
        if f.cov is not None:
            dynamic.append(
                plot_covariance_ellipses(
                    ax, f.pose[None, :2], f.cov[None, :2, :2], n_sigma=n_sigma, color="tab:blue"
                )
            )
        if f.landmarks is not None and len(f.landmarks.landmarks):
            dynamic.extend(
                plot_landmark_estimates(
                    ax,
                    f.landmarks.landmarks.positions,
                    f.landmarks.covariances,
                    n_sigma=n_sigma,
                    label=None,
                )
            )
        title.set_text(f"{result.estimator} on {result.dataset}: t = {f.t:.1f} s")
        return [path_line, title, *dynamic]

    anim = FuncAnimation(fig, draw, frames=len(frames), blit=False)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex}.tmp.gif")
    try:
        anim.save(str(tmp), writer=PillowWriter(fps=fps))
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return target


def _fix_limits(ax: Axes, result: Result, dataset: Dataset) -> None:
    """Axis limits around everything the animation will draw, with a 5 % margin."""
    pts = [result.poses[:, :2]]
    if dataset.truth.poses is not None:
        pts.append(dataset.truth.poses[:, :2])
    if dataset.truth.landmarks is not None:
        pts.append(dataset.truth.landmarks.positions)
    last = result.frames[-1].landmarks
    if last is not None and len(last.landmarks):
        pts.append(last.landmarks.positions)
    xy = np.concatenate(pts)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = 0.05 * max(float(np.max(hi - lo)), 1.0)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
