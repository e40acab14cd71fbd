"""The error model shared by the ICP matchers: reference normals, the Gauss-Newton Hessian of
the point-to-line error, the pose covariance and the degeneracy test.

**The final least-squares problem.** At the solution ``x = (t_x, t_y, θ)`` every kept
correspondence ``i`` pairs a current point ``q_i`` (current sensor frame) with a reference
point ``p_i`` and the unit normal ``n_i`` of the reference surface there. Its residual is the
normal distance ``e_i(x) = n_iᵀ (R(θ) q_i + t - p_i)``, and its Jacobian is

    J_i = ∂e_i/∂x = [n_x, n_y, n_iᵀ R'(θ) q_i],   R'(θ) q = (-sin θ q_x - cos θ q_y,
                                                          cos θ q_x - sin θ q_y).

The Hessian of ``½ Σ e_i²`` is ``H = Σ J_iᵀ J_i`` (Gauss-Newton, exact at the optimum for
linear residuals).

**Covariance** (Hessian method, *not* Censi's ICRA 2007 closed form, which also propagates
the noise of every reading through ``∂²J/∂z∂x``): if every residual carries independent noise
of variance ``σ²``, the least-squares estimate has covariance ``σ² H⁻¹``; ``σ²`` is estimated
from the residuals themselves, ``σ̂² = Σ e_i² / (m - 3)``. The residual already holds the noise
of both scans (a current reading and the reference surface it lands on), so ``σ̂²`` is the
combined variance. Correlations between residuals (neighbouring readings share a reference
segment) and the choice of correspondences are ignored, which is why a test checks the
estimate against the scatter of Monte-Carlo results.

The point-to-point matcher also uses this normal-distance model: its own Hessian ``Σ [I,
R' q_i]ᵀ[I, R' q_i]`` treats the correspondences as fixed points and so reports a wall as
constraining the motion *along* it, which it does not.

**Degeneracy.** ``H`` mixes metres and radians, so the rotation column is divided by a length
``L`` (the RMS distance of the current points from the sensor) and ``H`` by the number of
correspondences: the *normalised* Hessian ``Ĥ = (1/m) Σ Ĵ_iᵀ Ĵ_i`` is dimensionless, with
eigenvalues in ``[0, 2]`` (the trace is at most ``1 + 1``). An eigenvalue near 0 means a
direction of motion that no correspondence constrains — in a featureless corridor the normals
are all across it, so translation along it has ``Ĵ v = 0``. :func:`require_constrained`
raises ``MatchError("degenerate")`` below a threshold.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from slamkit._validation import FloatArray
from slamkit.errors import MatchError

__all__ = [
    "estimate_normals",
    "line_jacobian",
    "neighbour_table",
    "normalised_min_eigenvalue",
    "require_constrained",
    "residual_covariance",
]


def neighbour_table(points: FloatArray, tree: cKDTree | None, k: int) -> NDArray[np.intp]:
    """Indices ``(M, k)`` of each point's neighbourhood, itself included: with ``tree`` its
    ``k`` nearest points, without one the ``k`` points centred on it in scan order (clipped at
    the ends of the scan). Used by :func:`estimate_normals`."""
    m = points.shape[0]
    k = min(int(k), m)
    if tree is not None:
        _, idx = tree.query(points, k=k)
        return np.asarray(idx, dtype=np.intp).reshape(m, k)
    offsets = np.arange(k) - (k - 1) // 2
    start = np.clip(np.arange(m) - (k - 1) // 2, 0, m - k)
    return start[:, None] + (offsets + (k - 1) // 2)[None, :]


def estimate_normals(
    points: FloatArray, neighbours: NDArray[np.intp], radius: float
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Unit normals ``(M, 2)`` of the surface through ``points (M, 2)`` by principal
    components of each point's ``neighbours`` (an ``(M, k)`` index table, see
    :func:`neighbour_table`) that lie within ``radius`` [m] of it, and a mask ``(M,)`` of the
    points that had at least 3 such neighbours (the others get normal ``(0, 0)``).

    For the scatter ``[[sxx, sxy], [sxy, syy]]`` of a neighbourhood, the direction of largest
    spread (the tangent) is at ``φ = ½ atan2(2 sxy, sxx - syy)``; the normal is ``(-sin φ,
    cos φ)``. Its sign is arbitrary, which the squared residuals do not see.
    """
    m = points.shape[0]
    if m == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=bool)
    nb = points[neighbours]  # (M, k, 2)
    rel = nb - points[:, None, :]
    w = (np.einsum("ijk,ijk->ij", rel, rel) <= radius * radius).astype(np.float64)
    count = w.sum(axis=1)
    mean = np.einsum("ijk,ij->ik", rel, w) / np.maximum(count, 1.0)[:, None]
    d = (rel - mean[:, None, :]) * w[:, :, None]
    sxx = np.einsum("ij,ij->i", d[:, :, 0], d[:, :, 0])
    sxy = np.einsum("ij,ij->i", d[:, :, 0], d[:, :, 1])
    syy = np.einsum("ij,ij->i", d[:, :, 1], d[:, :, 1])
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    ok = count >= 3
    normals = np.column_stack([-np.sin(phi), np.cos(phi)]) * ok[:, None]
    return normals, ok


def line_jacobian(current: FloatArray, normals: FloatArray, theta: float) -> FloatArray:
    """``J (m, 3)``: rows ``[n_x, n_y, n_iᵀ R'(θ) q_i]``, the derivative of the normal
    distances with respect to the pose ``(t_x, t_y, θ)`` (see the module docstring)."""
    c, s = np.cos(theta), np.sin(theta)
    qx, qy = current[:, 0], current[:, 1]
    nx, ny = normals[:, 0], normals[:, 1]
    return np.column_stack([nx, ny, nx * (-s * qx - c * qy) + ny * (c * qx - s * qy)])


def normalised_min_eigenvalue(jacobian: FloatArray, current: FloatArray) -> float:
    """Smallest eigenvalue of the normalised Hessian ``Ĥ`` (module docstring): the rotation
    column of ``jacobian (m, 3)`` divided by the RMS norm of ``current (m, 2)``, ``JᵀJ`` by
    ``m``. Dimensionless; 0 for a direction of motion nothing constrains."""
    m = jacobian.shape[0]
    if m == 0:
        return 0.0
    length = float(np.sqrt(np.mean(np.einsum("ij,ij->i", current, current))))
    scale = np.array([1.0, 1.0, 1.0 / max(length, 1e-9)])
    jn = jacobian * scale
    h = jn.T @ jn / m
    return float(np.linalg.eigvalsh(h)[0])


def require_constrained(
    jacobian: FloatArray, current: FloatArray, min_eigenvalue: float, method: str
) -> float:
    """The normalised Hessian's smallest eigenvalue, or ``MatchError("degenerate")`` when it
    is below ``min_eigenvalue``: the scans leave a direction of motion unconstrained."""
    lam = normalised_min_eigenvalue(jacobian, current)
    if lam < min_eigenvalue:
        raise MatchError(
            f"{method}: the geometry leaves a direction of motion unconstrained (smallest "
            f"eigenvalue of the normalised Hessian {lam:.3g}, expected >= {min_eigenvalue:.3g}; "
            "e.g. a featureless corridor)",
            "degenerate",
        )
    return lam


def residual_covariance(jacobian: FloatArray, residuals: FloatArray) -> FloatArray:
    """``σ̂² H⁻¹`` with ``H = JᵀJ`` and ``σ̂² = Σ e² / (m - 3)``: the covariance ``(3, 3)`` of
    the least-squares pose (module docstring). Needs ``m > 3`` rows and a non-singular ``H``
    (callers test degeneracy first)."""
    m = jacobian.shape[0]
    sigma2 = float(residuals @ residuals) / max(m - 3, 1)
    h = jacobian.T @ jacobian
    cov = sigma2 * np.linalg.solve(h, np.eye(3))
    return 0.5 * (cov + cov.T)  # symmetric to rounding
