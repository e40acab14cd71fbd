"""UKF-SLAM's kernels: the unscented transform over the few state entries a step touches,
carried to the rest of the state by the conditional Gaussian (statistical linearisation).

The key fact (used three times below). Let the state be split into the part ``s`` a step
reads (``k`` numbers) and the rest ``r``, jointly Gaussian. Then ``r = μ_r + Σ_rs Σ_ss⁺
(s − μ_s) + w`` with ``w`` independent of ``s`` (and of the step's noise). For any output
``y = f(s, noise)``::

    Cov(y, r) = Cov(y, s) Σ_ss⁺ Σ_sr

exactly. The unscented transform over ``s`` and the noise alone (``2k + 1`` points, no map
entries) gives ``Cov(y, s)``; the identity carries it to the whole map in ``O(k n)``. An
unscented transform over the whole state would give the same ``Cov(y, r)`` up to its own
approximation, but costs ``O(n³)`` per step (a Cholesky factor of ``Σ``) and spreads its
points by ``√n`` standard deviations, so its answer would change with the map size.

**Prediction** (:meth:`UnscentedKernels.predict`): the augmented sigma points of the pose
and the control noise (:func:`~slamkit.localization.ukf.unscented_motion_unchecked`, the
UKF localisation's transform: ``2 (3 + k) + 1`` points) give the new pose mean, its
covariance ``Σ'_rr`` and ``C = Cov(x_r', x_r)``; the map does not move, so with
``F = C Σ_rr⁺``::

    Σ'_rm = F Σ_rm            (3 × 2L, as EKF-SLAM's G Σ_rm with G replaced by F)

**Update** with a reading ``z`` of landmark ``j`` (:meth:`UnscentedKernels.update`): sigma
points of ``s = (x_r, m_j)`` (5 numbers, 11 points) through ``h`` give ``ẑ`` (bearing by the
circular mean about the central point), ``S = Σ Wcᵢ (Zᵢ − ẑ)(Zᵢ − ẑ)ᵀ + R`` (residuals
wrapped) and ``P_sz``. With ``H̃ = P_zs Σ_ss⁺`` (the statistically linearised ``H``), the
covariance of the reading with the whole state is ``H̃ Σ_s,:`` and the Kalman update is
EKF-SLAM's (:func:`~slamkit.slam.ekf_slam.update.gain_update_inplace`) with these
ingredients: ``K = (H̃ Σ_s,:)ᵀ S⁻¹``, ``x ← x + K ν``, and the Joseph form multiplied out,
which for this ``K`` is ``Σ − K S Kᵀ`` — the UKF's covariance — and stays the exact
covariance of the estimator for any gain. The Schmidt update of a provisional feature is
the same with the gain kept to its two rows.

**A new landmark** (:meth:`UnscentedKernels.add`) from its first reading, by the inverse
model applied to the sigma points of ``[x_r; z]`` with covariance ``blockdiag(Σ_rr, R)``
(``2 (3 + m) + 1`` points)::

    m_new = Σ Wmᵢ g⁻¹(x_rᵢ, zᵢ),   Σ_new = Σ Wcᵢ (mᵢ − m_new)(mᵢ − m_new)ᵀ
    Σ_new,: = C_mx Σ_rr⁺ Σ_r,:     (C_mx = Σ Wcᵢ (mᵢ − m_new)(x_rᵢ − μ_r)ᵀ)

the reading's noise enters exactly where it acts (non-additively, through ``g⁻¹``), and
the cross-covariance with the whole state follows from the key fact — the same answer as
an unscented transform of the augmented state ``[x; z]``, without its ``O(n³)`` cost.

**Cost per step**: the prediction ``O(n)`` (one ``3 × 3`` solve and a ``3 × 2L``
product), an update ``O(n²)`` (the rank-``2m`` covariance update, as EKF-SLAM's; the sigma
points cost a constant), a new landmark ``O(n)``. ``Σ_ss⁺`` is the pseudo-inverse of the small
block (:func:`regress`): ``Σ_ss`` is singular when part of ``s`` is known exactly (a start
pose known exactly), and there the cross-covariances it multiplies are zero too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError
from slamkit.estimation.gaussian import (
    predict_measurement_unchecked,
    wrap_array,
    wrap_components,
)
from slamkit.localization.ukf import (
    SigmaPointParams,
    circular_mean_about,
    psd_sqrt,
    sigma_point_weights,
    unscented_motion_unchecked,
)
from slamkit.models import LandmarkModel, MotionModel
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.slam.ekf_slam.update import gain_update_inplace

__all__ = ["RANK_TOL", "UnscentedKernels", "regress"]


RANK_TOL = 1e-10
"""Eigenvalues of ``Σ_ss`` below this fraction of the largest count as zero in
:func:`regress`: a direction known that much better than the best-known one (standard
deviation ratio 1e-5) is treated as known exactly. Such directions are real — one
prediction from a start known exactly leaves the pose covariance of rank two (the Euler
step moves the position along the heading only) — and there the rounding of a zero
eigenvalue, divided into, would put noise of order one into the cross-covariances."""


def regress(P: FloatArray, C: FloatArray, rows: FloatArray) -> FloatArray:
    """``C P⁺ rows``: the covariance of an output with the rest of the state from its
    covariance ``C (a × k)`` with the ``k`` entries it read, their covariance ``P (k × k)``
    and their rows ``(k × n)`` of the state covariance (module docstring). ``P⁺`` is the
    pseudo-inverse from the eigen-decomposition of the small ``P``, with the cut-off
    :data:`RANK_TOL`."""
    w, V = np.linalg.eigh(P)
    top = float(w[-1])
    if not top > 0.0:  # nothing of s is uncertain: its cross-covariances are zero
        return np.zeros((C.shape[0], rows.shape[1]))
    keep = w > RANK_TOL * top
    Vk = V[:, keep]
    F = ((C @ Vk) / w[keep]) @ Vk.T  # C P⁺
    return np.asarray(F @ rows, dtype=np.float64)


@dataclass(frozen=True)
class UnscentedKernels:
    """The kernels of :class:`~slamkit.slam.ukf_slam.UkfSlam` (module docstring); the same
    fields as :class:`~slamkit.slam.ekf_slam.kernels.EkfKernels` plus the sigma points."""

    motion: MotionModel
    Q: FloatArray
    """Control-noise covariance."""
    model: LandmarkModel
    inverse: InvertibleLandmarkModel
    """The same sensor model, seen through its inverse (a new landmark from one reading)."""
    R: FloatArray
    """Reading-noise covariance."""
    angular: tuple[int, ...]
    """Indices of the reading's angular components."""
    params: SigmaPointParams = field(default_factory=SigmaPointParams)
    """α, β, κ of the scaled sigma points."""

    def __post_init__(self) -> None:
        # Fail at construction, not at the first step, if the sigma points are degenerate.
        m = int(self.R.shape[0])
        for n in (3 + int(self.Q.shape[0]), 5, 3 + m):
            sigma_point_weights(self.params, n)
        object.__setattr__(self, "sqrt_Q", psd_sqrt(self.Q, "control noise"))
        object.__setattr__(self, "sqrt_R", psd_sqrt(self.R, "reading noise"))

    sqrt_Q: FloatArray = field(init=False, repr=False, compare=False)
    """A square root of ``Q`` (computed once)."""
    sqrt_R: FloatArray = field(init=False, repr=False, compare=False)
    """A square root of ``R`` (computed once)."""

    def predict(self, mean: FloatArray, cov: FloatArray, u: FloatArray, dt: float) -> None:
        P = cov[:3, :3].copy()
        x, P_new, C = unscented_motion_unchecked(
            mean[:3].copy(), P, u, dt, self.motion, self.Q, self.params, self.sqrt_Q
        )
        mean[:3] = x
        cov[:3, :3] = P_new
        if cov.shape[0] > 3:
            cross = regress(P, C, cov[:3, 3:])  # Σ'_rm = C Σ_rr⁺ Σ_rm
            cov[:3, 3:] = cross
            cov[3:, :3] = cross.T
        if not (math.isfinite(float(P_new.sum())) and math.isfinite(float(x[0] + x[1]))):
            raise ConvergenceError("ukf-slam predict: the pose or its covariance became non-finite")

    def update(
        self,
        mean: FloatArray,
        cov: FloatArray,
        slot: int,
        z: FloatArray,
        scratch: FloatArray,
        consider: bool,
    ) -> float:
        s = slot
        idx = np.array([0, 1, 2, s, s + 1])
        P = cov[np.ix_(idx, idx)]
        Wm, Wc, c = sigma_point_weights(self.params, 5)
        L = math.sqrt(c) * psd_sqrt(P, "ukf-slam update")
        dX = np.zeros((11, 5))  # χᵢ − μ: the sigma offsets ±√c Lᵢ
        dX[1:6] = L.T
        dX[6:] = -L.T
        X = mean[idx] + dX
        Z = predict_measurement_unchecked(self.model, X[:, :3], X[:, 3:])  # (11, m)
        z_hat = Wm @ Z
        for i in self.angular:
            z_hat[i] = circular_mean_about(Z[:, i], Wm, float(Z[0, i]))
        dZ = Z - z_hat
        for i in self.angular:
            dZ[:, i] = wrap_array(dZ[:, i])  # bearing residuals wrapped before the products
        WdZ = dZ.T * Wc  # (m, 11)
        S = WdZ @ dZ + self.R
        P_zs = WdZ @ dX  # Σ Wcᵢ (Zᵢ − ẑ)(χᵢ − μ)ᵀ, (m, 5)
        rows = np.concatenate((cov[:3, :], cov[s : s + 2, :]))  # Σ_s,: (5, n)
        HS = regress(P, P_zs, rows)  # H̃ Σ_s,: = P_zs Σ_ss⁺ Σ_s,:, (m, n)
        nu = wrap_components(z - z_hat, self.angular)  # ν = z ⊖ ẑ: bearing wrapped
        return gain_update_inplace(mean, cov, s, nu, HS, S, scratch, consider=consider)

    def add(self, mean_buf: FloatArray, cov_buf: FloatArray, n: int, z: FloatArray) -> None:
        m = z.size
        N = 3 + m
        Wm, Wc, c = sigma_point_weights(self.params, N)
        sq = math.sqrt(c)
        P = cov_buf[:3, :3].copy()
        Lx = psd_sqrt(P, "ukf-slam new landmark")
        # Sigma points of [x_r; z] with the root blockdiag(Lx, √R): pose rows 1..3 and
        # N+1..N+3, reading rows 4..N and N+4..2N.
        X = np.tile(mean_buf[:3], (2 * N + 1, 1))
        E = np.tile(z, (2 * N + 1, 1))
        X[1:4] += sq * Lx.T
        X[N + 1 : N + 4] -= sq * Lx.T
        E[4 : N + 1] += sq * self.sqrt_R.T
        E[N + 4 :] -= sq * self.sqrt_R.T
        M = np.asarray(self.inverse.inverse(X, E), dtype=np.float64)  # (2N + 1, 2)
        m_new = Wm @ M
        D = M - m_new
        P_new = (D.T * Wc) @ D
        # Cov(m_new, x_r): only the pose rows have an offset (±√c Lx columns, Wc = 1/(2c)).
        C = (D[1:4] - D[N + 1 : N + 4]).T @ Lx.T * (0.5 / sq)
        cross = regress(P, C, cov_buf[:3, :n])  # Σ_new,: = C Σ_rr⁺ Σ_r,:
        mean_buf[n : n + 2] = m_new
        cov_buf[n : n + 2, :n] = cross
        cov_buf[:n, n : n + 2] = cross.T
        cov_buf[n : n + 2, n : n + 2] = 0.5 * (P_new + P_new.T)
