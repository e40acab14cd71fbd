"""Making a figure readable: robust axis limits, start and end markers, legends beside the
data, occupancy grids cropped to their known cells, and a scale bar.

Axis limits come from what the picture is *about* — the trajectories, the map's known cells,
the landmarks — never from a covariance ellipse (a prior of ±3 km, or the uniform cloud of a
global start, would shrink a 5 m arena to a dot) and never from the first transient of an
estimate that starts lost: the estimate's extent is taken between robust quantiles.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.legend import Legend
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar  # type: ignore[import-untyped]
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import as_array
from slamkit.maps import OccupancyGrid

__all__ = [
    "Box",
    "add_scale_bar",
    "crop_to_known",
    "emptiest_corner",
    "known_box",
    "legend_outside",
    "map_box",
    "pick_frames",
    "plot_start_end",
    "reference_box",
    "robust_abs_limit",
    "robust_box",
    "set_box",
    "union_box",
]

Box = tuple[float, float, float, float]
"""``(xmin, xmax, ymin, ymax)`` in metres."""

UNKNOWN_BAND = 0.02
"""A cell whose probability is within this of 0.5 counts as unknown (never observed)."""

CONFIDENT_BAND = 0.2
"""A cell further than this from 0.5 is known with confidence (one free reading moves a
cell to about 0.35 only): the cells a cropped map is sized round."""


def robust_box(points: ArrayLike, *, quantile: float = 0.0) -> Box | None:
    """The box of the finite ``points (N, 2)``, between the ``quantile`` and ``1 - quantile``
    quantiles of each axis (0: the whole extent); ``None`` when there is no finite point."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] == 0:
        return None
    lo = np.quantile(p, quantile, axis=0)
    hi = np.quantile(p, 1.0 - quantile, axis=0)
    return (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))


def union_box(*boxes: Box | None) -> Box | None:
    """The smallest box holding every box given (``None`` ones skipped)."""
    given = [b for b in boxes if b is not None]
    if not given:
        return None
    a = np.array(given)
    return (float(a[:, 0].min()), float(a[:, 1].max()), float(a[:, 2].min()), float(a[:, 3].max()))


def known_box(
    grid: OccupancyGrid, *, band: float = UNKNOWN_BAND, quantile: float = 0.0
) -> Box | None:
    """The world box of the cells of ``grid`` that were observed (probability further than
    ``band`` from 0.5), between the ``quantile`` and ``1 - quantile`` quantiles of their
    rows and columns (0: all of them); ``None`` when none was."""
    known = np.abs(grid.prob - 0.5) > band
    if not np.any(known):
        return None
    if quantile > 0.0:
        rr, cc = np.nonzero(known)
        r_lo, r_hi = np.quantile(rr, [quantile, 1.0 - quantile]).round().astype(int)
        c_lo, c_hi = np.quantile(cc, [quantile, 1.0 - quantile]).round().astype(int)
    else:
        rows = np.flatnonzero(known.any(axis=1))
        cols = np.flatnonzero(known.any(axis=0))
        r_lo, r_hi, c_lo, c_hi = rows[0], rows[-1], cols[0], cols[-1]
    x0, y0 = grid.origin_xy
    r = grid.resolution
    return (
        float(x0 + c_lo * r),
        float(x0 + (c_hi + 1) * r),
        float(y0 + r_lo * r),
        float(y0 + (r_hi + 1) * r),
    )


def map_box(
    grid: OccupancyGrid, *, band: float = CONFIDENT_BAND, quantile: float = 0.001
) -> Box | None:
    """The box a picture of ``grid`` is about: round its confidently occupied cells
    (probability above ``0.5 + band``: the walls, so the long free rays of readings through
    doors and windows do not count; the ``quantile`` outermost left out on each side);
    without such cells, round the cells confidently known free or occupied, else round every
    observed cell; ``None`` when none was observed."""
    walls = OccupancyGrid(
        np.where(grid.prob > 0.5 + band, 1.0, 0.5), grid.resolution, grid.origin_xy
    )
    box = known_box(walls, quantile=quantile)
    if box is None:
        box = known_box(grid, band=band, quantile=quantile)
    return known_box(grid) if box is None else box


def crop_to_known(
    grid: OccupancyGrid,
    *,
    margin: float = 1.0,
    band: float = CONFIDENT_BAND,
    quantile: float = 0.001,
) -> OccupancyGrid:
    """The part of ``grid`` in its :func:`map_box` with ``margin`` metres of border — the
    same cells on the same lattice; the whole grid when no cell was observed."""
    box = map_box(grid, band=band, quantile=quantile)
    if box is None:
        return grid
    r = grid.resolution
    x0, y0 = grid.origin_xy
    rows, cols = grid.shape
    m = int(np.ceil(margin / r))
    c0 = max(0, round((box[0] - x0) / r) - m)
    c1 = min(cols, round((box[1] - x0) / r) + m)
    r0 = max(0, round((box[2] - y0) / r) - m)
    r1 = min(rows, round((box[3] - y0) / r) + m)
    origin = np.array([x0 + c0 * r, y0 + r0 * r])
    return OccupancyGrid(np.ascontiguousarray(grid.prob[r0:r1, c0:c1]), r, origin)


def set_box(ax: Axes, box: Box | None, *, pad: float = 0.05, min_span: float = 1.0) -> None:
    """Fix ``ax``'s limits to ``box`` grown by ``pad`` of its larger side (at least
    ``min_span`` metres across), and stop later artists from widening them."""
    if box is None:
        return
    xmin, xmax, ymin, ymax = box
    span = max(xmax - xmin, ymax - ymin, min_span)
    p = pad * span
    cx, cy = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
    hx = max(0.5 * (xmax - xmin), 0.5 * min_span) + p
    hy = max(0.5 * (ymax - ymin), 0.5 * min_span) + p
    ax.set_xlim(cx - hx, cx + hx)
    ax.set_ylim(cy - hy, cy + hy)
    ax.set_autoscale_on(False)


def robust_abs_limit(values: ArrayLike, *, quantile: float = 0.99, floor: float = 0.0) -> float:
    """``quantile`` of ``|values|`` over the finite ones (``floor`` when there is none):
    the half-height of an error axis that a few wild values do not flatten."""
    v = np.abs(np.asarray(values, dtype=float).ravel())
    v = v[np.isfinite(v)]
    if v.size == 0:
        return floor
    return max(float(np.quantile(v, quantile)), floor)


def plot_start_end(ax: Axes, poses: ArrayLike, *, color: str = "tab:blue") -> list[Artist]:
    """A circle at the first pose of ``poses (N, 2|3)`` and a square at the last, labelled
    ``start`` and ``end``. Returns the two markers."""
    p = np.asarray(poses, dtype=float)
    p = p.reshape(-1, p.shape[-1]) if p.size else np.zeros((0, 2))
    if p.shape[0] == 0:
        return []
    style: dict[str, Any] = {"ms": 8, "mec": "black", "mew": 1.0, "zorder": 6, "ls": "none"}
    (start,) = ax.plot(p[0, 0], p[0, 1], "o", mfc="limegreen", label="start", **style)
    (end,) = ax.plot(p[-1, 0], p[-1, 1], "s", mfc=color, label="end", **style)
    return [start, end]


def legend_outside(ax: Axes, *, fontsize: str = "small", **kw: Any) -> Legend | None:
    """The legend of ``ax`` to the right of the axes, off the data (``None`` when nothing is
    labelled)."""
    handles, _ = ax.get_legend_handles_labels()
    if not handles:
        return None
    return ax.legend(
        loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=fontsize, **kw
    )


def _nice_length(span: float) -> float:
    """A round length near a fifth of ``span`` (1, 2 or 5 times a power of ten)."""
    target = max(span / 5.0, 1e-9)
    power = 10.0 ** np.floor(np.log10(target))
    for step in (1.0, 2.0, 5.0, 10.0):
        if step * power >= target:
            return float(step * power)
    return float(10.0 * power)  # pragma: no cover - the loop always returns


_CORNERS = {  # location: the corner's box in axes fractions (x0, x1, y0, y1)
    "lower right": (0.7, 1.0, 0.0, 0.15),
    "lower left": (0.0, 0.3, 0.0, 0.15),
    "upper right": (0.7, 1.0, 0.85, 1.0),
    "upper left": (0.0, 0.3, 0.85, 1.0),
}


def _drawn_points(ax: Axes) -> NDArray[np.float64]:
    """Every point the axes draw in data units ``(P, 2)``: line vertices, scatter offsets
    and the centres of an image's marked pixels (those darker than mid-grey: walls)."""
    parts = [np.asarray(line.get_xydata(), dtype=np.float64) for line in ax.lines]
    parts += [np.asarray(c.get_offsets(), dtype=np.float64) for c in ax.collections]
    for image in ax.images:
        values = image.get_array()
        if values is None or np.ndim(values) != 2 or np.size(values) == 0:
            continue
        rgba = np.asarray(image.to_rgba(values), dtype=np.float64)
        luminance = rgba[..., :3] @ np.array([0.299, 0.587, 0.114])
        x0, x1, y0, y1 = image.get_extent()
        rows, cols = np.nonzero(luminance < 0.5)
        h, w = luminance.shape
        ys = y0 + (rows + 0.5) / h * (y1 - y0)
        if image.origin == "upper":
            ys = y1 - (rows + 0.5) / h * (y1 - y0)
        parts.append(np.column_stack([x0 + (cols + 0.5) / w * (x1 - x0), ys]))
    parts = [p.reshape(-1, 2) for p in parts if p.size]
    return np.concatenate(parts) if parts else np.zeros((0, 2))


def emptiest_corner(ax: Axes) -> str:
    """The corner of ``ax`` (``"lower right"``, ``"lower left"``, ``"upper right"``,
    ``"upper left"``, in that order of preference) over which the fewest drawn points lie:
    where a scale bar hides the least."""
    points = _drawn_points(ax)
    if points.shape[0] == 0:
        return "lower right"
    frac = ax.transAxes.inverted().transform(ax.transData.transform(points))
    counts = {
        loc: int(
            np.count_nonzero(
                (frac[:, 0] >= x0) & (frac[:, 0] <= x1) & (frac[:, 1] >= y0) & (frac[:, 1] <= y1)
            )
        )
        for loc, (x0, x1, y0, y1) in _CORNERS.items()
    }
    return min(counts, key=lambda loc: counts[loc])  # ties: the first, lower right


def add_scale_bar(ax: Axes, *, length: float | None = None) -> AnchoredSizeBar:
    """A scale bar (data units are metres) of ``length`` metres, or a round length near a
    fifth of the x range, in the corner that hides the least of what is drawn
    (:func:`emptiest_corner`; call it once the data and the limits are set), without a
    box: only the bar and its label cover the plot."""
    xmin, xmax = ax.get_xlim()
    size = _nice_length(abs(xmax - xmin)) if length is None else float(length)
    label = f"{size:g} m" if size >= 1 else f"{100 * size:g} cm"
    bar = AnchoredSizeBar(
        ax.transData,
        size,
        label,
        emptiest_corner(ax),
        pad=0.4,
        sep=4,
        color="black",
        frameon=False,
        size_vertical=0,
        label_top=True,
    )
    ax.add_artist(bar)
    return bar


def pick_frames(times: ArrayLike, positions: ArrayLike, n: int) -> NDArray[np.int64]:
    """Indices of at most ``n`` frames among those at ``times (F,)`` with the robot at
    ``positions (F, 2)``, spread evenly over a mix of time and distance travelled, so a robot
    standing still gets few frames and a fast stretch gets many; always the first and last."""
    t = as_array(times, "times", (None,))
    p = as_array(positions, "positions", (t.shape[0], 2))
    if t.shape[0] <= n:
        return np.arange(t.shape[0], dtype=np.int64)
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    dist = np.concatenate([[0.0], np.cumsum(np.where(np.isfinite(step), step, 0.0))])
    span_t = float(t[-1] - t[0]) or 1.0
    span_d = float(dist[-1]) or 1.0
    progress = 0.5 * (t - t[0]) / span_t + 0.5 * dist / span_d  # 0 → 1, non-decreasing
    wanted = np.linspace(0.0, 1.0, n)
    idx = np.unique(np.searchsorted(progress, wanted, side="left").clip(0, t.shape[0] - 1))
    return idx.astype(np.int64)


def reference_box(parts: Sequence[ArrayLike | None], *, quantile: float = 0.0) -> Box | None:
    """The union of the boxes of the point sets in ``parts`` (``None`` ones skipped)."""
    return union_box(*(robust_box(p, quantile=quantile) for p in parts if p is not None))
