"""The Riemannian staircase: from the winding local minimum the certificate refuses to the
certified optimum; rounding gives rotations; a start at the optimum stays at rank d; the
escape direction's second-order model against the objective; max_rank reached; 3D from random
rotations; the published F* of the shared graphs from random rotations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_optim_certificate import SESYNC, ring_graph, ring_graph_3d, winding_start

from slamkit.errors import ConfigError, InputError
from slamkit.io.posegraph import read_graph
from slamkit.optim import (
    GraphData,
    GraphProblem,
    OptimizerConfig,
    OptimizeResult,
    optimize,
    sesync_objective,
)
from slamkit.optim import factors3d as f3
from slamkit.optim.certificate import (
    SchurQ,
    certify,
    certify_blocks,
    multipliers,
    sesync_matrices,
)
from slamkit.optim.staircase import (
    LiftedProblem,
    StaircaseConfig,
    nearest_rotations,
    riemannian_staircase,
    round_lifted,
)


def _winding_minimum(
    rng: np.random.Generator,
) -> tuple[GraphData, OptimizeResult, OptimizeResult]:
    """The ring, LM's optimum from chordal and LM's local minimum from the winding start."""
    graph = ring_graph(rng)
    best = optimize(graph, SESYNC)
    bad = optimize(
        graph,
        OptimizerConfig(objective="sesync", initialization="vertices"),
        initial_poses=winding_start(graph),
    )
    return graph, best, bad


def test_staircase_climbs_from_the_winding_local_minimum_to_the_certified_optimum(
    rng: np.random.Generator,
) -> None:
    """The certificate's refused local minimum (F ≈ 1.3e5, the optimum ≈ 11): rank 2 and 3
    are saddles (λ_min(S) < 0), rank 4 certifies; rounding gives LM's optimum's F to 1e-9,
    certified, and the relaxation's F matches (the relaxation is tight)."""
    graph, best, bad = _winding_minimum(rng)
    assert not certify(graph, bad.poses).certified
    res = riemannian_staircase(graph, bad.poses)
    ranks = [s.rank for s in res.steps]
    assert ranks == [2, 3, 4]
    assert [s.certified for s in res.steps] == [False, False, True]
    assert res.steps[0].objective == pytest.approx(bad.cost, rel=1e-4)
    assert all(s.lambda_min < -0.1 * res.certificate.q_norm for s in res.steps[:2])
    assert res.ranks_climbed == 2
    assert res.certified
    assert res.objective == pytest.approx(best.cost, rel=1e-9)
    assert res.relaxation_objective == pytest.approx(best.cost, rel=1e-9)
    assert res.certificate.gap < 1e-4 * res.objective
    # The poses written: F of the file-format rows is F*, pose 0 kept where the start had it.
    assert sesync_objective(graph, res.poses) == pytest.approx(best.cost, rel=1e-9)
    np.testing.assert_allclose(res.poses[0, :2], bad.poses[0, :2], atol=1e-9)
    turn = np.angle(np.exp(1j * (res.poses[0, 2] - bad.poses[0, 2])))
    assert abs(turn) < 1e-9
    # The same rotations as LM's optimum up to the gauge (one common rotation).
    rel = np.angle(np.exp(1j * (res.poses[:, 2] - best.poses[:, 2])))
    assert np.ptp(np.unwrap(rel)) < 1e-6


def test_start_at_the_optimum_stays_at_rank_d(rng: np.random.Generator) -> None:
    graph = ring_graph(rng)
    best = optimize(graph, SESYNC)
    res = riemannian_staircase(graph, best.poses)
    assert [s.rank for s in res.steps] == [2] and res.ranks_climbed == 0
    assert res.certified and res.steps[0].certified
    assert res.objective == pytest.approx(best.cost, rel=1e-9)
    np.testing.assert_allclose(res.poses[:, :2], best.poses[:, :2], atol=1e-6)


def test_max_rank_reached_is_reported_not_certified(rng: np.random.Generator) -> None:
    """Stopped at rank 3 (below the 4 the winding minimum needs): not certified, the rounded
    poses are still rotations with a valid lower bound below F*."""
    graph, best, bad = _winding_minimum(rng)
    res = riemannian_staircase(graph, bad.poses, StaircaseConfig(max_rank=3))
    assert [s.rank for s in res.steps] == [2, 3]
    assert not res.steps[-1].certified
    assert res.certificate.lower_bound <= best.cost
    assert res.objective >= best.cost * (1 - 1e-9)


def _assert_rotations(r: np.ndarray) -> None:
    eye = np.broadcast_to(np.eye(r.shape[1]), r.shape)
    np.testing.assert_allclose(np.swapaxes(r, 1, 2) @ r, eye, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)


def test_rounding_gives_rotations_from_a_lifted_point(rng: np.random.Generator) -> None:
    """Rank-5 points ``Y_i = W R_i`` and ``Y_i = W diag(1, -1) R_i`` (W: 5x2 orthonormal, the
    second a reflection of every block) round to rotations equal to ``R_i`` up to one common
    rotation; ``nearest_rotations`` of random blocks (half reflections) gives SO(3); the 3D
    staircase's poses are rotations."""
    a = rng.uniform(-np.pi, np.pi, 30)
    c, s = np.cos(a), np.sin(a)
    rots = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    w = np.linalg.qr(rng.normal(size=(5, 2)))[0]
    for lifted in (w[None] @ rots, w[None] @ np.diag([1.0, -1.0])[None] @ rots):
        assert lifted.shape == (30, 5, 2)
        rounded = round_lifted(lifted)
        _assert_rotations(rounded)
        common = rounded @ np.swapaxes(rots, 1, 2)  # G = R̂_i R_iᵀ, the same for every i
        np.testing.assert_allclose(common, np.broadcast_to(common[0], common.shape), atol=1e-12)

    blocks = rng.normal(size=(50, 3, 3))
    near = nearest_rotations(blocks)
    _assert_rotations(near)
    np.testing.assert_allclose(nearest_rotations(near), near, atol=1e-12)

    graph = ring_graph_3d(rng)
    best = optimize(graph, SESYNC)
    res = riemannian_staircase(graph, best.poses)
    _assert_rotations(f3.poses_to_internal(res.poses)[:, 3:].reshape(-1, 3, 3))
    assert res.certified and res.ranks_climbed == 0
    assert res.objective == pytest.approx(best.cost, rel=1e-7)


def test_3d_from_random_rotations_reaches_the_certified_optimum(rng: np.random.Generator) -> None:
    graph = ring_graph_3d(rng)
    best = optimize(graph, SESYNC)
    start = np.c_[np.zeros((12, 3)), rng.normal(size=(12, 4))]
    start[:, 3:] /= np.linalg.norm(start[:, 3:], axis=1, keepdims=True)
    res = riemannian_staircase(graph, start)
    assert res.certified
    assert res.objective == pytest.approx(best.cost, rel=1e-7)
    assert sesync_objective(graph, res.poses) == pytest.approx(best.cost, rel=1e-7)


def test_lifted_gradient_and_hessian_against_finite_differences(rng: np.random.Generator) -> None:
    """At a random point of St(2, 4)^16 and random tangent vectors: the objective along the
    (second-order) polar retraction has slope ⟨grad F, η⟩ and curvature ⟨η, Hess F[η]⟩
    (central differences, step 1e-4); the Hessian is symmetric and maps into the tangent
    space; the gradient is tangent and equals ``2 Y S`` with the certificate's multipliers."""
    graph = ring_graph(rng)
    q = SchurQ(sesync_matrices(graph, graph.pose_ids), "auto")
    prob = LiftedProblem(q, q.norm())
    y = LiftedProblem.retract(np.zeros((16, 4, 2)), rng.normal(size=(16, 4, 2)))
    eye = np.broadcast_to(np.eye(2), (16, 2, 2))
    np.testing.assert_allclose(np.swapaxes(y, 1, 2) @ y, eye, atol=1e-12)
    grad, lam = prob.gradient(y)
    np.testing.assert_allclose(lam, multipliers(q, y), rtol=1e-12, atol=1e-9)
    f0 = prob.objective(y)
    scale = max(abs(f0), 1.0)
    etas = [prob.project(y, rng.normal(size=y.shape)) for _ in range(2)]
    for eta in etas:
        assert np.abs(np.swapaxes(y, 1, 2) @ eta + np.swapaxes(eta, 1, 2) @ y).max() < 1e-12
        h = 1e-4
        fp = prob.objective(prob.retract(y, h * eta))
        fm = prob.objective(prob.retract(y, -h * eta))
        slope, curvature = (fp - fm) / (2 * h), (fp - 2 * f0 + fm) / h**2
        h_eta = prob.hessian(y, lam, eta)
        assert slope == pytest.approx(float(np.sum(grad * eta)), rel=1e-6, abs=1e-8 * scale)
        assert curvature == pytest.approx(float(np.sum(eta * h_eta)), rel=1e-4)
        np.testing.assert_allclose(prob.project(y, h_eta), h_eta, atol=1e-9 * scale)
    a, b = etas
    ab = float(np.sum(a * prob.hessian(y, lam, b)))
    assert ab == pytest.approx(float(np.sum(b * prob.hessian(y, lam, a))), rel=1e-10)


def test_lifted_certificate_eigenvector_is_a_descent_direction(rng: np.random.Generator) -> None:
    """At the winding minimum the eigenvector of λ_min(S) satisfies S v = λ v (dense S) and
    F([Y; 0] + α[0; vᵀ], retracted) ≈ F + α² λ for small α (the second-order model)."""
    graph, _, bad = _winding_minimum(rng)
    mats = sesync_matrices(graph, graph.pose_ids)
    q = SchurQ(mats, "auto")
    c, s = np.cos(bad.poses[:, 2]), np.sin(bad.poses[:, 2])
    rots = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    lifted = certify_blocks(q, rots)
    lam, v = lifted.certificate.lambda_min, lifted.eigenvector
    qd = q(np.eye(32))
    stacked = rots.transpose(1, 0, 2).reshape(2, 32)
    gy = (qd @ stacked.T).reshape(16, 2, 2) @ rots
    sd = qd.copy()
    for i in range(16):
        sd[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] -= 0.5 * (gy[i] + gy[i].T)
    np.testing.assert_allclose(sd @ v, lam * v, atol=1e-7 * lifted.certificate.q_norm)
    y = np.concatenate([rots, np.zeros((16, 1, 2))], axis=1)
    f0 = float(np.trace(stacked @ qd @ stacked.T))
    for alpha in (1e-3, 1e-2):
        z = y.copy()
        z[:, 2, :] = alpha * v.reshape(16, 2)
        u, _, vt = np.linalg.svd(z, full_matrices=False)
        zz = (u @ vt).transpose(1, 0, 2).reshape(3, 32)
        f = float(np.trace(zz @ qd @ zz.T))
        assert f - f0 == pytest.approx(alpha**2 * lam, rel=1e-2)


def test_bad_settings_and_graphs_are_refused(rng: np.random.Generator) -> None:
    graph = ring_graph(rng)
    with pytest.raises(ConfigError, match="max_rank"):
        StaircaseConfig(max_rank=1)
    with pytest.raises(ConfigError, match="gradient_rtol"):
        StaircaseConfig(gradient_rtol=float("nan"))
    with pytest.raises(InputError, match="below the dimension"):
        riemannian_staircase(ring_graph_3d(rng), ring_graph_3d(rng).poses, StaircaseConfig(2))
    with pytest.raises(InputError, match="poses"):
        riemannian_staircase(graph, graph.poses[:-1])


# ------------------------------------------------------------------------------ real data

F_STAR_2D = [
    ("posegraph2d/intel.g2o", 5.235e1),
    ("posegraph2d/CSAIL.g2o", 3.170e1),
    ("posegraph2d/manhattan.g2o", 6.432e3),
]


@pytest.mark.realdata
@pytest.mark.parametrize(("name", "f_star"), F_STAR_2D)
def test_published_optima_from_random_rotations(data_root: Path, name: str, f_star: float) -> None:
    """From uniformly random headings (seeded) the staircase certifies the published F* to
    its four digits (measured: rank 2 suffices on all three, 0.2-0.7 s)."""
    path = data_root / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    graph = read_graph(path)
    n = GraphProblem.from_data(graph, objective="sesync").pose_ids.shape[0]
    start = np.c_[np.zeros((n, 2)), np.random.default_rng(0).uniform(-np.pi, np.pi, n)]
    res = riemannian_staircase(graph, start)
    assert res.certified
    assert res.objective == pytest.approx(f_star, rel=5e-4)
    assert res.certificate.gap < 2e-3 * res.objective
