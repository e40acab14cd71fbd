"""Windowed correspondence for EKF-SLAM: the few landmarks a reading can be paired with,
found from two-vectors before any predicted reading is formed.

A reading ``z`` seen from the pose ``x_r`` places its landmark at ``p = g⁻¹(x_r, z)`` with
the covariance ``C = L_x Σ_rr L_xᵀ + L_z R L_zᵀ`` (``L_x = ∂g⁻¹/∂x_r``, ``L_z = ∂g⁻¹/∂z``).
To first order the innovation against landmark ``j`` is ``ν ≈ −H_j δ`` with
``δ = m_j − p`` and ``S ≈ H_j Cov(δ) H_jᵀ``, so the gate's ``d² = νᵀ S⁻¹ ν`` is about
``δᵀ Cov(δ)⁻¹ δ``. ``Cov(δ)`` holds the unknown correlation of ``m_j`` with the pose, but
``(a − b)(a − b)ᵀ ⪯ 2 a aᵀ + 2 b bᵀ`` bounds it for any correlation:
``Cov(δ) ⪯ 2 (C + Σ_jj) ⪯ 2 (tr C + tr Σ_jj) I``, hence

    d² ≥ |δ|² / (2 (tr C + tr Σ_jj))

and a landmark with ``|δ|² > 2 γ (tr C + tr Σ_jj)`` cannot pass a gate ``d² ≤ γ``
(up to the linearisation). The window of a reading is the landmarks inside that circle,
with ``γ`` the new-landmark threshold (the larger one: a reading starts a feature only if
every landmark is beyond it, so no landmark that could stop a creation is left out). It
costs ``O(K L)`` subtractions of two-vectors; the predicted readings, their Jacobians and
``S`` — ``O(U)`` 3 × 3 products — are formed only for the landmarks in some window.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.models.measurement import InvertibleLandmarkModel

__all__ = ["reading_window"]


def reading_window(
    mean: FloatArray,
    cov: FloatArray,
    z: FloatArray,
    model: InvertibleLandmarkModel,
    R: FloatArray,
    gate: float,
) -> NDArray[np.bool_]:
    """``(K, L)``: which landmarks of the state ``mean (3 + 2L,)``, ``cov`` lie inside the
    window of each reading of ``z (K, m)`` for the χ² threshold ``gate`` (the module
    docstring derives the circle ``|m_j − g⁻¹(x_r, z)|² ≤ 2 γ (tr C + tr Σ_jj)``)."""
    K, L = z.shape[0], (mean.size - 3) // 2
    if K == 0 or L == 0:
        return np.zeros((K, L), dtype=bool)
    x = mean[:3]
    p = model.inverse(np.broadcast_to(x, (K, 3)), z)  # (K, 2)
    Lx, Lz = model.inverse_jacobians(np.broadcast_to(x, (K, 3)), z)
    C = Lx @ cov[:3, :3] @ np.swapaxes(Lx, -1, -2) + Lz @ R @ np.swapaxes(Lz, -1, -2)
    tr_c = np.trace(C, axis1=-2, axis2=-1)  # (K,)
    idx = 3 + 2 * np.arange(L)
    tr_j = cov[idx, idx] + cov[idx + 1, idx + 1]  # (L,)
    lm = mean[3:].reshape(L, 2)
    d = lm[None, :, :] - p[:, None, :]
    dist2 = np.einsum("kli,kli->kl", d, d)
    return np.asarray(dist2 <= 2.0 * gate * (tr_c[:, None] + tr_j[None, :]))
