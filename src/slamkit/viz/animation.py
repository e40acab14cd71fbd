"""An animated GIF of a run: the estimate growing over time, from the runner's frames.

Frames are picked from :attr:`slamkit.pipeline.Result.frames` evenly over a mix of time and
distance travelled (:func:`~slamkit.viz.layout.pick_frames`: few frames while the robot
stands still). Each becomes one image: the path estimated so far, the current pose as an
arrow with its ``n_sigma`` position ellipse, the estimator's map at that moment (landmarks
with their ellipses) and at most :data:`PARTICLES_DRAWN` of its particles, over the map the
run localizes in, the true landmarks, and the true path and GPS track *up to that moment*
(a frame never shows the future). The axes are fixed to the extent of the whole run (the
trajectories and the map, not the ellipses), so the picture does not jump.
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
from slamkit.viz.layout import legend_outside, pick_frames, set_box
from slamkit.viz.maps import plot_map
from slamkit.viz.plots import (
    TRUTH_STYLE,
    new_figure,
    plot_covariance_ellipses,
    plot_landmark_estimates,
    plot_particles,
)
from slamkit.viz.reference import map_under, plot_reference, reference_extent

if TYPE_CHECKING:
    from collections.abc import Callable

    from matplotlib.artist import Artist
    from matplotlib.figure import Figure

    from slamkit.datasets import Dataset
    from slamkit.pipeline.runner import Result

__all__ = ["MAX_FRAMES", "PARTICLES_DRAWN", "animation_frames", "save_animation"]

PARTICLES_DRAWN = 2000
"""At most this many particles per frame (a deterministic stride over the cloud)."""

MAX_FRAMES = 120
"""At most this many frames in a GIF (about 15 s at 8 frames per second)."""


def animation_frames(
    result: Result,
    dataset: Dataset,
    *,
    n_sigma: float = 3.0,
    gps_alignment: Similarity | None = None,
    max_frames: int = MAX_FRAMES,
) -> tuple[Figure, Callable[[int], list[Artist]], int]:
    """The figure of the animation, the function that draws frame ``i`` on it (and returns
    the artists it changed), and the number of frames (see :func:`save_animation`)."""
    if not result.frames:
        raise InputError("save_animation: the run kept no frames (run it with frames > 0)")
    keep = pick_frames(
        np.array([f.t for f in result.frames]),
        np.array([f.pose[:2] for f in result.frames]),
        max(2, int(max_frames)),
    )
    frames = [result.frames[int(k)] for k in keep]
    fig = new_figure(figsize=(8.0, 6.4), dpi=90.0)
    ax = fig.add_subplot()
    truth = dataset.truth
    grid = map_under(result, dataset) if result.output.grid is None else None
    if grid is not None:  # the map localized in (a map being built would show the future)
        plot_map(ax, grid, scale_bar=False)
    plot_reference(ax, truth, None)  # walls and landmarks; the GPS track grows below
    gps_xy = None
    if truth.positions is not None and gps_alignment is not None:
        gps_xy = gps_alignment.inverse().apply_to_points(truth.positions)
    (gps_line,) = ax.plot(
        [],
        [],
        ".",
        ms=1.5,
        color="0.55",
        zorder=1,
        label="GPS (aligned)" if gps_xy is not None else None,
    )
    (truth_line,) = ax.plot([], [], linewidth=1.0, label="ground truth", zorder=4, **TRUTH_STYLE)
    set_box(ax, reference_extent(result, dataset, grid))
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    (path_line,) = ax.plot([], [], color="tab:blue", linewidth=1.4, label="estimate", zorder=3)
    span = np.diff(ax.get_xlim())[0]
    legend_outside(ax, fontsize="x-small")
    title = ax.set_title("")
    dynamic: list[Artist] = []
    t0 = float(result.times[0]) if len(result) else 0.0

    def draw(i: int) -> list[Artist]:
        for artist in dynamic:
            artist.remove()
        dynamic.clear()
        f = frames[i]
        upto = int(np.searchsorted(result.times, f.t, side="right"))
        path_line.set_data(result.poses[:upto, 0], result.poses[:upto, 1])
        if truth.poses is not None and truth.times is not None:
            k = int(np.searchsorted(truth.times, f.t, side="right"))
            truth_line.set_data(truth.poses[:k, 0], truth.poses[:k, 1])
        if gps_xy is not None and truth.position_times is not None:
            k = int(np.searchsorted(truth.position_times, f.t, side="right"))
            gps_line.set_data(gps_xy[:k, 0], gps_xy[:k, 1])
        if f.particles is not None and f.particles.size:
            dynamic.extend(plot_particles(ax, f.particles, max_points=PARTICLES_DRAWN))
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
        dynamic.append(  # the current pose
            ax.arrow(
                f.pose[0],
                f.pose[1],
                0.03 * span * np.cos(f.pose[2]),
                0.03 * span * np.sin(f.pose[2]),
                width=0.006 * span,
                color="tab:blue",
                ec="black",
                lw=0.5,
                length_includes_head=True,
                zorder=7,
            )
        )
        title.set_text(f"{result.estimator} on {result.dataset}: t = {f.t - t0:.1f} s")
        return [path_line, truth_line, gps_line, title, *dynamic]

    return fig, draw, len(frames)


def save_animation(
    result: Result,
    dataset: Dataset,
    path: str | os.PathLike[str],
    *,
    fps: int = 8,
    n_sigma: float = 3.0,
    gps_alignment: Similarity | None = None,
    max_frames: int = MAX_FRAMES,
) -> Path:
    """Write the frames of ``result`` as an animated GIF to ``path`` (atomically: a reader
    never sees a half-written file) and return the path.

    ``gps_alignment`` is the similarity that maps the estimate into the GPS frame (the
    ``alignment`` of an evaluation's :class:`~slamkit.eval.GpsError`); with it the GPS track
    is drawn in the estimate's frame. Raises :class:`~slamkit.errors.InputError` when the
    run kept no frames.
    """
    fig, draw, count = animation_frames(
        result, dataset, n_sigma=n_sigma, gps_alignment=gps_alignment, max_frames=max_frames
    )
    target = Path(path)
    anim = FuncAnimation(fig, draw, frames=count, blit=False)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex}.tmp.gif")
    try:
        anim.save(str(tmp), writer=PillowWriter(fps=fps))
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return target
