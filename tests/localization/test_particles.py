"""Particle sets: log-weight normalisation, ESS, low-variance resampling, estimates, sampling."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slamkit.errors import ConvergenceError, InputError
from slamkit.estimation.particles import (
    ParticleSet,
    effective_sample_size,
    low_variance_resample,
    normalize_log_weights,
    particle_estimate,
    uniform_particles_in_box,
    uniform_particles_in_free_space,
)
from slamkit.maps import OccupancyGrid

# -- log-weights ----------------------------------------------------------------------------


def test_normalize_log_weights_is_stable_far_below_float_range() -> None:
    # exp(-1e4) is 0.0 in float64; in log space the weights are exactly 1/2, 1/4, 1/4.
    logw = np.array([-1e4, -1e4 - np.log(2.0), -1e4 - np.log(2.0)])
    normed, total = normalize_log_weights(logw)
    np.testing.assert_allclose(np.exp(normed), [0.5, 0.25, 0.25], rtol=1e-12)
    assert total == pytest.approx(-1e4 + np.log(2.0), abs=1e-9)


def test_normalize_log_weights_keeps_zero_weights_zero() -> None:
    normed, total = normalize_log_weights([0.0, -np.inf, 0.0])
    assert normed[1] == -np.inf
    np.testing.assert_allclose(np.exp(normed), [0.5, 0.0, 0.5])
    assert total == pytest.approx(np.log(2.0))


def test_all_weights_zero_is_reported_not_reset() -> None:
    with pytest.raises(ConvergenceError, match="all 3 particle weights are zero"):
        normalize_log_weights([-np.inf, -np.inf, -np.inf])
    with pytest.raises(ConvergenceError, match="NaN"):
        normalize_log_weights([0.0, np.nan])
    with pytest.raises(ConvergenceError):
        ParticleSet.from_log_weights(np.zeros((2, 3)), [-np.inf, -np.inf])


def test_particle_set_copies_and_normalises() -> None:
    poses = np.array([[0.0, 0.0, 3.5], [1.0, 2.0, 0.1]])
    ps = ParticleSet.uniform_weights(poses)
    poses[0, 0] = 99.0
    assert ps.poses[0, 0] == 0.0  # a copy, not a view of the caller's array
    assert ps.poses[0, 2] == pytest.approx(3.5 - 2 * np.pi)  # wrapped
    np.testing.assert_allclose(ps.weights, [0.5, 0.5])
    ps2 = ParticleSet.from_log_weights(ps.poses, [np.log(3.0), 0.0])
    np.testing.assert_allclose(ps2.weights, [0.75, 0.25])
    assert not np.shares_memory(ps2.poses, ps.poses)
    with pytest.raises(InputError):
        ParticleSet(np.zeros((2, 3)), np.array([0.0, np.nan]))


# -- effective sample size -------------------------------------------------------------------


def test_effective_sample_size_hand_values() -> None:
    assert effective_sample_size(np.full(8, 1 / 8)) == pytest.approx(8.0)
    assert effective_sample_size([1.0, 0.0, 0.0, 0.0]) == pytest.approx(1.0)
    # 1 / (0.5² + 0.25² + 0.25²) = 1 / 0.375
    assert effective_sample_size([0.5, 0.25, 0.25]) == pytest.approx(8.0 / 3.0)
    # unnormalised weights are normalised first
    assert effective_sample_size([2.0, 1.0, 1.0]) == pytest.approx(8.0 / 3.0)
    with pytest.raises(InputError):
        effective_sample_size([0.0, 0.0])


# -- low-variance resampling -----------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    w=st.lists(st.floats(0.0, 10.0), min_size=1, max_size=40).filter(lambda v: sum(v) > 1e-3),
    n=st.integers(1, 200),
    seed=st.integers(0, 2**32 - 1),
)
def test_low_variance_counts_are_floor_or_ceil_of_expected(
    w: list[float], n: int, seed: int
) -> None:
    weights = np.asarray(w) / np.sum(w)
    idx = low_variance_resample(weights, np.random.default_rng(seed), n)
    assert idx.shape == (n,)
    counts = np.bincount(idx, minlength=weights.size)
    expected = n * weights
    # A tiny slack for round-off in the cumulative sum at exact integers.
    assert np.all(counts >= np.floor(expected - 1e-9))
    assert np.all(counts <= np.ceil(expected + 1e-9))
    assert np.all(counts[weights == 0] == 0)


def _counts(weights: np.ndarray, n: int, repeats: int, rng: np.random.Generator) -> np.ndarray:
    draws = [low_variance_resample(weights, rng, n) for _ in range(repeats)]
    return np.array([np.bincount(d, minlength=weights.size) for d in draws])


def test_low_variance_hand_example_and_mean_counts() -> None:
    rng = np.random.default_rng(7)
    counts = _counts(np.array([0.5, 0.3, 0.2]), 10, 2000, rng)
    assert np.all(counts == [5, 3, 2])  # n w_i are integers: exact every time
    counts = _counts(np.array([0.55, 0.3, 0.15]), 10, 4000, rng)  # n w = 5.5, 3, 1.5
    assert set(np.unique(counts[:, 0])) <= {5, 6}
    assert set(np.unique(counts[:, 2])) <= {1, 2}
    # unbiased: the mean count is n w_i (measured 5.510, 3.000, 1.490)
    np.testing.assert_allclose(counts.mean(axis=0), [5.5, 3.0, 1.5], atol=0.03)


def test_resampling_copies_particles() -> None:
    ps = ParticleSet.from_log_weights(np.arange(9.0).reshape(3, 3), [0.0, -np.inf, -np.inf])
    new = ps.select(low_variance_resample(ps.weights, np.random.default_rng(0)))
    np.testing.assert_array_equal(new.poses[:, 0], [0.0, 0.0, 0.0])
    new.poses[0, 0] = 5.0  # writing into one copy touches neither its siblings nor the source
    assert new.poses[1, 0] == 0.0 and ps.poses[0, 0] == 0.0


def test_low_variance_is_reproducible_with_the_same_seed() -> None:
    w = np.random.default_rng(3).random(50)
    a = low_variance_resample(w, np.random.default_rng(11))
    b = low_variance_resample(w, np.random.default_rng(11))
    np.testing.assert_array_equal(a, b)


# -- estimate ------------------------------------------------------------------------------


def test_particle_estimate_heading_near_pi() -> None:
    poses = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 0.0, -np.pi + 0.1]])
    mean, cov = particle_estimate(poses, [0.5, 0.5])
    # The circular mean of ±(π - 0.1) is π (wrapped to -π), not 0.
    assert abs(abs(mean[2]) - np.pi) < 1e-12
    np.testing.assert_allclose(mean[:2], [1.0, 0.0])
    # deviations are ±0.1 rad (wrapped), not ±(π - 0.1)
    assert cov[2, 2] == pytest.approx(0.01, rel=1e-9)
    assert cov[0, 0] == pytest.approx(1.0)
    # x = 0 has heading π - 0.1 (0.1 below the mean), x = 2 has 0.1 above: +0.1
    assert cov[0, 2] == pytest.approx(0.1)
    np.testing.assert_allclose(cov, cov.T)


def test_particle_estimate_weighted_hand_values() -> None:
    poses = np.array([[1.0, 0.0, 0.2], [3.0, 2.0, 0.0]])
    mean, cov = particle_estimate(poses, [3.0, 1.0])  # unnormalised: 0.75, 0.25
    np.testing.assert_allclose(mean[:2], [1.5, 0.5])
    expected_theta = np.arctan2(0.75 * np.sin(0.2), 0.75 * np.cos(0.2) + 0.25)
    assert mean[2] == pytest.approx(expected_theta, abs=1e-12)
    # var x = 0.75·0.5² + 0.25·1.5² = 0.75
    assert cov[0, 0] == pytest.approx(0.75)
    assert cov[0, 1] == pytest.approx(0.75)
    eig = np.linalg.eigvalsh(cov)
    assert eig.min() > -1e-12


# -- uniform sampling ------------------------------------------------------------------------


def test_uniform_particles_in_box() -> None:
    rng = np.random.default_rng(1)
    p = uniform_particles_in_box((-1.0, 2.0, 3.0, 4.0), 20_000, rng)
    assert p.shape == (20_000, 3)
    assert p[:, 0].min() >= -1.0 and p[:, 0].max() < 3.0
    assert p[:, 1].min() >= 2.0 and p[:, 1].max() < 4.0
    assert p[:, 2].min() >= -np.pi and p[:, 2].max() < np.pi
    np.testing.assert_allclose(p.mean(axis=0), [1.0, 3.0, 0.0], atol=0.05)
    with pytest.raises(InputError):
        uniform_particles_in_box((0.0, 0.0, 0.0, 1.0), 3, rng)


def test_uniform_particles_in_free_space_only_in_free_cells() -> None:
    prob = np.ones((4, 6))
    prob[1, 1:3] = 0.0  # two free cells: (1, 1) and (1, 2)
    prob[3, 5] = 0.5  # unknown: never sampled
    grid = OccupancyGrid(prob, 0.5, np.array([10.0, -2.0]))
    rng = np.random.default_rng(2)
    p = uniform_particles_in_free_space(grid, 10_000, rng)
    cells = grid.world_to_cell(p[:, :2])
    assert np.all(cells[:, 0] == 1)
    assert set(np.unique(cells[:, 1])) == {1, 2}
    # uniform over the two cells and within them: x spans [10.5, 11.5)
    assert p[:, 0].min() >= 10.5 and p[:, 0].max() < 11.5
    assert abs(np.mean(cells[:, 1] == 1) - 0.5) < 0.02
    np.testing.assert_allclose(p[:, 1].mean(), -1.25, atol=0.01)  # cell centre y
    with pytest.raises(InputError, match="no free cells"):
        uniform_particles_in_free_space(OccupancyGrid(np.ones((2, 2)), 1.0), 5, rng)


def test_unchecked_estimate_equals_the_validated_one() -> None:
    from slamkit.estimation.particles import particle_estimate_unchecked

    rng = np.random.default_rng(7)
    poses = np.column_stack([rng.normal(size=(400, 2)), rng.uniform(-np.pi, np.pi, 400)])
    w = rng.random(400)
    mean, cov = particle_estimate(poses, w)
    fast_mean, fast_cov = particle_estimate_unchecked(poses, w / w.sum())
    np.testing.assert_allclose(fast_mean, mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast_cov, cov, rtol=0, atol=1e-12)
