"""The calibration's two fits on synthetic pairs (no scan matching): the least squares finds
the parameters that made the data, the noise bases match a Monte Carlo, and the maximum
likelihood finds the noise that drew the residuals."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.calibration import (
    NOISE_MODELS,
    fit_noise,
    fit_systematic,
    odometry_cov_bases,
    pair_residuals,
)
from slamkit.calibration.noise import NoiseModelName
from slamkit.geometry import wrap_angle
from slamkit.geometry.pose2 import between, compose, inverse
from slamkit.models import integrate_odometry


def _steps(rng: np.random.Generator, n: int) -> np.ndarray:
    """A drive of ``n`` odometry steps: 0-0.3 m ahead with turns of up to ±0.3 rad."""
    rot1 = rng.uniform(-0.15, 0.15, n)
    rot2 = rng.uniform(-0.15, 0.15, n)
    trans = rng.uniform(0.0, 0.3, n)
    return np.column_stack([rot1, trans, rot2])


def _pairs(n: int, every: int) -> tuple[np.ndarray, np.ndarray]:
    first = np.arange(0, n - every + 1, every, dtype=np.int64)
    return first, first + every


def test_systematic_fit_recovers_the_parameters_that_made_the_pairs() -> None:
    rng = np.random.default_rng(3)
    steps = _steps(rng, 600)
    first, last = _pairs(600, 4)
    truth = np.array([0.98, 1.03, 0.05, -0.03, 0.02])
    # The laser's motions the true parameters predict: residuals zero at the truth.
    zero = np.zeros((first.size, 3))
    T_laser = compose(
        compose(
            inverse(truth[2:]),
            between(
                *(integrate_odometry(np.zeros(3), _scaled(steps, truth))[i] for i in (first, last))
            ),
        ),
        truth[2:],
    )
    assert np.allclose(pair_residuals(steps, first, last, T_laser, truth), zero, atol=1e-12)
    cov = np.broadcast_to(np.diag([1e-4, 1e-4, 1e-6]), (first.size, 3, 3)).copy()
    fit = fit_systematic(steps, first, last, T_laser, cov, np.array([1.0, 1.0, 0.0, 0.0, 0.0]))
    np.testing.assert_allclose(fit.params, truth, atol=1e-7)
    er, _, eb, _ = fit.wheel_errors()
    assert er == pytest.approx(1 / 0.98 - 1, abs=1e-7)
    assert eb == pytest.approx(1.03 / 0.98 - 1, abs=1e-7)


def test_systematic_fit_with_mounting_held() -> None:
    rng = np.random.default_rng(4)
    steps = _steps(rng, 300)
    first, last = _pairs(300, 3)
    truth = np.array([1.02, 0.97, 0.1, 0.0, 0.0])
    X = integrate_odometry(np.zeros(3), _scaled(steps, truth))
    T_laser = compose(compose(inverse(truth[2:]), between(X[first], X[last])), truth[2:])
    cov = np.broadcast_to(np.eye(3) * 1e-4, (first.size, 3, 3)).copy()
    start = np.concatenate([[1.0, 1.0], truth[2:]])
    fit = fit_systematic(steps, first, last, T_laser, cov, start, fit_mounting=False)
    np.testing.assert_allclose(fit.params, truth, atol=1e-8)
    assert np.all(fit.cov[2:] == 0.0)


def _scaled(steps: np.ndarray, params: np.ndarray) -> np.ndarray:
    return steps * np.array([params[1], params[0], params[1]])


@pytest.mark.parametrize(
    ("model", "theta"),
    [("per_step", (0.01**2, 0.02**2)), ("per_distance", (0.05**2, 0.1**2, 0.03**2))],
)
def test_noise_bases_match_a_monte_carlo(model: NoiseModelName, theta: tuple[float, ...]) -> None:
    rng = np.random.default_rng(5)
    steps = _steps(rng, 12)
    first, last = np.array([0, 5], dtype=np.int64), np.array([5, 12], dtype=np.int64)
    B = odometry_cov_bases(steps, first, last, model)
    predicted = np.einsum("k,kpij->pij", np.asarray(theta), B)
    d = np.abs(steps[:, 1])
    a = np.abs(wrap_angle(steps[:, 0] + steps[:, 2]))
    if model == "per_step":
        var = np.tile([theta[0], theta[1], theta[0]], (steps.shape[0], 1))
    else:
        rot = 0.5 * (theta[1] * a + theta[2] * d)
        var = np.column_stack([rot, theta[0] * d, rot])
    n = 40_000
    noisy = steps[None] + np.sqrt(var)[None] * rng.standard_normal((n, *steps.shape))
    X0 = integrate_odometry(np.zeros(3), steps)
    for p in range(first.size):
        nominal = between(X0[first[p]], X0[last[p]])
        ends = np.array([
            between(*(integrate_odometry(np.zeros(3), u)[i] for i in (first[p], last[p])))
            for u in noisy[:2000]
        ])  # fmt: skip
        err = between(nominal, ends)
        empirical = err.T @ err / err.shape[0]
        scale = np.sqrt(np.outer(np.diag(predicted[p]), np.diag(predicted[p])))
        # 2000 draws: a variance to ~3 % (1σ); small noise, so first order holds to < 1 %.
        np.testing.assert_allclose(empirical / scale, predicted[p] / scale, atol=0.12)


@pytest.mark.parametrize("model", ["per_step", "per_distance"])
def test_noise_fit_finds_the_noise_that_drew_the_residuals(model: NoiseModelName) -> None:
    rng = np.random.default_rng(6)
    steps = _steps(rng, 4000)
    first, last = _pairs(4000, 4)
    B = odometry_cov_bases(steps, first, last, model)
    sigmas = {"per_step": (0.004, 0.01), "per_distance": (0.02, 0.05, 0.01)}[model]
    theta = np.square(sigmas)
    base = np.broadcast_to(np.diag([1e-6, 1e-6, 1e-8]), (first.size, 3, 3)).copy()
    S = base + np.einsum("k,kpij->pij", theta, B)
    r = np.einsum("pij,pj->pi", np.linalg.cholesky(S), rng.standard_normal((first.size, 3)))
    fit = fit_noise(r, base, B, model)
    assert fit.names == NOISE_MODELS[model]
    for value, std, truth in zip(fit.values, fit.stds, sigmas, strict=True):
        assert abs(value - truth) < 4.0 * std
        assert abs(value - truth) < 0.25 * truth  # k_drift shares its signal with k_rot
    assert fit.chi2_per_dof == pytest.approx(1.0, abs=0.05)
