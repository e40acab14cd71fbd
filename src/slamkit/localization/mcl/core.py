"""The particle filter's steps as pure functions over a
:class:`~slamkit.estimation.particles.ParticleSet` (Probabilistic Robotics, chapter 8):
prediction through the motion model, Bayes' rule in log space, the laser-scan correction
through the likelihood field (tempered), and low-variance resampling with augmented MCL's
random particles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.errors import ConvergenceError, InputError
from slamkit.estimation.particles import (
    ParticleSet,
    low_variance_resample,
    normalize_log_weights,
)
from slamkit.localization.mcl.sampling import PoseSampler, sample_poses
from slamkit.maps.likelihood_field import LikelihoodField, log_likelihood, usable_beams
from slamkit.models import MotionModel
from slamkit.models.motion import motion_kernels

__all__ = [
    "MeasurementUpdate",
    "control_noise_root",
    "mcl_predict",
    "mcl_predict_unchecked",
    "mcl_resample",
    "mcl_update_laser",
    "moved_finite",
    "reweight",
]


def mcl_predict(
    particles: ParticleSet,
    u: ArrayLike,
    dt: float,
    model: MotionModel,
    control_cov: ArrayLike,
    rng: np.random.Generator,
) -> ParticleSet:
    """Sample every particle's next pose: ``x_i ← g(x_i, u + ε_i, dt)``, ``ε_i ~ N(0, Q)``
    independently per particle (``Q = control_cov``). Weights are unchanged."""
    poses = moved_finite(model.sample(particles.poses, u, dt, control_cov, rng))
    return ParticleSet(poses, particles.log_weights.copy())


def moved_finite(poses: FloatArray) -> FloatArray:
    """``poses`` after a motion step, or :class:`~slamkit.errors.ConvergenceError` when the
    motion took a particle to a non-finite pose (an overflowing control: the filter has
    diverged, the inputs were finite)."""
    if not math.isfinite(float(poses.sum())):
        raise ConvergenceError("the motion moved particles to non-finite poses")
    return poses


def control_noise_root(control_cov: FloatArray) -> FloatArray:
    """A square root ``A`` with ``A Aᵀ = Q`` of a PSD control covariance (``eigh``, like the
    motion models' sampler, so that singular ``Q`` works)."""
    eigval, eigvec = np.linalg.eigh(control_cov)
    root: FloatArray = eigvec * np.sqrt(np.clip(eigval, 0.0, None))[None, :]
    return root


def mcl_predict_unchecked(
    poses: FloatArray,
    u: FloatArray,
    dt: float,
    model: MotionModel,
    noise_root: FloatArray,
    rng: np.random.Generator,
) -> FloatArray:
    """:func:`mcl_predict`'s poses for validated arrays and a precomputed noise root (see
    :func:`control_noise_root`): the estimator's per-step kernel. It draws the same numbers
    in the same order as ``model.sample`` (a test checks the two agree to 1e-12), but skips
    validating and factorising ``Q`` at every step, which cost more than moving a few
    hundred particles."""
    k = noise_root.shape[0]
    eps = rng.standard_normal((poses.shape[0], k)) @ noise_root.T  # ε ~ N(0, A Aᵀ)
    return moved_finite(motion_kernels(model).apply_unchecked(poses, u + eps, dt))


@dataclass(frozen=True)
class MeasurementUpdate:
    """The result of a correction step.

    ``particles`` carry the new normalised weights; ``log_likelihood (P,)`` is
    ``log p(z | x_i)`` of each particle; ``log_evidence`` is ``log Σ_i w_i p(z | x_i)`` with
    the weights *before* the update — the filter's estimate of ``p(z_t | z_1:t-1)``, which
    augmented MCL averages; ``n_readings`` is how many readings (beams, landmark readings)
    entered the update.
    """

    particles: ParticleSet
    log_likelihood: FloatArray
    log_evidence: float
    n_readings: int


def reweight(particles: ParticleSet, log_lik: ArrayLike) -> MeasurementUpdate:
    """Bayes' rule in log space: ``log w_i ← log w_i + log p(z | x_i)``, then normalise.

    Raises :class:`ConvergenceError` when no particle has a non-zero weight afterwards (see
    :func:`~slamkit.estimation.particles.normalize_log_weights`); the particles are never
    silently reset.
    """
    ll = as_array(log_lik, "log_likelihood", (len(particles),), finite=False)
    logw, total = normalize_log_weights(particles.log_weights + ll)
    return MeasurementUpdate(ParticleSet(particles.poses.copy(), logw), ll, total, 0)


def mcl_update_laser(
    particles: ParticleSet,
    ranges: ArrayLike,
    field: LikelihoodField,
    beam_angles: ArrayLike,
    sensor_offset: ArrayLike | None = None,
    beam_stride: int = 1,
    exponent: float = 1.0,
) -> MeasurementUpdate:
    """Weight the particles by a laser scan through the likelihood field (see
    :func:`slamkit.maps.likelihood_field.log_likelihood`), tempered:
    ``w_i ← w_i p(z | x_i)^exponent``.

    The field scores the beams as independent, but neighbouring beams' errors are not (they
    hit the same wall, through the same map cells): ``exponent = 1/k`` counts every ``k``
    used beams as one independent reading. Raises :class:`ConvergenceError` if every weight
    becomes zero.
    """
    e = as_positive(exponent, "exponent")
    ll = log_likelihood(field, particles.poses, ranges, beam_angles, sensor_offset, beam_stride)
    if e != 1.0:
        ll = e * ll
    n = usable_beams(field, ranges, beam_angles, beam_stride)
    out = reweight(particles, ll)
    return MeasurementUpdate(out.particles, out.log_likelihood, out.log_evidence, n)


def mcl_resample(
    particles: ParticleSet,
    rng: np.random.Generator,
    n: int | None = None,
    *,
    n_random: int = 0,
    sampler: PoseSampler | None = None,
) -> ParticleSet:
    """An equally weighted set of ``n`` particles (default: as many as now).

    ``n - n_random`` are drawn by low-variance resampling (copies, by fancy indexing); the
    other ``n_random`` are fresh poses from ``sampler`` (augmented MCL's random particles).
    """
    count = len(particles) if n is None else int(n)
    k = int(n_random)
    if not 0 <= k <= count or count < 1:
        raise InputError(f"n_random: expected 0 <= n_random <= n (n = {count}), got {n_random}")
    parts = []
    if count - k > 0:
        idx = low_variance_resample(particles.weights, rng, count - k)
        parts.append(particles.poses[idx])
    if k > 0:
        if sampler is None:
            raise InputError("n_random > 0 needs a sampler of random poses")
        parts.append(sample_poses(sampler, k, rng))
    return ParticleSet.uniform_weights(np.concatenate(parts, axis=0))
