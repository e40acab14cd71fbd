"""g2o (C++, through its own Python bindings ``g2opy``) as a pose-graph peer.

The graph as slamkit reads it (:func:`slamkit.io.posegraph.read_graph`) becomes a g2o
``SparseOptimizer`` of ``VertexSE2``/``VertexSE3`` and ``EdgeSE2``/``EdgeSE3`` with the file's
information matrices unchanged: g2o's own error (2D ``(t, θ)`` of ``z⁻¹ xᵢ⁻¹ xⱼ``, 3D
``(t, q_v)``) is the objective slamkit minimises and :func:`slamkit.optim.g2o_chi2` reports.
The first pose is held fixed, as slamkit anchors it. The linear solver is g2o's Eigen sparse
Cholesky (``LinearSolverEigen``: ``SimplicialLDLT`` with AMD on the block structure); these
wheels are built without CHOLMOD (``G2O_HAVE_CHOLMOD`` undefined), so that is g2o's fastest
sparse direct solver here.

Stopping rule: g2o's ``SparseOptimizerTerminateAction`` with gain threshold 1e-6 (stop
after an iteration when ``0 ≤ (χ²_old − χ²_new) / χ²_new < 1e-6``) and at most 100
iterations: slamkit's default ``relative_tolerance = 1e-6``, which divides by ``χ²_old``
instead (the same test to within 1e-12).

Timed (:func:`solve`): ``initialize_optimization()`` (index, structure, workspace) and
``optimize()``; building the graph from Python (:func:`build`) is not timed, as GTSAM's
factor graph is not.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from slamkit.optim.data import GraphData
from slamkit.optim.factors3d import poses_to_internal

GAIN_THRESHOLD = 1e-6
MAX_ITERATIONS = 100


def available() -> bool:
    """Whether g2o's Python bindings import (``pip install g2opy``)."""
    try:
        import g2opy  # noqa: F401
    except ImportError:
        return False
    return True


def _isometry3(p: np.ndarray) -> Any:
    """slamkit's ``(x, y, z, qw, qx, qy, qz)`` as a g2o ``Isometry3d``."""
    import g2opy as g2o

    tR = poses_to_internal(np.asarray(p, dtype=np.float64)[None, :])[0]  # (t, R row-major)
    T = np.eye(4)
    T[:3, :3] = tR[3:].reshape(3, 3)
    T[:3, 3] = tR[:3]
    return g2o.Isometry3d(T)


@dataclass(frozen=True)
class G2oProblem:
    """A g2o optimizer and its stopping action (held here: the optimizer keeps only a
    pointer to it)."""

    optimizer: Any
    stop: Any


def build(
    graph: GraphData, ids: np.ndarray, start: np.ndarray, method: Literal["gn", "lm"]
) -> G2oProblem:
    """A g2o optimizer holding ``graph`` from the poses ``start`` (rows as ``ids``)."""
    import g2opy as g2o

    es = graph.edges[0]
    assert len(graph.edges) == 1 and es.kind in ("se2", "se3")
    three_d = es.kind == "se3"
    if three_d:
        block = g2o.BlockSolverSE3(g2o.LinearSolverEigenSE3())
    else:
        block = g2o.BlockSolverSE2(g2o.LinearSolverEigenSE2())
    algorithm = (
        g2o.OptimizationAlgorithmLevenberg(block)
        if method == "lm"
        else g2o.OptimizationAlgorithmGaussNewton(block)
    )
    opt = g2o.SparseOptimizer()
    opt.set_algorithm(algorithm)
    vertex = g2o.VertexSE3 if three_d else g2o.VertexSE2
    pose = _isometry3 if three_d else (lambda p: g2o.SE2(*p))
    for k, p in zip(ids.tolist(), start, strict=True):
        v = vertex()
        v.set_id(int(k))
        v.set_estimate(pose(p))
        opt.add_vertex(v)
    opt.vertex(int(ids[0])).set_fixed(True)
    edge = g2o.EdgeSE3 if three_d else g2o.EdgeSE2
    for i, j, z, info in zip(
        es.i.tolist(), es.j.tolist(), es.measurement, es.information, strict=True
    ):
        e = edge()
        e.set_vertex(0, opt.vertex(i))
        e.set_vertex(1, opt.vertex(j))
        e.set_measurement(pose(z))
        e.set_information(np.ascontiguousarray(info))
        opt.add_edge(e)
    stop = g2o.SparseOptimizerTerminateAction()
    stop.set_gain_threshold(GAIN_THRESHOLD)
    stop.set_max_iterations(MAX_ITERATIONS)
    opt.add_post_iteration_action(stop)
    return G2oProblem(opt, stop)


def solve(problem: G2oProblem) -> tuple[float, int]:
    """Optimise ``problem`` in place; the wall time (initialisation + iterations) and the
    iterations g2o ran."""
    opt = problem.optimizer
    t0 = time.perf_counter()
    opt.initialize_optimization()
    iterations = opt.optimize(MAX_ITERATIONS)
    return time.perf_counter() - t0, int(iterations)


def poses(problem: G2oProblem, ids: np.ndarray, dim: int) -> np.ndarray:
    """The optimised poses in slamkit's layout (rows as ``ids``)."""
    opt = problem.optimizer
    if dim == 2:
        out = np.empty((ids.shape[0], 3))
        for r, k in enumerate(ids.tolist()):
            est = opt.vertex(k).estimate()
            out[r, :2] = est.translation()
            out[r, 2] = est.rotation().angle()
        return out
    out = np.empty((ids.shape[0], 7))
    for r, k in enumerate(ids.tolist()):
        est = opt.vertex(k).estimate()
        q = est.Quaternion()
        wxyz = np.array([q.w(), q.x(), q.y(), q.z()])
        out[r, :3] = est.translation()
        out[r, 3:] = wxyz if wxyz[0] >= 0 else -wxyz
    return out
