"""The window step's maths: whitened residuals and Jacobians of the window's edges, the
normal equations over the window poses, and their solve (dense when small).

Every edge incident to a window pose contributes ``H += Jᵀ J`` and ``g += Jᵀ r`` with the
whitened residual ``r = U e`` and Jacobian ``J = U ∂e/∂(δ_a, δ_b)``; the columns of poses
held fixed are dropped, so ``H`` is ``3|W| x 3|W|`` whatever the size of the graph.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.sparse

from slamkit.optim import factors
from slamkit.optim.data import FloatArray, IntArray
from slamkit.optim.sparse import LinearSolverName, SingularSystem, solve_spd

__all__ = ["DENSE_MAX", "solve_window", "window_normal_equations", "window_terms"]


def window_terms(
    X: FloatArray, a: IntArray, b: IntArray, z: FloatArray, U: FloatArray, prior: np.ndarray
) -> tuple[FloatArray, FloatArray]:
    """Whitened residuals ``r = U e`` ``(E, 3)`` and Jacobians ``U ∂e/∂(δ_a, δ_b)``
    ``(E, 3, 6)`` of edges between pose rows ``a`` and ``b`` of ``X`` (``prior``: unary
    ``se2_prior`` edges on ``a``, whose ``b`` is ignored)."""
    if not bool(prior.any()):  # the common case: relative-pose edges only
        e, Ja, Jb = factors.se2_between_error(X[a], X[b], z)
        J = np.concatenate([Ja, Jb], axis=2)  # ∂e/∂(δ_a, δ_b)
    else:
        bw = ~prior
        e = np.empty((a.shape[0], 3))
        J = np.zeros((a.shape[0], 3, 6))
        if bw.any():
            e[bw], J[bw, :, :3], J[bw, :, 3:] = factors.se2_between_error(X[a[bw]], X[b[bw]], z[bw])
        e[prior], J[prior, :, :3] = factors.se2_prior_error(X[a[prior]], z[prior])
    r = np.einsum("eij,ej->ei", U, e)  # whitened residual U e and Jacobian U J
    return r, U @ J


def window_normal_equations(
    n: int, cols: IntArray, r: FloatArray, J: FloatArray
) -> tuple[IntArray, FloatArray, FloatArray]:
    """``H = Σ Jᵀ J`` as flat indices ``row · n + col`` and values (duplicates to be summed;
    ``n²`` marks a dropped entry) and ``g = Σ Jᵀ r`` (length ``n``), from each edge's whitened
    residual ``r (E, 3)``, Jacobian ``J (E, 3, 6)`` with respect to both of its poses and the
    window columns ``cols (E, 6)`` of those six unknowns (-1: the pose is held fixed)."""
    keep = cols >= 0
    flat = np.where(
        keep[:, :, None] & keep[:, None, :], cols[:, :, None] * n + cols[:, None, :], n * n
    )
    vals = np.einsum("eki,ekj->eij", J, J)
    gcols = np.where(keep, cols, n)
    g = np.bincount(gcols.ravel(), np.einsum("eki,ek->ei", J, r).ravel(), minlength=n + 1)
    return flat.ravel().astype(np.int64), vals.ravel(), g[:n].astype(np.float64)


# Up to this size the window system is solved densely. OpenBLAS runs LAPACK's Cholesky
# multithreaded on larger matrices, which on a loaded machine costs far more than the
# sparse back-end (timings in docs/estimators/optim.md).
DENSE_MAX = 96


def solve_window(
    n: int, flat: IntArray, vals: FloatArray, g: FloatArray, solver: LinearSolverName
) -> FloatArray:
    """``δ = -H⁻¹ g``; raises :class:`SingularSystem` when ``H`` is not positive definite."""
    if n <= DENSE_MAX:
        H = np.bincount(flat, vals, minlength=n * n + 1)[: n * n].reshape(n, n)
        try:
            c = scipy.linalg.cho_factor(H, lower=True, check_finite=False)
        except np.linalg.LinAlgError as exc:
            raise SingularSystem(str(exc)) from None
        return -scipy.linalg.cho_solve(c, g, check_finite=False)
    keep = flat < n * n
    flat, vals = flat[keep], vals[keep]
    H_sparse = scipy.sparse.coo_matrix((vals, (flat // n, flat % n)), shape=(n, n)).tocsc()
    return -solve_spd(H_sparse, g, solver)
