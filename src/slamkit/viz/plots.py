"""Plot functions for trajectories, uncertainty, maps and filter consistency.

Rules every function here follows:

* It draws on the ``Axes`` it is given (or the sequence of axes) and returns the artists it
  drew, so callers can restyle, test or remove them. Nothing here calls ``pyplot``: no
  ``plt.show``, no ``plt.pause``, no current figure, no global state.
* Inputs are validated like the numerical code's (shapes, finiteness, covariances).
* Keyword ``**style`` arguments go to the underlying matplotlib call and override the defaults.

Figures for scripts and the CLI come from :func:`new_figure`, which builds a
:class:`matplotlib.figure.Figure` on the Agg canvas directly, so plotting works headless and
never touches pyplot's figure manager; :func:`save_figure` writes it atomically.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal, cast

import numpy as np
from matplotlib import cbook
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import Collection, LineCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.image import AxesImage
from numpy.typing import ArrayLike

from slamkit._validation import as_array, as_positive
from slamkit.errors import InputError, ShapeError
from slamkit.geometry.angles import wrap_angle
from slamkit.maps.types import LandmarkMap, OccupancyGrid, SegmentMap
from slamkit.prob.gaussian import ellipse_points

__all__ = [
    "TRUTH_STYLE",
    "new_figure",
    "plot_consistency",
    "plot_covariance_ellipses",
    "plot_landmark_estimates",
    "plot_landmarks",
    "plot_occupancy_grid",
    "plot_pose_errors",
    "plot_segments",
    "plot_trajectories",
    "plot_trajectory",
    "plot_truth",
    "save_figure",
]

TRUTH_STYLE: dict[str, Any] = {"color": "black", "linestyle": (0, (4, 3))}
"""How every figure draws the true path: dashed black, over the estimate."""


# The one place the trajectory colours and labels are fixed, so every figure slamkit makes
# reads the same way: truth black dashed, estimate blue, dead reckoning grey dashed.
_TRAJECTORY_STYLES: Mapping[str, Mapping[str, Any]] = {
    "dead_reckoning": {
        "color": "0.55",
        "linestyle": "--",
        "linewidth": 1.0,
        "label": "dead reckoning",
    },
    "truth": {**TRUTH_STYLE, "linewidth": 1.5, "label": "ground truth", "zorder": 4},
    "estimate": {"color": "tab:blue", "linestyle": "-", "linewidth": 1.5, "label": "estimate"},
}

_ERROR_LABELS = ("x error [m]", "y error [m]", "heading error [deg]")


def _count(value: int, name: str, minimum: int) -> int:
    if isinstance(value, bool) or int(value) != value or value < minimum:
        raise InputError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    return int(value)


def _collection_style(defaults: Mapping[str, Any], style: Mapping[str, Any]) -> dict[str, Any]:
    """Merge ``style`` over ``defaults`` for a Collection; aliases (``ec``, ``edgecolors``,
    ``lw`` …) are normalised first, and a plain ``color`` means the edge colour."""
    user = dict(cbook.normalize_kwargs(dict(style), Collection))
    if "color" in user and "edgecolor" not in user:
        user["edgecolor"] = user.pop("color")
    return {**defaults, **user}


# --------------------------------------------------------------------------------------------
# figures
# --------------------------------------------------------------------------------------------


def new_figure(
    *,
    figsize: tuple[float, float] = (6.4, 4.8),
    dpi: float = 100.0,
    layout: Literal["constrained", "compressed", "tight"] | None = "constrained",
) -> Figure:
    """A new figure on an Agg canvas, independent of pyplot (works without a display).

    Add axes with ``fig.add_subplot()`` or ``fig.subplots(3, 1, sharex=True)``.
    """
    fig = Figure(figsize=figsize, dpi=dpi, layout=layout)
    FigureCanvasAgg(fig)  # attaches itself as fig.canvas
    return fig


def save_figure(
    fig: Figure,
    path: str | os.PathLike[str],
    *,
    dpi: float | None = None,
    fmt: str | None = None,
    **savefig_kw: Any,
) -> Path:
    """Write ``fig`` to ``path`` atomically and return the path.

    The image is written to a temporary file in the same folder and moved over ``path`` with
    ``os.replace``, so a reader never sees a half-written file. The format comes from ``fmt``
    or the suffix (``.png``, ``.pdf``, ``.svg`` …; PNG without one). Missing parent folders
    are created.
    """
    target = Path(path)
    fmt = (fmt or target.suffix.lstrip(".") or "png").lower()
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, "xb") as fh:
            fig.savefig(fh, format=fmt, dpi="figure" if dpi is None else dpi, **savefig_kw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return target


# --------------------------------------------------------------------------------------------
# trajectories and uncertainty
# --------------------------------------------------------------------------------------------


def plot_truth(
    ax: Axes,
    poses: ArrayLike,
    *,
    label: str = "ground truth",
    linewidth: float = 1.0,
    zorder: float = 4,
) -> list[Artist]:
    """Draw the true path ``poses (N, 3)`` in :data:`TRUTH_STYLE` (see
    :func:`plot_trajectory`)."""
    return plot_trajectory(
        ax, poses, label=label, linewidth=linewidth, zorder=zorder, **TRUTH_STYLE
    )


def plot_trajectory(
    ax: Axes,
    poses: ArrayLike,
    *,
    label: str | None = None,
    heading_every: int = 0,
    heading_length: float | None = None,
    **style: Any,
) -> list[Artist]:
    """Draw the path of ``poses (N, 3)`` ``(x, y, theta)`` as one line.

    With ``heading_every = k > 0`` an arrow of ``heading_length`` (default 5 % of the path's
    extent) shows the heading of every k-th pose, in the line's colour. Returns
    ``[line]`` or ``[line, quiver]``.
    """
    p = as_array(poses, "poses", (None, 3))
    every = _count(heading_every, "heading_every", 0)
    (line,) = ax.plot(p[:, 0], p[:, 1], label=label, **style)
    artists: list[Artist] = [line]
    if every > 0 and p.shape[0] > 0:
        if heading_length is None:
            extent = float(np.max(np.ptp(p[:, :2], axis=0)))
            length = 0.05 * extent if extent > 0 else 1.0
        else:
            length = as_positive(heading_length, "heading_length")
        sel = p[::every]
        quiver = ax.quiver(
            sel[:, 0],
            sel[:, 1],
            length * np.cos(sel[:, 2]),
            length * np.sin(sel[:, 2]),
            angles="xy",
            scale_units="xy",
            scale=1.0,
            color=line.get_color(),
            width=0.004,
        )
        artists.append(quiver)
    return artists


def plot_trajectories(
    ax: Axes,
    *,
    truth: ArrayLike | None = None,
    estimate: ArrayLike | None = None,
    dead_reckoning: ArrayLike | None = None,
    legend: bool = True,
) -> dict[str, list[Artist]]:
    """Draw ground truth (black), the estimate (blue) and dead reckoning (grey, dashed), each
    ``(N, 3)`` and each optional, with equal axis scales and metre labels.

    Returns the artists of :func:`plot_trajectory` keyed ``"truth"``, ``"estimate"``,
    ``"dead_reckoning"`` for the trajectories given.
    """
    given = {"dead_reckoning": dead_reckoning, "truth": truth, "estimate": estimate}
    drawn: dict[str, list[Artist]] = {}
    for key, poses in given.items():  # dead reckoning first, so it lies underneath
        if poses is not None:
            drawn[key] = plot_trajectory(
                ax, as_array(poses, key, (None, 3)), **_TRAJECTORY_STYLES[key]
            )
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if legend and drawn:
        ax.legend()
    return drawn


def plot_covariance_ellipses(
    ax: Axes,
    means: ArrayLike,
    covs: ArrayLike,
    n_sigma: float = 3.0,
    every: int = 1,
    *,
    n_points: int = 64,
    label: str | None = None,
    **style: Any,
) -> PolyCollection:
    """Draw the ``n_sigma`` ellipses of ``covs (N, 2, 2)`` around ``means (N, 2)`` (every
    ``every``-th one) as a single unfilled :class:`~matplotlib.collections.PolyCollection`.

    ``style`` goes to the collection (``color`` sets the edge colour). For a probability
    ellipse pass ``n_sigma=slamkit.prob.confidence_scale(p)``.
    """
    m = as_array(means, "means", (None, 2))
    c = as_array(covs, "covs", (m.shape[0], 2, 2))
    step = _count(every, "every", 1)
    verts = ellipse_points(m[::step], c[::step], n_sigma, _count(n_points, "n_points", 3))
    kw = _collection_style({"facecolor": "none", "edgecolor": "tab:blue", "linewidth": 0.8}, style)
    # An (N, n, 2) array takes matplotlib's vectorised path; its stubs only admit a Sequence.
    coll = PolyCollection(cast(Any, verts), closed=True, label=label, **kw)
    ax.add_collection(coll)
    ax.autoscale_view()
    return coll


# --------------------------------------------------------------------------------------------
# maps
# --------------------------------------------------------------------------------------------


def plot_landmarks(
    ax: Axes,
    landmarks: LandmarkMap | ArrayLike,
    *,
    label: str | None = None,
    annotate_ids: bool = False,
    **style: Any,
) -> list[Artist]:
    """Draw point landmarks (a :class:`LandmarkMap` or positions ``(M, 2)``, numbered
    ``0 .. M-1``) as black stars; with ``annotate_ids`` write each id beside its landmark.

    Returns ``[scatter, *annotations]``.
    """
    if isinstance(landmarks, LandmarkMap):
        pos, ids = landmarks.positions, landmarks.ids
    else:
        pos = as_array(landmarks, "landmarks", (None, 2))
        ids = np.arange(pos.shape[0])
    kw: dict[str, Any] = {"marker": "*", "s": 80, "zorder": 3}
    if "c" not in style and "color" not in style:
        kw["color"] = "black"
    kw.update(style)
    artists: list[Artist] = [ax.scatter(pos[:, 0], pos[:, 1], label=label, **kw)]
    if annotate_ids:
        for (x, y), i in zip(pos, ids, strict=True):
            artists.append(
                ax.annotate(
                    str(int(i)),
                    (float(x), float(y)),
                    xytext=(4, 4),
                    textcoords="offset points",
                    fontsize=8,
                )
            )
    return artists


def plot_landmark_estimates(
    ax: Axes,
    positions: ArrayLike,
    covs: ArrayLike | None = None,
    n_sigma: float = 3.0,
    *,
    label: str | None = "landmark estimates",
    color: str = "tab:orange",
) -> list[Artist]:
    """Draw estimated landmarks ``positions (M, 2)`` as crosses and, when ``covs (M, 2, 2)``
    is given, their ``n_sigma`` ellipses in the same colour.

    Returns ``[scatter]`` or ``[scatter, ellipses]``.
    """
    pos = as_array(positions, "positions", (None, 2))
    artists: list[Artist] = [
        ax.scatter(pos[:, 0], pos[:, 1], marker="+", s=60, color=color, label=label, zorder=3)
    ]
    if covs is not None:
        artists.append(plot_covariance_ellipses(ax, pos, covs, n_sigma, color=color))
    return artists


def plot_segments(
    ax: Axes,
    segments: SegmentMap | ArrayLike,
    *,
    label: str | None = None,
    **style: Any,
) -> LineCollection:
    """Draw wall segments (a :class:`SegmentMap` or an ``(S, 2, 2)`` array) as one
    :class:`~matplotlib.collections.LineCollection`, black by default."""
    if isinstance(segments, SegmentMap):
        seg = segments.segments
    else:
        seg = as_array(segments, "segments", (None, 2, 2))
    kw = _collection_style({"edgecolor": "black", "linewidth": 1.5}, style)
    coll = LineCollection(cast(Any, seg), label=label, **kw)
    ax.add_collection(coll)
    ax.autoscale_view()
    return coll


def plot_occupancy_grid(
    ax: Axes,
    grid: OccupancyGrid,
    *,
    cmap: str = "gray_r",
    **style: Any,
) -> AxesImage:
    """Draw an occupancy grid: free white, occupied black, unknown (0.5) mid grey.

    Follows the grid convention of :mod:`slamkit.maps.types`: row 0 is the lowest row
    (``origin="lower"``) and the image spans exactly ``grid.bounds()``, so cell ``(r, c)``
    covers its world square.
    """
    xmin, ymin, xmax, ymax = grid.bounds()
    kw: dict[str, Any] = {"cmap": cmap, "vmin": 0.0, "vmax": 1.0, "interpolation": "nearest"}
    kw.update(style)
    return ax.imshow(grid.prob, origin="lower", extent=(xmin, xmax, ymin, ymax), **kw)


# --------------------------------------------------------------------------------------------
# errors and consistency over time
# --------------------------------------------------------------------------------------------


def plot_pose_errors(
    axes: Iterable[Axes],
    times: ArrayLike,
    errors: ArrayLike,
    sigmas: ArrayLike | None = None,
    n_sigma: float = 3.0,
    *,
    label: str | None = None,
    color: str = "tab:blue",
) -> list[list[Artist]]:
    """Draw the x, y and heading errors ``errors (N, 3)`` (metres, metres, radians) over
    ``times (N,)`` on three axes, with the ``±n_sigma·sigma`` band shaded when
    ``sigmas (N, 3)`` (standard deviations, same units) is given.

    Heading errors are wrapped to ``[-π, π)`` and drawn in degrees. Returns one list per axis,
    ``[line]`` or ``[line, band]``.
    """
    axs = list(axes)
    if len(axs) != 3:
        raise ShapeError(f"axes: expected 3 axes (x, y, heading), got {len(axs)}")
    t = as_array(times, "times", (None,))
    e = as_array(errors, "errors", (t.shape[0], 3)).copy()
    e[:, 2] = wrap_angle(e[:, 2])
    s = None if sigmas is None else as_array(sigmas, "sigmas", (t.shape[0], 3))
    if s is not None and np.any(s < 0):
        raise InputError("sigmas: expected standard deviations >= 0")
    k = as_positive(n_sigma, "n_sigma")
    unit = np.array([1.0, 1.0, np.degrees(1.0)])
    drawn: list[list[Artist]] = []
    for i, ax in enumerate(axs):
        (line,) = ax.plot(t, e[:, i] * unit[i], color=color, linewidth=1.0, label=label)
        artists: list[Artist] = [line]
        if s is not None:
            bound = k * s[:, i] * unit[i]
            band = ax.fill_between(
                t, -bound, bound, color=color, alpha=0.2, linewidth=0, label=f"±{k:g}σ"
            )
            artists.append(band)
        ax.set_ylabel(_ERROR_LABELS[i])
        drawn.append(artists)
    axs[-1].set_xlabel("time [s]")
    return drawn


def plot_consistency(
    ax: Axes,
    times: ArrayLike,
    values: ArrayLike,
    bounds: tuple[ArrayLike, ArrayLike],
    label: str = "NEES",
    *,
    band_label: str = "χ² bounds",
    color: str = "tab:blue",
) -> list[Artist]:
    """Draw a NEES/NIS trace ``values (N,)`` over ``times (N,)`` with the χ² acceptance band
    ``bounds = (lo, hi)`` (scalars or ``(N,)`` arrays) shaded grey.

    Returns ``[band, line]``.
    """
    t = as_array(times, "times", (None,))
    v = as_array(values, "values", (t.shape[0],))
    if len(bounds) != 2:
        raise ShapeError(f"bounds: expected (lo, hi), got {len(bounds)} values")
    try:
        lo = np.broadcast_to(as_array(bounds[0], "bounds[0]"), t.shape)
        hi = np.broadcast_to(as_array(bounds[1], "bounds[1]"), t.shape)
    except ValueError as exc:
        raise ShapeError(f"bounds: expected scalars or arrays of shape {t.shape}") from exc
    if np.any(lo > hi):
        raise InputError("bounds: expected lo <= hi")
    band = ax.fill_between(t, lo, hi, color="0.6", alpha=0.3, linewidth=0, label=band_label)
    (line,) = ax.plot(t, v, color=color, linewidth=1.0, label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(label)
    return [band, line]


# --------------------------------------------------------------------------------------------
# particles and innovations
# --------------------------------------------------------------------------------------------


def plot_particles(
    ax: Axes,
    particles: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    max_points: int = 5000,
    true_pose: ArrayLike | None = None,
    color: str = "tab:red",
) -> list[Artist]:
    """Draw a particle cloud ``(P, 3)`` as dots whose opacity follows the weights, at most
    ``max_points`` of them (a deterministic stride, so plots are reproducible), and the true
    pose as a black arrow if given. Returns ``[scatter]`` or ``[scatter, arrow]``."""
    p = as_array(particles, "particles", (None, 3))
    w = None if weights is None else as_array(weights, "weights", (p.shape[0],))
    # ceil: a stride of P // max_points would draw up to twice max_points
    step = max(1, -(-p.shape[0] // _count(max_points, "max_points", 1)))
    p = p[::step]
    alpha: Any = 0.5
    if w is not None:
        w = w[::step]
        top = float(w.max()) if w.size else 0.0
        alpha = np.clip(0.15 + 0.85 * (w / top if top > 0 else w), 0.0, 1.0)
    drawn: list[Artist] = [ax.scatter(p[:, 0], p[:, 1], s=2.0, c=color, alpha=alpha, lw=0)]
    if true_pose is not None:
        x = as_array(true_pose, "true_pose", (3,))
        span = max(float(np.ptp(p[:, 0])) if p.size else 1.0, 1.0)
        drawn.append(
            ax.arrow(x[0], x[1], 0.05 * span * np.cos(x[2]), 0.05 * span * np.sin(x[2]),
                     width=0.01 * span, color="black", length_includes_head=True)
        )  # fmt: skip
    return drawn


def plot_nis(
    ax: Axes,
    window_times: ArrayLike,
    window_sums: ArrayLike,
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    color: str = "tab:blue",
) -> list[Artist]:
    """Window sums of NIS with each window's two-sided χ² band, all divided by the band's
    centre ``(lower + upper) / 2`` so that windows with different degrees of freedom share one
    axis: a value inside the grey band is a consistent window, above it over-confident.
    Returns ``[band, line]`` as :func:`plot_consistency`."""
    t = as_array(window_times, "window_times", (None,))
    v = as_array(window_sums, "window_sums", (t.size,))
    lo = as_array(lower, "lower", (t.size,))
    hi = as_array(upper, "upper", (t.size,))
    mid = 0.5 * (lo + hi)
    return plot_consistency(ax, t, v / mid, (lo / mid, hi / mid), label="window NIS", color=color)


def plot_path_by_time(
    ax: Axes, times: ArrayLike, poses: ArrayLike, *, label: str = "estimate"
) -> Artist:
    """The path ``poses (N, 2+)`` as a line coloured by the time since its start (``times
    (N,)``, viridis: dark early, yellow late) with a colour bar: on data without a truth to
    draw it against, when the robot was where, and where it came back."""
    from matplotlib.collections import LineCollection

    t = as_array(times, "times", (None,))
    p = as_array(poses, "poses", (t.shape[0], None))[:, :2]
    since = t - t[0]
    segments = np.stack([p[:-1], p[1:]], axis=1)
    lines = LineCollection(
        cast(Any, segments), cmap="viridis", linewidths=1.4, label=label, zorder=2
    )
    lines.set_array(0.5 * (since[:-1] + since[1:]))
    ax.add_collection(lines)
    ax.figure.colorbar(lines, ax=ax, label="time since the start [s]", shrink=0.8, pad=0.02)
    ax.update_datalim(p)
    ax.autoscale_view()
    return lines


def plot_closures(ax: Axes, poses: ArrayLike, pairs: ArrayLike) -> Artist | None:
    """Loop closures as thin red lines between the poses ``poses (K, 2+)`` of each pair
    ``(E, 2)`` (rows into ``poses``); None when there is none."""
    from matplotlib.collections import LineCollection

    p = as_array(poses, "poses", (None, None))[:, :2]
    ij = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if ij.shape[0] == 0:
        return None
    lines = LineCollection(
        cast(Any, np.stack([p[ij[:, 0]], p[ij[:, 1]]], axis=1)),
        colors="tab:red",
        linewidths=0.5,
        alpha=0.6,
        label=f"loop closures ({ij.shape[0]})",
        zorder=3,
    )
    ax.add_collection(lines)
    return lines
