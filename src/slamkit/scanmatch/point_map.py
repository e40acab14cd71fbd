"""A map of scan points with normals, one point per voxel, for scan-to-map matching.

Scans are inserted at their estimated poses; each point keeps the normal of the surface it
lies on, estimated in its own scan from its neighbours in beam order (principal components,
:func:`~slamkit.scanmatch.covariance.estimate_normals`), where the sampling is densest and the
surface is seen from one side. A voxel (a square cell of side ``voxel``) keeps the *first*
point that fell into it: when the robot comes back to a place, its new scans are registered
to the points laid down on the first visit instead of replacing them, so the drift of the
way round does not enter the map there. :meth:`PointMap.near` gives the points around a
pose as a :class:`~slamkit.scanmatch.normal_icp.NormalCloud`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.geometry.pose2 import transform_points
from slamkit.scanmatch.covariance import estimate_normals, neighbour_table
from slamkit.scanmatch.normal_icp import NormalCloud

__all__ = ["PointMap", "ScanNormals", "scan_normals"]

#: Points in a scan's neighbourhood for its normals (beam order), and their reach [m].
NORMAL_NEIGHBOURS = 7
NORMAL_RADIUS = 0.3


ScanNormals = tuple[FloatArray, NDArray[np.bool_]]
"""A scan's normals ``(K, 2)`` in its own frame and the mask ``(K,)`` of points that have
one (:func:`scan_normals`)."""


def scan_normals(points: ArrayLike) -> ScanNormals:
    """The normals :meth:`PointMap.insert` gives a scan's ``points (K, 2)`` (sensor frame,
    beam order): they depend on the scan alone, so a caller that inserts one scan many
    times (at different poses) may compute them once and pass them in."""
    p = as_array(points, "points", (None, 2))
    return estimate_normals(p, neighbour_table(p, None, NORMAL_NEIGHBOURS), NORMAL_RADIUS)


def _points_array(points: ArrayLike) -> FloatArray:
    """``points`` as a float64 ``(K, 2)`` array (shape checked, finiteness not: the caller
    checks that over all scans at once)."""
    p = points
    if type(p) is np.ndarray and p.dtype == np.float64 and p.ndim == 2 and p.shape[1] == 2:
        return p
    return as_array(points, "points", (None, 2), finite=False)


class PointMap:
    """Scan points with normals in the world frame, one per ``voxel``-sided cell [m]."""

    def __init__(self, voxel: float) -> None:
        self.voxel = as_positive(voxel, "voxel")
        self._keys = np.zeros(0, dtype=np.int64)  # sorted voxel keys
        self._points: list[FloatArray] = []
        self._normals: list[FloatArray] = []
        self._cache: tuple[FloatArray, FloatArray] | None = None

    def __len__(self) -> int:
        return int(self._keys.size)

    def insert(self, pose: ArrayLike, points: ArrayLike, known: ScanNormals | None = None) -> int:
        """Insert a scan's ``points (K, 2)`` (sensor frame, beam order) taken from ``pose``;
        returns how many went into empty voxels (points without a normal are left out).
        ``known``: the scan's :func:`scan_normals`, when the caller has them already."""
        placed = self._placed(pose, points, known)
        return 0 if placed is None else self._add(*placed)

    def insert_many(
        self,
        poses: ArrayLike,
        scans: Sequence[ArrayLike],
        known: Sequence[ScanNormals | None] | None = None,
    ) -> int:
        """Insert ``scans`` (each as :meth:`insert` takes it) taken from ``poses (S, 3)``, in
        order: the same map as inserting them one by one (a voxel keeps the first point of
        the first scan that reaches it), in one pass over the voxel keys."""
        T = as_array(poses, "poses", (len(scans), 3))
        arrays = [_points_array(p) for p in scans]
        if arrays:  # every scan's points finite (as insert checks them), in one pass
            as_array(np.concatenate(arrays), "points")
        # Per scan: the points with a normal, and their normals rotated into the world frame
        # (a BLAS product per scan, as _placed computes it: its rounding is the product's).
        kept, rotated, cos, sin, rows = [], [], [], [], []
        for a, p in enumerate(arrays):
            if p.shape[0] < 3:
                continue
            given = None if known is None else known[a]
            normals, ok = scan_normals(p) if given is None else given
            c, s = np.cos(T[a, 2]), np.sin(T[a, 2])
            kept.append(p[ok])
            rotated.append(normals[ok] @ np.array([[c, s], [-s, c]]))
            cos.append(c)
            sin.append(s)
            rows.append(a)
        if not kept:
            return 0
        # The points into the world frame all at once: per point the same operations as
        # transform_points (x = t_x + c p_x − s p_y, y = t_y + s p_x + c p_y, in that order)
        # with its scan's pose, so the same numbers.
        counts = [k.shape[0] for k in kept]
        p = np.concatenate(kept)
        c = np.repeat(np.array(cos), counts)
        s = np.repeat(np.array(sin), counts)
        t = np.repeat(T[rows], counts, axis=0)
        world = np.stack(
            [t[:, 0] + c * p[:, 0] - s * p[:, 1], t[:, 1] + s * p[:, 0] + c * p[:, 1]], axis=-1
        )
        return self._add(world, np.concatenate(rotated), self._keys_of(world))

    def _placed(
        self, pose: ArrayLike, points: ArrayLike, known: ScanNormals | None
    ) -> tuple[FloatArray, FloatArray, NDArray[np.int64]] | None:
        """A scan's points with normals in the world frame and their voxel keys (None:
        fewer than 3 points)."""
        p = as_array(points, "points", (None, 2))
        if p.shape[0] < 3:
            return None
        normals, ok = scan_normals(p) if known is None else known
        T = as_array(pose, "pose", (3,))
        world = transform_points(T, p[ok])
        c, s = np.cos(T[2]), np.sin(T[2])
        n = normals[ok] @ np.array([[c, s], [-s, c]])  # rotated into the world frame
        return world, n, self._keys_of(world)

    def _keys_of(self, world: FloatArray) -> NDArray[np.int64]:
        """The voxel keys of world points ``(N, 2)``."""
        cells = np.floor(world / self.voxel).astype(np.int64)
        # One int64 key per voxel: the column index in the low 32 bits, the row above.
        return (cells[:, 0] << 32) ^ (cells[:, 1] & 0xFFFFFFFF)

    def _add(self, world: FloatArray, n: FloatArray, keys: NDArray[np.int64]) -> int:
        """Add the first point of each voxel among ``keys`` not in the map yet."""
        _, first = np.unique(keys, return_index=True)  # one per voxel, its first point
        idx = np.sort(first)
        if self._keys.size == 0:  # a new map (local maps): nothing to compare with
            self._keys = np.sort(keys[idx])  # unique already: their union with nothing
        else:
            idx = idx[~np.isin(keys[idx], self._keys, assume_unique=True)]
            if idx.size == 0:
                return 0
            self._keys = np.union1d(self._keys, keys[idx])
        self._points.append(world[idx])
        self._normals.append(n[idx])
        self._cache = None
        return int(idx.size)

    def arrays(self) -> tuple[FloatArray, FloatArray]:
        """All points ``(M, 2)`` and their normals ``(M, 2)``, in insertion order."""
        if self._cache is None:
            if not self._points:
                self._cache = (np.zeros((0, 2)), np.zeros((0, 2)))
            else:
                self._cache = (np.concatenate(self._points), np.concatenate(self._normals))
                self._points, self._normals = [self._cache[0]], [self._cache[1]]
        return self._cache

    def near(self, center: ArrayLike, radius: float) -> NormalCloud:
        """The points within ``radius`` [m] of ``center (2,)`` (and their normals)."""
        c = as_array(center, "center", (2,))
        points, normals = self.arrays()
        d = points - c
        keep = np.einsum("ij,ij->i", d, d) <= radius * radius
        return NormalCloud.build(points[keep], normals[keep])
