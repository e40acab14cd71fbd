"""Simulated worlds: point-landmark fields and wall-segment buildings.

Every world is a plain map value (:class:`~slamkit.maps.LandmarkMap`,
:class:`~slamkit.maps.SegmentMap`); random ones take an injected ``np.random.Generator``.
"""

from __future__ import annotations

import numpy as np

from slamkit._validation import as_array, as_positive
from slamkit.errors import InputError
from slamkit.maps import LandmarkMap, OccupancyGrid, SegmentMap

__all__ = [
    "five_feature_world",
    "random_landmarks",
    "rasterize_segments",
    "rectangle_segments",
    "rooms_world",
]


def five_feature_world() -> LandmarkMap:
    """The classic small world of the course notes: five distinct point features around a
    10 m × 10 m area that the default route circles."""
    return LandmarkMap.from_positions(
        [[2.0, 1.0], [9.0, 2.5], [10.0, 9.0], [4.0, 11.0], [-1.5, 6.0]]
    )


def random_landmarks(
    rng: np.random.Generator,
    n: int,
    bounds: tuple[float, float, float, float],
    min_separation: float = 0.0,
    max_tries: int = 10_000,
) -> LandmarkMap:
    """``n`` landmarks uniform in ``bounds = (xmin, ymin, xmax, ymax)``, at least
    ``min_separation`` metres apart (rejection sampling, bounded by ``max_tries`` draws)."""
    if n < 0:
        raise InputError(f"n: expected a non-negative count, got {n}")
    xmin, ymin, xmax, ymax = bounds
    if not (xmax > xmin and ymax > ymin):
        raise InputError(f"bounds: expected (xmin, ymin, xmax, ymax) with max > min, got {bounds}")
    pts: list[np.ndarray] = []
    tries = 0
    while len(pts) < n:
        if tries >= max_tries:
            raise InputError(
                f"could only place {len(pts)} of {n} landmarks {min_separation} m apart in "
                f"{bounds}; lower min_separation"
            )
        tries += 1
        p = rng.uniform([xmin, ymin], [xmax, ymax])
        if min_separation <= 0 or all(np.hypot(*(p - q)) >= min_separation for q in pts):
            pts.append(p)
    return LandmarkMap.from_positions(np.reshape(pts, (n, 2)))


def rectangle_segments(xmin: float, ymin: float, xmax: float, ymax: float) -> np.ndarray:
    """The four walls ``(4, 2, 2)`` of an axis-aligned rectangle."""
    c = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], dtype=float)
    return np.stack([c, np.roll(c, -1, axis=0)], axis=1)


def rooms_world() -> SegmentMap:
    """A 20 m × 12 m floor: a corridor along the middle (y in [5, 7]) with two rooms on each
    side, each room reached through a 1.2 m door; a few free-standing pillars break the
    symmetry so that a laser can tell the rooms apart (needed for global localization)."""
    walls: list[list[list[float]]] = []
    # Outer walls.
    walls += rectangle_segments(0.0, 0.0, 20.0, 12.0).tolist()
    # Corridor walls with doors (door gaps of 1.2 m centred at x = 4, 14 below; 6, 16 above).
    for y, doors in ((5.0, (4.0, 14.0)), (7.0, (6.0, 16.0))):
        xs = [0.0]
        for d in doors:
            xs += [d - 0.6, d + 0.6]
        xs.append(20.0)
        for a, b in zip(xs[0::2], xs[1::2], strict=True):
            walls.append([[a, y], [b, y]])
    # Walls between the rooms on each side.
    walls.append([[10.0, 0.0], [10.0, 5.0]])
    walls.append([[11.0, 7.0], [11.0, 12.0]])
    # Pillars (0.4 m squares) placed asymmetrically.
    for cx, cy in ((3.0, 2.0), (16.5, 3.0), (13.0, 10.0), (2.5, 9.5), (7.5, 10.5)):
        walls += rectangle_segments(cx - 0.2, cy - 0.2, cx + 0.2, cy + 0.2).tolist()
    return SegmentMap(np.asarray(walls, dtype=float))


def rasterize_segments(
    segments: SegmentMap, resolution: float, padding: float = 1.0
) -> OccupancyGrid:
    """An occupancy grid (1 occupied, 0 free) whose occupied cells are those the segments
    cross, covering the segments' bounding box plus ``padding`` metres."""
    res = as_positive(resolution, "resolution")
    pad = as_positive(padding, "padding", allow_zero=True)
    seg = as_array(segments.segments, "segments", (None, 2, 2))
    xmin, ymin, xmax, ymax = segments.bounds()
    grid = OccupancyGrid.empty(xmin - pad, ymin - pad, xmax + pad, ymax + pad, res, 0.0)
    prob = grid.prob.copy()
    # Sample every segment densely (a quarter cell) and mark the cells hit.
    lengths = np.hypot(*(seg[:, 1] - seg[:, 0]).T)
    for (a, b), length in zip(seg, lengths, strict=True):
        n = max(2, int(np.ceil(length / (res / 4.0))) + 1)
        s = np.linspace(0.0, 1.0, n)[:, None]
        cells = grid.world_to_cell(a + s * (b - a))
        cells = cells[grid.contains(cells)]
        prob[cells[:, 0], cells[:, 1]] = 1.0
    return OccupancyGrid(prob, res, grid.origin_xy)
