"""Laser scans of round trunks and straight walls, ray-cast exactly (no polygon of the
circles): the test bed of :func:`slamkit.features.extract_trees`."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray
from slamkit.errors import InputError, ShapeError

__all__ = ["trunk_scan"]


def _circle_hits(angles: FloatArray, circles: FloatArray) -> FloatArray:
    """Range ``(B, K)`` along each beam to each circle ``(cx, cy, radius)``, inf on a miss:
    the smaller root of ``|t u - c|² = R²``, ``t = u·c - sqrt((u·c)² - |c|² + R²)``."""
    ux, uy = np.cos(angles)[:, None], np.sin(angles)[:, None]
    cx, cy, rad = circles[:, 0], circles[:, 1], circles[:, 2]
    proj = ux * cx + uy * cy
    disc = proj**2 - (cx**2 + cy**2) + rad**2
    with np.errstate(invalid="ignore"):
        t = proj - np.sqrt(disc)
    return np.asarray(np.where((disc >= 0) & (t > 0), t, np.inf), dtype=np.float64)


def _segment_hits(angles: FloatArray, segments: FloatArray) -> FloatArray:
    """Range ``(B, S)`` along each beam to each segment ``(x0, y0, x1, y1)``, inf on a
    miss: solve ``t u = p0 + s (p1 - p0)`` for ``t > 0``, ``0 <= s <= 1`` (Cramer)."""
    ux, uy = np.cos(angles)[:, None], np.sin(angles)[:, None]
    x0, y0 = segments[:, 0], segments[:, 1]
    dx, dy = segments[:, 2] - x0, segments[:, 3] - y0
    det = -ux * dy + uy * dx  # det [u, -(p1 - p0)]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (-x0 * dy + y0 * dx) / det
        s = (ux * y0 - uy * x0) / det
    ok = (np.abs(det) > 1e-12) & (t > 0) & (s >= 0) & (s <= 1)
    return np.asarray(np.where(ok, t, np.inf), dtype=np.float64)


def trunk_scan(
    angles: ArrayLike,
    circles: ArrayLike,
    segments: ArrayLike = (),
    *,
    max_range: float = 80.0,
    range_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
) -> FloatArray:
    """A scan ``(B,)`` from a laser at the origin looking along x: beams at ``angles (B,)``
    [rad] hit the nearest of the ``circles (K, 3)`` ``(cx, cy, radius)`` and ``segments
    (S, 4)`` ``(x0, y0, x1, y1)`` [m]; a beam that hits nothing within ``max_range`` reads
    ``max_range`` (no return). With ``range_sigma > 0`` Gaussian noise from ``rng`` is added
    to every return."""
    phi = np.asarray(angles, dtype=np.float64).reshape(-1)
    c = np.asarray(circles, dtype=np.float64).reshape(-1, 3)
    s = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    if phi.size == 0:
        raise ShapeError("trunk_scan: expected at least one beam angle")
    hits = np.concatenate(
        [_circle_hits(phi, c), _segment_hits(phi, s), np.full((phi.size, 1), np.inf)], axis=1
    )
    r = hits.min(axis=1)
    ret = r < max_range
    if range_sigma > 0:
        if rng is None:
            raise InputError("trunk_scan: range_sigma > 0 needs an rng")
        r = np.where(ret, r + range_sigma * rng.standard_normal(phi.size), r)
    return np.asarray(np.where(ret, r, max_range), dtype=np.float64)
