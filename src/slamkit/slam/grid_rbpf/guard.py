"""The grid RBPF's guard against its odometry: the laser weighed against the wheels on the
best particle's map, as every laser tracker does (:mod:`slamkit.scanmatch.relocate`).

A particle filter spreads its particles around the wheels' prediction by the motion noise
(a few centimetres and degrees per update) and each particle's scan match starts there: a
heading jump of 30-90° in one odometry step (an encoder or gyro fault) puts every particle
where no match can reach, and the filter carries the jump for ever. Before the particles
are moved, the best particle's scan is therefore checked on its own map:

1. its match from the wheels' prediction (or the prediction itself, when the match fails
   or lands beyond the gate) is scored by :func:`map_fit`, the share of the scan's end
   points within :data:`FIT_TOLERANCE` of the map's walls: the grid's twin of
   :func:`~slamkit.scanmatch.normal_icp.surface_fit`, so the shared thresholds of
   :func:`~slamkit.scanmatch.relocate.judge` mean the same;
2. where that fit is below :data:`~slamkit.scanmatch.relocate.TRUSTED_FIT`, the scan is
   searched for over every heading and :data:`~slamkit.scanmatch.relocate.WINDOW_XY`
   around the prediction (:func:`relocate_on_map`: Olson's correlative search on the
   particle's likelihood field, refined by the same Gauss-Newton match), and
   :func:`~slamkit.scanmatch.relocate.judge` keeps the laser's pose or the wheels';
3. a relocation more than :data:`WIDE_TURN` off the wheels' heading is first weighed
   against the best pose within ± 60° of it (:func:`refuse_wide_turn`): a corridor turned
   round fits as well as the corridor, so such a turn must fit clearly better;
4. when the laser wins, every particle's step is the laser's instead of the wheels' (the
   estimator's ``_update``); a correction beyond the gate is an overridden glitch.

Measured: ``docs/estimators/grid_rbpf.md``, "Odometry glitches".
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import MatchError
from slamkit.geometry.pose2 import transform_points
from slamkit.maps.likelihood_field import LikelihoodField, interpolate_distance
from slamkit.scanmatch.correlative import (
    CorrelativeConfig,
    CorrelativeReference,
    correlative_match,
)
from slamkit.scanmatch.relocate import RELOCATE_SEARCH, Relocation
from slamkit.scanmatch.to_map import MapMatchConfig, match_to_map

__all__ = [
    "FIT_TOLERANCE",
    "MAP_SEARCH",
    "NEAR_SEARCH",
    "TURN_RATIO",
    "WIDE_TURN",
    "map_fit",
    "refuse_wide_turn",
    "relocate_on_map",
]

FIT_TOLERANCE = 0.05
"""[m] an end point this near a wall cell's centre lies on the map (surface_fit's 5 cm)."""

MAP_SEARCH = replace(RELOCATE_SEARCH, levels=5)
"""The relocation's search (every heading, ±1.5 m) on a likelihood field, whose grid is the
map's (5 cm by default, half the point relocation's 10 cm): one more level keeps the branch
and bound's coarsest nodes as large."""


WIDE_TURN = math.radians(120.0)
"""An override that turns the robot by more than this [rad] from the wheels' heading asks
for more evidence (:func:`refuse_wide_turn`): a corridor turned round fits the scan as well
as the corridor itself, and on a map already broken the wheels' fit is low everywhere, so
the judge's ratio to it no longer protects (``docs/estimators/grid_rbpf.md``, building 1)."""

NEAR_SEARCH = replace(MAP_SEARCH, window_theta=math.radians(60.0))
"""The search for the wheels' side of such a turn: ± 60° about the wheels' heading."""

TURN_RATIO = 0.8
"""A wide turn is clear when the best pose within ± 60° of the wheels' heading fits less
than this share of what the turned pose fits."""


def map_fit(field: LikelihoodField, points: FloatArray, pose: FloatArray) -> float:
    """The share of the scan's end points ``points (K, 2)`` (robot frame) that ``pose``
    puts within :data:`FIT_TOLERANCE` of a wall of ``field``'s map (its distance map,
    interpolated): 0 for no points."""
    if points.shape[0] == 0:
        return 0.0
    d, _ = interpolate_distance(field, transform_points(pose, points))
    return float(np.count_nonzero(d <= FIT_TOLERANCE)) / points.shape[0]


def relocate_on_map(
    field: LikelihoodField,
    points: FloatArray,
    around: FloatArray,
    match: MapMatchConfig,
    search: CorrelativeConfig = MAP_SEARCH,
) -> Relocation | None:
    """The scan ``points (K, 2)`` found on ``field`` over every heading and ±1.5 m around
    ``around`` (:data:`MAP_SEARCH`), refined by :func:`~slamkit.scanmatch.to_map.
    match_to_map` without a prior, with its :func:`map_fit`; None when either step finds
    nothing. ``field`` must cover the scan seen from anywhere in the window. ``search``:
    another window (:data:`NEAR_SEARCH`)."""
    try:
        ref = CorrelativeReference.from_likelihood_field(field, search)
        coarse = correlative_match(ref, points, around, search)
        refined = match_to_map(field, points, coarse.pose, match)
    except MatchError:
        return None
    return Relocation(refined, map_fit(field, points, refined.pose))


def refuse_wide_turn(
    field: LikelihoodField,
    points: FloatArray,
    around: FloatArray,
    match: MapMatchConfig,
    turned: Relocation,
) -> Relocation | None:
    """For a relocation ``turned`` more than :data:`WIDE_TURN` off the heading of
    ``around`` (the wheels' prediction): the best pose within ± 60° of that heading
    (:data:`NEAR_SEARCH`) when it fits at least :data:`TURN_RATIO` of ``turned``'s fit —
    the turn is refused and that pose is judged instead; None when the turn is clear."""
    near = relocate_on_map(field, points, around, match, NEAR_SEARCH)
    return near if near is not None and near.fit >= TURN_RATIO * turned.fit else None
