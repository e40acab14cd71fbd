"""Range-only SLAM: beacons at unknown positions, initialised from the ranges along the path
(mirror ambiguity kept until it resolves), then one robust batch least-squares solve."""

from slamkit.slam.range_only.beacons import (
    MIRROR_GAP,
    SAME_POINT_M,
    BeaconFix,
    BeaconHypothesis,
    locate_beacon,
    mirror_seeds,
    refine_beacon,
)
from slamkit.slam.range_only.estimator import RangeOnlySlam, RangeOnlySlamConfig
from slamkit.slam.range_only.problem import (
    INIT_EVERY,
    INIT_MIN_READINGS,
    ODOMETRY_FLOOR,
    BeaconStart,
    RangeOnlyProblem,
    RangeOnlySolution,
    initialise_beacons,
    odometry_information,
    range_only_graph,
    solve_range_only,
)

__all__ = [
    "INIT_EVERY",
    "INIT_MIN_READINGS",
    "MIRROR_GAP",
    "ODOMETRY_FLOOR",
    "SAME_POINT_M",
    "BeaconFix",
    "BeaconHypothesis",
    "BeaconStart",
    "RangeOnlyProblem",
    "RangeOnlySlam",
    "RangeOnlySlamConfig",
    "RangeOnlySolution",
    "initialise_beacons",
    "locate_beacon",
    "mirror_seeds",
    "odometry_information",
    "range_only_graph",
    "refine_beacon",
    "solve_range_only",
]
