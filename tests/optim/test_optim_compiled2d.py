"""The compiled pass of a plain 2D pose graph (slamkit.optim.compiled2d) against the NumPy
path: the same H, g and χ² (bit for bit: the same formulas, summed in the same order), the
same retraction to rounding, the same optimum; and the graphs it must leave to NumPy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slamkit.backend import AVAILABLE
from slamkit.errors import SlamkitError
from slamkit.geometry import pose2
from slamkit.io.posegraph import read_graph
from slamkit.optim import (
    EdgeSet,
    GraphData,
    GraphProblem,
    OptimizerConfig,
    RobustConfig,
    optimize,
)
from slamkit.optim.compiled2d import compiled_window
from slamkit.optim.incremental import (
    IncrementalConfig,
    IncrementalOptimizer,
    time_ordered_updates,
)
from slamkit.optim.updates import check_update_edges

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba is not installed (slamkit[fast])")


def _edges(kind: str, i, j, z, info) -> EdgeSet:
    i = np.asarray(i, dtype=np.int64)
    return EdgeSet(
        kind,  # type: ignore[arg-type]
        i,
        np.asarray(j, dtype=np.int64),
        np.asarray(z, dtype=float),
        np.asarray(info, dtype=float),
        np.zeros(i.shape[0], dtype=np.int64),
    )


def _noisy_loop(rng: np.random.Generator, n: int = 40) -> GraphData:
    """A loop of ``n`` poses with odometry, closures in both directions (so that some block
    products land transposed) and a correlated information matrix; vertices perturbed."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    truth = np.stack([5 * np.cos(a), 5 * np.sin(a), np.arctan2(np.cos(a), -np.sin(a))], -1)
    pairs = [(k, k + 1) for k in range(n - 1)] + [(0, 20), (33, 4), (n - 1, 0), (25, 10)]
    i = np.array([p[0] for p in pairs])
    j = np.array([p[1] for p in pairs])
    z = pose2.between(truth[i], truth[j]) + rng.normal(size=(len(pairs), 3)) * 0.05
    info = np.array([[[100.0, 10.0, 1.0], [10.0, 80.0, 2.0], [1.0, 2.0, 400.0]]] * len(pairs))
    start = truth + rng.normal(size=truth.shape) * np.array([0.3, 0.3, 0.2])
    return GraphData(
        dim=2,
        pose_ids=np.arange(n, dtype=np.int64),
        poses=start,
        edges=(_edges("se2", i, j, z, info),),
    )


def test_compiled_system_equals_numpy_bit_for_bit() -> None:
    graph = _noisy_loop(np.random.default_rng(3))
    fast = GraphProblem.from_data(graph)
    slow = GraphProblem.from_data(graph, compiled=False)
    assert fast.compiled is not None and slow.compiled is None
    no_lm = np.zeros((0, 2))
    a, b = fast.linearize(graph.poses, no_lm), slow.linearize(graph.poses, no_lm)
    assert a.H is not None and b.H is not None and a.g is not None and b.g is not None
    np.testing.assert_array_equal(a.H, b.H)
    np.testing.assert_array_equal(a.g, b.g)
    assert a.chi2 == pytest.approx(b.chi2, rel=1e-13) and a.cost == pytest.approx(b.cost, rel=1e-13)
    cost_only = fast.linearize(graph.poses, no_lm, jacobians=False)
    assert cost_only.H is None and cost_only.chi2 == a.chi2
    assert fast.objective_values(graph.poses, no_lm) == pytest.approx(
        slow.objective_values(graph.poses, no_lm), rel=1e-13
    )


def test_compiled_retraction_equals_numpy() -> None:
    rng = np.random.default_rng(4)
    graph = _noisy_loop(rng)
    fast = GraphProblem.from_data(graph)
    slow = GraphProblem.from_data(graph, compiled=False)
    delta = rng.normal(size=fast.n) * 0.5
    delta[2::3][:5] = 1e-5  # the Taylor branch of Exp (|δθ| < 1e-3)
    delta[2::3][5:8] = (3.0, -3.1, 4.0)  # headings that wrap
    x_fast, _ = fast.retract(graph.poses, np.zeros((0, 2)), delta)
    x_slow, _ = slow.retract(graph.poses, np.zeros((0, 2)), delta)
    np.testing.assert_allclose(x_fast, x_slow, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(x_fast[0], graph.poses[0])  # the anchored first pose
    assert (x_fast[:, 2] >= -np.pi).all() and (x_fast[:, 2] < np.pi).all()


@pytest.mark.parametrize("solver", ["lm", "gn", "dogleg"])
def test_compiled_optimum_equals_numpy(solver: str) -> None:
    graph = _noisy_loop(np.random.default_rng(5))
    cfg = OptimizerConfig(solver=solver)  # type: ignore[arg-type]
    fast = optimize(graph, cfg, initial_poses=graph.poses)
    slow = optimize(
        graph,
        cfg,
        initial_poses=graph.poses,
        problem=GraphProblem.from_data(graph, compiled=False),
    )
    assert fast.converged and slow.converged
    assert fast.iterations == slow.iterations
    assert fast.g2o_chi2 == pytest.approx(slow.g2o_chi2, rel=1e-12)
    np.testing.assert_allclose(fast.poses, slow.poses, rtol=0, atol=1e-10)


def test_graphs_the_compiled_pass_leaves_to_numpy() -> None:
    graph = _noisy_loop(np.random.default_rng(6))
    assert GraphProblem.from_data(graph, objective="sesync").compiled is None
    prior = _edges("se2_prior", [0], [-1], graph.poses[:1], [np.eye(3)])
    with_prior = GraphData(
        dim=2, pose_ids=graph.pose_ids, poses=graph.poses, edges=(*graph.edges, prior)
    )
    assert GraphProblem.from_data(with_prior).compiled is None
    # A robust kernel takes the NumPy path of the same problem: same result either way.
    cfg = OptimizerConfig(robust=RobustConfig(kernel="cauchy"))
    fast = optimize(graph, cfg, initial_poses=graph.poses)
    slow = optimize(
        graph, cfg, initial_poses=graph.poses, problem=GraphProblem.from_data(graph, compiled=False)
    )
    np.testing.assert_allclose(fast.poses, slow.poses, rtol=0, atol=1e-10)


@pytest.mark.realdata
def test_intel_chi2_unchanged(data_root: Path) -> None:
    """intel from the file's vertices: the compiled run ends at the NumPy run's χ²
    (45.004696, the batch optimum of benchmarks/results/posegraph.md)."""
    path = data_root / "posegraph2d" / "intel.g2o"
    if not path.exists():
        pytest.skip(f"{path} not found")
    graph = read_graph(path)
    fast = optimize(graph, initial_poses=graph.poses)
    slow = optimize(
        graph, initial_poses=graph.poses, problem=GraphProblem.from_data(graph, compiled=False)
    )
    assert fast.g2o_chi2 == pytest.approx(45.004696, abs=5e-7)
    assert fast.g2o_chi2 == pytest.approx(slow.g2o_chi2, rel=1e-12)
    np.testing.assert_allclose(fast.poses, slow.poses, rtol=0, atol=1e-9)


def test_compiled_window_steps_equal_numpy() -> None:
    """The incremental optimiser's window steps in one compiled pass: the same estimate
    after every update (to rounding), the same batch-step decisions, the same end."""
    graph = _noisy_loop(np.random.default_rng(8), n=60)
    updates = time_ordered_updates(graph)
    runs = []
    for compiled in (True, False):
        inc = IncrementalOptimizer(IncrementalConfig(relinearize_every=25), compiled=compiled)
        trail, infos = [], []
        for u in updates:
            infos.append(inc.update(u.pose_ids, u.edges, u.initial_poses))
            trail.append(inc.estimate()[1])
        runs.append((trail, infos, inc.finish()))
    (fast_trail, fast_infos, fast_end), (slow_trail, slow_infos, slow_end) = runs
    assert sum(i.step_norm > 0 for i in fast_infos) >= 4  # window steps did run
    assert [i.batch_step for i in fast_infos] == [i.batch_step for i in slow_infos]
    np.testing.assert_allclose(
        [i.step_norm for i in fast_infos], [i.step_norm for i in slow_infos], rtol=1e-9, atol=1e-13
    )
    for xf, xs in zip(fast_trail, slow_trail, strict=True):
        np.testing.assert_allclose(xf, xs, rtol=0, atol=1e-10)
    assert fast_end.chi2 == pytest.approx(slow_end.chi2, rel=1e-12)


def test_compiled_window_refuses_a_singular_system() -> None:
    """Two free poses joined by one edge and to nothing fixed: ``H`` has rank 3 of 6, and the
    compiled Cholesky says so instead of returning a step."""
    window = compiled_window()
    assert window is not None
    X = np.array([[0.0, 0.0, 0.0], [1.0, 0.2, 0.1]])
    a, b = np.array([0]), np.array([1])
    z = np.array([[1.0, 0.0, 0.0]])
    U = np.linalg.cholesky(np.diag([10.0, 10.0, 40.0]))[None].transpose(0, 2, 1).copy()
    free = np.arange(6)[None, :]
    assert window.step(X, np.arange(2), a, b, z, U, free) is None
    fixed_first = np.array([[-1, -1, -1, 0, 1, 2]])  # pose 0 held: one pose, full rank
    delta = window.step(X, np.arange(1), a, b, z, U, fixed_first)
    assert delta is not None
    # One edge, one free pose: the step lands pose 1 exactly on the measurement.
    moved = window.retract(X[1:], delta)
    np.testing.assert_allclose(moved[0], [1.0, 0.0, 0.0], atol=1e-2)


def test_compiled_whitening_and_chaining_equal_numpy() -> None:
    window = compiled_window()
    assert window is not None
    rng = np.random.default_rng(9)
    M = rng.normal(size=(20, 3, 3))
    info = M @ M.transpose(0, 2, 1) + 0.5 * np.eye(3)
    U = window.whitening(info)
    assert U is not None
    np.testing.assert_allclose(U, np.linalg.cholesky(info).transpose(0, 2, 1), rtol=1e-13)
    np.testing.assert_allclose(U.transpose(0, 2, 1) @ U, info, rtol=1e-12)
    for broken in (np.diag([1.0, -1.0, 1.0]), np.diag([1.0, np.nan, 1.0]), np.eye(3) + 0.1):
        bad = info.copy()
        bad[7] = broken
        if broken[0, 1] != 0:
            bad[7, 0, 1] += 0.2  # not symmetric
        assert window.whitening(bad) is None
        es = _edges("se2", np.arange(20), np.arange(1, 21), np.zeros((20, 3)), bad)
        with pytest.raises(SlamkitError, match="edge 7"):
            check_update_edges(es, window.whitening)  # the NumPy checks name the edge
    x = np.array([1.0, -2.0, 3.0])
    for z in (np.array([0.5, 0.2, 0.4]), np.array([-1.0, 3.0, -3.1])):
        np.testing.assert_allclose(window.chain(x, z, False), pose2.compose(x, z), atol=1e-14)
        np.testing.assert_allclose(
            window.chain(x, z, True), pose2.compose(x, pose2.inverse(z)), atol=1e-14
        )


def test_compiled_pattern_equals_numpy() -> None:
    """The pattern of ``H`` and every slot, built by the compiled pass, equal
    ``NormalPattern.from_blocks``'s, with parallel edges in both directions."""
    graph = _noisy_loop(np.random.default_rng(10))
    es = graph.edges[0]
    extra = np.array([3, 20, 0])  # parallel to 3 → 4, reversed 0 → 20, and 0 → 20 again
    extra_j = np.array([4, 0, 20])
    doubled = _edges(
        "se2",
        np.concatenate([es.i, extra]),
        np.concatenate([es.j, extra_j]),
        np.concatenate([es.measurement, es.measurement[:3]]),
        np.concatenate([es.information, es.information[:3]]),
    )
    for data in (
        graph,
        GraphData(dim=2, pose_ids=graph.pose_ids, poses=graph.poses, edges=(doubled,)),
    ):
        fast = GraphProblem.from_data(data).pattern
        slow = GraphProblem.from_data(data, compiled=False).pattern
        assert fast.n == slow.n
        for name in ("indptr", "indices", "slots", "grad_slots", "diag"):
            np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)
