"""Range-only SLAM as one batch least-squares problem: poses at the reading times, odometry
between them, ranges to beacons whose positions are unknown.

::

    prior ─▶ X0 ──U01──▶ X1 ──U12──▶ X2 ──▶ …        odometry U: relative pose, Σ propagated
              ╲           │ ╲          │               from the motion noise between nodes
               r          r  r         r               r: ‖l_b - t_i‖ = z (σ_r), robust ρ
                ╲         │   ╲        │
                 B0       B1   B0      B5             beacons B: unknown, initialised from
                                                      the dead-reckoned path (beacons.py)

A node is made at every readings event that follows some motion, so every range sees the
pose of its own time stamp. The odometry edge from node ``i`` to ``j`` is the motion model
integrated from the identity over the controls between them, its covariance ``Σ``
propagated alongside (in the frame of node ``i``); the graph's SE(2) error is
``e_t = R_zᵀ (d - t_z)``, so its information is ``(A Σ Aᵀ)⁻¹`` with
``A = diag(R_zᵀ, 1)``.

Each beacon is initialised causally (:func:`initialise_beacons`): its readings are taken in
time order, and every :data:`INIT_EVERY` readings from :data:`INIT_MIN_READINGS` on, the
dead-reckoned positions of its readings so far and their ranges go to
:func:`~slamkit.slam.range_only.beacons.locate_beacon`; the first fix taken is its start.
Readings of a beacon never fixed are left out (counted). Then one batch solve
(:func:`~slamkit.optim.optimize`, Levenberg-Marquardt, the robust kernel on every edge),
starting from the dead-reckoned path and the fixes.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.errors import InputError
from slamkit.optim import OptimizerConfig, optimize
from slamkit.optim.data import EdgeSet, GraphData
from slamkit.optim.marginals import marginal_covariances
from slamkit.optim.robust import RobustKernel
from slamkit.optim.settings import RobustConfig
from slamkit.optim.solvers import OptimizeResult
from slamkit.slam.range_only.beacons import BeaconFix, locate_beacon

__all__ = [
    "INIT_EVERY",
    "INIT_MIN_READINGS",
    "ODOMETRY_FLOOR",
    "BeaconStart",
    "RangeOnlyProblem",
    "RangeOnlySolution",
    "initialise_beacons",
    "odometry_information",
    "range_only_graph",
    "solve_range_only",
]

ODOMETRY_FLOOR = np.diag([1e-4, 1e-4, 1e-6])
"""Added to every odometry edge's covariance [m², m², rad²] (1 cm, 1 mrad): a unicycle's
control noise has no sideways part, so the covariance of a short step is singular; the floor
stands for the slip the model leaves out."""

INIT_MIN_READINGS = 10
"""Readings of a beacon before its first attempt at a fix."""
INIT_EVERY = 5
"""A new attempt at a fix every this many readings of the beacon."""


@dataclass(frozen=True)
class RangeOnlyProblem:
    """What a run collected. ``N`` nodes, ``K`` readings.

    ``node_times (N,)`` [s]; ``node_poses (N, 3)`` the dead-reckoned poses; ``odometry
    (N-1, 3)`` node ``k+1`` in the frame of node ``k`` and ``odometry_cov (N-1, 3, 3)`` its
    covariance (in node ``k``'s frame); ``prior_cov (3, 3)`` of node 0 about
    ``node_poses[0]`` (``None``: node 0 is held fixed); ``reading_node (K,)``, ``beacon_id
    (K,)``, ``ranges (K,)`` [m]; ``sigma_range`` [m]."""

    node_times: FloatArray
    node_poses: FloatArray
    odometry: FloatArray
    odometry_cov: FloatArray
    prior_cov: FloatArray | None
    reading_node: NDArray[np.int64]
    beacon_id: NDArray[np.int64]
    ranges: FloatArray
    sigma_range: float

    def __post_init__(self) -> None:
        n, k = self.node_poses.shape[0], self.ranges.shape[0]
        if self.node_poses.shape != (n, 3) or self.odometry.shape != (max(n - 1, 0), 3):
            raise InputError(
                f"range-only problem: expected node poses (N, 3) and odometry (N-1, 3), got "
                f"{self.node_poses.shape} and {self.odometry.shape}"
            )
        if self.reading_node.shape != (k,) or self.beacon_id.shape != (k,):
            raise InputError("range-only problem: readings need one node and one id each")
        if k and not (self.reading_node.min() >= 0 and self.reading_node.max() < n):
            raise InputError("range-only problem: a reading names a node that does not exist")
        if not self.sigma_range > 0:
            raise InputError(f"sigma_range: expected a number > 0, got {self.sigma_range}")


@dataclass(frozen=True)
class BeaconStart:
    """How a beacon was started: its first ``position (2,)``, the time and reading count of
    the decision, and the fix (both hypotheses while it was ambiguous)."""

    beacon_id: int
    position: FloatArray
    time: float
    readings_used: int
    fix: BeaconFix
    ambiguous_attempts: int
    """Attempts before the fix at which the two mirror hypotheses were both kept."""


@dataclass(frozen=True)
class RangeOnlySolution:
    """The optimum: node poses ``(N, 3)``, beacons ``(M, 2)`` with their ids ``(M,)``, how
    each was started, the readings used, and the optimiser's record."""

    node_poses: FloatArray
    beacon_ids: NDArray[np.int64]
    beacons: FloatArray
    starts: dict[int, BeaconStart]
    readings_used: int
    readings_unfixed: int
    optimizer: OptimizeResult | None
    init_seconds: float = 0.0
    beacon_covariances: FloatArray | None = None
    """``(M, 2, 2)``: the beacons' marginal covariances at the optimum (Laplace)."""


def odometry_information(odometry: FloatArray, cov: FloatArray) -> FloatArray:
    """Information ``(E, 3, 3)`` of the SE(2) error ``e_t = R_zᵀ(d - t_z)`` given the
    covariance ``cov (E, 3, 3)`` of the relative pose in the frame of its first node:
    ``(A Σ Aᵀ)⁻¹`` with ``A = diag(R_zᵀ, 1)`` (module docstring)."""
    c, s = np.cos(odometry[:, 2]), np.sin(odometry[:, 2])
    A = np.zeros_like(cov)
    A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1] = c, s, -s, c
    A[:, 2, 2] = 1.0
    S = A @ (cov + ODOMETRY_FLOOR) @ A.transpose(0, 2, 1)
    S = 0.5 * (S + S.transpose(0, 2, 1))
    return np.asarray(np.linalg.inv(S), dtype=np.float64)  # 3x3 blocks, each PD


def initialise_beacons(
    problem: RangeOnlyProblem, kernel: RobustKernel, max_sigma: float
) -> dict[int, BeaconStart]:
    """The first fix of every beacon from its readings in time order (module docstring);
    beacons never fixed are absent."""
    starts: dict[int, BeaconStart] = {}
    xy = problem.node_poses[:, :2]
    for b in np.unique(problem.beacon_id):
        rows = np.flatnonzero(problem.beacon_id == b)
        ambiguous = 0
        for n in range(INIT_MIN_READINGS, rows.size + 1, INIT_EVERY):
            use = rows[:n]
            pts = xy[problem.reading_node[use]]
            if np.ptp(pts, axis=0).max() <= 0.0:
                continue
            fix = locate_beacon(pts, problem.ranges[use], problem.sigma_range, kernel, max_sigma)
            if fix.resolved:
                t = float(problem.node_times[problem.reading_node[use[-1]]])
                starts[int(b)] = BeaconStart(int(b), fix.best.position, t, n, fix, ambiguous)
                break
            ambiguous += fix.reason.startswith("ambiguous")
    return starts


def range_only_graph(
    problem: RangeOnlyProblem, starts: dict[int, BeaconStart]
) -> tuple[GraphData, NDArray[np.bool_]]:
    """The graph (poses ``0..N-1``, beacon ``b`` as landmark ``N + rank of b``) and which
    readings it holds (those of started beacons)."""
    n = problem.node_poses.shape[0]
    ids = np.array(sorted(starts), dtype=np.int64)
    keep = np.isin(problem.beacon_id, ids)
    lm_of = n + np.searchsorted(ids, problem.beacon_id[keep])
    k = int(keep.sum())
    edges = [
        EdgeSet(
            "se2",
            np.arange(n - 1, dtype=np.int64),
            np.arange(1, n, dtype=np.int64),
            problem.odometry.copy(),
            odometry_information(problem.odometry, problem.odometry_cov),
            np.zeros(n - 1, dtype=np.int64),
        ),
        EdgeSet(
            "range",
            problem.reading_node[keep].astype(np.int64),
            lm_of.astype(np.int64),
            problem.ranges[keep][:, None].copy(),
            np.full((k, 1, 1), 1.0 / problem.sigma_range**2),
            np.zeros(k, dtype=np.int64),
        ),
    ]
    fixed = np.zeros(0, dtype=np.int64)
    if problem.prior_cov is not None:
        edges.append(
            EdgeSet(
                "se2_prior",
                np.zeros(1, dtype=np.int64),
                np.full(1, -1, dtype=np.int64),
                problem.node_poses[:1].copy(),
                np.asarray(np.linalg.inv(problem.prior_cov), dtype=np.float64)[None],
                np.zeros(1, dtype=np.int64),
            )
        )
    else:
        fixed = np.zeros(1, dtype=np.int64)
    graph = GraphData(
        dim=2,
        pose_ids=np.arange(n, dtype=np.int64),
        poses=problem.node_poses.copy(),
        landmark_ids=n + np.arange(ids.size, dtype=np.int64),
        landmarks=np.array([starts[int(b)].position for b in ids]).reshape(-1, 2),
        edges=tuple(edges),
        fixed_ids=fixed,
    )
    return graph, keep


def solve_range_only(
    problem: RangeOnlyProblem,
    kernel: RobustKernel,
    max_sigma: float,
    max_iterations: int = 100,
    *,
    initial_poses: FloatArray | None = None,
    initial_beacons: Mapping[int, FloatArray] | None = None,
) -> RangeOnlySolution:
    """Start the beacons, build the graph, one batch solve from the dead-reckoned path —
    or from ``initial_poses (N, 3)`` and, for the beacons it names, ``initial_beacons`` (a
    warm start from an earlier solution; other beacons start where they were started)."""
    t0 = time.perf_counter()
    starts = initialise_beacons(problem, kernel, max_sigma)
    t_init = time.perf_counter() - t0
    ids = np.array(sorted(starts), dtype=np.int64)
    if ids.size == 0 or problem.node_poses.shape[0] < 2:
        return RangeOnlySolution(
            problem.node_poses.copy(),
            ids,
            np.zeros((0, 2)),
            starts,
            0,
            int(problem.ranges.size),
            None,
            t_init,
        )
    graph, keep = range_only_graph(problem, starts)
    cfg = OptimizerConfig(
        solver="lm",
        robust=RobustConfig(kernel=kernel.name, width=kernel.width),
    )
    cfg = _with_iterations(cfg, max_iterations)
    poses = graph.poses if initial_poses is None else np.asarray(initial_poses, np.float64)
    beacons = graph.landmarks.copy()
    for row, b in enumerate(ids):
        if initial_beacons is not None and int(b) in initial_beacons:
            beacons[row] = initial_beacons[int(b)]
    res = optimize(graph, cfg, initial_poses=poses, initial_landmarks=beacons)
    marg = marginal_covariances(graph, res, landmark_ids=graph.landmark_ids, config=cfg)
    return RangeOnlySolution(
        node_poses=res.poses,
        beacon_ids=ids,
        beacons=res.landmarks,
        starts=starts,
        readings_used=int(keep.sum()),
        readings_unfixed=int((~keep).sum()),
        optimizer=res,
        init_seconds=t_init,
        beacon_covariances=marg.landmark_covariances,
    )


def _with_iterations(cfg: OptimizerConfig, n: int) -> OptimizerConfig:
    return replace(cfg, stopping=replace(cfg.stopping, max_iterations=n))
