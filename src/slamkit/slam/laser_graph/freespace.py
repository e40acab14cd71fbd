"""Whether a loop closure contradicts what both places saw: the free-space check.

The correlative score counts the new scan's end points that land on the candidate submap's
walls; it never counts those that land where the submap's rays passed freely. An alias (a
corridor laid into a room seen through a door, one L-shaped corner for another) can score
as well as the true place while half of its walls stand in the other side's open space.
So a verified closure ``T_j_k`` is checked both ways:

* the points of the new keyframe's recent neighbourhood (keyframes ``k - 10 .. k`` in
  ``k``'s frame, placed by ``T_j_k``) against the free cells of the candidate's submap;
* the submap's points (in ``j``'s frame, placed by ``T_j_k⁻¹``) against the free cells of
  the new neighbourhood;

and the larger share of points that land in the other side's free space is the closure's
*contradiction*. A cell is free when a ray from a laser origin to one of its end points
crosses it and no end point lies within :data:`TOLERANCE_CELLS` cells of it, so a closure
a few centimetres off, or a submap bent by its own drift, is not a contradiction; people
who walked through and glass are, a little, which the bar allows for. Measurements and
how the numbers were chosen: ``docs/estimators/laser_graph.md``, "The free-space check".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.geometry.pose2 import between, compose, transform_points
from slamkit.mapping.bresenham import bresenham_rays

__all__ = [
    "MAX_CONTRADICTION",
    "NEIGHBOURHOOD_KEYFRAMES",
    "RAY_RANGE",
    "RESOLUTION",
    "TOLERANCE_CELLS",
    "FreeSpace",
    "contradiction",
    "neighbourhood",
    "neighbourhood_scans",
    "revisit_contradictions",
]

RESOLUTION = 0.1
"""Side of the free-space grid's cells [m]."""
TOLERANCE_CELLS = 2
"""Cells within this many of an end point (Chebyshev) are never free: 0.2 m of slack for
the submaps' own misalignment."""
RAY_RANGE = 30.0
"""Rays and points beyond this from their origin [m] are left out (long rays through doors
and windows are where a small heading error moves a point the most)."""
MAX_CONTRADICTION = 0.04
"""A closure whose contradiction (the module docstring) exceeds this share is refused."""
NEIGHBOURHOOD_KEYFRAMES = 11
"""The new keyframe's side: itself and the keyframes before it, this many in all."""
AUDIT_EVERY = 4
"""The final map's audit (:func:`revisit_contradictions`) looks at every this many
keyframes ..."""
REVISIT_RADIUS = 1.0
"""... and the nearest earlier keyframe within this [m] of it in the final map ..."""
AUDIT_MAX = 200
"""... and checks at most this many of the revisits it finds, evenly spread (its cost is
two neighbourhoods' ray casting per revisit: Intel has 700 revisits)."""

_STRIDE = np.int64(1 << 32)


@dataclass(frozen=True)
class FreeSpace:
    """The free cells of a set of scans in one frame (sorted cell keys) and their end
    points ``(M, 2)`` in that frame."""

    cells: np.ndarray
    points: FloatArray

    @classmethod
    def from_scans(cls, origins: FloatArray, clouds: list[FloatArray]) -> FreeSpace:
        """The free space of scans taken from laser poses ``origins (S, 3)`` whose end
        points ``clouds[s] (N_s, 2)`` are in the same frame as the origins."""
        starts, ends, kept = [], [], []
        for origin, cloud in zip(origins, clouds, strict=True):
            d = np.hypot(cloud[:, 0] - origin[0], cloud[:, 1] - origin[1])
            cloud = cloud[d <= RAY_RANGE]
            kept.append(cloud)
            ends.append(_cell(cloud))
            starts.append(np.broadcast_to(_cell(origin[None, :2]), (cloud.shape[0], 2)))
        points = np.concatenate(kept) if kept else np.zeros((0, 2))
        if points.shape[0] == 0:
            return cls(np.zeros(0, dtype=np.int64), points)
        rays = bresenham_rays(np.concatenate(starts), np.concatenate(ends))
        inside = rays.step < rays.n_steps[rays.ray]  # not the end cell itself
        free = np.unique(_key(rays.rows[inside], rays.cols[inside]))
        end = np.concatenate(ends)
        span = range(-TOLERANCE_CELLS, TOLERANCE_CELLS + 1)
        near = [_key(end[:, 0] + a, end[:, 1] + b) for a in span for b in span]
        return cls(np.setdiff1d(free, np.concatenate(near)), points)

    def share_inside(self, points: FloatArray) -> float:
        """The share of ``points (N, 2)`` (this frame) that land in a free cell (0 with no
        point)."""
        if points.shape[0] == 0 or self.cells.size == 0:
            return 0.0
        c = _cell(points)
        keys = _key(c[:, 0], c[:, 1])
        at = np.minimum(np.searchsorted(self.cells, keys), self.cells.size - 1)
        return float(np.mean(self.cells[at] == keys))


def neighbourhood_scans(
    poses: FloatArray, points: list[FloatArray], mounting: FloatArray, c: int, lo: int, hi: int
) -> tuple[FloatArray, list[FloatArray]]:
    """The laser poses ``(S, 3)`` and end points of keyframes ``lo .. hi - 1`` (those that
    exist) in keyframe ``c``'s frame (``poses (K, 3)``, ``points[i]`` in keyframe ``i``'s
    robot frame, the laser at ``mounting`` on the robot)."""
    ids = list(range(max(lo, 0), min(hi, len(points))))
    T_c = between(poses[c], poses[ids]).reshape(-1, 3)
    origins = compose(T_c, np.broadcast_to(mounting, T_c.shape)).reshape(-1, 3)
    return origins, [transform_points(T_c[a], points[i]) for a, i in enumerate(ids)]


def neighbourhood(
    poses: FloatArray, points: list[FloatArray], mounting: FloatArray, c: int, lo: int, hi: int
) -> FreeSpace:
    """The free space of :func:`neighbourhood_scans` (same arguments)."""
    return FreeSpace.from_scans(*neighbourhood_scans(poses, points, mounting, c, lo, hi))


def contradiction(reference: FreeSpace, new: FreeSpace, T_j_k: FloatArray) -> float:
    """The smaller share of either side's points in the other's free space when the new
    side (in ``k``'s frame) is placed in the reference's (``j``'s) by ``T_j_k``."""
    forward = reference.share_inside(transform_points(T_j_k, new.points))
    backward = new.share_inside(transform_points(between(T_j_k, np.zeros(3)), reference.points))
    return min(forward, backward)


def _cell(points: FloatArray) -> np.ndarray:
    return np.floor(np.asarray(points) / RESOLUTION).astype(np.int64)


def _key(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    return rows * _STRIDE + cols


def revisit_contradictions(
    poses: FloatArray,
    points: list[FloatArray],
    mounting: FloatArray,
    travelled: FloatArray,
    min_travel: float,
) -> tuple[int, list[int]]:
    """The final map's audit: every :data:`AUDIT_EVERY`-th keyframe ``k`` that revisits a
    place (an earlier keyframe at least ``min_travel`` [m] of path behind it lies within
    :data:`REVISIT_RADIUS` of it, ``poses (K, 3)``, ``travelled (K,)``; at most
    :data:`AUDIT_MAX` of them) is checked against the nearest such keyframe by
    :func:`contradiction` of their neighbourhoods at those poses. Returns the number of
    revisits checked and the keyframes that contradict (above :data:`MAX_CONTRADICTION`): a
    map that holds one place twice, or bent, contradicts itself where the robot came
    back."""
    cache: dict[int, FreeSpace] = {}

    def side(c: int) -> FreeSpace:
        if c not in cache:
            lo = c - NEIGHBOURHOOD_KEYFRAMES + 1
            cache[c] = neighbourhood(poses, points, mounting, c, lo, c + 1)
        return cache[c]

    revisits = []
    for k in range(0, poses.shape[0], AUDIT_EVERY):
        earlier = np.flatnonzero(travelled[k] - travelled[:k] >= min_travel)
        if earlier.size == 0:
            continue
        d = np.hypot(*(poses[earlier, :2] - poses[k, :2]).T)
        if d.min() <= REVISIT_RADIUS:
            revisits.append((int(earlier[np.argmin(d)]), k))
    if len(revisits) > AUDIT_MAX:
        revisits = [revisits[i] for i in np.linspace(0, len(revisits) - 1, AUDIT_MAX).astype(int)]
    contradicting = [
        k
        for j, k in revisits
        if contradiction(side(j), side(k), between(poses[j], poses[k])) > MAX_CONTRADICTION
    ]
    return len(revisits), contradicting
