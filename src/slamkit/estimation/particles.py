"""Particle sets as arrays, and the operations every particle filter needs.

A particle set is a struct of arrays: poses ``(P, 3)`` = ``(x, y, theta)`` and log-weights
``(P,)``. Weights are kept in log space throughout: a laser scan multiplies a weight by a
product of ~100 beam likelihoods, which underflows float64 long before the filter has learnt
anything, whereas sums of logs do not. :func:`normalize_log_weights` turns them into
probabilities by the log-sum-exp trick.

Every stochastic function takes an injected ``rng: np.random.Generator``. Resampling returns
*indices*; selecting particles with them is fancy indexing, which copies, so two resampled
particles never share a buffer. No function modifies its arguments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.errors import ConvergenceError, InputError
from slamkit.geometry.angles import angle_diff, circular_mean, wrap_angle
from slamkit.maps import FREE_THRESHOLD, OccupancyGrid

__all__ = [
    "ParticleSet",
    "effective_sample_size",
    "low_variance_resample",
    "normalize_log_weights",
    "particle_estimate",
    "uniform_particles_in_box",
    "uniform_particles_in_free_space",
]


_NEGLIGIBLE_LOG_WEIGHT = -700.0


@dataclass(frozen=True)
class ParticleSet:
    """Poses ``(P, 3)`` and normalised log-weights ``(P,)`` (``logsumexp = 0``).

    Build one with :meth:`uniform_weights` or :meth:`from_log_weights`; both copy their inputs,
    so the set never aliases an array the caller still holds.
    """

    poses: FloatArray
    log_weights: FloatArray

    def __post_init__(self) -> None:
        poses = as_array(self.poses, "particle poses", (None, 3))
        if poses.shape[0] == 0:
            raise InputError("particle poses: expected at least one particle, got none")
        logw = as_array(self.log_weights, "log_weights", (poses.shape[0],), finite=False)
        if np.any(np.isnan(logw)) or np.any(logw == np.inf):
            raise InputError("log_weights: expected finite values or -inf, got NaN or +inf")
        object.__setattr__(self, "poses", poses)
        object.__setattr__(self, "log_weights", logw)

    @classmethod
    def uniform_weights(cls, poses: ArrayLike) -> ParticleSet:
        """The particles ``poses (P, 3)`` (copied, headings wrapped), each of weight ``1/P``."""
        p = as_array(poses, "particle poses", (None, 3)).copy()
        p[:, 2] = wrap_angle(p[:, 2])
        n = p.shape[0]
        return cls(p, np.full(n, -np.log(n) if n else 0.0))

    @classmethod
    def from_log_weights(cls, poses: ArrayLike, log_weights: ArrayLike) -> ParticleSet:
        """The particles with unnormalised ``log_weights``, normalised here (copies both).

        Raises :class:`ConvergenceError` when every weight is zero (see
        :func:`normalize_log_weights`).
        """
        p = as_array(poses, "particle poses", (None, 3)).copy()
        logw, _ = normalize_log_weights(log_weights)
        return cls(p, logw)

    def __len__(self) -> int:
        return int(self.poses.shape[0])

    @property
    def weights(self) -> FloatArray:
        """Normalised weights ``(P,)`` (they sum to 1).

        Weights below ``exp(-700)`` (≈ 1e-304, relative to a largest weight of at least
        ``1/P``) come back as exactly 0: they are below any effect on a sum, and as subnormal
        numbers they would only slow every later operation down.
        """
        lw = self.log_weights
        w: FloatArray = np.zeros(lw.shape)
        np.exp(lw, out=w, where=lw > _NEGLIGIBLE_LOG_WEIGHT)
        return w / w.sum()

    def select(self, indices: NDArray[np.intp]) -> ParticleSet:
        """The particles ``indices`` (a copy, by fancy indexing) with uniform weights."""
        return ParticleSet.uniform_weights(self.poses[indices])


def normalize_log_weights(log_weights: ArrayLike) -> tuple[FloatArray, float]:
    """Normalise log-weights: ``(log_weights - L, L)`` with ``L = log Σ exp(log_weights)``.

    ``L`` is computed as ``m + log Σ exp(log_weights - m)`` with ``m`` the largest log-weight,
    so weights like ``exp(-1e4)`` (which are 0 in float64) normalise without loss. ``-inf``
    entries are zero weights and stay ``-inf``.

    When *every* weight is zero (all ``-inf``) or any is NaN, the set carries no information
    and there is no correct normalisation: this raises :class:`ConvergenceError` rather than
    quietly resetting the weights. Callers that can recover (skip the measurement, re-seed
    the particles) catch it and report that they did.
    """
    lw = as_array(log_weights, "log_weights", (None,), finite=False)
    if lw.size == 0:
        raise InputError("log_weights: expected at least one weight, got none")
    if np.any(np.isnan(lw)):
        raise ConvergenceError(f"{int(np.isnan(lw).sum())} particle log-weight(s) are NaN")
    m = float(lw.max())
    if m == -np.inf:
        raise ConvergenceError(
            f"all {lw.size} particle weights are zero: no particle explains the measurement"
        )
    if m == np.inf:
        raise ConvergenceError("a particle log-weight is +inf")
    total = m + float(np.log(np.sum(np.exp(lw - m))))
    return lw - total, total


def effective_sample_size(weights: ArrayLike) -> float:
    """``ESS = 1 / Σ w_i²`` of normalised weights ``(P,)`` (normalised here if they are not):
    ``P`` for equal weights, 1 when one particle carries all the weight."""
    w = as_array(weights, "weights", (None,))
    if w.size == 0 or np.any(w < 0) or not w.sum() > 0:
        raise InputError("weights: expected non-negative weights with a positive sum")
    w = w / w.sum()
    # np.sum, not np.dot: a BLAS call on a few 10⁴ weights cost milliseconds on a 2-core
    # machine whenever BLAS threads had to be woken, which np.sum never does.
    return float(1.0 / np.sum(w * w))


def low_variance_resample(
    weights: ArrayLike, rng: np.random.Generator, n: int | None = None
) -> NDArray[np.intp]:
    """Indices ``(n,)`` of a low-variance (systematic) resample of ``weights (P,)``.

    One random offset ``r ~ U[0, 1/n)`` and the ``n`` equally spaced pointers
    ``r + k/n`` into the cumulative weights (Probabilistic Robotics, table 4.4), found all
    at once by ``searchsorted``. Particle ``i`` is drawn ``floor(n w_i)`` or
    ``ceil(n w_i)`` times, never more or less, which is why this scheme loses less
    diversity than independent draws. ``n`` defaults to ``P``. Weights need not be normalised.
    """
    w = as_array(weights, "weights", (None,))
    if w.size == 0 or np.any(w < 0) or not w.sum() > 0:
        raise InputError("weights: expected non-negative weights with a positive sum")
    count = w.size if n is None else int(n)
    if count < 1:
        raise InputError(f"n: expected at least one draw, got {n}")
    return low_variance_resample_unchecked(w, rng, count)


def low_variance_resample_unchecked(
    w: FloatArray, rng: np.random.Generator, count: int
) -> NDArray[np.intp]:
    """:func:`low_variance_resample` of validated weights ``(P,)`` (float64, non-negative,
    positive sum) and ``count >= 1`` draws: a particle filter's kernel, where the checks
    cost as much as the resampling. A test checks it equals the validated function."""
    cum = np.cumsum(w)
    cum /= cum[-1]  # exactly 1 at the end, so every pointer < 1 finds a particle
    pointers = (rng.random() + np.arange(count)) / count
    idx = np.searchsorted(cum, pointers, side="right")
    # Zero-weight particles have cum[i] == cum[i-1]; side="right" never selects them.
    return np.minimum(idx, w.size - 1).astype(np.intp, copy=False)


def particle_estimate(poses: ArrayLike, weights: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Weighted mean ``(3,)`` and covariance ``(3, 3)`` of a particle set.

    Positions are averaged arithmetically; the heading is the weighted circular mean
    ``atan2(Σ w sin θ, Σ w cos θ)``, so particles at ``+179°`` and ``-179°`` average to
    ``180°``, not ``0°``. The covariance uses the deviations ``(x - x̄, y - ȳ,
    wrap(θ - θ̄))`` (the same wrapped heading error as :func:`~slamkit.geometry.angle_diff`)
    and is the weighted second moment ``Σ w d dᵀ`` (no small-sample correction), symmetrised.
    """
    p = as_array(poses, "particle poses", (None, 3))
    w = as_array(weights, "weights", (p.shape[0],))
    total = float(w.sum())
    if p.shape[0] == 0 or np.any(w < 0) or not total > 0:
        raise InputError("weights: expected non-negative weights with a positive sum")
    return particle_estimate_unchecked(p, w / total)


def particle_estimate_unchecked(p: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`particle_estimate` of validated poses ``(P, 3)`` and normalised weights: the
    filter's per-step kernel (the checks cost more than the arithmetic for a few hundred
    particles). A test checks it equals the validated function."""
    # einsum, not BLAS: see effective_sample_size.
    xy = np.einsum("i,ij->j", w, p[:, :2])
    theta = float(circular_mean(p[:, 2], w))
    mean = np.array([xy[0], xy[1], theta])
    d = np.empty_like(p)
    d[:, :2] = p[:, :2] - xy
    d[:, 2] = angle_diff(p[:, 2], theta)
    cov = np.einsum("ij,ik->jk", d * w[:, None], d)  # Σ w d dᵀ
    return mean, 0.5 * (cov + cov.T)


def uniform_particles_in_box(
    bounds: tuple[float, float, float, float] | ArrayLike, n: int, rng: np.random.Generator
) -> FloatArray:
    """``n`` poses ``(n, 3)`` uniform over the box ``(xmin, ymin, xmax, ymax)`` with headings
    uniform in ``[-pi, pi)``."""
    b = as_array(bounds, "bounds", (4,))
    xmin, ymin, xmax, ymax = (float(v) for v in b)
    if not (xmax > xmin and ymax > ymin):
        raise InputError(f"bounds: expected (xmin, ymin, xmax, ymax) with max > min, got {b}")
    count = _as_count(n)
    out = np.empty((count, 3))
    out[:, 0] = rng.uniform(xmin, xmax, count)
    out[:, 1] = rng.uniform(ymin, ymax, count)
    out[:, 2] = rng.uniform(-np.pi, np.pi, count)
    return out


def uniform_particles_in_free_space(
    grid: OccupancyGrid, n: int, rng: np.random.Generator, free_threshold: float = FREE_THRESHOLD
) -> FloatArray:
    """``n`` poses ``(n, 3)`` uniform over the free cells of ``grid``.

    A free cell (probability ``<= free_threshold``) is chosen uniformly, then a point
    uniformly inside it, then a heading uniform in ``[-pi, pi)``; all cells have the same
    area, so the positions are uniform over the free space.
    """
    if not isinstance(grid, OccupancyGrid):
        raise InputError(f"grid: expected an OccupancyGrid, got {type(grid).__name__}")
    count = _as_count(n)
    free = np.flatnonzero(grid.free(free_threshold).ravel())
    if free.size == 0:
        raise InputError(f"grid: no free cells (probability <= {free_threshold}) to sample from")
    cells = free[rng.integers(0, free.size, count)]
    rows, cols = np.divmod(cells, grid.shape[1])
    res = grid.resolution
    out = np.empty((count, 3))
    out[:, 0] = grid.origin_xy[0] + (cols + rng.random(count)) * res
    out[:, 1] = grid.origin_xy[1] + (rows + rng.random(count)) * res
    out[:, 2] = rng.uniform(-np.pi, np.pi, count)
    return out


def _as_count(n: int) -> int:
    count = int(n)
    if count != n or count < 0:
        raise InputError(f"n: expected a whole number >= 0, got {n!r}")
    return count
