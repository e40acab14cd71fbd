"""Robust kernels on the vertigo ring and ringCity graphs with false loop closures added.

The outlier model (seeded, ``np.random.default_rng(0)``): as many false loop closures as 10 %
of the graph's true ones (ring: 3 false against 26 true; ringCity: 90 against 901), each
between two poses drawn uniformly at random more than 10 ids apart, claiming they are at the
same place: ``(dx, dy) ~ U(-1, 1)² m``, ``dθ ~ U(-π, π)``, with the information matrix of the
file's true loop closures (a false place recognition). Every solve starts from the file's
vertices (the odometry chain); the reference is the least-squares optimum of the graph without
false closures, and each result is scored by its SE(2)-aligned ATE against the ground truth
as a multiple of the reference's (ring 1.432 m, ringCity 0.948 m).

Measured over seeds 0-4 (default kernel widths, :data:`slamkit.optim.robust.DEFAULT_WIDTHS`):

| graph | least squares (200 it.) | Huber δ=3 | Cauchy c=1 | Geman-McClure c=3 | DCS φ=3 |
|---|---|---|---|---|---|
| ring | 12.3-20.9x | 13-46x | 0.93-1.51x | 1.00x | 1.00x |
| ringCity | 43.9-48.2x | 53-57x | 1.43-3.47x | 0.99-1.00x | 1.00x |

With as many false closures as 10 % of *all* edges (ring 46, ringCity 326, more than ring's
true closures) Geman-McClure c=3 still gives 1.00x on ring but 0.96-17x on ringCity depending
on the seed (a false closure accepted early bends the map into another local minimum, whose
robust cost is higher than the right one's); that harder setting is not asserted here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slamkit.eval.trajectory import absolute_trajectory_error
from slamkit.io.posegraph import read_graph
from slamkit.optim import (
    EdgeSet,
    GraphData,
    GraphProblem,
    OptimizerConfig,
    RobustConfig,
    StoppingConfig,
    optimize,
)
from slamkit.optim.robust import robust_rho_and_weight

pytestmark = pytest.mark.realdata


def _with_false_closures(
    data_root: Path, name: str, rng: np.random.Generator
) -> tuple[GraphData, GraphData, np.ndarray, np.ndarray]:
    """The file's graph, the graph with false closures, the true poses, the mask of the
    false edges."""
    folder = data_root / "posegraph2d" / "vertigo"
    path = folder / f"{name}__originalDataset__{name}.g2o"
    truth_path = folder / f"{name}__groundTruth__poses.txt"
    if not (path.exists() and truth_path.exists()):
        pytest.skip(f"{path} or its ground truth not found")
    graph = read_graph(path)
    truth = np.loadtxt(truth_path)
    np.testing.assert_array_equal(truth[:, 0].astype(np.int64), graph.pose_ids)
    es = graph.edges[0]
    closure = np.abs(es.j - es.i) != 1
    n_false = round(0.1 * int(closure.sum()))
    n = graph.pose_ids.shape[0]
    pairs: list[tuple[int, int]] = []
    while len(pairs) < n_false:
        a, b = (int(v) for v in rng.integers(0, n, 2))
        if abs(a - b) > 10:
            pairs.append((min(a, b), max(a, b)))
    rows = np.array(pairs, dtype=np.int64)
    z = np.stack(
        [
            rng.uniform(-1.0, 1.0, n_false),
            rng.uniform(-1.0, 1.0, n_false),
            rng.uniform(-np.pi, np.pi, n_false),
        ],
        axis=-1,
    )
    info = np.repeat(es.information[np.flatnonzero(closure)[0]][None], n_false, axis=0)
    edges = EdgeSet(
        "se2",
        np.concatenate([es.i, graph.pose_ids[rows[:, 0]]]),
        np.concatenate([es.j, graph.pose_ids[rows[:, 1]]]),
        np.concatenate([es.measurement, z]),
        np.concatenate([es.information, info]),
        np.concatenate([es.lines, np.zeros(n_false, dtype=np.int64)]),
    )
    corrupted = GraphData(dim=2, pose_ids=graph.pose_ids, poses=graph.poses, edges=(edges,))
    false = np.arange(len(edges)) >= len(es)
    return graph, corrupted, truth[:, 1:], false


# (graph, least-squares floor, Cauchy ceiling): measured seed 0 — LS after 30 iterations
# 8.86x / 31.5x (it only gets worse: 14.4x / 43.0x after 100), Cauchy 1.20x / 1.43x.
CASES = [("ring", 5.0, 1.5), ("ringCity", 20.0, 2.0)]


@pytest.mark.parametrize(("name", "ls_floor", "cauchy_ceiling"), CASES)
def test_robust_kernels_recover_the_trajectory(
    data_root: Path, name: str, ls_floor: float, cauchy_ceiling: float
) -> None:
    """Redescending kernels recover the outlier-free trajectory, least squares does not.

    Seed 0, measured: Geman-McClure 1.000x / 0.991x, DCS 1.000x / 1.002x in 11-14
    iterations, every false closure weighted below 2e-5 and every true one above 0.75;
    Cauchy 1.20x / 1.43x. Thresholds: 1.05x for GM and DCS, the Cauchy ceilings above (about
    +25 % / +40 %), and all false closures below weight 1e-3 (GM, DCS).
    """
    graph, corrupted, truth, false = _with_false_closures(data_root, name, np.random.default_rng(0))

    def ate(poses: np.ndarray) -> float:
        return absolute_trajectory_error(poses, truth, align="se2").rmse

    reference = ate(optimize(graph).poses)
    plain = optimize(corrupted, OptimizerConfig(stopping=StoppingConfig(max_iterations=30)))
    assert ate(plain.poses) > ls_floor * reference
    problem = GraphProblem.from_data(corrupted)
    es = corrupted.edges[0]
    true_closure = (np.abs(es.j - es.i) != 1) & ~false
    for kernel in ("geman_mcclure", "dcs"):
        cfg = OptimizerConfig(robust=RobustConfig(kernel=kernel))
        res = optimize(corrupted, cfg)
        assert res.converged and res.iterations > 5, res.reason
        assert ate(res.poses) < 1.05 * reference, kernel
        (s,) = problem.block_terms(res.poses, np.zeros((0, 2)))
        _, w = robust_rho_and_weight(cfg.kernel, s)
        assert w[false].max() < 1e-3 and w[true_closure].min() > 0.5, kernel
    cauchy = optimize(corrupted, OptimizerConfig(robust=RobustConfig(kernel="cauchy")))
    assert ate(cauchy.poses) < cauchy_ceiling * reference


def test_too_narrow_a_kernel_stays_at_the_odometry_start(data_root: Path) -> None:
    """Why Geman-McClure c = 1 and DCS φ = 1 "converge" after one iteration on ring.

    From the odometry chain every loop closure, true or false, has a squared error in the
    hundreds or more, so with ``c² = 1`` (or ``φ = 1``) all get IRLS weight ≈ 0; the odometry
    edges alone are already satisfied, so the start is a stationary point of the robust cost
    and the first step changes it by ~1e-8 relative. The result is the odometry (5.86x the
    reference ATE, measured); the default widths move off it (previous test). The one step
    is LM's shortened Gauss-Newton step (``damping="hessian"``), which moves the trajectory's
    soft modes on the flat robust cost by 1.5 % of its ATE (within 1 % with ``D = I``).
    """
    _, corrupted, truth, false = _with_false_closures(data_root, "ring", np.random.default_rng(0))
    odometry = absolute_trajectory_error(corrupted.poses, truth, align="se2").rmse
    es = corrupted.edges[0]
    true_closure = (np.abs(es.j - es.i) != 1) & ~false
    problem = GraphProblem.from_data(corrupted)
    for kernel in ("geman_mcclure", "dcs"):
        cfg = OptimizerConfig(robust=RobustConfig(kernel=kernel, width=1.0))
        res = optimize(corrupted, cfg)
        assert res.converged and res.iterations == 1
        moved = absolute_trajectory_error(res.poses, truth, align="se2").rmse
        assert moved == pytest.approx(odometry, rel=0.03)
        (s,) = problem.block_terms(res.poses, np.zeros((0, 2)))
        _, w = robust_rho_and_weight(cfg.kernel, s)
        assert w[true_closure].max() < 1e-3  # the true closures are rejected too
