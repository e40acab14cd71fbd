"""Landmark SLAM as a factor graph (GraphSLAM) over a landmark data set, with GPS fusion.

* :mod:`~slamkit.slam.landmark_graph.build`: the graph of a data set (odometry integrated
  between nodes, associated range-bearing readings, GPS fixes at nodes of their own times).
* :mod:`~slamkit.slam.landmark_graph.smooth`: the graph without its fixes streamed through
  the fixed-lag smoother (a smoothed alternative to EKF-SLAM).
* :mod:`~slamkit.slam.landmark_graph.solve`: solving it without and with the fixes, the fixes
  re-weighted against outliers (:mod:`slamkit.optim.gps`).
* :mod:`~slamkit.slam.landmark_graph.hierarchical`: the fixes fused hierarchically, local
  maps without GPS joined at a top level of their base frames anchored by the fixes.

Derivations and measurements on Victoria Park: ``docs/estimators/gps.md``.
"""

from slamkit.slam.landmark_graph.build import (
    GpsFixes,
    LandmarkGraph,
    build_landmark_graph,
    odometry_segments,
)
from slamkit.slam.landmark_graph.hierarchical import HierarchicalResult, solve_hierarchical
from slamkit.slam.landmark_graph.smooth import smooth_graph
from slamkit.slam.landmark_graph.solve import (
    FusionResult,
    GraphSolution,
    LandmarkGraphConfig,
    antenna_positions,
    fit_to_fixes,
    fuse_gps,
    fused_start,
    solve_fused,
    solve_unfused,
    without_gps,
)

__all__ = [
    "FusionResult",
    "GpsFixes",
    "GraphSolution",
    "HierarchicalResult",
    "LandmarkGraph",
    "LandmarkGraphConfig",
    "antenna_positions",
    "build_landmark_graph",
    "fit_to_fixes",
    "fuse_gps",
    "fused_start",
    "odometry_segments",
    "smooth_graph",
    "solve_fused",
    "solve_hierarchical",
    "solve_unfused",
    "without_gps",
]
