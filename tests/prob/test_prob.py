"""slamkit.prob: hand values, cross-checks against scipy.stats, shapes and errors."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import special, stats

from slamkit.errors import CovarianceError, InputError, NonFiniteError, ShapeError
from slamkit.prob import (
    Ellipse,
    chi2_gate,
    confidence_scale,
    covariance_determinant,
    covariance_ellipse,
    covariance_size,
    covariance_trace,
    ellipse_points,
    gaussian_cdf,
    gaussian_logpdf,
    gaussian_pdf,
    mahalanobis,
    mahalanobis_squared,
    mvn_logpdf,
    mvn_pdf,
    symmetrize,
    within_gate,
)


def rotation(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def random_spd(rng: np.random.Generator, batch: tuple[int, ...], n: int) -> np.ndarray:
    a = rng.normal(size=(*batch, n, n))
    return a @ np.swapaxes(a, -1, -2) + 0.5 * np.eye(n)


# --------------------------------------------------------------------------------------------
# scalar Gaussian
# --------------------------------------------------------------------------------------------


def test_gaussian_pdf_hand_values() -> None:
    assert gaussian_pdf(0.0) == pytest.approx(1.0 / math.sqrt(2.0 * math.pi), rel=1e-15)
    # N(1, 2²) at x = 3 is one sigma out: exp(-1/2) / (2 √(2π))
    expected = math.exp(-0.5) / (2.0 * math.sqrt(2.0 * math.pi))
    assert gaussian_pdf(3.0, 1.0, 2.0) == pytest.approx(expected, rel=1e-14)
    assert gaussian_logpdf(3.0, 1.0, 2.0) == pytest.approx(math.log(expected), rel=1e-14)


def test_gaussian_functions_match_scipy_and_broadcast() -> None:
    x = np.linspace(-6.0, 8.0, 57)[:, None]
    mean = np.array([-1.0, 0.0, 2.5])
    sigma = np.array([0.3, 1.0, 4.0])
    np.testing.assert_allclose(gaussian_pdf(x, mean, sigma), stats.norm.pdf(x, mean, sigma))
    np.testing.assert_allclose(
        gaussian_logpdf(x, mean, sigma), stats.norm.logpdf(x, mean, sigma), rtol=1e-13
    )
    np.testing.assert_allclose(gaussian_cdf(x, mean, sigma), stats.norm.cdf(x, mean, sigma))
    assert gaussian_pdf(x, mean, sigma).shape == (57, 3)


def test_gaussian_cdf_hand_values_and_erf_form() -> None:
    assert gaussian_cdf(2.0, 2.0, 0.7) == 0.5
    assert gaussian_cdf(1.0, 0.0, 1.0) == pytest.approx(0.8413447460685429, rel=1e-15)
    assert gaussian_cdf(5.0, 3.0, 2.0) == pytest.approx(0.8413447460685429, rel=1e-15)
    # The corrected formula of the notes: ½ (1 + erf((x − μ) / (σ √2))).
    x, mu, sigma = np.array([-1.3, 0.2, 4.0]), 0.5, 1.7
    by_erf = 0.5 * (1.0 + special.erf((x - mu) / (sigma * math.sqrt(2.0))))
    np.testing.assert_allclose(gaussian_cdf(x, mu, sigma), by_erf, rtol=1e-14)
    # The lower tail keeps relative precision where 1 + erf would cancel to 0.
    assert gaussian_cdf(-30.0) == pytest.approx(stats.norm.cdf(-30.0), rel=1e-12)
    assert gaussian_cdf(-30.0) > 0.0


@pytest.mark.parametrize("bad", [0.0, -1.0, [1.0, 0.0]])
def test_gaussian_rejects_non_positive_sigma(bad: object) -> None:
    with pytest.raises(InputError, match="sigma"):
        gaussian_pdf(0.0, 0.0, bad)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="sigma"):
        gaussian_cdf(0.0, 0.0, bad)  # type: ignore[arg-type]


def test_gaussian_rejects_nan_and_bad_broadcast() -> None:
    with pytest.raises(NonFiniteError):
        gaussian_logpdf(np.nan)
    with pytest.raises(NonFiniteError):
        gaussian_cdf(0.0, 0.0, np.inf)
    with pytest.raises(ShapeError):
        gaussian_pdf(np.zeros(3), np.zeros(2), 1.0)


# --------------------------------------------------------------------------------------------
# multivariate Gaussian, Mahalanobis
# --------------------------------------------------------------------------------------------


def test_mvn_logpdf_matches_scipy_one_covariance_many_points() -> None:
    rng = np.random.default_rng(1)
    cov = random_spd(rng, (), 3)
    mean = rng.normal(size=3)
    x = rng.normal(size=(40, 3)) * 2.0
    ref = stats.multivariate_normal(mean, cov).logpdf(x)
    np.testing.assert_allclose(mvn_logpdf(x, mean, cov), ref, rtol=1e-12)
    np.testing.assert_allclose(mvn_pdf(x, mean, cov), np.exp(ref), rtol=1e-12)
    assert np.ndim(mvn_logpdf(x[0], mean, cov)) == 0


@pytest.mark.parametrize("batch", [(1,), (7,), (2, 5)])
@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_mvn_logpdf_batched_covariances(batch: tuple[int, ...], n: int) -> None:
    rng = np.random.default_rng([n, *batch])
    cov = random_spd(rng, batch, n)
    mean = rng.normal(size=(*batch, n))
    x = rng.normal(size=(*batch, n))
    got = mvn_logpdf(x, mean, cov)
    assert got.shape == batch
    ref = [
        stats.multivariate_normal(m, c).logpdf(xx)
        for xx, m, c in zip(
            x.reshape(-1, n), mean.reshape(-1, n), cov.reshape(-1, n, n), strict=True
        )
    ]
    np.testing.assert_allclose(got.ravel(), ref, rtol=1e-11)


def test_mvn_logpdf_broadcasts_points_against_covariances() -> None:
    rng = np.random.default_rng(2)
    covs = random_spd(rng, (4,), 2)
    x = rng.normal(size=(6, 1, 2))
    got = mvn_logpdf(x, np.zeros(2), covs)
    assert got.shape == (6, 4)
    assert got[3, 2] == pytest.approx(
        stats.multivariate_normal(np.zeros(2), covs[2]).logpdf(x[3, 0]), rel=1e-12
    )


def test_mahalanobis_hand_case_diagonal() -> None:
    cov = np.diag([4.0, 9.0])
    r = np.array([2.0, -6.0])
    # (2/2)² + (6/3)² = 1 + 4
    assert mahalanobis_squared(r, cov) == pytest.approx(5.0, rel=1e-15)
    assert mahalanobis(r, cov) == pytest.approx(math.sqrt(5.0), rel=1e-15)


@pytest.mark.parametrize("cov_batch", [(), (8,), (2, 4)])
def test_mahalanobis_agrees_with_solve(cov_batch: tuple[int, ...]) -> None:
    rng = np.random.default_rng(3)
    cov = random_spd(rng, cov_batch, 3)
    r = rng.normal(size=(2, 4, 3)) if cov_batch == (2, 4) else rng.normal(size=(8, 3))
    ref = np.einsum("...i,...i->...", r, np.linalg.solve(cov, r[..., None])[..., 0])
    np.testing.assert_allclose(mahalanobis_squared(r, cov), ref, rtol=1e-11)


def test_non_positive_definite_covariance_raises() -> None:
    not_pd = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3 and -1
    with pytest.raises(CovarianceError, match="positive definite"):
        mahalanobis_squared(np.ones(2), not_pd)
    with pytest.raises(CovarianceError):
        mvn_logpdf(np.zeros(2), np.zeros(2), np.stack([np.eye(2), not_pd]))
    with pytest.raises(CovarianceError, match="symmetric"):
        mahalanobis(np.ones(2), np.array([[1.0, 0.5], [0.0, 1.0]]))
    with pytest.raises(CovarianceError):
        covariance_ellipse(np.diag([1.0, -1.0]))
    with pytest.raises(CovarianceError):
        covariance_determinant(np.diag([1.0, -1.0]))


def test_non_finite_and_shape_errors() -> None:
    with pytest.raises(NonFiniteError):
        mvn_logpdf([np.nan, 0.0], np.zeros(2), np.eye(2))
    with pytest.raises(NonFiniteError):
        mahalanobis_squared(np.zeros(2), [[1.0, np.nan], [np.nan, 1.0]])
    with pytest.raises(ShapeError):
        mahalanobis_squared(np.zeros(3), np.eye(2))
    with pytest.raises(ShapeError):
        mvn_logpdf(np.zeros((3, 2)), np.zeros(2), random_spd(np.random.default_rng(0), (4,), 2))


def test_inputs_are_not_modified() -> None:
    cov = np.array([[2.0, 0.5], [0.5, 1.0]])
    r = np.array([1.0, 2.0])
    cov0, r0 = cov.copy(), r.copy()
    mvn_logpdf(r, np.zeros(2), cov)
    symmetrize(cov)
    ellipse_points(r, cov)
    np.testing.assert_array_equal(cov, cov0)
    np.testing.assert_array_equal(r, r0)


# --------------------------------------------------------------------------------------------
# χ² gates
# --------------------------------------------------------------------------------------------


def test_chi2_gate_values() -> None:
    assert chi2_gate(2, 0.95) == pytest.approx(5.991464547107979, rel=1e-14)
    assert chi2_gate(1, 0.95) == pytest.approx(1.959963984540054**2, rel=1e-13)
    # For 2 dof the χ² quantile has the closed form −2 ln(1 − p).
    assert chi2_gate(2) == pytest.approx(-2.0 * math.log(0.01), rel=1e-13)
    assert confidence_scale(0.95) == pytest.approx(math.sqrt(5.991464547107979), rel=1e-14)


def test_within_gate() -> None:
    g = chi2_gate(2, 0.95)
    inside = within_gate([0.0, g - 1e-9, g, g + 1e-9, np.inf], 2, 0.95)
    np.testing.assert_array_equal(inside, [True, True, True, False, False])
    assert inside.dtype == np.bool_


@pytest.mark.parametrize(
    ("dof", "p"), [(0, 0.9), (-1, 0.9), (1.5, 0.9), (2, 0.0), (2, 1.0), (2, 1.2)]
)
def test_chi2_gate_rejects_bad_arguments(dof: int, p: float) -> None:
    with pytest.raises(InputError):
        chi2_gate(dof, p)


def test_within_gate_rejects_nan_and_negative() -> None:
    with pytest.raises(NonFiniteError):
        within_gate([1.0, np.nan], 2)
    with pytest.raises(InputError):
        within_gate([-1.0], 2)


# --------------------------------------------------------------------------------------------
# ellipses and sizes
# --------------------------------------------------------------------------------------------


def test_ellipse_of_diagonal_covariance() -> None:
    e = covariance_ellipse(np.diag([4.0, 1.0]))
    assert isinstance(e, Ellipse)
    assert (float(e.semi_major), float(e.semi_minor)) == pytest.approx((2.0, 1.0), rel=1e-15)
    assert float(e.angle) == pytest.approx(0.0, abs=1e-15)
    e3 = covariance_ellipse(np.diag([1.0, 4.0]), n_sigma=3.0)
    assert (float(e3.semi_major), float(e3.semi_minor)) == pytest.approx((6.0, 3.0))
    assert abs(float(e3.angle)) == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("theta", [math.pi / 4, -math.pi / 3, 0.3, 1.2])
def test_ellipse_of_rotated_covariance(theta: float) -> None:
    R = rotation(theta)
    cov = R @ np.diag([4.0, 1.0]) @ R.T
    e = covariance_ellipse(cov, n_sigma=2.0)
    assert float(e.semi_major) == pytest.approx(4.0, rel=1e-12)
    assert float(e.semi_minor) == pytest.approx(2.0, rel=1e-12)
    assert float(e.angle) == pytest.approx(theta, abs=1e-12)  # all in [-π/2, π/2)


def test_ellipse_angle_is_wrapped_to_half_turn() -> None:
    R = rotation(3 * math.pi / 4)  # the same axis as -π/4
    e = covariance_ellipse(R @ np.diag([9.0, 1.0]) @ R.T)
    assert float(e.angle) == pytest.approx(-math.pi / 4, abs=1e-12)


def test_ellipse_batch_shapes_and_degenerate_covariance() -> None:
    rng = np.random.default_rng(4)
    e = covariance_ellipse(random_spd(rng, (3, 5), 2))
    assert e.semi_major.shape == e.semi_minor.shape == e.angle.shape == (3, 5)
    assert np.all(e.semi_major >= e.semi_minor)
    assert np.all((e.angle >= -math.pi / 2) & (e.angle < math.pi / 2))
    zero = covariance_ellipse(np.zeros((2, 2)))  # a known pose: zero-size ellipse, no error
    assert float(zero.semi_major) == 0.0


@settings(max_examples=50, deadline=None)
@given(
    sx=st.floats(0.01, 100.0),
    sy=st.floats(0.01, 100.0),
    theta=st.floats(-math.pi, math.pi),
    k=st.floats(0.5, 4.0),
)
def test_ellipse_points_lie_on_the_ellipse(sx: float, sy: float, theta: float, k: float) -> None:
    R = rotation(theta)
    cov = R @ np.diag([sx**2, sy**2]) @ R.T
    mean = np.array([3.0, -2.0])
    pts = ellipse_points(mean, cov, n_sigma=k, n=32)
    assert pts.shape == (32, 2)
    d = pts - mean
    q = np.einsum("ni,ni->n", d, np.linalg.solve(cov, d.T).T)
    np.testing.assert_allclose(q, k**2, rtol=1e-8)


def test_ellipse_points_batched() -> None:
    rng = np.random.default_rng(5)
    covs = random_spd(rng, (6,), 2)
    means = rng.normal(size=(6, 2))
    pts = ellipse_points(means, covs, n_sigma=3.0, n=16)
    assert pts.shape == (6, 16, 2)
    d = pts - means[:, None, :]
    q = mahalanobis_squared(d, covs[:, None])
    np.testing.assert_allclose(q, 9.0, rtol=1e-10)
    with pytest.raises(InputError):
        ellipse_points(np.zeros(2), np.eye(2), n=2)


def test_trace_and_determinant_hand_values() -> None:
    cov = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]])
    # det = 4 (3·2 − 0.25) − 1 (1·2 − 0) = 23 − 2 = 21
    assert covariance_trace(cov) == pytest.approx(9.0)
    assert covariance_determinant(cov) == pytest.approx(21.0, rel=1e-13)
    trace, det = covariance_size(np.stack([cov, 2.0 * cov]))
    np.testing.assert_allclose(trace, [9.0, 18.0])
    np.testing.assert_allclose(det, [21.0, 168.0], rtol=1e-13)
    assert covariance_determinant(np.zeros((2, 2))) == 0.0
    # Tiny variances: the determinant stays accurate (1e-40 per axis, 1e-160 in 4-D).
    assert covariance_determinant(1e-40 * np.eye(4)) == pytest.approx(1e-160, rel=1e-12)


def test_symmetrize() -> None:
    a = np.array([[1.0, 2.0], [4.0, 3.0]])
    np.testing.assert_array_equal(symmetrize(a), [[1.0, 3.0], [3.0, 3.0]])
    batch = np.random.default_rng(6).normal(size=(5, 3, 3))
    s = symmetrize(batch)
    np.testing.assert_array_equal(s, np.swapaxes(s, -1, -2))
    with pytest.raises(ShapeError):
        symmetrize(np.zeros((2, 3)))


def test_numerics_do_not_import_matplotlib() -> None:
    code = "import sys, slamkit.prob; sys.exit('matplotlib' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0
