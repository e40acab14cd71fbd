"""FastSLAM 2.0's association kernel (slamkit.slam.fastslam.marginal): the planar marginal
likelihoods against a matrix oracle, entry-wise evaluation (a gathered subset gives the same
bits), the range gate against the ungated maximum, and the gate's bound by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamkit.geometry.angles import wrap_angle
from slamkit.models import RangeBearing, RelativePosition
from slamkit.slam.fastslam import default_p0
from slamkit.slam.fastslam.marginal import (
    best_landmarks,
    gate_bound,
    marginal_log_likelihoods,
    pair_terms,
)

R = np.diag([0.6**2, 0.06**2])  # Victoria Park's tree readings with the preset's scale


def _scene(rng: np.random.Generator, c: int, n: int, spread: float = 30.0):
    """Poses (P,) planes, proposal covariances (P, 3, 3), landmarks (5, C, P)."""
    poses = np.column_stack(
        [rng.normal(0, 0.5, n), rng.normal(0, 0.5, n), rng.normal(0.3, 0.05, n)]
    )
    A = rng.normal(0, 0.05, (n, 3, 3))
    pose_cov = A @ np.swapaxes(A, -1, -2) + 1e-4 * np.eye(3)
    base = rng.uniform(-spread, spread, (c, 1, 2))
    mu = base + rng.normal(0, 0.3, (c, n, 2))  # the same tree, a little apart per particle
    B = rng.normal(0, 0.3, (c, n, 2, 2))
    cov = B @ np.swapaxes(B, -1, -2) + 0.01 * np.eye(2)
    g = np.stack([mu[..., 0], mu[..., 1], cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]])
    return poses, pose_cov, g, mu, cov


def _oracle(model, poses, pose_cov, mu, cov, z):
    """log N(z ⊟ h(x, m); 0, H_x P_x H_xᵀ + H_m Σ H_mᵀ + R) pair by pair, with the models'
    validated methods, matmul and slogdet/solve."""
    c, n = mu.shape[:2]
    out = np.empty((c, n))
    for j in range(c):
        for p in range(n):
            x, m = poses[p], mu[j, p]
            nu = z - model.predict(x, m)
            if model.angular[1]:
                nu[1] = wrap_angle(nu[1])
            Hx, Hm = model.jacobians(x, m)
            L = Hx @ pose_cov[p] @ Hx.T + Hm @ cov[j, p] @ Hm.T + R
            _, logdet = np.linalg.slogdet(L)
            out[j, p] = -0.5 * (nu @ np.linalg.solve(L, nu) + logdet) - math.log(2 * math.pi)
    return out


@pytest.mark.parametrize("model", [RangeBearing(), RelativePosition()])
def test_marginal_log_likelihoods_equal_the_matrix_oracle(model) -> None:
    rng = np.random.default_rng(3)
    poses, pose_cov, g, mu, cov = _scene(rng, 7, 5)
    z = model.predict(poses[0], mu[2, 0]) + np.array([0.2, 0.01])
    ll, ok = marginal_log_likelihoods(model, tuple(poses.T), pose_cov, g, z, R)
    assert ll.shape == (7, 5) and bool(np.all(ok))
    np.testing.assert_allclose(ll, _oracle(model, poses, pose_cov, mu, cov, z), rtol=1e-11)
    # The terms handed to the proposal's update, against the same matrices.
    nu, Hx, Q, L = pair_terms(model, tuple(poses.T), pose_cov, g, z, R).take((2, 4))
    Hx_ref, Hm_ref = model.jacobians(poses[4], mu[2, 4])
    Q_ref = Hm_ref @ cov[2, 4] @ Hm_ref.T + R
    np.testing.assert_allclose(Hx, Hx_ref, rtol=1e-12)
    np.testing.assert_allclose(Q, Q_ref, rtol=1e-12)
    np.testing.assert_allclose(L, Hx_ref @ pose_cov[4] @ Hx_ref.T + Q_ref, rtol=1e-12)
    np.testing.assert_allclose(nu, model.residual(z, model.predict(poses[4], mu[2, 4])), rtol=1e-12)


def test_a_gathered_subset_gives_the_same_bits() -> None:
    """Entry-wise: the gate evaluates gathered pairs, and their numbers are those of the
    full (C, P) evaluation exactly."""
    rng = np.random.default_rng(4)
    poses, pose_cov, g, _, _ = _scene(rng, 40, 30)
    model, z = RangeBearing(), np.array([12.0, 0.4])
    ll, _ = marginal_log_likelihoods(model, tuple(poses.T), pose_cov, g, z, R)
    c_in, p_in = np.nonzero(rng.random((40, 30)) < 0.1)
    pose = (poses[p_in, 0], poses[p_in, 1], poses[p_in, 2])
    ll_sub, _ = marginal_log_likelihoods(model, pose, pose_cov[p_in], g[:, c_in, p_in], z, R)
    assert c_in.size > 50
    assert np.array_equal(ll_sub, ll[c_in, p_in])


def test_a_landmark_at_the_sensor_is_flagged() -> None:
    poses = np.zeros((2, 3))
    g = np.array([[[0.0, 5.0]], [[0.0, 0.0]], [[1.0, 1.0]], [[0.0, 0.0]], [[1.0, 1.0]]])
    _, ok = marginal_log_likelihoods(
        RangeBearing(), tuple(poses.T), np.zeros((2, 3, 3)), g, np.array([5.0, 0.0]), R
    )
    assert ok.tolist() == [[False, True]]


def test_gate_bound_by_hand() -> None:
    """With the default p0 (the density of N(0, R) at χ²₂(0.999) = −2 ln 0.001) the bound on
    νᵀ L⁻¹ ν is that χ² value itself, plus the slack."""
    log_p0 = math.log(default_p0(R))
    d = -2.0 * math.log(0.001)  # 13.8155
    assert gate_bound(log_p0, R) == pytest.approx(d * (1 + 1e-6) + 1.0, rel=1e-12)
    assert gate_bound(log_p0 + 100.0, R) == 1.0  # no landmark can reach such a p0


@pytest.mark.parametrize("seed", range(6))
def test_best_landmarks_equal_the_ungated_maximum(seed: int) -> None:
    """Readings of mapped trees (and some clutter), p0 from strict to lax: wherever the best
    log-likelihood reaches log p0 the gated search returns the same slot and the same value,
    bit for bit, and where it does not, the gated one does not either."""
    rng = np.random.default_rng(seed)
    c, n = 60, 40
    poses, pose_cov, g, mu, _ = _scene(rng, c, n)
    model = RangeBearing()
    cand = rng.random((c, n)) < 0.9
    matched = 0
    for trial in range(12):
        if trial % 4 == 3:  # clutter
            z = np.array([rng.uniform(2, 40), rng.uniform(-np.pi, np.pi)])
        else:
            z = model.predict(poses[0], mu[rng.integers(c), 0]) + rng.normal(0, [0.6, 0.06])
        for scale in (0.1, 1.0, 1e3):
            log_p0 = math.log(scale * default_p0(R))
            ll, ok = marginal_log_likelihoods(model, tuple(poses.T), pose_cov, g, z, R)
            ll[~(cand & ok)] = -np.inf
            best_ref = np.argmax(ll, axis=0)
            lb_ref = ll[best_ref, np.arange(n)]
            found = best_landmarks(model, tuple(poses.T), pose_cov, g, cand, z, R, log_p0)
            best, lb = found.slot, found.ll
            hit = lb_ref >= log_p0
            assert np.array_equal(lb >= log_p0, hit)
            assert np.array_equal(best[hit], best_ref[hit])
            assert np.array_equal(lb[hit], lb_ref[hit])
            matched += int(hit.sum())
            if hit.any():  # the terms of the chosen pairs: those of the full evaluation
                rows = np.flatnonzero(hit)
                full = pair_terms(model, tuple(poses.T), pose_cov, g, z, R)
                for a, b in zip(found.take(rows), full.take((best[rows], rows)), strict=True):
                    assert np.array_equal(a, b)
    assert matched > 100  # the readings did find their trees


def test_best_landmarks_without_a_gate_for_other_models() -> None:
    rng = np.random.default_rng(7)
    poses, pose_cov, g, mu, _ = _scene(rng, 20, 10)
    model = RelativePosition()
    z = model.predict(poses[0], mu[5, 0])
    cand = np.ones((20, 10), dtype=bool)
    cand[5, 3] = False
    ll, _ = marginal_log_likelihoods(model, tuple(poses.T), pose_cov, g, z, R)
    ll[~cand] = -np.inf
    found = best_landmarks(model, tuple(poses.T), pose_cov, g, cand, z, R, -50.0)
    assert np.array_equal(found.slot, np.argmax(ll, axis=0))
    assert np.array_equal(found.ll, ll.max(axis=0))
    assert found.slot[3] != 5


def test_best_landmarks_break_ties_by_the_first_slot() -> None:
    """Two slots holding the same landmark (as after a duplicate start): the first one is
    chosen, as argmax chooses it."""
    rng = np.random.default_rng(8)
    poses, pose_cov, g, mu, _ = _scene(rng, 12, 6)
    g[:, 9] = g[:, 4]  # slot 9 a copy of slot 4 in every particle
    model = RangeBearing()
    z = model.predict(poses[0], mu[4, 0])
    cand = np.ones((12, 6), dtype=bool)
    found = best_landmarks(model, tuple(poses.T), pose_cov, g, cand, z, R, -50.0)
    assert found.slot.tolist() == [4] * 6
    cand[4, 2] = False
    found = best_landmarks(model, tuple(poses.T), pose_cov, g, cand, z, R, -50.0)
    assert found.slot.tolist() == [4, 4, 9, 4, 4, 4]


def test_best_landmarks_without_candidates_find_nothing() -> None:
    g = np.zeros((5, 3, 4))
    g[0], g[2], g[4] = 10.0, 1.0, 1.0
    pose = (np.zeros(4), np.zeros(4), np.zeros(4))
    found = best_landmarks(
        RangeBearing(), pose, np.zeros((4, 3, 3)), g, np.zeros((3, 4), dtype=bool),
        np.array([10.0, 0.0]), R, -5.0,
    )  # fmt: skip
    assert found.ll.tolist() == [-np.inf] * 4
