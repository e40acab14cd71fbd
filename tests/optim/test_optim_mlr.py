"""Multilevel relaxation and block Gauss-Seidel (``solver="mlr"`` / ``"gauss_seidel"``): the
same optimum as Gauss-Newton on a synthetic graph, the V-cycle against plain sweeps on the
same linear system, and the published optimum of intel.g2o and M3500."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse.linalg

from slamkit.config import config_from_mapping
from slamkit.errors import ConfigError
from slamkit.geometry import pose2
from slamkit.io.posegraph import read_graph
from slamkit.optim import (
    EdgeSet,
    GraphData,
    GraphProblem,
    OptimizerConfig,
    RelaxationConfig,
    StoppingConfig,
    initial_values,
    optimize,
)
from slamkit.optim.mlr import (
    BlockGaussSeidel,
    build_hierarchy,
    free_pose_frames,
    gauss_seidel_solve,
    multilevel_solve,
)

LAP = 80  # poses per lap


def _laps(n_laps: int = 3) -> np.ndarray:
    """Poses walking the perimeter (60 m) of a 20 m x 10 m rectangle ``n_laps`` times, 0.75 m
    a step, heading along each side."""
    u = (np.arange(LAP * n_laps) % LAP) / LAP * 60.0
    x = np.select([u < 20, u < 30, u < 50], [u, np.full_like(u, 20.0), 50 - u], 0.0)
    y = np.select([u < 20, u < 30, u < 50], [0 * u, u - 20, np.full_like(u, 10.0)], 60 - u)
    th = np.select([u < 20, u < 30, u < 50], [0.0, np.pi / 2, np.pi], -np.pi / 2)
    return np.column_stack([x, y, th])


def _lap_graph(rng: np.random.Generator, sigma: float) -> tuple[GraphData, np.ndarray]:
    """240 poses: odometry and a closure from every pose of laps 2-3 to the same place one lap
    before; measurements with noise ``sigma`` (m; rad x 0.2); no vertices (odometry start)."""
    truth = _laps()
    n = truth.shape[0]
    i = np.r_[np.arange(n - 1), np.arange(LAP, n)]
    j = np.r_[np.arange(1, n), np.arange(LAP, n) - LAP]
    z = pose2.between(truth[i], truth[j]) + rng.normal(size=(i.shape[0], 3)) * sigma * np.array(
        [1.0, 1.0, 0.2]
    )
    info = np.tile(np.diag([100.0, 100.0, 2500.0]), (i.shape[0], 1, 1))
    edges = EdgeSet("se2", i, j, z, info, np.zeros(i.shape[0], dtype=np.int64))
    data = GraphData(
        dim=2, pose_ids=np.arange(n, dtype=np.int64), poses=np.zeros((0, 3)), edges=(edges,)
    )
    return data, truth


def test_noise_free_graph_is_solved_exactly_from_odometry() -> None:
    data, truth = _lap_graph(np.random.default_rng(1), 0.0)
    res = optimize(data, OptimizerConfig(solver="mlr", initialization="odometry"))
    assert res.converged and res.method == "mlr" and res.linear_solver == "multigrid"
    assert res.chi2 < 1e-20 and res.factorizations == 0 and res.linear_iterations > 0
    # the first pose is the anchor and sits at the truth's origin: the rest must follow
    err = pose2.between(truth, res.poses)
    assert np.abs(err[:, :2]).max() < 1e-9 and np.abs(err[:, 2]).max() < 1e-10


def test_mlr_reaches_the_gauss_newton_chi2() -> None:
    """Noisy graph, odometry start (χ² 9,674): GN's minimum is χ² 108.1525 (4 iterations);
    MLR reaches it to 1e-9 relative in as many linearisations (12 V-cycles in all)."""
    data, _ = _lap_graph(np.random.default_rng(7), 0.05)
    gn = optimize(data, OptimizerConfig(solver="gn", initialization="odometry"))
    mlr = optimize(data, OptimizerConfig(solver="mlr", initialization="odometry"))
    assert gn.converged and mlr.converged
    assert gn.chi2 == pytest.approx(108.1525, rel=1e-6)
    assert mlr.chi2 == pytest.approx(gn.chi2, rel=1e-9)
    assert mlr.iterations <= gn.iterations + 1
    assert np.abs(pose2.between(gn.poses, mlr.poses)).max() < 1e-5


def test_gauss_seidel_lowers_the_cost_but_stops_short() -> None:
    """The baseline: at most 200 sweeps per linearisation leave the smooth error, so after 10
    linearisations (1,817 sweeps) χ² is still 111.07 against GN's 108.15, and the loop does
    not call that converged (the solves missed their tolerance)."""
    data, _ = _lap_graph(np.random.default_rng(7), 0.05)
    cfg = OptimizerConfig(
        solver="gauss_seidel",
        initialization="odometry",
        stopping=StoppingConfig(max_iterations=10),
    )
    res = optimize(data, cfg)
    assert not res.converged and res.iterations == 10
    assert 1000 < res.linear_iterations <= 10 * cfg.relaxation.max_sweeps
    assert res.chi2 == pytest.approx(111.07, abs=0.01)
    costs = [h.cost for h in res.history]
    assert all(b <= a for a, b in itertools.pairwise(costs))


def _linear_system(data: GraphData) -> tuple[scipy.sparse.csr_matrix, np.ndarray, np.ndarray]:
    problem = GraphProblem.from_data(data)
    poses, landmarks = initial_values(problem, "odometry", "auto")
    lin = problem.linearize(poses, landmarks, OptimizerConfig().kernel)
    assert lin.H is not None and lin.g is not None
    A = problem.pattern.full_matrix(lin.H).tocsr()
    return A, -lin.g, free_pose_frames(problem, poses)


def test_one_v_cycle_beats_as_many_gauss_seidel_sweeps() -> None:
    """At the odometry start: one plain V-cycle with two sweeps before and after (four on the
    fine level, 717 → 180 → 45 unknowns) leaves a relative residual of 0.0086 and an
    energy-norm error of 0.018; four Gauss-Seidel sweeps leave 0.052 and 0.126, twelve still
    0.012. Three cycles: 0.0016 plain, 0.00084 as CG's preconditioner."""
    A, b, frames = _linear_system(_lap_graph(np.random.default_rng(7), 0.05)[0])
    hierarchy = build_hierarchy(A, frames, sweeps=2)
    assert hierarchy.sizes == (717, 180, 45)
    v = multilevel_solve(hierarchy, b, tolerance=0.0, max_cycles=1, krylov=False)
    smoother = BlockGaussSeidel.of(A)
    gs = gauss_seidel_solve(smoother, b, tolerance=0.0, max_sweeps=12)
    assert v.iterations == 1 and gs.iterations == 12
    assert v.relative_residual < gs.residuals[4] / 5
    assert v.relative_residual < gs.residuals[12] / 1.4
    exact = scipy.sparse.linalg.spsolve(A.tocsc(), b)

    def energy(x: np.ndarray) -> float:
        e = exact - x
        return float(np.sqrt(e @ (A @ e) / (exact @ (A @ exact))))

    gs4 = gauss_seidel_solve(smoother, b, tolerance=0.0, max_sweeps=4)
    assert energy(v.x) < energy(gs4.x) / 5
    plain = multilevel_solve(hierarchy, b, 0.0, 3, krylov=False)
    krylov = multilevel_solve(hierarchy, b, 0.0, 3)
    assert plain.relative_residual < v.relative_residual / 4
    assert krylov.relative_residual < plain.relative_residual / 1.5


def test_a_sweep_solves_its_own_block_equations() -> None:
    """After a forward sweep the last pose's block equation holds exactly (nothing after it
    changes); after a backward sweep the first's."""
    A, b, _ = _linear_system(_lap_graph(np.random.default_rng(7), 0.05)[0])
    sm = BlockGaussSeidel.of(A)
    x = sm.forward(np.zeros_like(b), b)
    assert np.abs((b - A @ x)[-3:]).max() < 1e-9 * np.abs(b).max()
    x = sm.backward(x, b)
    assert np.abs((b - A @ x)[:3]).max() < 1e-9 * np.abs(b).max()


def test_landmark_and_3d_graphs_are_refused() -> None:
    truth = _laps(1)[:6]
    edges = EdgeSet(
        "se2_xy",
        np.arange(6, dtype=np.int64),
        np.full(6, 100, dtype=np.int64),
        pose2.inverse_transform_points(truth, np.array([[1.0, 2.0]] * 6)),
        np.tile(np.eye(2), (6, 1, 1)),
        np.zeros(6, dtype=np.int64),
    )
    odo = EdgeSet(
        "se2",
        np.arange(5, dtype=np.int64),
        np.arange(1, 6, dtype=np.int64),
        pose2.between(truth[:-1], truth[1:]),
        np.tile(np.eye(3), (5, 1, 1)),
        np.zeros(5, dtype=np.int64),
    )
    data = GraphData(
        dim=2,
        pose_ids=np.arange(6, dtype=np.int64),
        poses=truth,
        landmark_ids=np.array([100], dtype=np.int64),
        landmarks=np.array([[1.0, 2.0]]),
        edges=(odo, edges),
    )
    with pytest.raises(ConfigError, match="solver 'mlr': needs a 2D pose graph, got a graph"):
        optimize(data, OptimizerConfig(solver="mlr"))


def test_relaxation_settings_are_validated() -> None:
    with pytest.raises(ConfigError, match=r"relaxation\.max_cycles"):
        config_from_mapping(OptimizerConfig, {"relaxation": {"max_cycles": 0}})
    assert RelaxationConfig().linear_tolerance == 1e-2


def _read(data_root: Path, name: str) -> GraphData:
    path = data_root / "posegraph2d" / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    return read_graph(path)


@pytest.mark.realdata
def test_intel_reaches_the_published_optimum(data_root: Path) -> None:
    """SE-Sync's certified F* = 5.235e1 of intel.g2o (Rosen et al., IJRR 2019): MLR from the
    auto (chordal) start ends at 52.3483 in 8 linearisations (37 V-cycles), GN's value to
    1e-7 (both stop at a relative cost change below 1e-6)."""
    graph = _read(data_root, "intel.g2o")
    res = optimize(graph, OptimizerConfig(solver="mlr", objective="sesync"))
    assert res.converged
    assert abs(res.sesync_objective / 5.235e1 - 1) < 0.01
    assert float(f"{res.sesync_objective:.4g}") == 5.235e1
    gn = optimize(graph, OptimizerConfig(solver="gn", objective="sesync"))
    assert res.sesync_objective == pytest.approx(gn.sesync_objective, rel=1e-6)


@pytest.mark.realdata
def test_m3500_from_odometry_reaches_the_published_optimum(data_root: Path) -> None:
    """manhattan.g2o (M3500) from the odometry chain (F 5.2e6 → 6431.40 in 19 linearisations,
    as GN; 100 V-cycles): within 1 % of the published F* = 6.432e3 (our minimum is 6431.39,
    just below)."""
    graph = _read(data_root, "manhattan.g2o")
    cfg = OptimizerConfig(solver="mlr", objective="sesync", initialization="odometry")
    res = optimize(graph, cfg)
    assert res.converged
    assert abs(res.sesync_objective / 6.432e3 - 1) < 0.01
    assert res.sesync_objective == pytest.approx(6431.39, rel=1e-5)
