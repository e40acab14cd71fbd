"""The landmark graph smoothed over a sliding window: the fixed-lag back end of
``slamkit landmark-graph --window L``, a smoothed alternative to EKF-SLAM.

The graph of :func:`~slamkit.slam.landmark_graph.build_landmark_graph` without its GPS
(:func:`~slamkit.slam.landmark_graph.without_gps`) is streamed node by node, in time order,
through :class:`~slamkit.optim.fixed_lag_landmarks.LandmarkFixedLagSmoother`: each node
brings its odometry edge and its range-bearing readings, as EKF-SLAM's prediction and update
would, and the answer at each node is its online estimate (its value when it left the
window). The first node is held at the data set's initial pose. What the window does with
landmarks (enter, stay, leave, re-enter) is in the smoother's module docstring.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from slamkit.optim import g2o_chi2
from slamkit.optim.fixed_lag import FixedLagConfig
from slamkit.optim.fixed_lag_landmarks import LandmarkFixedLagResult, smooth_landmark_fixed_lag
from slamkit.slam.landmark_graph.build import LandmarkGraph
from slamkit.slam.landmark_graph.solve import GraphSolution, without_gps

__all__ = ["smooth_graph"]


def smooth_graph(
    built: LandmarkGraph,
    config: FixedLagConfig,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[GraphSolution, LandmarkFixedLagResult]:
    """Stream ``built`` (its fixes left out) through the fixed-lag smoother (module
    docstring); returns the online estimates as a :class:`GraphSolution` (``chi2``: every
    edge at those estimates, each landmark at its latest variable) and the smoother's result
    (step times, re-entries, system sizes)."""
    graph = without_gps(built)
    t0 = time.perf_counter()
    res = smooth_landmark_fixed_lag(graph, config, progress, first_pose=built.initial_poses[0])
    seconds = time.perf_counter() - t0
    lm = res.landmarks[np.searchsorted(res.landmark_ids, graph.landmark_ids)]
    solution = GraphSolution(
        times=built.times,
        poses=res.poses,
        landmark_ids=res.landmark_ids,
        landmarks=res.landmarks,
        lever_arm=None,
        weights=None,
        rounds=1,
        iterations=int(res.step_iterations.sum()),
        chi2=g2o_chi2(graph, res.poses, lm),
        converged=res.converged,
        seconds=seconds,
    )
    return solution, res
