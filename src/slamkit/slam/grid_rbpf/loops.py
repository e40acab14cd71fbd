"""Whether the grid RBPF lost a loop: its best particle's map holding one place twice.

A particle filter closes a loop only if one of its particles came back close enough to the
old map for its scan match to snap onto it. When the drift around the loop is larger than
the particles' spread (and the proposal's gate), every particle maps the revisited place
anew beside its old self, and the run goes on as if nothing happened. The best particle's
map then disagrees with itself: the scan fits the *old* map well somewhere far from where
the filter believes the robot is.

The watch (:class:`LoopWatch`) keeps every update's scan end points (robot frame) and
checks, every :data:`CHECK_EVERY` metres of travel, the current scan against the map of
the best particle's *old* scans alone — those taken more than :data:`OLD_AFTER` metres of
travel ago whose poses lie within :data:`NEAR` of the current estimate, placed along the
best particle's path, which is how its map was made:

1. a wide correlative search (:data:`SEARCH`: ± 3 m, ± 45°, Olson's branch and bound on
   the old end points) around the filter's pose finds where the scan fits the old map best
   (a flat response, or a best pose on the window's edge, is no evidence: skipped);
2. the map holds the place twice (``doubled``) when that match is good (:data:`GOOD_FIT`
   of its points within 30 cm of an old end point), clear (no rival peak of
   :data:`RIVAL_RATIO` of its score farther than :data:`RIVAL_SEPARATION` from it,
   :func:`~slamkit.scanmatch.correlative.correlative_rival`) and far from the filter's
   pose: more than :data:`MIN_OFFSET` and more than :data:`SPREAD_MULTIPLE` times the
   particles' spread (a loop smaller than that is one the particles can still close);
3. a loop is lost when two checks in a row (:data:`CHECK_EVERY` apart) find the place
   doubled: one alone may be a look-alike the rival search missed, or a loop the filter
   closes a few metres on (both seen on the generated buildings).

The match's distance from the filter's pose is the loop's error there (the true error of
the filter's pose against its old scans, where the truth is known). The scan's fit to the
old map *at* the filter's pose (``fit_here``) is kept for the record but decides nothing:
in a corridor a scan moved metres along it still fits the walls.

A lost loop is counted, listed and reported as the run warning ``loop_lost``. Measured:
``docs/estimators/grid_rbpf.md``, "A lost loop is said".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from slamkit._validation import FloatArray
from slamkit.errors import InputError, MatchError
from slamkit.estimation.contract import RunWarning
from slamkit.geometry.pose2 import between, transform_points
from slamkit.scanmatch.correlative import (
    CorrelativeConfig,
    CorrelativeReference,
    correlative_match,
    correlative_rival,
)

__all__ = [
    "CHECK_EVERY",
    "FIT_DISTANCE",
    "GOOD_FIT",
    "MIN_OFFSET",
    "MIN_OLD_SCANS",
    "NEAR",
    "OLD_AFTER",
    "RIVAL_RATIO",
    "RIVAL_SEPARATION",
    "SEARCH",
    "SHOWN",
    "SPREAD_MULTIPLE",
    "LoopCheck",
    "LoopWatch",
    "particle_spread",
]

CHECK_EVERY = 5.0
"""[m] of odometry travel between two checks."""
OLD_AFTER = 30.0
"""[m] of travel: a scan taken this long ago or longer is old (the loop it closes is at
least this long)."""
NEAR = 10.0
"""[m] the old scans whose poses lie this near the filter's pose make the old map."""
MIN_OLD_SCANS = 3
"""Fewer old scans near the pose than this: nothing to check against."""
SEARCH = CorrelativeConfig(
    window_xy=3.0,
    window_theta=math.radians(45.0),
    resolution=0.1,
    sigma=0.1,
    join_gap=None,
    levels=6,
    max_flatness=0.5,
)
"""The wide search: ± 3 m, ± 45° around the filter's pose, on a 10 cm grid (the check looks
for metres, not centimetres), the old end points smeared as they are (they come from many
scans, so consecutive ones need not lie on one wall); a flat response (a corridor) is no
evidence."""
GOOD_FIT = 0.5
"""Share of the scan's end points within 3 σ (30 cm) of an old wall at the match."""
FIT_DISTANCE = 3.0 * SEARCH.sigma
"""[m] an end point this near an old one fits the old map (the match's inlier distance)."""
RIVAL_RATIO = 0.9
"""A second peak scoring this share of the match's score ..."""
RIVAL_SEPARATION = 0.5
"""... farther than this [m] from it makes the match unclear."""
MIN_OFFSET = 1.0
"""[m] the least distance from the filter's pose to the match that is a lost loop."""
SPREAD_MULTIPLE = 3.0
"""... and it must exceed this many times the particles' spread."""
SHOWN = 20
"""The diagnostics list this many lost-loop checks (the first ones); all are counted."""


def particle_spread(poses: FloatArray, weights: FloatArray) -> float:
    """The particles' spread [m]: ``sqrt(tr Σ_xy)`` of their weighted positions."""
    mean = weights @ poses[:, :2]
    d = poses[:, :2] - mean
    return float(math.sqrt(max(float(weights @ np.einsum("ij,ij->i", d, d)), 0.0)))


@dataclass(frozen=True)
class LoopCheck:
    """One check: the stamp [s], the filter's pose, the match on the old map relative to it
    (``offset`` [m], ``turn`` [rad]), the match's normalised score and the share of its
    end points on the old map (``fit``), that share at the filter's own pose
    (``fit_here``), the particles' spread [m], the old scans used, whether a rival peak was
    found, whether the match says the map holds the place twice (``doubled``), and the
    verdict: ``lost`` when the check before said so too."""

    t: float
    pose: FloatArray
    offset: float
    turn: float
    score: float
    fit: float
    fit_here: float
    spread: float
    old_scans: int
    rival: bool
    doubled: bool
    lost: bool

    def row(self) -> dict[str, float | int | bool]:
        return {
            "t": self.t,
            "x": float(self.pose[0]),
            "y": float(self.pose[1]),
            "offset_m": self.offset,
            "deg": math.degrees(self.turn),
            "fit": self.fit,
            "fit_here": self.fit_here,
            "spread_m": self.spread,
        }


class LoopWatch:
    """The record of scans and checks (module docstring). :meth:`add` every update's scan,
    :meth:`check` when :meth:`due`."""

    def __init__(self) -> None:
        self._points: list[FloatArray] = []
        self._travel: list[float] = []
        self._next = CHECK_EVERY
        self.checks: list[LoopCheck] = []
        self.skipped = 0
        """Checks due that found too few old scans near, a flat response or a match on the
        search window's edge."""

    def add(self, points: FloatArray, travelled: float) -> None:
        """One update's scan end points ``(K, 2)`` (robot frame) and the odometry's total
        travel at it [m]."""
        self._points.append(np.asarray(points, dtype=np.float32))
        self._travel.append(float(travelled))

    def due(self) -> bool:
        """Whether the last update is a check's."""
        if not self._travel or self._travel[-1] < self._next:
            return False
        self._next = self._travel[-1] + CHECK_EVERY
        return True

    def check(self, t: float, path: FloatArray, spread: float) -> LoopCheck | None:
        """Check the last scan against the old scans, all placed along ``path`` ``(U, 3)``
        (the best particle's poses at every update added, the last one the filter's pose);
        None when there is nothing to check against or the search finds no clear peak."""
        if path.shape[0] != len(self._points):
            raise InputError(f"path: expected {len(self._points)} poses, got {path.shape[0]}")
        here = path[-1]
        travel = np.asarray(self._travel)
        old = travel <= travel[-1] - OLD_AFTER
        near = np.hypot(path[:, 0] - here[0], path[:, 1] - here[1]) <= NEAR
        chosen = np.flatnonzero(old & near)
        current = np.asarray(self._points[-1], dtype=np.float64)
        if chosen.size < MIN_OLD_SCANS or current.shape[0] < SEARCH.min_points:
            self.skipped += 1
            return None
        reference = np.concatenate(
            [transform_points(path[u], self._points[u].astype(np.float64)) for u in chosen]
        )
        try:
            ref = CorrelativeReference.from_points(reference, SEARCH)
            found = correlative_match(ref, current, here)
        except MatchError:
            self.skipped += 1
            return None
        corr = between(here, found.pose)
        # The window is a box in world x, y around ``here``: a match on its edge may be
        # the slope of a peak outside it, no evidence of where the scan fits.
        shift = float(np.abs(found.pose[:2] - here[:2]).max())
        if shift >= SEARCH.window_xy - SEARCH.resolution or abs(float(corr[2])) >= (
            SEARCH.window_theta - math.radians(1.0)
        ):
            self.skipped += 1
            return None
        d, _ = cKDTree(reference).query(
            transform_points(here, current), distance_upper_bound=FIT_DISTANCE
        )
        fit_here = float(np.count_nonzero(np.isfinite(d))) / current.shape[0]
        offset = math.hypot(float(corr[0]), float(corr[1]))
        far = offset > max(MIN_OFFSET, SPREAD_MULTIPLE * spread)
        rival = False
        if far and found.inlier_fraction >= GOOD_FIT:
            second = correlative_rival(ref, current, here, found, RIVAL_SEPARATION, RIVAL_RATIO)
            rival = second is not None
        doubled = far and found.inlier_fraction >= GOOD_FIT and not rival
        lost = doubled and bool(self.checks) and self.checks[-1].doubled
        out = LoopCheck(
            float(t),
            here.copy(),
            offset,
            float(corr[2]),
            float(found.score),
            float(found.inlier_fraction),
            fit_here,
            float(spread),
            int(chosen.size),
            rival,
            doubled,
            lost,
        )
        self.checks.append(out)
        return out

    @property
    def lost(self) -> list[LoopCheck]:
        return [c for c in self.checks if c.lost]

    def diagnostics(self) -> dict[str, object]:
        """``loop_checks`` (checks made), ``loop_checks_skipped``, ``loops_lost`` (checks that
        found one) and the first :data:`SHOWN` of them as rows (``loop_lost_at``)."""
        lost = self.lost
        return {
            "loop_checks": len(self.checks),
            "loop_checks_skipped": self.skipped,
            "loops_lost": len(lost),
            "loop_lost_at": [c.row() for c in lost[:SHOWN]],
        }

    def warnings(self) -> list[RunWarning]:
        """``loop_lost`` when a check found the map holding a place twice."""
        lost = self.lost
        if not lost:
            return []
        c = lost[0]
        return [
            RunWarning(
                "loop_lost",
                f"the map holds a place twice: {len(lost)} of {len(self.checks)} checks "
                f"found the scan on the map made earlier {c.offset:.1f} m and "
                f"{math.degrees(c.turn):+.0f}° from the filter's pose (first at t = {c.t:.1f} "
                f"s, x = {c.pose[0]:.1f}, y = {c.pose[1]:.1f} m): a loop was not closed",
            )
        ]
