"""The full-matrix EKF mapping update: the textbook filter over ``(2n,)`` and ``(2n, 2n)``,
the reference the block-diagonal kernels are tested against (they agree to 1e-10), and the
form EKF-SLAM needs once the pose is uncertain."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import cho_factor, cho_solve

from slamkit.errors import InputError, ShapeError
from slamkit.mapping.ekf_mapping.beliefs import DenseLandmarkBelief
from slamkit.mapping.ekf_mapping.inputs import check_reading_inputs, require_invertible
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.prob import symmetrize

__all__ = ["dense_initialise_landmark", "dense_update_landmark"]


def dense_initialise_landmark(
    belief: DenseLandmarkBelief,
    pose: ArrayLike,
    z: ArrayLike,
    landmark_id: int,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> DenseLandmarkBelief:
    """Grow the full state by one landmark seen at ``z (m,)``: mean ``g(pose, z)``,
    covariance ``[[Σ, 0], [0, L_z R L_zᵀ]]`` (zero cross-covariances: the pose is known)."""
    model = require_invertible(model)
    x, za, R = check_reading_inputs(pose, np.atleast_2d(z), noise_cov, model)
    if za.shape[0] != 1:
        raise ShapeError(f"z: expected one reading, got {za.shape[0]}")
    if landmark_id in belief.ids.tolist():
        raise InputError(f"dense_initialise_landmark: id {landmark_id} is already mapped")
    mu = model.inverse(x, za[0])
    _, Lz = model.inverse_jacobians(x, za[0])
    n2 = belief.mean.size
    cov = np.zeros((n2 + 2, n2 + 2))
    cov[:n2, :n2] = belief.cov
    cov[n2:, n2:] = symmetrize(Lz @ R @ Lz.T)  # L_z R L_zᵀ
    return DenseLandmarkBelief(
        np.append(belief.ids, np.int64(landmark_id)), np.concatenate([belief.mean, mu]), cov
    )


def dense_update_landmark(
    belief: DenseLandmarkBelief,
    index: int,
    pose: ArrayLike,
    z: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> tuple[DenseLandmarkBelief, float]:
    """The full-state EKF update with one reading ``z (m,)`` of the landmark in row
    ``index``, touching only that landmark's two columns of ``Σ`` for the gain and applying
    the Joseph form through its rank-``m`` expansion ``Σ − B − Bᵀ + K S Kᵀ``,
    ``B = K H Σ_{i:}`` (see :mod:`slamkit.mapping.ekf_mapping`). ``O(n²)``; no ``m × 2n``
    Jacobian is formed. Returns the new belief and the NIS."""
    model = require_invertible(model)
    x, za, R = check_reading_inputs(pose, np.atleast_2d(z), noise_cov, model)
    if za.shape[0] != 1:
        raise ShapeError(f"z: expected one reading, got {za.shape[0]}")
    if not 0 <= index < len(belief):
        raise InputError(f"index: expected a row in [0, {len(belief)}), got {index}")
    cols = slice(2 * index, 2 * index + 2)
    mu_i = belief.mean[cols]
    nu = model.residual(za[0], model.predict(x, mu_i))  # (m,)
    _, H = model.jacobians(x, mu_i)  # (m, 2)
    P = belief.cov
    P_ci = P[:, cols]  # Σ_{:i}, (2n, 2)
    HPi = H @ P_ci.T  # H Σ_{i:} = G Σ, (m, 2n)
    S = symmetrize(H @ P[cols, cols] @ H.T + R)  # S = H Σ_ii Hᵀ + R
    factor = cho_factor(S)
    gain = cho_solve(factor, HPi).T  # K = Σ_{:i} Hᵀ S⁻¹, (2n, m)
    nis = float(nu @ cho_solve(factor, nu))
    B = gain @ HPi  # K G Σ, rank m
    # Joseph form multiplied out: (I − K G) Σ (I − K G)ᵀ + K R Kᵀ = Σ − B − Bᵀ + K S Kᵀ.
    cov = symmetrize(P - B - B.T + gain @ S @ gain.T)
    return DenseLandmarkBelief(belief.ids, belief.mean + gain @ nu, cov), nis
