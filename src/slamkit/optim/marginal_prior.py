"""The marginal prior of a fixed-lag smoother: what the poses marginalised out of the window
still say about the poses that remain, as one linear factor kept at its linearisation point.

**Marginalisation (Schur complement).** Linearise every factor touching the pose(s) ``m`` to
be removed at a point ``Y``, in the right-perturbation tangents ``δ`` of
:func:`~slamkit.optim.factors.retract_poses` (``X = Y · Exp(δ)``). Their whitened sum
``Σ ‖r + J δ‖²`` is ``c + 2 gᵀ δ + δᵀ H δ`` with ``H = Σ Jᵀ J``, ``g = Σ Jᵀ r``. Split ``δ``
into ``(δ_m, δ_s)``, ``s`` the *separator* (the kept poses these factors touch), and minimise
over ``δ_m``: ``δ_m = -H_mm⁻¹ (g_m + H_ms δ_s)``, which leaves over ``δ_s`` alone ::

    H' = H_ss - H_sm H_mm⁻¹ H_ms        g' = g_s - H_sm H_mm⁻¹ g_m

(the constant dropped). Nothing is lost for the kept poses at this linearisation: the
Gaussian of ``δ_s`` has information ``H'`` whether ``m`` stays or goes.

**Square root.** ``H' = V Λ Vᵀ`` (eigenvalues below ``rtol · λ_max`` dropped: a direction the
removed factors said nothing about), ``R = Λ^½ Vᵀ``, ``d = Λ^-½ Vᵀ g'``, so that
``‖R δ_s + d‖² = δ_sᵀ H' δ_s + 2 g'ᵀ δ_s + const`` (expand the square; ``RᵀR = H'``,
``Rᵀd = g'``). The prior is then an ordinary whitened factor with residual ``R δ_s + d``.

**Evaluated when the window moves.** ``R`` and ``d`` are fixed at the linearisation point
``X̄ = Y_s`` (first estimates: while the prior stands they are never recomputed). When the
window poses move to ``X_s``, ``δ_s`` is read as the local coordinates of ``X_s`` around
``X̄``: per pose, ``e_k = (x, y, θ)`` of ``X̄_k⁻¹ X_k`` (θ wrapped), the chart of g2o's
absolute-pose prior (:func:`~slamkit.optim.factors.se2_prior_error` with ``Z = X̄_k``),
which is zero with identity Jacobian at ``X̄``. The residual is ``r(X_s) = R e(X_s) + d`` and
its Jacobian is kept at its first estimate, ``R`` (the Jacobian of ``R δ_s + d`` at ``X̄``),
as a linear factor is: the prior adds ``RᵀR`` to the window's ``H`` and ``Rᵀ r`` to its
``g`` wherever the window is. At ``X_s = X̄`` this is exact; away from it the step differs
from the exact derivative ``R · diag(∂e_k/∂δ_k)`` (``∂e_k/∂δ_k = [[R(θ_k - θ̄_k), 0],
[0, 1]]``) at first order in ``θ - θ̄``. The exact derivative is the worse choice: it makes
Gauss-Newton see the curvature ``2 (Rᵀ r)ᵀ ∂²e``, which is large where ``d`` is, in the
prior's weakest directions (``d = Λ^-½ Vᵀ g'``), and there the window's Gauss-Newton
iteration diverged (the measurement is in ``docs/estimators/optim.md``).

**The next marginalisation** linearises at the current estimate ``Y = X``, the old prior
included as the linear factor above (residual ``R e(X) + d``, Jacobian ``R``), so its
information ``RᵀR`` is carried over and the new prior's ``X̄`` is the current estimate of its
poses. Keeping instead every pose's first ``X̄`` as the point of all later marginalisations
(strict first estimates for every factor, as consistent filters do for observability)
linearises the edges between poses marginalised at different times around estimates from
different times, and its online estimates were an order of magnitude further from batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from slamkit.errors import GeometryError
from slamkit.optim import factors
from slamkit.optim.data import FloatArray, IntArray

__all__ = ["EIGEN_RTOL", "MarginalPrior", "schur_prior", "schur_square_root"]

EIGEN_RTOL = 1e-12
"""Eigenvalues of the marginal information below this fraction of the largest are dropped
(directions the removed factors do not constrain; round-off otherwise)."""


@dataclass(frozen=True)
class MarginalPrior:
    """A linear factor ``‖R e(X) + d‖²`` on the poses ``pose_ids`` (module docstring)."""

    pose_ids: IntArray  # (k,) increasing
    linearization_point: FloatArray  # (k, 3) X̄, the poses' estimates when the prior was made
    R: FloatArray  # (r, 3k) square root of the information, r ≤ 3k
    d: FloatArray  # (r,)

    @property
    def information(self) -> FloatArray:
        """``H' = RᵀR`` ``(3k, 3k)`` in the tangent order ``(x, y, θ)`` of each pose."""
        return self.R.T @ self.R

    def terms(self, X: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Whitened residual ``R e(X) + d`` ``(r,)`` and its first-estimate Jacobian ``R``
        ``(r, 3k)`` with respect to the right perturbations of ``X`` ``(k, 3)`` (rows follow
        ``pose_ids``; module docstring)."""
        e, _ = factors.se2_prior_error(X, self.linearization_point)
        return self.R @ e.ravel() + self.d, self.R


def schur_prior(
    H: FloatArray,
    g: FloatArray,
    n_marginalized: int,
    pose_ids: IntArray,
    linearization_point: FloatArray,
) -> MarginalPrior:
    """The prior left on the separator when the first ``n_marginalized`` unknowns of the
    system ``(H, g)`` are eliminated (module docstring). ``pose_ids`` ``(k,)`` and
    ``linearization_point`` ``(k, 3)`` name the remaining ``3k`` unknowns.

    Raises :class:`~slamkit.errors.GeometryError` when ``H_mm`` is not positive definite
    (the removed poses are not determined by their factors)."""
    R, d = schur_square_root(H, g, n_marginalized)
    return MarginalPrior(
        np.asarray(pose_ids, dtype=np.int64).copy(),
        np.asarray(linearization_point, dtype=np.float64).copy(),
        R,
        d,
    )


def schur_square_root(
    H: FloatArray, g: FloatArray, n_marginalized: int
) -> tuple[FloatArray, FloatArray]:
    """``(R, d)`` with ``RᵀR = H'`` and ``Rᵀd = g'``, the Schur complement of the first
    ``n_marginalized`` unknowns of ``(H, g)`` in square-root form (module docstring), for any
    unknowns (poses, landmarks). Raises :class:`~slamkit.errors.GeometryError` when ``H_mm``
    is not positive definite."""
    n = n_marginalized
    Hmm, Hms, Hss = H[:n, :n], H[:n, n:], H[n:, n:]
    try:
        c = scipy.linalg.cho_factor(Hmm, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        raise GeometryError(
            "marginalisation: the variables leaving the window are not determined by their factors"
        ) from None
    Hs = Hss - Hms.T @ scipy.linalg.cho_solve(c, Hms, check_finite=False)  # H_ss - H_sm H_mm⁻¹ H_ms
    gs = g[n:] - Hms.T @ scipy.linalg.cho_solve(c, g[:n], check_finite=False)
    Hs = 0.5 * (Hs + Hs.T)  # symmetric to round-off before the eigendecomposition
    lam, V = np.linalg.eigh(Hs)
    keep = lam > EIGEN_RTOL * max(float(lam[-1]), 0.0) if lam.shape[0] else lam > 0
    root = np.sqrt(lam[keep])
    R = root[:, None] * V[:, keep].T  # R = Λ^½ Vᵀ, so RᵀR = H'
    d = (V[:, keep].T @ gs) / root  # d = Λ^-½ Vᵀ g', so Rᵀd = g'
    return R, d
