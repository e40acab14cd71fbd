"""Settings of graph-based laser SLAM (:class:`LaserGraphConfig` and its sections).

Metres, and degrees where a name says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal

from slamkit.config import (
    Section,
    finite_above,
    finite_at_least,
    fraction,
    int_at_least,
    setting,
)
from slamkit.localization.laser_odometry import MapSettings
from slamkit.optim.settings import OptimizerConfig, RobustConfig, StoppingConfig
from slamkit.scanmatch.normal_icp import NormalIcpConfig
from slamkit.scanmatch.plicp import PlIcpConfig

__all__ = ["FrontEndSettings", "LaserGraphConfig", "LoopSettings", "default_optimizer"]


@dataclass(frozen=True)
class FrontEndSettings(Section):
    """Keyframes and the edges between neighbouring keyframes."""

    SECTION: ClassVar[str] = "frontend"

    reference: Literal["auto", "map", "keyframe"] = "auto"
    """What a scan is tracked against: the local map of the last ``map_keyframes``
    keyframes at their current estimates, in the current keyframe's frame (point-to-normal
    ICP with the odometry's prediction as a prior, as laser odometry's map reference), or
    the current keyframe's scan alone (point-to-line ICP). ``"auto"`` (default): the map
    with odometry, the keyframe without (the map's strength is the odometry prior; on
    simulated rooms without odometry the map scored 2.7 m ATE, the keyframe 0.94 m). On
    the raw logs the map beat the keyframe on Intel (0.020 against 0.037 m) and ACES (0.040
    against 0.041 m), not on Freiburg 079 (0.042 against 0.033 m), and on 8 of 9 simulated
    runs (``docs/estimators/laser_graph.md``, 2026-12-04)."""
    map_keyframes: int = setting(20, int_at_least(1), "an integer >= 1")
    """Map reference: keyframes in the local map."""
    voxel: float = setting(0.05, finite_above(0.0), "a finite number > 0")
    """Map reference: one point per square cell of this side [m]."""
    keyframe_distance: float = setting(0.4, finite_at_least(0.0), "a finite number >= 0")
    """A scan becomes a keyframe once the robot is this far from the current keyframe [m]."""
    keyframe_angle_deg: float = setting(12.0, finite_at_least(0.0), "a finite number >= 0")
    """... or has turned this much from it [deg]."""
    min_overlap: float = setting(0.6, fraction(), "a fraction in [0, 1]")
    """... or its match paired less than this fraction of its points with the keyframe."""
    max_correction_xy: float = setting(0.5, finite_above(0.0), "a finite number > 0")
    """Gate: a scan match that moves the pose farther than this from the odometry's
    prediction is refused (the prediction is kept, the scan counted as unmatched) [m]."""
    max_correction_deg: float = setting(20.0, finite_above(0.0), "a finite number > 0")
    """Gate: ... or turns it more than this [deg]."""
    cov_floor_xy: float = setting(0.01, finite_above(0.0), "a finite number > 0")
    """Standard deviation added (in quadrature) to a match's covariance in x and y before it
    weights an edge [m]: scan matchers' own covariances ignore the map's systematic errors."""
    cov_floor_deg: float = setting(0.25, finite_above(0.0), "a finite number > 0")
    """... and in heading [deg]."""
    motion_cov_scale: float = setting(1.0, finite_above(0.0), "a finite number > 0")
    """Multiplies the data set's control-noise covariance in the wheel-odometry edge that
    replaces a failed match."""


@dataclass(frozen=True)
class LoopSettings(Section):
    """Loop-closure candidates, their verification and the search region."""

    SECTION: ClassVar[str] = "loops"

    enabled: bool = True
    min_travel: float = setting(3.0, finite_above(0.0), "a finite number > 0")
    """A keyframe is a candidate only once the robot has travelled this far along its path
    since it [m] (nearer ones are tied by the front end's edges already)."""
    radius: float = setting(0.5, finite_above(0.0), "a finite number > 0")
    """Search radius around the current estimate at zero travel [m] ..."""
    radius_per_metre: float = setting(0.03, finite_at_least(0.0), "a finite number >= 0")
    """... grown by this much per metre travelled since the candidate [m/m] (the drift a
    front end accumulates: radius = radius + radius_per_metre · travel) ..."""
    max_radius: float = setting(8.0, finite_above(0.0), "a finite number > 0")
    """... up to this [m]; also the largest translation window of the correlative search."""
    angle_deg: float = setting(10.0, finite_above(0.0), "a finite number > 0")
    """Rotation window at zero travel [deg] ..."""
    angle_per_metre_deg: float = setting(0.2, finite_at_least(0.0), "a finite number >= 0")
    """... grown by this much per metre travelled [deg/m] ..."""
    max_angle_deg: float = setting(30.0, finite_above(0.0), "a finite number > 0")
    """... up to this [deg]."""
    max_candidates: int = setting(2, int_at_least(1), "an integer >= 1")
    """Candidates tried per new keyframe: the nearest ones (in the current estimate), at
    least ``submap_keyframes`` keyframes apart from each other."""
    submap_keyframes: int = setting(11, int_at_least(1), "an integer >= 1")
    """A candidate's reference: its own points and those of ``submap_keyframes // 2``
    keyframes either side, in its frame."""
    resolution: float = setting(0.05, finite_above(0.0), "a finite number > 0")
    """Cell of the correlative lookup grid [m]."""
    sigma: float = setting(0.05, finite_above(0.0), "a finite number > 0")
    """Smear of the lookup grid [m]."""
    min_score: float = setting(0.55, fraction(), "a fraction in [0, 1]")
    """Verification: the correlative match's normalised score must reach this."""
    min_inliers: float = setting(0.6, fraction(), "a fraction in [0, 1]")
    """Verification: the refining point-to-normal ICP must pair this fraction of the scan."""
    max_refinement_xy: float = setting(0.25, finite_above(0.0), "a finite number > 0")
    """Verification: the refinement may move the correlative optimum at most this far [m]
    ..."""
    max_refinement_deg: float = setting(3.0, finite_above(0.0), "a finite number > 0")
    """... and turn it at most this much [deg]."""
    pair_keyframes: int = setting(10, int_at_least(1), "an integer >= 1")
    """Pairwise consistency: a verified closure waits for a partner whose ends both lie
    within this many keyframes of its own ..."""
    pair_xy: float = setting(0.1, finite_above(0.0), "a finite number > 0")
    """... and which closes the cycle with it within this [m] ..."""
    pair_deg: float = setting(1.5, finite_above(0.0), "a finite number > 0")
    """... and this [deg]."""
    max_chi2: float = setting(100.0, finite_above(0.0), "a finite number > 0")
    """Consistency: optimising the graph with new closures may raise its total
    ``Σ eᵀ Ω e`` by at most this much per closure (generous: the front end's edges are
    treated as independent, so a long chain looks surer than it is), else the worst
    closure is removed and the graph solved again
    (:func:`~slamkit.slam.laser_graph.backend.optimize_consistent`)."""
    max_edge_chi2: float = setting(100.0, finite_above(0.0), "a finite number > 0")
    """Consistency: ... and may move no earlier edge's residual by more than this in its
    own metric, ``Δeᵀ Ω Δe`` (10 standard deviations): the change, not the value, so an
    edge already strained by earlier closures is not counted as torn by a few σ more."""
    rejudge: bool = True
    """Closures the Δχ² check refused wait (while their newer end is among the last
    ``2 · pair_keyframes`` keyframes); once they outnumber the closures in the graph that
    join the same two places, all of them are judged again together, from the graph solved
    without the contested ones, and the worst residuals removed
    (:func:`~slamkit.slam.laser_graph.backend.rejudge`), so an early wrong closure can give
    way to later consistent evidence. On the raw logs with 1 µm range noise, seeds 0-9
    (``docs/estimators/laser_graph.md``, "Robustness"): ACES 0.037-0.042 m every seed
    (without: 0.108 and 0.111 m on two), Freiburg 079 0.031-0.035 m (0.038-0.043 m), Intel
    0.017-0.018 m (the same)."""
    cov_scale: float = setting(4.0, finite_above(0.0), "a finite number > 0")
    """Multiplies a closure's (floored) match covariance: its reference is a submap of
    several keyframes whose relative poses carry errors of their own."""
    optimize_every: int = setting(1, int_at_least(1), "an integer >= 1")
    """Optimise the graph after the keyframe that brings new closures, at most every this
    many keyframes (closures wait in between)."""


def default_optimizer() -> OptimizerConfig:
    """The back-end's default: Levenberg-Marquardt on plain least squares (closures are
    checked for consistency instead, which a robust kernel would blur: it gives a correct
    closure that must pull a long drift too little weight to close the loop), at most 20
    iterations from the warm start."""
    return OptimizerConfig(
        robust=RobustConfig(kernel="none"),
        stopping=StoppingConfig(max_iterations=20, relative_tolerance=1e-5),
    )


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
    frontend: FrontEndSettings = field(default_factory=FrontEndSettings)
    loops: LoopSettings = field(default_factory=LoopSettings)
    optimizer: OptimizerConfig = field(default_factory=default_optimizer)
    plicp: PlIcpConfig = field(default_factory=PlIcpConfig)
    normal_icp: NormalIcpConfig = field(default_factory=NormalIcpConfig)
    map: MapSettings = field(default_factory=MapSettings)
