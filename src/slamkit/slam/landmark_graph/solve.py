"""Solving a landmark graph, and fusing GPS into it with the fixes re-weighted.

:func:`fuse_gps` is the whole job on one data set:

1. build the graph with a node at every fix (:func:`~slamkit.slam.landmark_graph.build.
   build_landmark_graph`) and solve it **without** the fixes (first pose held at the data
   set's start; started by solves over growing prefixes, :func:`slamkit.optim.
   grow_initialization`, because dead reckoning over a long drive lies in a bad basin);
2. move that solution into the GPS frame by the SE(2) transform that best maps its antenna
   positions onto the fixes (Huber-weighted, 3 m, so the jumps do not tilt it): the start of
3. the fused solve: the same graph with the ``gps`` edges and the lever-arm variable, solved
   in rounds, the fixes re-weighted between rounds (:func:`slamkit.optim.gps.reweight`)
   until the weights settle.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset
from slamkit.errors import InputError
from slamkit.geometry.alignment import Similarity, align_points_2d
from slamkit.optim import OptimizerConfig, OptimizeResult, optimize
from slamkit.optim.data import GraphData
from slamkit.optim.gps import GpsWeighting, gps_weights, reweight, whitened_squares
from slamkit.slam.landmark_graph.build import GpsFixes, LandmarkGraph, build_landmark_graph

__all__ = [
    "FusionResult",
    "GraphSolution",
    "LandmarkGraphConfig",
    "antenna_positions",
    "fit_to_fixes",
    "fuse_gps",
    "fused_start",
    "solve_fused",
    "solve_unfused",
    "without_gps",
]

_ALIGN_HUBER = 3.0  # [m] Huber threshold of the start's alignment to the fixes


@dataclass(frozen=True)
class LandmarkGraphConfig:
    """Settings of :func:`fuse_gps` (covariance scales multiply the data set's nominal ones)."""

    motion_cov_scale: float = 1.0
    """Multiplies the control covariance of the odometry edges."""
    measurement_cov_scale: float = 1.0
    """Multiplies the reading covariance of the range-bearing edges."""
    weighting: GpsWeighting = field(default_factory=GpsWeighting)
    """How fixes are re-weighted against outliers."""
    optimizer: OptimizerConfig = field(default_factory=OptimizerConfig)
    """The batch optimiser (its own robust kernel applies to every edge: leave it "none")."""


@dataclass(frozen=True, eq=False)
class GraphSolution:
    """One solved graph: poses at the node times, the landmark map, and the fixes' state."""

    times: FloatArray
    """Node times ``(N,)`` [s]."""
    poses: FloatArray
    """``(N, 3)``."""
    landmark_ids: NDArray[np.int64]
    """Ids of the map's landmarks ``(L,)`` (the lever arm left out)."""
    landmarks: FloatArray
    """``(L, 2)``."""
    lever_arm: FloatArray | None
    """The estimated antenna position in the robot frame ``(2,)`` [m] (None: no GPS)."""
    weights: FloatArray | None
    """Final weight of each fused fix (None: no GPS)."""
    rounds: int
    """Solves (outer re-weighting rounds; 1 without GPS)."""
    iterations: int
    """Linearisations over all rounds."""
    chi2: float
    """χ² of the final solve (fixes at their final weights)."""
    converged: bool
    """The last solve converged and (with GPS) the weights settled within ``max_rounds``."""
    seconds: float
    """Wall time of the solves (building not included)."""


@dataclass(frozen=True, eq=False)
class FusionResult:
    """:func:`fuse_gps`'s answer: the graph, the solution without GPS and the fused one."""

    built: LandmarkGraph
    unfused: GraphSolution
    fused: GraphSolution
    build_seconds: float


def without_gps(built: LandmarkGraph) -> GraphData:
    """The graph without its ``gps`` edges and lever arm, its first pose held."""
    g = built.graph
    keep = g.landmark_ids != built.lever_id
    return replace(
        g,
        edges=tuple(e for e in g.edges if e.kind != "gps"),
        landmark_ids=g.landmark_ids[keep],
        landmarks=g.landmarks[keep],
        fixed_ids=np.array([int(g.pose_ids[0])], dtype=np.int64),
    )


def antenna_positions(poses: FloatArray, lever_arm: FloatArray) -> FloatArray:
    """``t + R(θ) o`` for poses ``(N, 3)`` and one lever arm ``o (2,)``."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return np.stack(
        [
            poses[:, 0] + c * lever_arm[0] - s * lever_arm[1],
            poses[:, 1] + s * lever_arm[0] + c * lever_arm[1],
        ],
        axis=1,
    )


def _solution(
    built: LandmarkGraph,
    res: OptimizeResult,
    weights: FloatArray | None,
    rounds: int,
    iterations: int,
    seconds: float,
    settled: bool = True,
) -> GraphSolution:
    lm_keep = res.landmark_ids != built.lever_id
    lever = None
    if weights is not None:
        lever = res.landmarks[np.flatnonzero(~lm_keep)[0]].copy()
    return GraphSolution(
        times=built.times,
        poses=res.poses,
        landmark_ids=res.landmark_ids[lm_keep],
        landmarks=res.landmarks[lm_keep],
        lever_arm=lever,
        weights=weights,
        rounds=rounds,
        iterations=iterations,
        chi2=res.cost,
        converged=res.converged and settled,
        seconds=seconds,
    )


def solve_unfused(built: LandmarkGraph, config: LandmarkGraphConfig | None = None) -> GraphSolution:
    """Solve ``built`` without its fixes (:func:`without_gps`), started by solves over growing
    prefixes (module docstring, step 1)."""
    config = config or LandmarkGraphConfig()
    t0 = time.perf_counter()
    res = optimize(without_gps(built), replace(config.optimizer, initialization="grow"))
    return _solution(built, res, None, 1, res.iterations, time.perf_counter() - t0)


def _gps_frame_start(built: LandmarkGraph, poses: FloatArray) -> FloatArray:
    """``poses`` moved into the GPS frame (module docstring, step 2)."""
    gps = built.graph.edges[_gps_edges(built)]
    return fit_to_fixes(poses[gps.i, :2], gps.measurement).apply_to_poses(poses)


def fit_to_fixes(points: FloatArray, fixes: FloatArray) -> Similarity:
    """The SE(2) transform that best maps ``points (M, 2)`` onto ``fixes (M, 2)``,
    Huber-weighted (3 m) so that jumps of the fixes do not tilt it (five re-weightings)."""
    w = np.ones(points.shape[0])
    sim = align_points_2d(points, fixes, w)
    for _ in range(5):
        r = np.linalg.norm(sim.apply_to_points(points) - fixes, axis=1)
        w = np.minimum(1.0, _ALIGN_HUBER / np.maximum(r, 1e-12))
        sim = align_points_2d(points, fixes, w)
    return sim


def solve_fused(
    built: LandmarkGraph,
    initial_poses: FloatArray,
    initial_landmarks: FloatArray,
    config: LandmarkGraphConfig | None = None,
) -> GraphSolution:
    """Solve ``built`` (with its ``gps`` edges) from the given start (rows of
    ``graph.pose_ids`` / ``graph.landmark_ids``, the lever arm included), re-weighting the
    fixes between solves until no weight moves by more than ``weighting.tolerance``."""
    cfg = config or LandmarkGraphConfig()
    g = built.graph
    k_gps = _gps_edges(built)
    base = g.edges[k_gps]
    lever_row = int(np.flatnonzero(g.landmark_ids == built.lever_id)[0])
    opt = replace(cfg.optimizer, initialization="vertices")
    weights = np.ones(len(base))
    poses, landmarks = initial_poses, initial_landmarks
    t0 = time.perf_counter()
    iterations = 0
    rounds = 0
    res: OptimizeResult | None = None
    settled = False
    while rounds < cfg.weighting.max_rounds:
        rounds += 1
        edges = list(g.edges)
        edges[k_gps] = reweight(base, base.information, weights)
        graph = replace(g, edges=tuple(edges))
        res = optimize(graph, opt, initial_poses=poses, initial_landmarks=landmarks)
        iterations += res.iterations
        poses, landmarks = res.poses, res.landmarks
        if cfg.weighting.name == "none":
            settled = True
            break
        lever = landmarks[lever_row]
        s = whitened_squares(poses[base.i], lever, base.measurement, base.information)
        new = gps_weights(cfg.weighting, s)
        moved = float(np.max(np.abs(new - weights))) if new.size else 0.0
        weights = new
        if moved <= cfg.weighting.tolerance:
            settled = True
            break
    assert res is not None
    seconds = time.perf_counter() - t0
    return _solution(built, res, weights, rounds, iterations, seconds, settled)


def _gps_edges(built: LandmarkGraph) -> int:
    """Index of the graph's ``gps`` edge set; :class:`InputError` unless it holds at least
    two fixes (fewer do not place the graph in the GPS frame)."""
    for k, e in enumerate(built.graph.edges):
        if e.kind == "gps" and len(e) >= 2:
            return k
    raise InputError(
        f"{built.graph.source or 'the graph'}: fewer than two GPS fixes in the graph (none "
        "given, all held out, or all outside the controls' time span)"
    )


def fuse_gps(
    dataset: Dataset, gps: GpsFixes, config: LandmarkGraphConfig | None = None
) -> FusionResult:
    """Build ``dataset``'s landmark graph with ``gps``, solve it without and with the fixes
    (module docstring). The readings must carry their landmark ids."""
    cfg = config or LandmarkGraphConfig()
    t0 = time.perf_counter()
    built = build_landmark_graph(
        dataset,
        gps=gps,
        motion_cov_scale=cfg.motion_cov_scale,
        measurement_cov_scale=cfg.measurement_cov_scale,
    )
    build_seconds = time.perf_counter() - t0
    unfused = solve_unfused(built, cfg)
    poses, landmarks = fused_start(built, unfused)
    fused = solve_fused(built, poses, landmarks, cfg)
    return FusionResult(built, unfused, fused, build_seconds)


def fused_start(built: LandmarkGraph, unfused: GraphSolution) -> tuple[FloatArray, FloatArray]:
    """The fused solve's start (module docstring, step 2): ``unfused`` moved into the GPS
    frame, its landmarks with it, the lever arm at the graph's initial value; rows as
    ``graph.pose_ids`` / ``graph.landmark_ids``."""
    g = built.graph
    start = _gps_frame_start(built, unfused.poses)
    lm_start = np.array(g.landmarks, copy=True)
    keep = g.landmark_ids != built.lever_id
    order = np.searchsorted(unfused.landmark_ids, g.landmark_ids[keep])
    lm_start[keep] = _moved_points(unfused.poses, start, unfused.landmarks[order])
    return start, lm_start


def _moved_points(before: FloatArray, after: FloatArray, points: FloatArray) -> FloatArray:
    """``points`` moved by the rigid motion that took pose ``before[0]`` to ``after[0]``."""
    d = after[0, 2] - before[0, 2]
    c, s = np.cos(d), np.sin(d)
    p = points - before[0, :2]
    return np.stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]], axis=1) + after[0, :2]
