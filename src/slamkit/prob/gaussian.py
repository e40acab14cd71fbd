"""Gaussian densities, Mahalanobis distances, χ² gates and covariance ellipses.

Everything here is vectorised over leading batch axes and validated at the entry point:
vectors are ``(..., n)``, covariance matrices ``(..., n, n)``, and batch axes broadcast
against each other (one covariance against many residuals is one call).

Numerics: every multivariate quantity goes through a Cholesky factor ``Σ = L Lᵀ`` and a
triangular solve — never an explicit inverse. With ``y = L⁻¹ r`` the squared Mahalanobis
distance is ``rᵀ Σ⁻¹ r = yᵀ y`` and ``½ log det Σ = Σᵢ log Lᵢᵢ``. A factorisation that fails
means the matrix is not positive definite and raises :class:`~slamkit.errors.CovarianceError`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special, stats
from scipy.linalg import solve_triangular

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.errors import CovarianceError, InputError, NonFiniteError, ShapeError
from slamkit.geometry.angles import wrap_angle

__all__ = [
    "Ellipse",
    "chi2_gate",
    "confidence_scale",
    "covariance_determinant",
    "covariance_ellipse",
    "covariance_size",
    "covariance_trace",
    "ellipse_points",
    "gaussian_cdf",
    "gaussian_draws",
    "gaussian_logpdf",
    "gaussian_pdf",
    "mahalanobis",
    "mahalanobis_squared",
    "mvn_logpdf",
    "mvn_pdf",
    "symmetrize",
    "within_gate",
]

_LOG_2PI = float(np.log(2.0 * np.pi))
_SQRT_2 = float(np.sqrt(2.0))
# Relative tolerance of the symmetry check; the same as slamkit._validation.as_covariance.
_SYMMETRY_RTOL = 1e-9


# --------------------------------------------------------------------------------------------
# internal checks and kernels
# --------------------------------------------------------------------------------------------


def _broadcast_shape(names: str, *shapes: tuple[int, ...]) -> tuple[int, ...]:
    try:
        return np.broadcast_shapes(*shapes)
    except ValueError as exc:
        raise ShapeError(f"{names}: shapes {', '.join(map(str, shapes))} do not broadcast") from exc


def _sigma(sigma: ArrayLike) -> FloatArray:
    s = as_array(sigma, "sigma")
    if np.any(s <= 0):
        raise InputError(f"sigma: expected standard deviations > 0, got minimum {float(s.min())}")
    return s


def _square(value: ArrayLike, name: str, n: int | None = None) -> FloatArray:
    """A finite float array of shape ``(..., n, n)`` (any ``n`` when ``n`` is None)."""
    arr = as_array(value, name, (..., n, n))
    if arr.shape[-1] != arr.shape[-2]:
        raise ShapeError(f"{name}: expected square matrices (..., n, n), got shape {arr.shape}")
    return arr


def _check_symmetric(arr: FloatArray, name: str) -> None:
    scale = max(float(np.max(np.abs(arr))) if arr.size else 0.0, 1.0)
    tol = _SYMMETRY_RTOL * scale
    if not np.allclose(arr, np.swapaxes(arr, -1, -2), rtol=_SYMMETRY_RTOL, atol=tol):
        raise CovarianceError(f"{name}: expected symmetric matrices")


def _cholesky(cov: ArrayLike, name: str, n: int) -> FloatArray:
    """Validate ``cov (..., n, n)`` as symmetric positive definite and return ``L`` (lower)."""
    c = _square(cov, name, n)
    _check_symmetric(c, name)
    try:
        return np.asarray(np.linalg.cholesky(c), dtype=np.float64)
    except np.linalg.LinAlgError as exc:
        smallest = float(np.linalg.eigvalsh(c).min())
        raise CovarianceError(
            f"{name}: expected positive definite matrices, smallest eigenvalue {smallest:.3g}"
        ) from exc


def _solve_lower(L: FloatArray, r: FloatArray) -> FloatArray:
    """``y = L⁻¹ r`` for lower-triangular ``L (..., n, n)`` and ``r (..., n)``, broadcasting."""
    n = L.shape[-1]
    if L.ndim == 2:
        # One factor for every residual: a single LAPACK triangular solve with many right-hand
        # sides, L Y = Rᵀ.
        flat = r.reshape(-1, n)
        if flat.shape[0] == 0:
            return np.empty(r.shape)
        y = solve_triangular(L, flat.T, lower=True, check_finite=False)
        return np.asarray(y.T.reshape(r.shape), dtype=np.float64)
    # A batch of factors: forward substitution, yᵢ = (rᵢ − Σ_{j<i} Lᵢⱼ yⱼ) / Lᵢᵢ, vectorised
    # over the batch (n is small — 2 or 3 — wherever covariances come in batches).
    batch = np.broadcast_shapes(L.shape[:-2], r.shape[:-1])
    y = np.empty((*batch, n))
    for i in range(n):
        acc = r[..., i] - np.sum(L[..., i, :i] * y[..., :i], axis=-1)
        y[..., i] = acc / L[..., i, i]
    return y


def _vector_and_factor(
    residual: ArrayLike, cov: ArrayLike, rname: str, cname: str
) -> tuple[FloatArray, FloatArray]:
    r = as_array(residual, rname, (..., None))
    L = _cholesky(cov, cname, r.shape[-1])
    _broadcast_shape(f"{rname} and {cname}", r.shape[:-1], L.shape[:-2])
    return r, L


# --------------------------------------------------------------------------------------------
# scalar Gaussian
# --------------------------------------------------------------------------------------------


def gaussian_logpdf(x: ArrayLike, mean: ArrayLike = 0.0, sigma: ArrayLike = 1.0) -> FloatArray:
    """Log density of ``N(mean, sigma²)`` at ``x``; arguments broadcast.

    ``log p = −½ ((x − μ)/σ)² − log σ − ½ log 2π``.
    """
    xa, mu, s = as_array(x, "x"), as_array(mean, "mean"), _sigma(sigma)
    _broadcast_shape("x, mean and sigma", xa.shape, mu.shape, s.shape)
    z = (xa - mu) / s
    return -0.5 * z * z - np.log(s) - 0.5 * _LOG_2PI


def gaussian_pdf(x: ArrayLike, mean: ArrayLike = 0.0, sigma: ArrayLike = 1.0) -> FloatArray:
    """Density of ``N(mean, sigma²)`` at ``x``: ``exp(−½((x − μ)/σ)²) / (σ √(2π))``."""
    return np.exp(gaussian_logpdf(x, mean, sigma))


def gaussian_cdf(x: ArrayLike, mean: ArrayLike = 0.0, sigma: ArrayLike = 1.0) -> FloatArray:
    """Cumulative distribution of ``N(mean, sigma²)`` at ``x``; arguments broadcast.

    ``F(x) = ½ (1 + erf((x − μ) / (σ √2)))`` (the course notes misprint the argument as
    ``(x − μ)·√(2σ²)``). It is evaluated as the identical ``½ erfc(−(x − μ) / (σ √2))``,
    which keeps full relative precision in the lower tail where ``1 + erf`` cancels to 0.
    """
    xa, mu, s = as_array(x, "x"), as_array(mean, "mean"), _sigma(sigma)
    _broadcast_shape("x, mean and sigma", xa.shape, mu.shape, s.shape)
    u = (xa - mu) / (s * _SQRT_2)
    return np.asarray(0.5 * special.erfc(-u), dtype=np.float64)


# --------------------------------------------------------------------------------------------
# multivariate Gaussian and Mahalanobis distance
# --------------------------------------------------------------------------------------------


def mahalanobis_squared(residual: ArrayLike, cov: ArrayLike) -> FloatArray:
    """Squared Mahalanobis distance ``rᵀ Σ⁻¹ r`` of ``residual (..., n)`` under
    ``cov (..., n, n)``; batch axes broadcast. Result has the broadcast batch shape.

    Angular components of the residual must already be wrapped by the caller.
    """
    r, L = _vector_and_factor(residual, cov, "residual", "cov")
    y = _solve_lower(L, r)  # Σ = L Lᵀ  ⇒  rᵀ Σ⁻¹ r = |L⁻¹ r|²
    return np.sum(y * y, axis=-1)


def mahalanobis(residual: ArrayLike, cov: ArrayLike) -> FloatArray:
    """Mahalanobis distance ``√(rᵀ Σ⁻¹ r)``; see :func:`mahalanobis_squared`."""
    return np.sqrt(mahalanobis_squared(residual, cov))


def mvn_logpdf(x: ArrayLike, mean: ArrayLike, cov: ArrayLike) -> FloatArray:
    """Log density of ``N(mean, cov)`` at ``x (..., n)``; ``mean (..., n)``, ``cov (..., n, n)``;
    batch axes broadcast.

    ``log p = −½ (rᵀ Σ⁻¹ r + log det Σ + n log 2π)`` with ``r = x − mean``, evaluated through
    the Cholesky factor (``log det Σ = 2 Σᵢ log Lᵢᵢ``).
    """
    xa = as_array(x, "x", (..., None))
    n = xa.shape[-1]
    mu = as_array(mean, "mean", (..., n))
    shape = _broadcast_shape("x and mean", xa.shape, mu.shape)
    L = _cholesky(cov, "cov", n)
    _broadcast_shape("x, mean and cov", shape[:-1], L.shape[:-2])
    y = _solve_lower(L, xa - mu)
    d2 = np.sum(y * y, axis=-1)
    half_logdet = np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    return -0.5 * (d2 + n * _LOG_2PI) - half_logdet


def mvn_pdf(x: ArrayLike, mean: ArrayLike, cov: ArrayLike) -> FloatArray:
    """Density of ``N(mean, cov)`` at ``x``: ``exp(mvn_logpdf(x, mean, cov))``.

    Prefer :func:`mvn_logpdf` when densities are multiplied (particle weights): the density
    underflows to 0 far from the mean.
    """
    return np.exp(mvn_logpdf(x, mean, cov))


# --------------------------------------------------------------------------------------------
# χ² gates
# --------------------------------------------------------------------------------------------


def _dof(dof: int) -> int:
    if isinstance(dof, bool) or not float(dof).is_integer() or int(dof) < 1:
        raise InputError(f"dof: expected a positive integer, got {dof!r}")
    return int(dof)


def _probability(probability: float) -> float:
    p = float(probability)
    if not 0.0 < p < 1.0:
        raise InputError(f"probability: expected a value in (0, 1), got {probability!r}")
    return p


def chi2_gate(dof: int, probability: float = 0.99) -> float:
    """The ``probability`` quantile of the χ² distribution with ``dof`` degrees of freedom.

    A squared Mahalanobis distance of a consistent ``dof``-dimensional innovation exceeds it
    with probability ``1 − probability``; e.g. ``chi2_gate(2, 0.95) = 5.9915``.
    """
    return float(stats.chi2.ppf(_probability(probability), _dof(dof)))


def within_gate(d2: ArrayLike, dof: int, probability: float = 0.99) -> NDArray[np.bool_]:
    """Whether squared Mahalanobis distances ``d2`` lie inside the χ² gate (``d2 ≤ gate``).

    ``+inf`` (an impossible association) is outside the gate; NaN raises.
    """
    d = as_array(d2, "d2", finite=False)
    if np.any(np.isnan(d)):
        raise NonFiniteError(f"d2: expected numbers, got {int(np.isnan(d).sum())} NaN value(s)")
    if np.any(d < 0):
        raise InputError(f"d2: expected squared distances >= 0, got minimum {float(d.min())}")
    return np.asarray(d <= chi2_gate(dof, probability))


def confidence_scale(probability: float, dof: int = 2) -> float:
    """Number of "sigmas" ``k = √(χ²_dof⁻¹(probability))`` whose ellipse (``dof = 2``) or
    ellipsoid contains ``probability`` of the Gaussian's mass; e.g. 2.4477 for 95 % in 2-D.
    """
    return float(np.sqrt(chi2_gate(dof, probability)))


# --------------------------------------------------------------------------------------------
# covariance ellipses and sizes
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Ellipse:
    """Ellipses ``xᵀ Σ⁻¹ x = n_sigma²`` of a batch of 2×2 covariances (arrays shaped like the
    batch).

    ``semi_major ≥ semi_minor ≥ 0`` are the semi-axis lengths (units of the covariance's
    square root, e.g. metres). ``angle`` is the direction of the major axis in radians,
    counter-clockwise from +x; an axis has no sign, so it is wrapped to ``[-π/2, π/2)``.
    """

    semi_major: FloatArray
    semi_minor: FloatArray
    angle: FloatArray


def covariance_ellipse(cov: ArrayLike, n_sigma: float = 1.0) -> Ellipse:
    """The ``n_sigma`` ellipse of ``cov (..., 2, 2)`` from its symmetric eigendecomposition.

    ``Σ = V diag(λ₁ ≤ λ₂) Vᵀ`` gives semi-axes ``n_sigma √λ₂`` along ``v₂`` and
    ``n_sigma √λ₁``. Positive semi-definite input is allowed (a zero-width ellipse). For a
    probability ellipse pass ``n_sigma=confidence_scale(p)``.
    """
    c = _square(cov, "cov", 2)
    _check_symmetric(c, "cov")
    k = as_positive(n_sigma, "n_sigma")
    lam, vec = np.linalg.eigh(c)  # ascending eigenvalues, orthonormal eigenvectors in columns
    scale = max(float(np.max(np.abs(c))) if c.size else 0.0, 1e-300)
    if np.any(lam[..., 0] < -1e-9 * scale):
        raise CovarianceError(
            f"cov: expected positive semi-definite matrices, smallest eigenvalue "
            f"{float(lam[..., 0].min()):.3g}"
        )
    lam = np.clip(lam, 0.0, None)  # round-off can make a zero eigenvalue slightly negative
    major = vec[..., :, 1]
    # The axis direction is defined modulo π: wrap 2θ to [-π, π) and halve.
    angle = 0.5 * wrap_angle(2.0 * np.arctan2(major[..., 1], major[..., 0]))
    return Ellipse(
        semi_major=np.asarray(k * np.sqrt(lam[..., 1]), dtype=np.float64),
        semi_minor=np.asarray(k * np.sqrt(lam[..., 0]), dtype=np.float64),
        angle=np.asarray(angle, dtype=np.float64),
    )


def ellipse_points(
    mean: ArrayLike, cov: ArrayLike, n_sigma: float = 1.0, n: int = 64
) -> FloatArray:
    """``n`` points ``(..., n, 2)`` evenly spaced in parameter around the ``n_sigma`` ellipse of
    ``cov (..., 2, 2)`` centred on ``mean (..., 2)``; a closed polygon (the first point is not
    repeated). ``mean (2,)`` and ``cov (2, 2)`` give ``(n, 2)``; batch axes broadcast.

    Every point ``p`` satisfies ``(p − mean)ᵀ Σ⁻¹ (p − mean) = n_sigma²``.
    """
    m = as_array(mean, "mean", (..., 2))
    if isinstance(n, bool) or int(n) != n or n < 3:
        raise InputError(f"n: expected an integer >= 3, got {n!r}")
    e = covariance_ellipse(cov, n_sigma)
    batch = _broadcast_shape("mean and cov", m.shape[:-1], e.angle.shape)
    t = np.linspace(0.0, 2.0 * np.pi, int(n), endpoint=False)
    # Point on the axis-aligned ellipse, (a cos t, b sin t), rotated by the major-axis angle.
    u = e.semi_major[..., None] * np.cos(t)
    v = e.semi_minor[..., None] * np.sin(t)
    c, s = np.cos(e.angle)[..., None], np.sin(e.angle)[..., None]
    pts = np.stack([c * u - s * v, s * u + c * v], axis=-1) + m[..., None, :]
    return np.broadcast_to(pts, (*batch, int(n), 2)).copy()


def covariance_trace(cov: ArrayLike) -> FloatArray:
    """Trace of ``cov (..., n, n)``: the sum of the variances (for a 2×2 covariance it grows
    like the ellipse's size along both axes). Shape ``(...)``."""
    c = _square(cov, "cov")
    return np.asarray(np.trace(c, axis1=-2, axis2=-1), dtype=np.float64)


def covariance_determinant(cov: ArrayLike) -> FloatArray:
    """Determinant of ``cov (..., n, n)``: the generalised variance (for 2×2 proportional to
    the squared ellipse area, ``area = π n_sigma² √det Σ``). Shape ``(...)``.

    Computed through ``slogdet`` (an LU factorisation) so large matrices do not overflow
    before the sign is known; a negative determinant raises :class:`CovarianceError`.
    """
    c = _square(cov, "cov")
    sign, logabs = np.linalg.slogdet(c)
    if np.any(sign < 0):
        raise CovarianceError("cov: expected positive semi-definite matrices, got det < 0")
    return np.asarray(sign * np.exp(logabs), dtype=np.float64)


def covariance_size(cov: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """``(trace, determinant)`` of ``cov (..., n, n)``: the two usual scalar sizes used to
    compare covariance matrices (total variance and generalised variance)."""
    return covariance_trace(cov), covariance_determinant(cov)


def symmetrize(cov: ArrayLike) -> FloatArray:
    """``(Σ + Σᵀ) / 2`` of ``cov (..., n, n)``: removes the round-off asymmetry that covariance
    updates accumulate. The one place slamkit writes this operation. Returns a new array."""
    c = _square(cov, "cov")
    return 0.5 * (c + np.swapaxes(c, -1, -2))


def gaussian_draws(cov: FloatArray, batch: tuple[int, ...], rng: np.random.Generator) -> FloatArray:
    """Draws ``(..., k)`` from ``N(0, cov)`` for a (batch of) PSD ``cov (..., k, k)``.

    A symmetric square root from ``eigh`` (negative round-off eigenvalues clipped to zero)
    works for singular covariances too, where a Cholesky factor would fail.
    """
    k = cov.shape[-1]
    eigval, eigvec = np.linalg.eigh(cov)
    root = eigvec * np.sqrt(np.clip(eigval, 0.0, None))[..., None, :]
    shape = np.broadcast_shapes(batch, cov.shape[:-2])
    z = rng.standard_normal((*shape, k))
    return np.einsum("...ij,...j->...i", root, z)
