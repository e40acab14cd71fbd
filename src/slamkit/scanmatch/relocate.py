"""Finding a scan on a local map when the prediction may be wrong: the evidence against the
wheels.

A tracker predicts each scan's pose from the last match moved by the wheels, and a matcher
started there finds the scan's pose nearby. That fails in two ways real logs show: the
wheels glitch (an encoder or gyro fault turns the prediction 30-90° in one step; the wheels
stall while the robot moves on) and the match, started far from the truth or held to a
wrong prior, either fails or settles on the few walls that agree with the wrong pose. A
gate on the correction ("no more than 0.5 m or 20° from the wheels") then keeps the wheels,
which are what is wrong.

:func:`relocate` asks the map instead: a correlative search over the whole circle of
headings and :data:`WINDOW_XY` around the prediction (Olson's multi-resolution search,
:mod:`slamkit.scanmatch.correlative`, at a coarse :data:`RELOCATE_SEARCH` grid that keeps
it to tens of milliseconds), refined by point-to-normal ICP *without* the wheels' prior,
and judged by :func:`~slamkit.scanmatch.normal_icp.surface_fit`, the share of the scan the
pose lays on the map's surfaces, which does not trust the matcher's own residuals.

A corridor fits as well turned round, and a row of look-alike rooms as well shifted by one:
the whole circle holds aliases of the true pose. So when the search's best heading lies
more than :data:`NEAR_THETA` from the prediction's, the best pose within :data:`NEAR_THETA`
of it is found too (and must stay within it once refined), and the far one is kept only
when it beats that by :data:`FIT_MARGIN`, the margin the laser needs to beat the wheels'
match: among poses the laser cannot tell apart, the one nearest the wheels.

:func:`judge` compares the two hypotheses. The laser's wins when its fit is at least
:data:`TRUSTED_FIT` and beats the wheels' match by :data:`FIT_MARGIN`. Overriding the
wheels (a pose outside the tracker's gate) asks more: the laser's pose must lay at least
twice as much of the scan on the map (:data:`OVERRIDE_RATIO`). A scan that lies on the map
where the wheels say it cannot is evidence that the wheels glitched; a scan that lies a
little better half a metre along a corridor, as it does where it sees new ground, is not.
Measured (``docs/estimators/laser_graph.md``, "Odometry glitches"): a generated building's
false slide had wheels 0.49 against laser 0.70; its injected heading jumps of 55-62° gave
wheels 0.0-0.13 against 0.7-0.9; Intel's one-message heading glitches of 20-40° wheels
0.02-0.31 against 0.72-0.99.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import MatchError
from slamkit.geometry.angles import wrap_angle_float
from slamkit.scanmatch.correlative import (
    CorrelativeConfig,
    CorrelativeReference,
    correlative_match,
)
from slamkit.scanmatch.normal_icp import NormalCloud, NormalIcpConfig, normal_icp, surface_fit
from slamkit.scanmatch.result import MatchResult

__all__ = [
    "FIT_MARGIN",
    "NEAR_THETA",
    "OVERRIDE_RATIO",
    "REFUTED_FIT",
    "RELOCATE_SEARCH",
    "TRUSTED_FIT",
    "WINDOW_XY",
    "Relocation",
    "Verdict",
    "judge",
    "relocate",
]

WINDOW_XY = 1.5
"""Half-width of the search around the prediction [m]: one step of the sparsest logs of the
corpus (scans a metre or more apart) with a stall's lost motion."""

RELOCATE_SEARCH = CorrelativeConfig(
    window_xy=WINDOW_XY,
    window_theta=math.pi,
    angular_step=math.radians(0.5),
    resolution=0.1,
    sigma=0.1,
    levels=4,
    max_flatness=None,
)
"""The relocation's correlative search: every heading in 0.5° steps, 10 cm cells with a
10 cm smear (so the half-degree steps lose no point within 10 m), no degeneracy refusal
(the ICP that follows and the fit judge the result)."""

NEAR_THETA = math.radians(30.0)
"""A relocation turned more than this from the prediction [rad] must beat the best pose
within it by :data:`FIT_MARGIN` (module docstring)."""

TRUSTED_FIT = 0.6
"""A pose that lays at least this share of the scan on the map's surfaces (within 5 cm) is
a fit the laser can stand on."""

FIT_MARGIN = 0.2
"""The laser's pose replaces the wheels' match only when its fit beats theirs by this much:
in a corridor both fit, and then the wheels decide along it."""

REFUTED_FIT = 0.3
"""A pose that lays less than this share of the scan on the map is refuted: with no better
hypothesis, the track is lost."""

OVERRIDE_RATIO = 0.5
"""The laser overrides the wheels (a correction beyond the gate) only where the wheels'
fit is at most this fraction of the laser's."""


@dataclass(frozen=True)
class Relocation:
    """Where :func:`relocate` put the scan (the ICP refinement's match) and its fit."""

    match: MatchResult
    fit: float


Verdict = Literal["wheels", "laser", "lost"]
"""Which hypothesis :func:`judge` keeps: the wheels' match, the laser's relocation, or
neither (no hypothesis fits)."""


def relocate(
    cloud: NormalCloud,
    points: FloatArray,
    around: FloatArray,
    icp_config: NormalIcpConfig,
    reference: CorrelativeReference | None = None,
) -> Relocation | None:
    """The scan ``points (K, 2)`` on the map ``cloud`` searched over every heading and
    :data:`WINDOW_XY` around the pose ``around`` (module docstring), refined by ICP without
    a prior; None when either step finds nothing. ``reference``: the map's correlative
    reference built with :data:`RELOCATE_SEARCH`, if the caller keeps one."""
    ref = reference or CorrelativeReference.from_points(cloud.points, RELOCATE_SEARCH)
    try:
        found = _located(ref, cloud, points, around, RELOCATE_SEARCH, icp_config)
    except MatchError:
        return None
    if _turn(found, around) <= NEAR_THETA:
        return found
    try:
        near = _located(ref, cloud, points, around, _NEAR_SEARCH, icp_config)
    except MatchError:
        return found
    # (a refinement that turned out of the window found no pose near the wheels' heading)
    return (
        near if _turn(near, around) <= NEAR_THETA and near.fit + FIT_MARGIN > found.fit else found
    )


def _turn(relocation: Relocation, around: FloatArray) -> float:
    """How far the relocation turned from ``around`` [rad, absolute]."""
    return abs(wrap_angle_float(float(relocation.match.pose[2] - around[2])))


_NEAR_SEARCH = dataclasses.replace(RELOCATE_SEARCH, window_theta=NEAR_THETA)


def _located(
    reference: CorrelativeReference,
    cloud: NormalCloud,
    points: FloatArray,
    around: FloatArray,
    search: CorrelativeConfig,
    icp_config: NormalIcpConfig,
) -> Relocation:
    """The correlative ``search`` around ``around`` refined by ICP, with its fit. Raises
    :class:`MatchError`."""
    coarse = correlative_match(reference, points, around, search)
    refined = normal_icp(cloud, points, coarse.pose, icp_config)
    return Relocation(refined, surface_fit(cloud, points, refined.pose))


def judge(wheels_fit: float, relocation: Relocation | None, overrides: bool) -> Verdict:
    """Which pose a tracker keeps (module docstring): ``"laser"`` when the relocation fits
    at least :data:`TRUSTED_FIT` and beats the wheels' fit ``wheels_fit`` by
    :data:`FIT_MARGIN` and, where it ``overrides`` the wheels (lies outside the tracker's
    gate), the wheels' fit is at most :data:`OVERRIDE_RATIO` of it; else ``"wheels"``
    unless their pose is refuted (fit below :data:`REFUTED_FIT`): ``"lost"``."""
    laser_fit = -np.inf if relocation is None else relocation.fit
    better = laser_fit >= TRUSTED_FIT and laser_fit >= wheels_fit + FIT_MARGIN
    if better and (not overrides or wheels_fit <= OVERRIDE_RATIO * laser_fit):
        return "laser"
    return "lost" if wheels_fit < REFUTED_FIT else "wheels"
