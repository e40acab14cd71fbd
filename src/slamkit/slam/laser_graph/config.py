"""Settings of graph-based laser SLAM (:class:`LaserGraphConfig` and its sections).

Metres, and degrees where a name says so. Only what a new robot or a new building plausibly
needs is a setting; every other number is a constant beside the code that uses it, and
``docs/estimators/laser_graph.md`` ("Settings") lists them all with where they live. The
scan matchers' and the optimiser's settings are built inside (the front end's
:data:`~slamkit.slam.laser_graph.frontend.PLICP` and
:data:`~slamkit.slam.laser_graph.frontend.NORMAL_ICP`, the back end's
:func:`~slamkit.slam.laser_graph.backend.default_optimizer`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal

from slamkit.config import (
    Section,
    finite_above,
    finite_at_least,
    fraction,
    setting,
)

__all__ = ["FrontEndSettings", "LaserGraphConfig", "LoopSettings"]


@dataclass(frozen=True)
class FrontEndSettings(Section):
    """Keyframes and the edges between neighbouring keyframes."""

    SECTION: ClassVar[str] = "frontend"

    reference: Literal["auto", "map", "keyframe"] = "auto"
    """What a scan is tracked against: the local map of the last keyframes at their current
    estimates, in the current keyframe's frame (point-to-normal ICP with the wheels' offset
    as a prior), or the current keyframe's scan alone (point-to-line ICP). ``"auto"``: the
    map with odometry, the keyframe without (the map's strength is the odometry prior;
    measurements in ``docs/estimators/laser_graph.md``)."""
    keyframe_distance: float = setting(0.4, finite_at_least(0.0), "a finite number >= 0")
    """A scan becomes a keyframe once the robot is this far from the current keyframe [m]."""
    keyframe_angle_deg: float = setting(12.0, finite_at_least(0.0), "a finite number >= 0")
    """... or has turned this much from it [deg]."""
    max_correction_xy: float = setting(0.5, finite_above(0.0), "a finite number > 0")
    """Gate: a scan match that moves the pose farther than this from the odometry's
    prediction is not taken on the match's word: with the map reference the scan is
    relocated and judged against the wheels (a win for the laser overrides the wheels, a
    glitch); with the keyframe reference the prediction is kept [m]."""
    max_correction_deg: float = setting(20.0, finite_above(0.0), "a finite number > 0")
    """Gate: ... or turns it more than this [deg]."""
    motion_cov_scale: float = setting(1.0, finite_above(0.0), "a finite number > 0")
    """Multiplies the data set's control-noise covariance: the odometry's weight as the
    local-map match's prior, and in the wheel-odometry edge that replaces a failed match."""


@dataclass(frozen=True)
class LoopSettings(Section):
    """Loop closures: the search region and the score a closure must reach."""

    SECTION: ClassVar[str] = "loops"

    enabled: bool = True
    """Search for loop closures (False: the front end's chain alone)."""
    min_travel: float = setting(3.0, finite_above(0.0), "a finite number > 0")
    """A keyframe is a candidate only once the robot has travelled this far along its path
    since it [m] (nearer ones are tied by the front end's edges already)."""
    radius_per_metre: float = setting(0.03, finite_at_least(0.0), "a finite number >= 0")
    """The search radius around the current estimate grows by this much per metre
    travelled since the candidate [m/m] (the drift a front end accumulates: radius =
    :data:`~slamkit.slam.laser_graph.loops.SEARCH_RADIUS` + radius_per_metre · travel) ..."""
    max_radius: float = setting(8.0, finite_above(0.0), "a finite number > 0")
    """... up to this [m]; also the largest translation window of the correlative search."""
    angle_per_metre_deg: float = setting(0.2, finite_at_least(0.0), "a finite number >= 0")
    """The rotation window grows by this much per metre travelled [deg/m] (from
    :data:`~slamkit.slam.laser_graph.loops.SEARCH_ANGLE_DEG`) ..."""
    max_angle_deg: float = setting(30.0, finite_above(0.0), "a finite number > 0")
    """... up to this [deg]."""
    min_score: float = setting(0.55, fraction(), "a fraction in [0, 1]")
    """Verification: the correlative match's normalised score must reach this."""


@dataclass(frozen=True)
class LaserGraphConfig(Section):
    """Settings of :class:`~slamkit.slam.laser_graph.LaserGraphSlam`."""

    min_range: float = setting(0.05, finite_at_least(0.0), "a finite number >= 0")
    """Readings at or below this [m] are dropped."""
    max_range: float | None = None
    """Readings at or beyond this [m] are dropped; None: the laser's max range."""
    mounting: tuple[float, float, float] | None = None
    """The laser's pose in the robot frame (x [m], y [m], yaw [rad]); None: the data set's
    (:attr:`~slamkit.datasets.LaserSpec.mounting`)."""
    map_resolution: float = setting(0.05, finite_above(0.0), "a finite number > 0")
    """Side of a cell of the occupancy map built from the optimised keyframes [m]."""
    frontend: FrontEndSettings = field(default_factory=FrontEndSettings)
    loops: LoopSettings = field(default_factory=LoopSettings)
