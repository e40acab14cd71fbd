"""SEIF's batched steps give the numbers of the step-by-step filter up to rounding: the
motion steps between two scans composed into one information update, against one update per
control (kernels and the whole estimator)."""

from __future__ import annotations

import numpy as np

from slamkit.datasets import Dataset, load_dataset
from slamkit.models import Ackermann, UnicycleEuler
from slamkit.runtime import blas_threads
from slamkit.slam.seif import Seif, SeifConfig, seif_motion_update
from slamkit.slam.seif.kernels import PendingMotion, apply_motion, landmark_indices, motion_step
from slamkit.slam.seif.recovery import relax, relaxation_order

Q_U = np.diag([0.1**2, np.deg2rad(5.0) ** 2])


def linked_state(L: int, active: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A positive definite ``Ω`` whose pose is linked to the ``active`` landmarks only, and
    its ``ξ`` for a random mean."""
    rng = np.random.default_rng(seed)
    n = 3 + 2 * L
    mean = np.concatenate([[0.5, -0.3, 3.0], rng.uniform(-8.0, 8.0, 2 * L)])
    A = rng.normal(size=(n, n)) * 0.1
    omega = A @ A.T
    passive = np.setdiff1d(np.arange(L), active)
    pi = landmark_indices(passive)
    omega[:3, pi] = omega[pi, :3] = 0.0
    omega += np.eye(n) * (0.05 - min(0.0, np.linalg.eigvalsh(omega).min()))
    return omega, omega @ mean, mean


def test_composed_motion_steps_equal_one_update_per_step() -> None:
    """Eight motion steps (the heading crossing ±π, so the unwrapped mean is exercised)
    applied to ``Ω``, ``ξ`` at once give the ``Ω``, ``ξ`` and ``μ`` of eight
    :func:`seif_motion_update` calls, for the unicycle and the Ackermann model."""
    L, active = 6, np.array([1, 4, 5])
    for model, u in (
        (UnicycleEuler(), np.array([1.2, 0.9])),
        (Ackermann(2.83, (3.78, 0.5), 0.76), np.array([3.0, 0.3])),
    ):
        omega, xi, mu = linked_state(L, active, 3)
        Q = Q_U if model.control_dim == 2 else np.diag([0.2**2, np.deg2rad(3.0) ** 2])
        o1, x1, m1 = omega, xi, mu
        for k in range(8):
            o1, x1, m1 = seif_motion_update(o1, x1, m1, u * (1 + 0.1 * k), 0.1, model, Q, active)
        o2, x2, m2 = omega.copy(), xi.copy(), mu.copy()
        pending = PendingMotion(m2[:3])
        for k in range(8):
            pending.add(*motion_step(m2, u * (1 + 0.1 * k), 0.1, model, Q))
        assert pending.steps == 8
        idx = np.concatenate([np.arange(3), landmark_indices(active)])
        apply_motion(o2, x2, m2, idx, pending)
        assert pending.steps == 0 and np.array_equal(pending.start, m2[:3])
        assert m2[2] > np.pi  # crossed π: the heading stays unwrapped inside
        np.testing.assert_allclose(m2, m1, rtol=0, atol=1e-12)
        scale = np.abs(o1).max()
        np.testing.assert_allclose(o2, o1, rtol=0, atol=1e-11 * scale)
        np.testing.assert_allclose(x2, x1, rtol=0, atol=1e-11 * np.abs(x1).max())
        # untouched outside the block: the passive landmarks keep their information
        rest = np.setdiff1d(np.arange(o1.shape[0]), idx)
        np.testing.assert_array_equal(o2[np.ix_(rest, rest)], omega[np.ix_(rest, rest)])


class StepByStepSeif(Seif):
    """SEIF applying each motion step's information at once (one update per control)."""

    def on_control(self, u: np.ndarray, dt: float) -> None:
        super().on_control(u, dt)
        self.apply_motion()


def run_both(dataset: Dataset, config: SeifConfig) -> tuple[list[np.ndarray], Seif, Seif]:
    batched = Seif(dataset, config, np.random.default_rng(0))
    stepwise = StepByStepSeif(dataset, config, np.random.default_rng(0))
    gaps = []
    with blas_threads():  # as slamkit.pipeline.run: one BLAS thread for the small solves
        for ev in dataset.events:
            batched.handle(ev)
            stepwise.handle(ev)
            gaps.append(np.abs(batched.mean - stepwise.mean))
    return gaps, batched, stepwise


def test_the_batched_filter_is_the_step_by_step_filter() -> None:
    """On ``landmark-loop-closure`` (known ids; 100 landmarks, sparsified at every scan)
    and ``landmark-clutter`` without ids (association by maximum likelihood), the filter
    that applies the motion information once per scan keeps the running mean of the one
    that applies it per control to 1e-9 m at every event, makes the same associations and
    ends with the same map and marginal covariances."""
    cases = (
        (load_dataset("landmark-loop-closure", seed=0), SeifConfig()),
        (
            load_dataset("landmark-clutter", seed=1, options={"identities": False}),
            SeifConfig(use_ids=False, max_active=20),
        ),
    )
    for dataset, config in cases:
        gaps, batched, stepwise = run_both(dataset, config)
        assert max(float(g.max()) for g in gaps) < 1e-9
        out_b, out_s = batched.finish(), stepwise.finish()
        np.testing.assert_array_equal(out_b.reading_landmarks, out_s.reading_landmarks)
        assert out_b.landmarks is not None and out_s.landmarks is not None
        np.testing.assert_allclose(
            out_b.landmarks.landmarks.positions, out_s.landmarks.landmarks.positions, atol=1e-9
        )
        assert out_b.landmarks.covariances is not None
        assert out_s.landmarks.covariances is not None
        np.testing.assert_allclose(
            out_b.landmarks.covariances, out_s.landmarks.covariances, rtol=1e-8
        )
        # every nonzero landmark-landmark block of Ω is a recorded link (the relaxation and
        # the association's blankets read only those)
        omega, _ = batched.information
        L = batched.landmark_ids.size
        blocks = omega[3:, 3:].reshape(L, 2, L, 2)
        nonzero = np.any(blocks != 0.0, axis=(1, 3))
        np.fill_diagonal(nonzero, False)
        for row in range(L):
            assert set(np.flatnonzero(nonzero[row]).tolist()) <= batched.links(row)
        d_b, d_s = out_b.diagnostics, out_s.diagnostics
        assert d_b["sparsifications"] > 50 and d_b["predictions"] == d_s["predictions"]
        for key in ("updates", "new_landmarks", "rejected", "sparsifications", "max_block"):
            assert d_b[key] == d_s[key], key


def test_relaxation_with_cached_links_follows_new_links() -> None:
    """The relaxation keeps each landmark's link indices between calls; after a link is
    added (a new ``Ω`` entry) a relaxation with the kept cache gives exactly the mean of
    one with a fresh cache, and both differ from one that ignores the new link."""
    L, active = 6, [1, 4, 5]
    omega, xi, mu = linked_state(L, np.array(active), 5)
    # the landmark-landmark links of ``omega`` (dense: all pairs), minus 0-2, re-added below
    links = [set(range(L)) - {a} for a in range(L)]
    i0, i2 = landmark_indices([0]), landmark_indices([2])
    saved = omega[np.ix_(i0, i2)].copy()
    omega[np.ix_(i0, i2)] = omega[np.ix_(i2, i0)] = 0.0
    omega += np.eye(omega.shape[0]) * (0.05 - min(0.0, np.linalg.eigvalsh(omega).min()))
    links[0].discard(2)
    links[2].discard(0)
    blocks, _ = relaxation_order(active, 2, L, L, 0)
    cache: dict[int, tuple[int, np.ndarray]] = {}
    m_cached = mu.copy()
    relax(omega, xi, m_cached, blocks, active, links, list(range(L)), cache)
    assert set(cache) == set(range(L))
    omega[np.ix_(i0, i2)] = saved  # a new link 0-2
    omega[np.ix_(i2, i0)] = saved.T
    omega += np.eye(omega.shape[0]) * (0.05 - min(0.0, np.linalg.eigvalsh(omega).min()))
    stale = [set(s) for s in links]
    links[0].add(2)
    links[2].add(0)
    m_fresh, m_stale = m_cached.copy(), m_cached.copy()
    relax(omega, xi, m_cached, blocks, active, links, list(range(L)), cache)
    relax(omega, xi, m_fresh, blocks, active, links, list(range(L)), {})
    relax(omega, xi, m_stale, blocks, active, stale, list(range(L)), {})
    np.testing.assert_array_equal(m_cached, m_fresh)
    assert np.abs(m_fresh - m_stale).max() > 1e-6
