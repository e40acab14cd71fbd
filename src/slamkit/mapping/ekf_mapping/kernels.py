"""The per-landmark Gaussian kernels of EKF mapping in block-diagonal form: initialise
landmarks from first sightings, update them (one 2-D Kalman filter each, vectorised over a
scan's readings), and the squared Mahalanobis distances data association gates on.

The ``*_unchecked`` kernels trust their arguments (the estimators' hot path); the public
functions validate them and call the kernels.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray
from slamkit.errors import InputError
from slamkit.estimation.gaussian import check_covariance
from slamkit.mapping.ekf_mapping.beliefs import LandmarkBelief, trusted_belief
from slamkit.mapping.ekf_mapping.inputs import (
    as_landmark_ids,
    check_reading_inputs,
    require_invertible,
)
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.prob import mahalanobis_squared, symmetrize

__all__ = [
    "association_distances",
    "association_distances_unchecked",
    "initialise_landmarks",
    "initialise_unchecked",
    "update_landmarks",
    "update_unchecked",
]


def initialise_unchecked(
    belief: LandmarkBelief,
    x: FloatArray,
    z: FloatArray,
    new_ids: NDArray[np.int64],
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> LandmarkBelief:
    """:func:`initialise_landmarks` of checked arguments (new, distinct ``new_ids``)."""
    mu = model.inverse(x, z)  # μ = g(x, z), (K, 2)
    _, Lz = model.inverse_jacobians(x, z)  # (K, 2, m)
    cov = symmetrize(Lz @ R @ np.swapaxes(Lz, -1, -2))  # L_z R L_zᵀ; pose known: no L_x term
    return trusted_belief(
        np.concatenate([belief.ids, new_ids]),
        np.concatenate([belief.means, mu.reshape(-1, 2)]),
        np.concatenate([belief.covs, cov.reshape(-1, 2, 2)]),
    )


def update_unchecked(
    belief: LandmarkBelief,
    rows: NDArray[np.int64],
    x: FloatArray,
    z: FloatArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> tuple[LandmarkBelief, FloatArray]:
    """:func:`update_landmarks` of checked arguments (distinct valid ``rows``)."""
    mu, P = belief.means[rows], belief.covs[rows]  # (K, 2), (K, 2, 2)
    nu = model.residual(z, model.predict(x, mu))  # ν = z ⊟ h(x, μ), (K, m)
    _, H = model.jacobians(x, mu)  # (K, m, 2)
    HP = H @ P  # (K, m, 2)
    S = HP @ np.swapaxes(H, -1, -2) + R  # S = H P Hᵀ + R
    gain = np.swapaxes(np.linalg.solve(S, HP), -1, -2)  # K = P Hᵀ S⁻¹ = (S⁻¹ H P)ᵀ
    nis = np.einsum("ki,ki->k", nu, np.linalg.solve(S, nu[..., None])[..., 0])  # νᵀ S⁻¹ ν
    A = np.eye(2) - gain @ H  # I − K H, (K, 2, 2)
    # Joseph form: (I − K H) P (I − K H)ᵀ + K R Kᵀ stays PSD under round-off.
    P_new = symmetrize(A @ P @ np.swapaxes(A, -1, -2) + gain @ R @ np.swapaxes(gain, -1, -2))
    check_covariance(P_new, "ekf-mapping update")  # the check every Gaussian filter shares
    means, covs = belief.means.copy(), belief.covs.copy()
    means[rows] = mu + np.einsum("kij,kj->ki", gain, nu)  # μ + K ν
    covs[rows] = P_new
    return trusted_belief(belief.ids, means, covs), nis


def association_distances_unchecked(
    belief: LandmarkBelief,
    x: FloatArray,
    z: FloatArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> FloatArray:
    """:func:`association_distances` of checked arguments."""
    if len(belief) == 0 or z.shape[0] == 0:
        return np.zeros((z.shape[0], len(belief)))
    z_hat = model.predict(x, belief.means)  # (n, m)
    _, H = model.jacobians(x, belief.means)  # (n, m, 2)
    S = symmetrize(H @ belief.covs @ np.swapaxes(H, -1, -2) + R)  # (n, m, m)
    nu = model.residual(z[:, None, :], z_hat[None, :, :])  # (K, n, m)
    return mahalanobis_squared(nu, S)


def initialise_landmarks(
    belief: LandmarkBelief,
    pose: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> LandmarkBelief:
    """Add the landmarks first seen in readings ``z (K, m)`` with new ``ids (K,)`` from the
    known ``pose (3,)``: ``μ = g(pose, z)``, ``Σ = L_z R L_zᵀ`` (no pose term: the pose is
    known), no cross-covariances. Raises :class:`InputError` if an id is already mapped."""
    model = require_invertible(model)
    x, za, R = check_reading_inputs(pose, z, noise_cov, model)
    new_ids = as_landmark_ids(ids, "ids", za.shape[0])
    if np.any(belief.index_of(new_ids) >= 0) or np.unique(new_ids).size != new_ids.size:
        raise InputError("initialise_landmarks: an id is already in the map or repeated")
    return initialise_unchecked(belief, x, za, new_ids, R, model)


def update_landmarks(
    belief: LandmarkBelief,
    index: ArrayLike,
    pose: ArrayLike,
    z: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> tuple[LandmarkBelief, FloatArray]:
    """EKF update of the landmarks in rows ``index (K,)`` (distinct) with their readings
    ``z (K, m)`` from the known ``pose (3,)``.

    Each landmark is its own 2-D Kalman filter (the block-diagonal form): ``S = H P Hᵀ + R``,
    ``K = P Hᵀ S⁻¹``, ``μ ← μ + K ν``, ``P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ`` (Joseph),
    vectorised over the ``K`` readings. Returns the new belief and the normalised innovation
    squared ``νᵀ S⁻¹ ν`` of each reading ``(K,)``.
    """
    model = require_invertible(model)
    x, za, R = check_reading_inputs(pose, z, noise_cov, model)
    rows = as_landmark_ids(index, "index", za.shape[0])
    if np.any((rows < 0) | (rows >= len(belief))):
        raise InputError(f"index: expected rows in [0, {len(belief)}), got {rows.tolist()}")
    if np.unique(rows).size != rows.size:
        raise InputError("index: expected distinct landmarks (update repeats one at a time)")
    return update_unchecked(belief, rows, x, za, R, model)


def association_distances(
    belief: LandmarkBelief,
    pose: ArrayLike,
    z: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> FloatArray:
    """Squared Mahalanobis distances ``(K, n)`` of readings ``z (K, m)`` to every mapped
    landmark: ``νᵀ S⁻¹ ν`` with ``ν = z ⊟ h(pose, μ_j)`` and ``S = H_j P_j H_jᵀ + R``."""
    model = require_invertible(model)
    x, za, R = check_reading_inputs(pose, z, noise_cov, model)
    return association_distances_unchecked(belief, x, za, R, model)
