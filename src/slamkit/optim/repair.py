"""Repair of information matrices that are not positive definite, by eigenvalue clamping.

Public 3D graphs sometimes carry information matrices with a zero or slightly negative
eigenvalue (rounded or hand-edited covariances). They are refused by default (the reader's
:class:`~slamkit.errors.DatasetFormatError` names the file and line); a read with
``repair_information="clamp"`` repairs them with :func:`clamp_information` instead, and
says so (count, lines, a warning).

**The repair.** With ``Ω = V diag(λ) Vᵀ`` and ``λ_max`` its largest eigenvalue, every
eigenvalue below ``floor = rtol · λ_max`` is raised to ``floor``:
``Ω' = V diag(max(λ, floor)) Vᵀ``. For a symmetric matrix this is the nearest matrix in the
Frobenius norm whose eigenvalues are all ``≥ floor`` (Higham 1988: the nearest symmetric
positive semidefinite matrix is the eigenvalue clipping at 0; with a floor the same argument
holds eigenvalue by eigenvalue), so it is Higham's nearest-PD answer for the symmetric
matrices every graph file stores (an upper triangle), computed in closed form per edge,
vectorised over all edges, with no iteration. The directions that had no (or negative)
information get almost none: ``floor`` with ``rtol = 1e-6`` means a standard deviation
1000 times that of the best-measured direction of the same edge, so the edge constrains
nothing it did not constrain before and the condition number stays ``≤ 1e6``. The other
eigenvalues and eigenvectors are kept; a matrix that was positive definite is not touched
(bit for bit). A matrix with no positive eigenvalue carries no information to keep and
cannot be repaired.
"""

from __future__ import annotations

import numpy as np

from slamkit.optim.data import FloatArray

__all__ = ["REPAIR_RTOL", "clamp_information", "not_positive_definite"]

REPAIR_RTOL = 1e-6
"""The clamping floor as a fraction of the matrix's largest eigenvalue (dimensionless)."""


def not_positive_definite(information: FloatArray, pd_rtol: float) -> np.ndarray:
    """``(E,)`` mask of the ``(E, r, r)`` symmetric matrices whose smallest eigenvalue is not
    above ``pd_rtol`` times their largest (the readers' positive-definiteness test)."""
    if information.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    eig = np.linalg.eigvalsh(information)
    return ~(eig[:, 0] > pd_rtol * eig[:, -1])


def clamp_information(
    information: FloatArray, rows: np.ndarray, rtol: float = REPAIR_RTOL
) -> FloatArray:
    """A copy of the ``(E, r, r)`` symmetric ``information`` with the matrices at ``rows``
    (indices or a mask) clamped to eigenvalues ``≥ rtol · λ_max`` (module docstring); the
    other matrices are copied unchanged. Every clamped matrix must have ``λ_max > 0``
    (:class:`ValueError` otherwise: the caller names the edge)."""
    out = np.array(information, dtype=np.float64, copy=True)
    sub = out[rows]
    if sub.shape[0] == 0:
        return out
    lam, V = np.linalg.eigh(sub)
    top = lam[:, -1]
    if not (top > 0).all():
        raise ValueError("an information matrix with no positive eigenvalue cannot be repaired")
    lam = np.maximum(lam, (rtol * top)[:, None])
    fixed = np.einsum("eij,ej,ekj->eik", V, lam, V)
    out[rows] = 0.5 * (fixed + np.swapaxes(fixed, 1, 2))  # exactly symmetric
    return out
