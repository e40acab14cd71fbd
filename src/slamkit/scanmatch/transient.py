"""Points of things that moved: a scan's points that another scan saw through.

A wall is where every scan from nearby says it is. A walking person is not: a scan taken a
moment earlier or later, from a pose close by, sends its beam through the place where the
person stood and measures something farther away. A point map built from raw scans keeps
the person at each of those places, and a scan matched against it is pulled along with the
person (in a corridor, where the walls leave the motion along it to the prior, by as much
as the person walked). :class:`ScanView` is one scan as the free space it saw, and
:meth:`ScanView.seen_through` says which points, given in that scan's robot frame, lie in
it.

A point at range ``r`` from the viewing laser, at bearing ``b``, is *seen through* when the
beams at ``b`` and on either side of it all returned, and all farther than
``r + SEE_THROUGH_MARGIN + SEE_THROUGH_FRACTION · r``. The three beams (not one) keep a
point on a corner's edge, where one beam may slip past onto the wall behind, and the margin
keeps range noise, a surface seen at a grazing angle and small pose errors between the
scans from removing walls. A beam without a return says nothing (glass, open space, a
surface out of range): it clears nothing.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import minimum_filter1d

from slamkit._validation import FloatArray, as_array
from slamkit.geometry.pose2 import transform_points

__all__ = ["SEE_THROUGH_BEAMS", "SEE_THROUGH_FRACTION", "SEE_THROUGH_MARGIN", "ScanView"]

SEE_THROUGH_MARGIN = 0.15
"""[m] A beam must pass this far beyond a point (plus :data:`SEE_THROUGH_FRACTION` of its
range) to clear it."""
SEE_THROUGH_FRACTION = 0.03
"""... plus this fraction of the point's range."""
SEE_THROUGH_BEAMS = 1
"""... on the nearest beam and this many on either side of it."""


class ScanView:
    """One scan as the free space it saw: ``ranges (B,)`` along ``beam_angles (B,)`` from a
    laser mounted at ``mounting = (x, y, yaw)`` in the robot frame. Returns are the ranges
    in ``(min_range, max_range)``; the rest clear nothing."""

    def __init__(
        self,
        ranges: FloatArray,
        beam_angles: FloatArray,
        max_range: float,
        min_range: float = 0.0,
        mounting: FloatArray | None = None,
    ) -> None:
        r = as_array(ranges, "ranges", (None,), finite=False)
        a = as_array(beam_angles, "beam_angles", (r.size,))
        order = np.argsort(a, kind="stable")
        self._angles = a[order]
        r = r[order]
        returned = np.isfinite(r) & (r > min_range) & (r < max_range)
        ranges = np.where(returned, r, -np.inf)  # -inf: no return, clears nothing
        # The nearest of the beams around each one: a point is cleared only by them all.
        self._ranges = minimum_filter1d(ranges, 2 * SEE_THROUGH_BEAMS + 1, mode="nearest")
        self._mounting = None if mounting is None or not np.any(mounting) else mounting
        step = float(np.median(np.diff(self._angles))) if self._angles.size > 1 else 0.0
        self._half_step = 0.5 * step

    def seen_through(self, points: FloatArray) -> np.ndarray:
        """Which of ``points (M, 2)``, in this scan's robot frame, lie in the free space it
        saw ``(M,)`` bool."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        n = self._angles.size
        if p.shape[0] == 0 or n < 3:
            return np.zeros(p.shape[0], dtype=bool)
        if self._mounting is not None:  # into the laser's frame
            m = self._mounting
            c, s = math.cos(m[2]), math.sin(m[2])
            d = p - m[:2]
            p = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        r = np.hypot(p[:, 0], p[:, 1])
        a0 = self._angles[0]
        bearing = a0 + np.mod(np.arctan2(p[:, 1], p[:, 0]) - a0, 2.0 * math.pi)
        inside = bearing <= self._angles[-1] + self._half_step
        k = np.clip(np.searchsorted(self._angles, bearing), 1, n - 1)
        k -= bearing - self._angles[k - 1] < self._angles[k] - bearing  # the nearest beam
        seen = self._ranges[k]
        beyond = r + SEE_THROUGH_MARGIN + SEE_THROUGH_FRACTION * r
        return inside & (seen > beyond)

    def seen_through_from(self, pose: FloatArray, points: FloatArray) -> np.ndarray:
        """:meth:`seen_through` of ``points (M, 2)`` given in another frame, ``pose`` being
        that frame in this scan's robot frame ``(3,)``."""
        return self.seen_through(transform_points(pose, points))
