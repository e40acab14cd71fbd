"""Landmark readings in MCL: the log-likelihood of point landmarks with known identities for
every particle, the correction step it drives, and the innovation log of the readings
against a Gaussian summary of the particles (which gives MCL the NIS statistics of the EKF).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import InputError
from slamkit.estimation.particles import ParticleSet
from slamkit.localization.mcl.core import MeasurementUpdate, reweight
from slamkit.maps import LandmarkMap
from slamkit.models import LandmarkModel

__all__ = [
    "LandmarkInnovations",
    "landmark_innovations",
    "landmark_innovations_unchecked",
    "landmark_log_likelihood",
    "landmark_log_likelihood_unchecked",
    "mcl_update_landmarks",
    "whitener",
]


def _known_readings(
    z: ArrayLike, ids: ArrayLike, landmarks: LandmarkMap, model: LandmarkModel, noise_cov: ArrayLike
) -> tuple[FloatArray, NDArray[np.int64], FloatArray]:
    """Validated readings ``z (K, m)`` with ids ``(K,)`` and noise ``(m, m)``: the readings
    ``(K', m)`` of landmarks in the map, their ids ``(K',)``, and the noise."""
    m = model.dim
    zz = as_array(z, "z", (None, m))
    id_arr = np.asarray(ids)
    if id_arr.shape != (zz.shape[0],) or not np.issubdtype(id_arr.dtype, np.integer):
        raise InputError(f"ids: expected {zz.shape[0]} integers, got shape {id_arr.shape}")
    R = as_covariance(noise_cov, "noise_cov", m)
    known = np.isin(id_arr, landmarks.ids)
    return zz[known], id_arr[known].astype(np.int64), R


def landmark_log_likelihood(
    poses: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike,
    landmarks: LandmarkMap,
    model: LandmarkModel,
    noise_cov: ArrayLike,
) -> tuple[FloatArray, int]:
    """``log p(z | x_i)`` ``(P,)`` of landmark readings ``z (K, m)`` with identities ``ids
    (K,)``, and how many readings were used.

    Each reading is Gaussian about the model's prediction, ``N(z_k; h(x_i, l_k), R)``
    (``R = noise_cov (m, m)``), with bearing residuals wrapped; readings are independent, so
    their log-densities add. Readings with an unknown id (``-1``) or an id that is not in
    ``landmarks`` are skipped (the count tells how many were not).
    """
    p = as_array(poses, "poses", (None, 3))
    zk, used, R = _known_readings(z, ids, landmarks, model, noise_cov)
    if used.size == 0:
        return np.zeros(p.shape[0]), 0
    lm = landmarks.position_of(used)  # (K, 2)
    L_inv, log_norm = whitener(R)
    return landmark_log_likelihood_unchecked(p, zk, lm, model, L_inv, log_norm), int(zk.shape[0])


def whitener(R: FloatArray) -> tuple[FloatArray, float]:
    """``(L⁻¹, log_norm)`` for a reading noise ``R = L Lᵀ`` (Cholesky): ``|L⁻¹ ν|²`` is the
    Mahalanobis distance ``νᵀ R⁻¹ ν`` and ``log_norm = -½ log|2πR|`` the log of the Gaussian's
    normaliser (``log|R| = 2 Σ log diag(L)``)."""
    m = R.shape[0]
    L = np.linalg.cholesky(R)
    # L⁻¹ comes from one m × m solve (NumPy's solve, not SciPy's solve_triangular: a SciPy
    # LAPACK call right after NumPy BLAS work can stall while the two libraries' OpenBLAS
    # thread pools compete for the cores; timings in docs/estimators/mcl.md).
    L_inv: FloatArray = np.linalg.solve(L, np.eye(m))
    log_norm = -(float(np.sum(np.log(np.diag(L)))) + 0.5 * m * float(np.log(2.0 * np.pi)))
    return L_inv, log_norm


def landmark_log_likelihood_unchecked(
    poses: FloatArray,
    zk: FloatArray,
    lm: FloatArray,
    model: LandmarkModel,
    L_inv: FloatArray,
    log_norm: float,
) -> FloatArray:
    """:func:`landmark_log_likelihood` of validated poses ``(P, 3)``, known readings ``zk
    (K, m)`` of the landmarks at ``lm (K, 2)`` and the :func:`whitener` of their noise."""
    z_hat = model.predict(poses[:, None, :], lm[None, :, :])  # (P, K, m)
    nu = model.residual(zk[None, :, :], z_hat)
    # Mahalanobis distance |L⁻¹ ν|², no inverse of R; einsum keeps the (P, K) batch out of
    # BLAS/LAPACK.
    white = np.einsum("ij,pkj->pki", L_inv, nu)
    maha = np.sum(white * white, axis=(1, 2))
    # log N(ν; 0, R) = -½ νᵀR⁻¹ν - ½ log|2πR| per reading; the K readings are independent.
    out: FloatArray = -0.5 * maha + zk.shape[0] * log_norm
    return out


def mcl_update_landmarks(
    particles: ParticleSet,
    z: ArrayLike,
    ids: ArrayLike,
    landmarks: LandmarkMap,
    model: LandmarkModel,
    noise_cov: ArrayLike,
) -> MeasurementUpdate:
    """Weight the particles by landmark readings (see :func:`landmark_log_likelihood`).

    Raises :class:`ConvergenceError` if every weight becomes zero.
    """
    ll, n = landmark_log_likelihood(particles.poses, z, ids, landmarks, model, noise_cov)
    out = reweight(particles, ll)
    return MeasurementUpdate(out.particles, out.log_likelihood, out.log_evidence, n)


@dataclass(frozen=True)
class LandmarkInnovations:
    """Innovations of landmark readings against a Gaussian summary of the belief.

    ``landmark_ids (K,)`` of the readings used, innovations ``nu (K, m)`` (bearings wrapped),
    their covariances ``S (K, m, m)`` and ``nis (K,) = νᵀ S⁻¹ ν``, each with ``m`` degrees of
    freedom.
    """

    landmark_ids: NDArray[np.int64]
    nu: FloatArray
    S: FloatArray
    nis: FloatArray


def landmark_innovations(
    mean: ArrayLike,
    cov: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike,
    landmarks: LandmarkMap,
    model: LandmarkModel,
    noise_cov: ArrayLike,
) -> LandmarkInnovations:
    """Each reading's innovation against the belief ``N(mean (3,), cov (3, 3))``, as an EKF
    would see it: ``ν_k = z_k ⊖ h(μ, l_k)`` and ``S_k = H_k Σ H_kᵀ + R`` with ``H_k`` the pose
    Jacobian of ``h`` at the mean.

    For a particle filter, pass the weighted mean and covariance of the particles *before*
    the update (:func:`~slamkit.estimation.particles.particle_estimate`): if the filter is
    consistent, each ``nis`` is then (approximately) ``χ²_m`` distributed, so the standard
    NIS statistics apply to it. Every reading of the call is compared with the same belief
    (an EKF would condition the second reading on the first): readings of one event share
    the belief's error, which correlates their NIS values slightly. Readings with an id that
    is unknown or not in ``landmarks`` are left out; readings at zero range from the mean
    raise :class:`~slamkit.errors.GeometryError`.
    """
    mu = as_array(mean, "mean", (3,))
    sigma = as_covariance(cov, "cov", 3, semidefinite=True)
    zk, used, R = _known_readings(z, ids, landmarks, model, noise_cov)
    return landmark_innovations_unchecked(
        mu, sigma, zk, used, landmarks.position_of(used), model, R
    )


def landmark_innovations_unchecked(
    mu: FloatArray,
    sigma: FloatArray,
    zk: FloatArray,
    ids: NDArray[np.int64],
    lm: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
) -> LandmarkInnovations:
    """:func:`landmark_innovations` of validated arrays: known readings ``zk (K, m)`` with
    ids ``(K,)`` of the landmarks at ``lm (K, 2)``."""
    poses = np.broadcast_to(mu, (ids.size, 3))
    z_hat = model.predict(poses, lm)  # (K, m)
    H, _ = model.jacobians(poses, lm)  # (K, m, 3)
    nu = model.residual(zk, z_hat)
    S = np.einsum("kia,ab,kjb->kij", H, sigma, H) + R  # H Σ Hᵀ + R
    S = 0.5 * (S + np.swapaxes(S, -1, -2))
    # νᵀ S⁻¹ ν by a solve per reading (S is m × m, m <= 2), no inverse.
    nis = np.einsum("ki,ki->k", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    return LandmarkInnovations(ids, nu, S, nis)
