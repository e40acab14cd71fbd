"""3D pose graphs: noise-free graphs solved exactly by every method, exact spanning-tree and
chordal initialisations, and SE-Sync's certified optimum of the parking-garage graph."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slamkit.io.posegraph import read_graph
from slamkit.optim import (
    EdgeSet,
    GraphData,
    GraphProblem,
    OptimizerConfig,
    StoppingConfig,
    chordal_initialization,
    g2o_chi2,
    marginal_covariances,
    optimize,
    sesync_objective,
    spanning_tree_initialization,
)
from slamkit.optim import factors3d as f3


def _helix(n: int = 20) -> np.ndarray:
    """Internal-format poses along a rising helix, turning about z and rolling slowly."""
    a = np.linspace(0, 3 * np.pi, n)
    out = np.zeros((n, 12))
    out[:, 0], out[:, 1], out[:, 2] = 4 * np.cos(a), 4 * np.sin(a), 0.3 * a
    for k, (yaw, roll) in enumerate(zip(a + np.pi / 2, 0.2 * np.sin(a), strict=True)):
        cy, sy, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(roll), np.sin(roll)
        Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
        Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
        out[k, 3:] = (Rz @ Rx).ravel()
    return out


def _relative(xi: np.ndarray, xj: np.ndarray) -> np.ndarray:
    Ri, Rj = xi[:, 3:].reshape(-1, 3, 3), xj[:, 3:].reshape(-1, 3, 3)
    out = np.empty_like(xi)
    out[:, :3] = np.einsum("nji,nj->ni", Ri, xj[:, :3] - xi[:, :3])
    out[:, 3:] = (np.swapaxes(Ri, 1, 2) @ Rj).reshape(-1, 9)
    return out


def _graph(truth: np.ndarray, vertices: np.ndarray | None) -> GraphData:
    n = truth.shape[0]
    pairs = [(k, k + 1) for k in range(n - 1)] + [(0, 10), (3, 17), (19, 5)]
    i = np.array([p[0] for p in pairs], dtype=np.int64)
    j = np.array([p[1] for p in pairs], dtype=np.int64)
    z = f3.poses_to_external(_relative(truth[i], truth[j]))
    info = np.diag([20.0, 20.0, 30.0, 300.0, 300.0, 500.0])
    info[0, 4] = info[4, 0] = 5.0
    es = EdgeSet(
        "se3", i, j, z, np.repeat(info[None], len(pairs), 0), np.zeros(len(pairs), np.int64)
    )
    poses = np.zeros((0, 7)) if vertices is None else f3.poses_to_external(vertices)
    ids = np.arange(n, dtype=np.int64) if vertices is not None else np.zeros(0, np.int64)
    return GraphData(dim=3, pose_ids=ids, poses=poses, edges=(es,))


def _assert_same(ext_a: np.ndarray, internal_b: np.ndarray, atol: float) -> None:
    a = f3.poses_to_internal(ext_a)
    np.testing.assert_allclose(a, internal_b, atol=atol)


@pytest.mark.parametrize("method", ["gn", "lm", "dogleg"])
def test_noise_free_3d_graph_is_solved_exactly(method: str) -> None:
    truth = _helix()
    start = f3.retract_poses3(truth, np.random.default_rng(0).normal(size=(20, 6)) * 0.1)
    start[0] = truth[0]
    data = _graph(truth, start)
    cfg = OptimizerConfig(solver=method, initialization="vertices")  # type: ignore[arg-type]
    res = optimize(data, cfg)
    assert res.converged and res.initial_cost > 10.0 and res.cost < 1e-14
    assert res.poses.shape == (20, 7)
    _assert_same(res.poses, truth, 1e-7)
    assert g2o_chi2(data, res.poses) == pytest.approx(res.cost, abs=1e-14)


def test_3d_initialisations_are_exact_without_noise() -> None:
    truth = _helix()
    # Without vertices the first pose is anchored at the identity.
    T0 = truth[:1]
    rel = _relative(np.repeat(T0, 20, 0), truth)
    problem = GraphProblem.from_data(_graph(truth, None))
    _assert_same(spanning_tree_initialization(problem), rel, 1e-9)
    _assert_same(chordal_initialization(problem), rel, 1e-9)


def test_3d_sesync_objective_and_marginals() -> None:
    truth = _helix()
    rng = np.random.default_rng(1)
    data = _graph(truth, truth)
    es = data.edges[0]
    noisy = f3.poses_to_external(
        f3.retract_poses3(f3.poses_to_internal(es.measurement), rng.normal(size=(22, 6)) * 0.05)
    )
    data = GraphData(
        dim=3,
        pose_ids=data.pose_ids,
        poses=data.poses,
        edges=(EdgeSet("se3", es.i, es.j, noisy, es.information, es.lines),),
    )
    g2o = optimize(data, OptimizerConfig(stopping=StoppingConfig(relative_tolerance=1e-12)))
    fs = optimize(
        data, OptimizerConfig(objective="sesync", stopping=StoppingConfig(relative_tolerance=1e-12))
    )
    assert fs.cost == pytest.approx(sesync_objective(data, fs.poses), rel=1e-12)
    assert fs.cost < sesync_objective(data, g2o.poses)
    assert g2o.cost < g2o_chi2(data, fs.poses)
    # Both objectives of both solutions are reported.
    assert fs.sesync_objective == pytest.approx(fs.cost, rel=1e-12)
    assert fs.g2o_chi2 == pytest.approx(g2o_chi2(data, fs.poses), rel=1e-12)
    assert g2o.g2o_chi2 == pytest.approx(g2o.cost, rel=1e-12)
    assert g2o.sesync_objective == pytest.approx(sesync_objective(data, g2o.poses), rel=1e-12)
    marg = marginal_covariances(data, g2o, pose_ids=[0, 10, 19])
    assert marg.pose_covariances.shape == (3, 6, 6)
    np.testing.assert_array_equal(marg.pose_covariances[0], 0.0)
    assert np.all(np.linalg.eigvalsh(marg.pose_covariances[1:]) > 0)


@pytest.mark.realdata
def test_parking_garage_sesync_optimum(data_root: Path) -> None:
    path = data_root / "posegraph3d" / "parking-garage.g2o"
    if not path.exists():
        pytest.skip(f"{path} not found")
    graph = read_graph(path)
    res = optimize(graph, OptimizerConfig(objective="sesync", initialization="chordal"))
    assert res.converged
    assert float(f"{res.cost:.4g}") == 1.263  # Rosen et al. (IJRR 2019): F* = 1.263e0
