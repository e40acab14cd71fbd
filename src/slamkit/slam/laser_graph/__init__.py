"""Graph-based 2D laser SLAM: keyframes tracked by scan matching, loop closures found by
correlative matching in a search region grown with the path travelled and verified, and
the pose graph optimised by :func:`slamkit.optim.optimize` (see
``docs/estimators/laser_graph.md``).

* :mod:`~slamkit.slam.laser_graph.config`: :class:`LaserGraphConfig` and its sections (the
  few settings a new robot may need; every other number is a constant beside its code).
* :mod:`~slamkit.slam.laser_graph.frontend`: scan-to-keyframe tracking, neighbour edges.
* :mod:`~slamkit.slam.laser_graph.loops`: candidates, submaps, verification.
* :mod:`~slamkit.slam.laser_graph.backend`: the pose graph and its optimisation.
* :mod:`~slamkit.slam.laser_graph.estimator`: :class:`LaserGraphSlam` on the shell.
"""

from slamkit.slam.laser_graph.backend import PoseGraph, default_optimizer, edge_chi2
from slamkit.slam.laser_graph.config import FrontEndSettings, LaserGraphConfig, LoopSettings
from slamkit.slam.laser_graph.estimator import NO_ODOMETRY, LaserGraphSlam
from slamkit.slam.laser_graph.frontend import Keyframe, Tracker, floored_information
from slamkit.slam.laser_graph.loops import (
    LoopMatch,
    SubmapCache,
    loop_candidates,
    loop_reference,
    search_window,
    submap,
    verify_closure,
)

__all__ = [
    "NO_ODOMETRY",
    "FrontEndSettings",
    "Keyframe",
    "LaserGraphConfig",
    "LaserGraphSlam",
    "LoopMatch",
    "LoopSettings",
    "PoseGraph",
    "SubmapCache",
    "Tracker",
    "default_optimizer",
    "edge_chi2",
    "floored_information",
    "loop_candidates",
    "loop_reference",
    "search_window",
    "submap",
    "verify_closure",
]
