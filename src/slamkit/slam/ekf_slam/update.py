"""The EKF-SLAM measurement update on the active state, in place: 5 columns, Joseph form.

``h(x_r, m_j)`` depends on five state entries, so its ``m × n`` Jacobian ``H`` is zero
outside the columns ``0, 1, 2, s_j, s_j + 1``, where it holds ``H_r = ∂h/∂x_r`` and
``H_j = ∂h/∂m_j``. Because ``Σ`` is symmetric, ``H Σ`` (``m × n``) needs five ROWS of ``Σ``
(contiguous in memory)::

    H Σ = H_r Σ[0:3, :] + H_j Σ[s_j:s_j+2, :]          (= (Σ Hᵀ)ᵀ)
    S   = (H Σ)[:, 0:3] H_rᵀ + (H Σ)[:, s_j:s_j+2] H_jᵀ + R
    Kᵀ  = S⁻¹ (H Σ)                                      (K = Σ Hᵀ S⁻¹, n × m)
    x   ← x + K ν,   ν = z ⊖ h(x_r, m_j)                 (bearing wrapped, heading wrapped)

and the Joseph form ``Σ ← (I − K H) Σ (I − K H)ᵀ + K R Kᵀ``, multiplied out:
``Σ − K (H Σ) − (H Σ)ᵀ Kᵀ + K S Kᵀ``. With ``D = K S / 2 − (H Σ)ᵀ`` this is exactly

    Σ ← Σ + D Kᵀ + K Dᵀ                                  (one rank-2m product)

— see :mod:`slamkit.slam.ekf_slam` for why the Joseph form and not the short one. The
product is applied block-row by block-row through a small scratch buffer
(:data:`SCRATCH_BYTES`), so one update reads and writes the ``n × n`` matrix once and
allocates nothing of size ``n²``.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError
from slamkit.estimation.gaussian import small_spd_inverse, wrap_components
from slamkit.models import LandmarkModel
from slamkit.slam.common import reading_jacobians

__all__ = [
    "SCRATCH_BYTES",
    "check_diagonal",
    "gain_update_inplace",
    "rank_update",
    "update_inplace",
]

SCRATCH_BYTES = 1 << 20
"""Size of the block of rows the rank-2m covariance product is formed in: small enough to
stay in cache, so the ``n × n`` matrix is streamed through memory once per update (the
bandwidth by block size is measured in ``docs/estimators/ekf_slam.md``)."""


def rank_update(cov: FloatArray, A: FloatArray, B: FloatArray, scratch: FloatArray) -> None:
    """``cov += Aᵀ B`` for ``A, B (k, n)`` in blocks of rows formed in ``scratch`` (no
    ``n × n`` temporary: one read and one write of ``cov``)."""
    n = cov.shape[0]
    rows = max(1, min(n, scratch.size // max(n, 1)))  # the caller gives scratch.size >= n
    for a in range(0, n, rows):
        b = min(a + rows, n)
        t = scratch[: (b - a) * n].reshape(b - a, n)
        np.matmul(A[:, a:b].T, B, out=t)
        cov[a:b] += t


def update_inplace(
    mean: FloatArray,
    cov: FloatArray,
    slot: int,
    z: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
    angular: tuple[int, ...],
    scratch: FloatArray,
    *,
    consider: bool = False,
) -> tuple[float, FloatArray, FloatArray]:
    """The 5-column EKF update with reading ``z`` of the landmark in state rows ``slot``,
    ``slot + 1``; returns ``(nis, ν, S)``. ``scratch`` holds at least ``n`` numbers.

    ``consider=True`` is the Schmidt ("consider") update of a provisional feature: the gain
    is zero outside the feature's two rows, so the pose and the rest of the map keep their
    mean and covariance, and only the feature's rows and columns change — by the Joseph
    form, which is the exact covariance of the filter for ANY gain, this one included::

        K_f = (Σ Hᵀ)_f S⁻¹,  Σ_f,: ← Σ_f,: − K_f (H Σ),
        Σ_ff ← Σ_ff − K_f (H Σ)_:,f − (H Σ)_:,fᵀ K_fᵀ + K_f S K_fᵀ
    """
    s = slot
    h, Hr, Hj = reading_jacobians(model, mean[:3], mean[s : s + 2])
    nu = wrap_components(z - h, angular)  # ν = z ⊖ h: bearing wrapped
    HS = Hr @ cov[:3, :] + Hj @ cov[s : s + 2, :]  # H Σ from five rows (m × n)
    S = HS[:, :3] @ Hr.T + HS[:, s : s + 2] @ Hj.T + R
    S = 0.5 * (S + S.T)
    nis = gain_update_inplace(mean, cov, s, nu, HS, S, scratch, consider=consider)
    return nis, nu, S


def gain_update_inplace(
    mean: FloatArray,
    cov: FloatArray,
    slot: int,
    nu: FloatArray,
    HS: FloatArray,
    S: FloatArray,
    scratch: FloatArray,
    *,
    consider: bool = False,
) -> float:
    """The Kalman update of :func:`update_inplace` from its ingredients: the innovation
    ``ν (m,)`` (angles wrapped), ``H Σ = (Σ Hᵀ)ᵀ (m × n)`` — the covariance of the reading's
    prediction with the whole state — and ``S (m × m)``; returns the NIS. Any filter whose
    reading depends on the pose and the landmark in rows ``slot, slot + 1`` only can supply
    them (the UKF's statistically linearised ``H Σ``, see :mod:`slamkit.slam.ukf_slam`);
    ``consider`` as in :func:`update_inplace`."""
    s = slot
    S = 0.5 * (S + S.T)
    S_inv = small_spd_inverse(S, "ekf-slam update")
    if S_inv is None:  # readings of more than two components
        S_inv = _spd_inverse(S)
    Sinv_nu = S_inv @ nu
    nis = float(nu @ Sinv_nu)
    if consider:
        Kf = HS[:, s : s + 2].T @ S_inv  # (2, m): the feature's rows of the gain
        mean[s : s + 2] += Kf @ nu
        HSf = HS[:, s : s + 2]  # (m, 2)
        block = cov[s : s + 2, s : s + 2] - Kf @ HSf - HSf.T @ Kf.T + Kf @ S @ Kf.T
        row = cov[s : s + 2, :] - Kf @ HS
        cov[s : s + 2, :] = row
        cov[:, s : s + 2] = row.T
        cov[s : s + 2, s : s + 2] = 0.5 * (block + block.T)
        if not math.isfinite(float(block.sum() + mean[s] + mean[s + 1])):
            raise ConvergenceError("ekf-slam update: the covariance became non-finite")
        return nis
    Kt = S_inv @ HS  # Kᵀ = S⁻¹ H Σ (m × n)
    if not math.isfinite(float(Kt.sum() + nis)):
        raise ConvergenceError("ekf-slam update: the gain became non-finite")
    mean += HS.T @ Sinv_nu  # x + K ν with K ν = Σ Hᵀ S⁻¹ ν
    wrap_components(mean, (2,))
    # Joseph form multiplied out: Σ + D Kᵀ + K Dᵀ with D = K S / 2 − Σ Hᵀ (module docstring).
    Dt = 0.5 * (S @ Kt) - HS  # Dᵀ (m × n)
    rank_update(cov, np.concatenate((Dt, Kt)), np.concatenate((Kt, Dt)), scratch)
    # Exact symmetry where the next steps read and the checks look.
    cov[:3, :3] = 0.5 * (cov[:3, :3] + cov[:3, :3].T)
    blk = cov[s : s + 2, s : s + 2]
    cov[s : s + 2, s : s + 2] = 0.5 * (blk + blk.T)
    return nis


def _spd_inverse(S: FloatArray) -> FloatArray:
    try:
        factor = scipy.linalg.cho_factor(S)
    except np.linalg.LinAlgError:
        raise ConvergenceError(
            "ekf-slam update: the innovation covariance S is not positive definite"
        ) from None
    return np.asarray(scipy.linalg.cho_solve(factor, np.eye(S.shape[0])), dtype=np.float64)


def check_diagonal(cov: FloatArray) -> None:
    """Raise :class:`~slamkit.errors.ConvergenceError` naming the state index if a variance
    on the diagonal of ``cov`` is negative (beyond rounding, ``1e-9`` of the largest): the
    cheap definiteness check run after every map update."""
    d = np.diagonal(cov)
    low = float(d.min())
    if low < -1e-9 * max(float(d.max()), 1e-300):
        i = int(np.argmin(d))
        raise ConvergenceError(
            f"the covariance lost positive definiteness (variance {low:.3g} at state index {i})"
        )
