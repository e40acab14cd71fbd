"""The 2D graph optimiser on small in-memory graphs with known optima: noise-free graphs are
solved exactly, the three methods and the three linear back-ends agree, initialisations,
robust kernels and marginal covariances behave as derived."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from slamkit.errors import ConfigError, GeometryError
from slamkit.geometry import pose2
from slamkit.optim import (
    EdgeSet,
    GraphData,
    GraphProblem,
    GrowConfig,
    LmConfig,
    OptimizerConfig,
    RobustConfig,
    StoppingConfig,
    cholmod_available,
    chordal_initialization,
    g2o_chi2,
    marginal_covariances,
    optimize,
    sesync_objective,
    spanning_tree_initialization,
)
from slamkit.optim.factors import range_bearing_error
from slamkit.optim.sparse import make_factorizer

BACKENDS = ["dense", "superlu"] + (["cholmod"] if cholmod_available() else [])


def _edges(kind, i, j, z, info) -> EdgeSet:
    i = np.asarray(i, dtype=np.int64)
    return EdgeSet(
        kind,
        i,
        np.asarray(j, dtype=np.int64),
        np.asarray(z, dtype=float),
        np.asarray(info, dtype=float),
        np.zeros(i.shape[0], dtype=np.int64),
    )


def _loop_truth(n: int = 24) -> np.ndarray:
    """Poses on a circle of radius 5 m, heading along the tangent."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([5 * np.cos(a), 5 * np.sin(a), np.arctan2(np.cos(a), -np.sin(a))], -1)


def _pose_graph(
    truth: np.ndarray,
    rng: np.random.Generator | None = None,
    sigma: float = 0.0,
    closures: tuple[tuple[int, int], ...] = ((0, 12), (5, 20), (23, 0)),
    vertices: np.ndarray | None = None,
) -> GraphData:
    n = truth.shape[0]
    pairs = [(k, k + 1) for k in range(n - 1)] + list(closures)
    i = np.array([p[0] for p in pairs])
    j = np.array([p[1] for p in pairs])
    z = pose2.between(truth[i], truth[j])
    if rng is not None and sigma > 0:
        z = z + rng.normal(size=z.shape) * sigma * np.array([1.0, 1.0, 0.3])
    info = np.array([[[100.0, 10.0, 1.0], [10.0, 80.0, 2.0], [1.0, 2.0, 400.0]]] * len(pairs))
    poses = truth if vertices is None else vertices
    return GraphData(
        dim=2,
        pose_ids=np.arange(n, dtype=np.int64),
        poses=poses,
        edges=(_edges("se2", i, j, z, info),),
    )


def _landmark_graph(rng: np.random.Generator) -> tuple[GraphData, np.ndarray, np.ndarray]:
    """Eight poses, six landmarks, every landmark edge kind, noise-free."""
    truth = _loop_truth(8)
    lms = rng.uniform(-6, 6, size=(6, 2))
    edges = [
        _edges(
            "se2",
            np.arange(7),
            np.arange(1, 8),
            pose2.between(truth[:-1], truth[1:]),
            [np.eye(3) * 50] * 7,
        )
    ]
    obs_i = np.repeat(np.arange(8), 6)
    obs_j = np.tile(np.arange(6), 8)
    x, lm = truth[obs_i], lms[obs_j]
    rb, _, _ = range_bearing_error(x, lm, np.zeros((48, 2)))
    q = pose2.inverse_transform_points(x, lm)
    sets = {
        "se2_xy": (q, np.eye(2) * 20),
        "range_bearing": (rb, np.diag([10.0, 100.0])),
        "range": (rb[:, :1], np.eye(1) * 10),
        "bearing": (rb[:, 1:], np.eye(1) * 100),
    }
    for k, (kind, (z, info)) in enumerate(sets.items()):
        sel = obs_i % 4 == k  # each pose contributes one kind, every landmark seen 2x per kind
        edges.append(_edges(kind, obs_i[sel], obs_j[sel] + 100, z[sel], [info] * int(sel.sum())))
    data = GraphData(
        dim=2,
        pose_ids=np.arange(8, dtype=np.int64),
        poses=truth.copy(),
        landmark_ids=np.arange(100, 106, dtype=np.int64),
        landmarks=lms.copy(),
        edges=tuple(edges),
    )
    return data, truth, lms


def _assert_poses_close(a: np.ndarray, b: np.ndarray, atol: float) -> None:
    """Poses equal up to ``atol`` with headings compared modulo 2π."""
    d = np.asarray(a) - np.asarray(b)
    d[:, 2] = np.arctan2(np.sin(d[:, 2]), np.cos(d[:, 2]))
    np.testing.assert_allclose(d, 0.0, atol=atol)


def _perturb(poses: np.ndarray, rng: np.random.Generator, keep_first: bool = True) -> np.ndarray:
    out = poses + rng.normal(size=poses.shape) * [0.3, 0.3, 0.1]
    if keep_first:
        out[0] = poses[0]
    return out


@pytest.mark.parametrize("method", ["gn", "lm", "dogleg"])
def test_noise_free_loop_is_solved_exactly(method: str) -> None:
    rng = np.random.default_rng(0)
    truth = _loop_truth()
    data = _pose_graph(truth, vertices=_perturb(truth, rng))
    cfg = OptimizerConfig(solver=method, initialization="vertices")  # type: ignore[arg-type]
    res = optimize(data, cfg)
    assert res.converged and res.anchored_first
    assert res.initial_cost > 100.0
    assert res.cost < 1e-12
    _assert_poses_close(res.poses, truth, 1e-7)


def test_methods_and_backends_agree_on_noisy_graph() -> None:
    rng = np.random.default_rng(1)
    truth = _loop_truth()
    data = _pose_graph(truth, rng, sigma=0.1, vertices=_perturb(truth, rng))
    results = []
    for method in ("gn", "lm", "dogleg"):
        for backend in BACKENDS:
            cfg = OptimizerConfig(
                solver=method,
                linear_solver=backend,
                stopping=StoppingConfig(relative_tolerance=1e-12),
            )  # type: ignore[arg-type]
            results.append(optimize(data, cfg))
    ref = results[0]
    assert ref.cost > 0.5  # noisy: a genuine least-squares optimum, not zero
    for r in results[1:]:
        assert r.cost == pytest.approx(ref.cost, rel=1e-9)
        _assert_poses_close(r.poses, ref.poses, 1e-7)
    # The reported objective is g2o's χ², recomputed independently.
    assert g2o_chi2(data, ref.poses) == pytest.approx(ref.cost, rel=1e-12)


def test_dense_and_sparse_solves_agree_on_the_normal_equations() -> None:
    rng = np.random.default_rng(2)
    data, _, _ = _landmark_graph(rng)
    problem = GraphProblem.from_data(data)
    lin = problem.linearize(_perturb(data.poses, rng), data.landmarks + 0.2)
    assert lin.H is not None and lin.g is not None
    H = problem.pattern.full_matrix(lin.H).toarray()
    np.testing.assert_allclose(H, H.T)
    expected = np.linalg.solve(H, lin.g)
    for backend in BACKENDS:
        fac = make_factorizer(backend, problem.pattern)  # type: ignore[arg-type]
        fac.factor(lin.H)
        np.testing.assert_allclose(fac.solve(lin.g), expected, rtol=1e-9, atol=1e-12)


def test_normal_equations_match_dense_jacobian() -> None:
    """H and g from the scattered block products equal JᵀJ and Jᵀr of a dense numerical J."""
    rng = np.random.default_rng(3)
    data, _, _ = _landmark_graph(rng)
    problem = GraphProblem.from_data(data)
    p0, l0 = _perturb(data.poses, rng), data.landmarks + rng.normal(size=(6, 2)) * 0.3
    lin = problem.linearize(p0, l0)

    def residual(delta: np.ndarray) -> np.ndarray:
        p, lm = problem.retract(p0, l0, delta)
        rs = [problem.block_residuals(b, p, lm)[0].T.ravel() for b in problem.blocks]
        return np.concatenate(rs)

    r0 = residual(np.zeros(problem.n))
    J = np.empty((r0.shape[0], problem.n))
    for k in range(problem.n):
        d = np.zeros(problem.n)
        d[k] = 1e-6
        diff = residual(d) - residual(-d)
        J[:, k] = diff / 2e-6
    assert lin.H is not None and lin.g is not None
    np.testing.assert_allclose(
        problem.pattern.full_matrix(lin.H).toarray(), J.T @ J, rtol=1e-5, atol=1e-4
    )
    np.testing.assert_allclose(lin.g, J.T @ r0, rtol=1e-5, atol=1e-5)
    assert lin.cost == pytest.approx(float(r0 @ r0))


@pytest.mark.parametrize("method", ["gn", "lm", "dogleg"])
def test_landmark_graph_recovers_truth(method: str) -> None:
    rng = np.random.default_rng(4)
    data, truth, lms = _landmark_graph(rng)
    cfg = OptimizerConfig(solver=method)  # type: ignore[arg-type]
    res = optimize(
        data,
        cfg,
        initial_poses=_perturb(truth, rng),
        initial_landmarks=lms + rng.normal(size=lms.shape) * 0.3,
    )
    assert res.cost < 1e-12
    _assert_poses_close(res.poses, truth, 1e-6)
    np.testing.assert_allclose(res.landmarks, lms, atol=1e-6)


def test_landmarks_without_vertices_are_initialised_from_readings() -> None:
    rng = np.random.default_rng(5)
    data, truth, lms = _landmark_graph(rng)
    bare = GraphData(dim=2, pose_ids=data.pose_ids, poses=data.poses, edges=data.edges)
    res = optimize(bare)
    np.testing.assert_array_equal(res.landmark_ids, np.arange(100, 106))
    np.testing.assert_allclose(res.landmarks, lms, atol=1e-6)
    # Bearing-only landmarks are triangulated (two poses each suffice) ...
    only = tuple(e for e in data.edges if e.kind in ("se2", "bearing"))
    g = GraphData(dim=2, pose_ids=data.pose_ids, poses=data.poses, edges=only)
    np.testing.assert_allclose(optimize(g).landmarks, lms, atol=1e-6)
    # ... and range-only ones multilaterated (from all eight poses; two would be ambiguous).
    x = truth[np.repeat(np.arange(8), 6)]
    lm_of = np.tile(np.arange(6), 8)
    ranges = np.hypot(*(lms[lm_of] - x[:, :2]).T)[:, None]
    rng_set = _edges(
        "range", x[:, 0] * 0 + np.repeat(np.arange(8), 6), lm_of + 100, ranges, [np.eye(1)] * 48
    )
    g = GraphData(dim=2, pose_ids=data.pose_ids, poses=data.poses, edges=(data.edges[0], rng_set))
    np.testing.assert_allclose(optimize(g).landmarks, lms, atol=1e-6)
    with pytest.raises(GeometryError, match="landmark 100"):
        two = tuple(e for e in data.edges if e.kind in ("se2", "range"))
        optimize(GraphData(dim=2, pose_ids=data.pose_ids, poses=data.poses, edges=two))


def test_spanning_tree_and_chordal_initialisation_are_exact_without_noise() -> None:
    truth = _loop_truth()
    shifted = pose2.compose(pose2.inverse(truth[0]), truth)  # the first pose at the origin
    data = _pose_graph(truth)
    no_vertices = GraphData(
        dim=2, pose_ids=np.zeros(0, np.int64), poses=np.zeros((0, 3)), edges=data.edges
    )
    problem = GraphProblem.from_data(no_vertices)
    _assert_poses_close(spanning_tree_initialization(problem), shifted, 1e-9)
    _assert_poses_close(chordal_initialization(problem), shifted, 1e-9)
    res = optimize(no_vertices)
    assert res.cost < 1e-16
    _assert_poses_close(res.poses, shifted, 1e-9)


def test_chordal_initialisation_beats_odometry_on_a_noisy_loop() -> None:
    rng = np.random.default_rng(6)
    truth = _loop_truth(60)
    closures = tuple((k, (k + 30) % 60) for k in range(0, 60, 5))
    data = _pose_graph(truth, rng, sigma=0.08, closures=closures)
    problem = GraphProblem.from_data(data)
    odo = spanning_tree_initialization(problem)
    cho = chordal_initialization(problem)
    assert sesync_objective(data, cho) < 0.2 * sesync_objective(data, odo)


def test_sesync_objective_solver_minimises_F() -> None:
    rng = np.random.default_rng(7)
    truth = _loop_truth()
    data = _pose_graph(truth, rng, sigma=0.05)
    g2o = optimize(data, OptimizerConfig(stopping=StoppingConfig(relative_tolerance=1e-12)))
    fs = optimize(
        data, OptimizerConfig(objective="sesync", stopping=StoppingConfig(relative_tolerance=1e-12))
    )
    assert fs.cost == pytest.approx(sesync_objective(data, fs.poses), rel=1e-12)
    assert fs.cost < sesync_objective(data, g2o.poses)
    assert g2o.cost < g2o_chi2(data, fs.poses)


def test_prior_fixes_the_gauge_instead_of_anchoring() -> None:
    truth = _loop_truth()
    data = _pose_graph(truth, vertices=truth + 0.1)
    prior = _edges("se2_prior", [3], [-1], truth[3:4], [np.eye(3) * 1e4])
    with_prior = GraphData(
        dim=2, pose_ids=data.pose_ids, poses=data.poses, edges=(*data.edges, prior)
    )
    res = optimize(with_prior)
    assert not res.anchored_first
    _assert_poses_close(res.poses, truth, 1e-7)


def test_fixed_ids_are_held() -> None:
    truth = _loop_truth()
    start = truth + 0.05
    data = _pose_graph(truth, vertices=start)
    fixed = GraphData(
        dim=2, pose_ids=data.pose_ids, poses=start, edges=data.edges, fixed_ids=np.array([5])
    )
    res = optimize(fixed)
    np.testing.assert_array_equal(res.poses[5], start[5])
    assert not res.anchored_first


@pytest.mark.parametrize("kernel", ["huber", "cauchy", "geman_mcclure", "dcs"])
def test_robust_kernels_reject_a_false_loop_closure(kernel: str) -> None:
    rng = np.random.default_rng(8)
    truth = _loop_truth()
    good = _pose_graph(truth, rng, sigma=0.01)
    es = good.edges[0]
    bad_z = np.array([[4.0, -3.0, 2.0]])  # a wrong closure between poses 3 and 17
    edges = _edges(
        "se2",
        np.concatenate([es.i, [3]]),
        np.concatenate([es.j, [17]]),
        np.concatenate([es.measurement, bad_z]),
        np.concatenate([es.information, es.information[:1]]),
    )
    data = GraphData(dim=2, pose_ids=np.zeros(0, np.int64), poses=np.zeros((0, 3)), edges=(edges,))
    plain = optimize(data)  # both start from the odometry chain
    cfg = OptimizerConfig(robust=RobustConfig(kernel=kernel, width=1.0))  # type: ignore[arg-type]
    robust = optimize(data, cfg)
    truth = pose2.compose(pose2.inverse(truth[0]), truth)  # pose 0 anchored at the origin
    err_plain = np.abs(plain.poses[:, :2] - truth[:, :2]).max()
    err_robust = np.abs(robust.poses[:, :2] - truth[:, :2]).max()
    assert err_plain > 3.0
    # Huber bounds the outlier's pull; the redescending kernels ignore it (0.05 m is the
    # odometry noise accumulated around the loop).
    assert err_robust < (0.5 * err_plain if kernel == "huber" else 0.06)
    assert robust.cost < robust.chi2  # the outlier's ρ(s) < s


def test_marginals_equal_blocks_of_the_dense_inverse() -> None:
    rng = np.random.default_rng(9)
    data, _, _ = _landmark_graph(rng)
    res = optimize(data)
    marg = marginal_covariances(data, res, pose_ids=[0, 3, 7], landmark_ids=[102, 105])
    problem = GraphProblem.from_data(data)
    lin = problem.linearize(res.poses, res.landmarks)
    assert lin.H is not None
    cov = np.linalg.inv(problem.pattern.full_matrix(lin.H).toarray())
    np.testing.assert_array_equal(marg.pose_covariances[0], np.zeros((3, 3)))  # the anchor
    for k, pid in ((1, 3), (2, 7)):
        c = 3 * int(problem.pose_var[pid])
        np.testing.assert_allclose(marg.pose_covariances[k], cov[c : c + 3, c : c + 3], rtol=1e-9)
    for k, lid in ((0, 102), (1, 105)):
        c = 3 * problem.n_free_poses + 2 * (lid - 100)
        np.testing.assert_allclose(
            marg.landmark_covariances[k], cov[c : c + 2, c : c + 2], rtol=1e-9
        )
    assert np.all(np.linalg.eigvalsh(marg.pose_covariances[1:]) > 0)


def test_marginal_of_a_single_edge_is_its_covariance() -> None:
    info = np.array([[50.0, 5.0, 1.0], [5.0, 30.0, 2.0], [1.0, 2.0, 200.0]])
    z = np.array([[1.0, 0.5, 0.3]])
    data = GraphData(
        dim=2,
        pose_ids=np.array([0, 1]),
        poses=np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.3]]),
        edges=(_edges("se2", [0], [1], z, [info]),),
    )
    res = optimize(data)
    cov = marginal_covariances(data, res, pose_ids=[1]).pose_covariances[0]
    # e = Z⁻¹ X0⁻¹ X1 with X0 = I and e = 0 at the optimum: ∂e/∂δ1 = I, so Σ = Ω⁻¹.
    np.testing.assert_allclose(cov, np.linalg.inv(info), rtol=1e-10)


def test_callback_sees_every_iteration_and_can_stop() -> None:
    rng = np.random.default_rng(10)
    truth = _loop_truth()
    data = _pose_graph(truth, rng, sigma=0.05, vertices=_perturb(truth, rng))
    seen = []
    res = optimize(data, callback=lambda info: seen.append(info) and None)
    assert [i.iteration for i in seen] == list(range(1, res.iterations + 1))
    assert all(b.cost <= a.cost for a, b in itertools.pairwise(seen))
    stopped = optimize(data, callback=lambda info: True)
    assert stopped.iterations == 1 and not stopped.converged and "callback" in stopped.reason


def test_max_iterations_and_bad_config() -> None:
    rng = np.random.default_rng(11)
    truth = _loop_truth()
    data = _pose_graph(truth, rng, sigma=0.05, vertices=_perturb(truth, rng))
    res = optimize(data, OptimizerConfig(solver="gn", stopping=StoppingConfig(max_iterations=1)))
    assert res.iterations == 1 and not res.converged
    with pytest.raises(ConfigError):
        OptimizerConfig(solver="newton")  # type: ignore[arg-type]
    with pytest.raises(ConfigError):
        OptimizerConfig(lm=LmConfig(lambda_factor=1.0))
    with pytest.raises(ConfigError):
        OptimizerConfig(robust=RobustConfig(kernel="tukey"))  # type: ignore[arg-type]


def test_equivalent_poses_are_merged() -> None:
    """A loop whose last vertex is declared the same pose as the first (TORO ``EQUIV``)."""
    truth = _loop_truth(12)
    closed = np.concatenate([truth, truth[:1]])  # vertex 12 is pose 0 again
    i, j = np.arange(12), np.arange(1, 13)
    z = pose2.between(closed[i], closed[j])
    edges = (_edges("se2", i, j, z, [np.eye(3) * 10] * 12),)
    start = closed + np.random.default_rng(12).normal(size=closed.shape) * 0.05
    start[0] = closed[0]
    data = GraphData(
        dim=2,
        pose_ids=np.arange(13, dtype=np.int64),
        poses=start,
        edges=edges,
        equivalences=np.array([[0, 12]]),
    )
    res = optimize(data)
    assert res.cost < 1e-14
    np.testing.assert_array_equal(res.poses[12], res.poses[0])
    _assert_poses_close(res.poses, closed, 1e-7)


def _landmark_loop(rng: np.random.Generator) -> tuple[GraphData, np.ndarray, np.ndarray]:
    """Two laps (120 poses) of a 10 m circle among 16 trees, noisy odometry (heading noise
    0.03 rad per step, so the chained start drifts by ~0.3 rad per lap) and noisy tree
    positions in the robot frame (σ = 0.1 m) within 7 m; no vertices, as an iSAM file."""
    n = 120
    a = np.linspace(0, 4 * np.pi, n, endpoint=False)
    truth = np.stack([10 * np.cos(a), 10 * np.sin(a), np.arctan2(np.cos(a), -np.sin(a))], -1)
    b = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    r = np.where(np.arange(16) % 2 == 0, 7.0, 13.0)
    trees = np.stack([r * np.cos(b), r * np.sin(b)], -1)
    z = pose2.between(truth[:-1], truth[1:]) + rng.normal(size=(n - 1, 3)) * [0.02, 0.02, 0.03]
    odo = _edges(
        "se2", np.arange(n - 1), np.arange(1, n), z, [np.diag([2500, 2500, 1111.0])] * (n - 1)
    )
    i, j = np.nonzero(np.linalg.norm(truth[:, None, :2] - trees[None], axis=2) < 7.0)
    q = pose2.inverse_transform_points(truth[i], trees[j]) + rng.normal(size=(i.shape[0], 2)) * 0.1
    xy = _edges("se2_xy", i, j + 1000, q, [np.eye(2) * 100.0] * i.shape[0])
    data = GraphData(dim=2, pose_ids=np.zeros(0, np.int64), poses=np.zeros((0, 3)), edges=(odo, xy))
    return data, truth, trees


def test_grow_initialization_reaches_the_optimum_near_the_truth() -> None:
    """The grown start (prefixes of 10, 20, 40, 70, 100 poses) leads LM to the optimum that
    GN reaches from the true poses and trees; ``"auto"`` picks it for a landmark graph
    without vertices, and the grown start is far better than the odometry chain."""
    data, truth, trees = _landmark_loop(np.random.default_rng(8))
    problem = GraphProblem.from_data(data)
    assert np.array_equal(problem.landmark_ids, np.unique(data.edges[1].j))
    # Reference: GN from the truth (the first pose anchored at its true value).
    t0 = pose2.compose(pose2.inverse(truth[0]), truth)  # the truth in the anchored frame
    tr0 = pose2.inverse_transform_points(truth[0], trees[np.unique(data.edges[1].j) - 1000])
    ref = optimize(
        data,
        OptimizerConfig(solver="gn", stopping=StoppingConfig(relative_tolerance=1e-12)),
        initial_poses=t0,
        initial_landmarks=tr0,
    )
    cfg = OptimizerConfig(grow=GrowConfig(initial_poses=10, max_step=30))
    res = optimize(data, cfg)
    assert res.initialization == "grow" and res.converged
    assert res.cost == pytest.approx(ref.cost, rel=1e-7)
    _assert_poses_close(res.poses, ref.poses, 1e-4)
    odo = optimize(
        data, OptimizerConfig(initialization="odometry", stopping=StoppingConfig(max_iterations=0))
    )
    assert res.initial_cost < 0.1 * odo.initial_cost
    with pytest.raises(ConfigError, match=r"grow\.max_step"):
        OptimizerConfig(grow=GrowConfig(max_step=0))


@pytest.mark.parametrize("objective", ["g2o", "sesync"])
def test_result_reports_both_objectives(objective: str) -> None:
    """Whatever is minimised, the result carries g2o's χ² (every edge, landmarks included)
    and SE-Sync's F (relative-pose edges) of its solution, as the objective functions give."""
    rng = np.random.default_rng(11)
    data, _, _ = _landmark_graph(rng)
    noisy = tuple(
        EdgeSet(e.kind, e.i, e.j, e.measurement + rng.normal(size=e.measurement.shape) * 0.02,
                e.information, e.lines)
        for e in data.edges
    )  # fmt: skip
    data = GraphData(
        dim=2, pose_ids=data.pose_ids, poses=data.poses, landmark_ids=data.landmark_ids,
        landmarks=data.landmarks, edges=noisy,
    )  # fmt: skip
    res = optimize(data, OptimizerConfig(objective=objective))  # type: ignore[arg-type]
    assert res.g2o_chi2 == pytest.approx(g2o_chi2(data, res.poses, res.landmarks), rel=1e-12)
    assert res.sesync_objective == pytest.approx(sesync_objective(data, res.poses), rel=1e-12)
    assert res.g2o_chi2 > 0 and res.sesync_objective > 0
    minimised = res.g2o_chi2 if objective == "g2o" else res.sesync_objective
    if objective == "g2o":
        assert res.cost == pytest.approx(minimised, rel=1e-12)
    else:  # the landmark edges keep their g2o error in the SE-Sync objective
        assert res.cost > minimised


@pytest.mark.realdata
def test_dogleg_does_not_claim_convergence_on_a_step_cut_by_its_trust_region(data_root) -> None:
    """From a trust radius of 1e-7, the first steps are cut to the region: their tiny cost
    change once ended the run "converged" at χ² 551.7 after one iteration; now the region
    grows until the Gauss-Newton step fits and dogleg reaches LM's optimum (45.0)."""
    from slamkit.io.posegraph import read_graph
    from slamkit.optim import optimize
    from slamkit.optim.settings import DoglegConfig, OptimizerConfig

    path = data_root / "posegraph2d/intel.g2o"
    if not path.exists():
        pytest.skip(f"{path} not found")
    graph = read_graph(path)
    tiny = optimize(
        graph, OptimizerConfig(solver="dogleg", dogleg=DoglegConfig(trust_radius_initial=1e-7))
    )
    lm = optimize(graph, OptimizerConfig(solver="lm"))
    assert tiny.converged and tiny.iterations > 1
    assert tiny.chi2 == pytest.approx(lm.chi2, rel=1e-6)


def test_dogleg_first_step_is_the_gauss_newton_step() -> None:
    """The first trust region holds the GN step (Δ₀ = max(trust_radius_initial, ‖δ_gn‖)):
    after one iteration dogleg is where GN is, whatever the configured Δ₀."""
    from slamkit.optim.settings import DoglegConfig

    rng = np.random.default_rng(3)
    truth = _loop_truth()
    data = _pose_graph(truth, rng, sigma=0.05, vertices=_perturb(truth, rng))
    one = StoppingConfig(max_iterations=1)
    gn = optimize(data, OptimizerConfig(solver="gn", initialization="vertices", stopping=one))
    dl = optimize(
        data,
        OptimizerConfig(
            solver="dogleg",
            initialization="vertices",
            stopping=one,
            dogleg=DoglegConfig(trust_radius_initial=1e-3),
        ),
    )
    assert gn.initial_cost > 100.0 * gn.cost  # the GN step is a big one, far beyond 1e-3
    assert dl.cost == pytest.approx(gn.cost, rel=1e-12)
    _assert_poses_close(dl.poses, gn.poses, 1e-12)


@pytest.mark.realdata
@pytest.mark.parametrize(
    ("name", "chi2"),
    [("MIT.g2o", 770.66), ("vertigo/ringCity__originalDataset__ringCity.g2o", 262.82)],
)
def test_dogleg_reaches_the_gauss_newton_optimum_on_hard_graphs(data_root, name, chi2) -> None:
    """From Δ₀ = 1 dogleg's first steps followed the gradient into another basin and it
    stopped at χ² 1,940 on MIT and 2,717 on ringCity (GN/LM: 770.7 and 262.8)."""
    from slamkit.io.posegraph import read_graph

    path = data_root / "posegraph2d" / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    graph = read_graph(path)
    dl = optimize(graph, OptimizerConfig(solver="dogleg", initialization="vertices"))
    gn = optimize(graph, OptimizerConfig(solver="gn", initialization="vertices"))
    assert dl.converged and gn.converged
    assert dl.chi2 == pytest.approx(gn.chi2, rel=1e-5)
    assert dl.chi2 == pytest.approx(chi2, abs=0.01)
