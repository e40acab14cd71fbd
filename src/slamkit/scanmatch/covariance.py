"""The error model shared by the ICP matchers: reference normals, the Jacobian of the normal
distances, the pose covariances and the degeneracy test.

**The final least-squares problem.** At the solution ``x = (t_x, t_y, θ)`` every kept
correspondence ``i`` pairs a current point ``q_i`` (current sensor frame) with a reference
point ``p_i`` and the unit normal ``n_i`` of the reference surface there. Its residual is the
normal distance ``e_i(x) = n_iᵀ (R(θ) q_i + t - p_i)``, and its Jacobian is

    J_i = ∂e_i/∂x = [n_x, n_y, n_iᵀ R'(θ) q_i],   R'(θ) q = (-sin θ q_x - cos θ q_y,
                                                          cos θ q_x - sin θ q_y).

The Gauss-Newton Hessian of ``½ Σ e_i²`` is ``H = Σ J_iᵀ J_i``.

**Covariance.** Two estimates, both with the range noise ``σ`` estimated robustly from the
residuals of all correspondences within range (``1.4826 × median``; the trimming would shrink
a mean-square estimate, since it removes the largest residuals):

* point-to-line (:func:`point_to_line_covariance`): Censi's closed form (ICRA 2007) — the
  implicit function theorem on ``∂J/∂x = 0`` propagates the noise of every range of *both*
  scans, including its effect on the reference lines' normals, which are only two noisy
  points apart;
* point-to-point (:func:`normal_distance_covariance`): ``σ̂² H⁻¹`` of the normal-distance
  model above, with the normals of the reference surface. The point-to-point Hessian itself,
  ``Σ [I, R' q_i]ᵀ[I, R' q_i]``, treats the paired points as fixed and so reports a wall as
  constraining motion *along* it, which it does not. Neither holds the bias of point-to-point
  matching (the two scans sample a wall at different places).

The correspondences are taken as fixed in both, which is why tests check them against the
scatter of Monte-Carlo results.

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
from slamkit.backend import SEAM
from slamkit.errors import MatchError
from slamkit.scanmatch.kernel_covariance import point_to_line_cov

__all__ = [
    "degenerate_error",
    "estimate_normals",
    "line_jacobian",
    "median",
    "neighbour_table",
    "normal_distance_covariance",
    "normalised_min_eigenvalue",
    "point_to_line_covariance",
    "point_to_line_covariance_numpy",
    "require_constrained",
    "scan_order_normals",
]


def scan_order_normals(
    points: FloatArray, window: int, max_spacing: float
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Unit normals ``(M, 2)`` of a scan (``points (M, 2)`` in scan order) by principal
    components of the ``window`` points centred on each (odd, clipped at the ends of the
    scan), and a mask ``(M,)`` of the points whose window has no spacing above
    ``max_spacing`` [m] (no range discontinuity inside; the others get ``(0, 0)``).

    Window sums of ``x, y, x², xy, y²`` come from prefix sums, so the cost is a few array
    passes whatever the window; the scatter and the normal are as in :func:`estimate_normals`.
    Coordinates are taken relative to the scan's centroid to keep the sums well conditioned.
    """
    m = points.shape[0]
    k = min(int(window) | 1, m if m % 2 else m - 1)
    if m < 3 or k < 3:
        return np.zeros((m, 2)), np.zeros(m, dtype=bool)
    rel = points - points.mean(axis=0)
    x, y = rel[:, 0], rel[:, 1]
    stacked = np.column_stack([x, y, x * x, x * y, y * y])
    prefix = np.vstack([np.zeros((1, 5)), np.cumsum(stacked, axis=0)])
    start = np.clip(np.arange(m) - k // 2, 0, m - k)
    sums = (prefix[start + k] - prefix[start]) / k
    sxx = sums[:, 2] - sums[:, 0] ** 2
    sxy = sums[:, 3] - sums[:, 0] * sums[:, 1]
    syy = sums[:, 4] - sums[:, 1] ** 2
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    gaps = np.hypot(np.diff(x), np.diff(y))
    too_far = np.concatenate([[0], np.cumsum(gaps > max_spacing)])
    ok = (too_far[start + k - 1] - too_far[start]) == 0
    normals = np.column_stack([-np.sin(phi), np.cos(phi)]) * ok[:, None]
    return normals, ok


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


def median(values: FloatArray) -> float:
    """``np.median`` of a non-empty 1-D array (the middle order statistic, or the mean of the
    two middle ones for an even count), by one partition without ``np.median``'s general
    axis handling: the robust scale of every ICP iteration takes one."""
    n = values.shape[0]
    h = n // 2
    if n % 2:
        return float(np.partition(values, h)[h])
    part = np.partition(values, (h - 1, h))
    return float((part[h - 1] + part[h]) / 2.0)


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
        raise degenerate_error(lam, min_eigenvalue, method)
    return lam


def degenerate_error(eigenvalue: float, min_eigenvalue: float, method: str) -> MatchError:
    """The ``MatchError("degenerate")`` for a normalised Hessian whose smallest eigenvalue
    ``eigenvalue`` is below ``min_eigenvalue``, naming the matcher ``method``."""
    return MatchError(
        f"{method}: the geometry leaves a direction of motion unconstrained (smallest "
        f"eigenvalue of the normalised Hessian {eigenvalue:.3g}, expected >= "
        f"{min_eigenvalue:.3g}; e.g. a featureless corridor)",
        "degenerate",
    )


def _rotations(theta: float) -> tuple[FloatArray, FloatArray]:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, s], [-s, c]]), np.array([[-s, c], [-c, -s]])  # (R, R') transposed


def _sandwich(h: FloatArray, gram: FloatArray, sigma2: float) -> FloatArray:
    """``σ² H⁻¹ (Gᵀ G) H⁻¹`` for ``H (3, 3)`` and ``gram = Gᵀ G (3, 3)`` (``G`` with rows
    ``∂g/∂z_k``)."""
    h_inv = np.linalg.inv(h)  # 3×3, non-singular after the degeneracy test
    cov = sigma2 * (h_inv @ gram @ h_inv.T)
    return 0.5 * (cov + cov.T)  # symmetric to rounding


def point_to_line_covariance(
    current: FloatArray,
    ref_a: FloatArray,
    ref_b: FloatArray,
    index_a: NDArray[np.intp],
    index_b: NDArray[np.intp],
    n_reference: int,
    pose: FloatArray,
    kept: NDArray[np.bool_],
) -> FloatArray:
    """Covariance ``(3, 3)`` of the point-to-line pose by the implicit function theorem
    (Censi, ICRA 2007) with range noise estimated from the residuals.

    Inputs are the correspondences before trimming: current points ``q_i (m, 2)``, the
    segment ends ``p_a = ref_a (m, 2)`` (nearest) and ``p_b = ref_b (m, 2)``, their indices in
    the reference scan of ``n_reference`` points, the solution ``pose`` and the mask ``kept
    (m,)`` of those the solution used. Each scan's sensor
    is at its frame's origin and a reading ``z`` is a range: ``q_i = r_i u_i``,
    ``p_j = ρ_j w_j`` with unit beam directions ``u, w``.

    With ``y_i = R q_i + t``, ``d = p_b - p_a = L τ``, ``n = τ`` turned by +90° and the
    position along the segment ``s_i = (y_i - p_a)·τ / L``, the error is ``e_i = nᵀ (y_i -
    p_a)`` and its derivatives (using ``∂n/∂d = -τ nᵀ / L``) are

        ∂e/∂r_i = nᵀ R u_i,   ∂e/∂ρ_a = -(1 - s) nᵀ w_a,   ∂e/∂ρ_b = -s nᵀ w_b,
        ∂n/∂ρ_a = τ (nᵀ w_a) / L,   ∂n/∂ρ_b = -τ (nᵀ w_b) / L.

    The solution satisfies ``g(x, z) = ∂J/∂x = 2 Σ e_i J_iᵀ = 0`` (``J_i`` the row of
    :func:`line_jacobian`), so ``dx/dz = -H⁻¹ ∂g/∂z`` with ``H = ∂g/∂x = 2 Σ (J_iᵀ J_i + e_i
    ∂²e_i/∂x²)`` and ``∂g/∂z = 2 Σ (J_iᵀ ∂e_i/∂z + e_i ∂J_iᵀ/∂z)``; for independent ranges of
    variance ``σ²``, ``cov x = σ² H⁻¹ (∂g/∂z)(∂g/∂z)ᵀ H⁻¹``. ``σ²`` comes from the residuals:
    ``Var e_i = σ² k_i`` with ``k_i = (nᵀRu_i)² + (1 - s)² (nᵀw_a)² + s² (nᵀw_b)²``, and
    ``σ̂ = 1.4826 · median_i |e_i| / √k_i`` over *all* the correspondences given (the median
    of ``|N(0, 1)|`` is 1/1.4826): robust to the outliers, and not shrunk by the trimming,
    which removes the largest residuals. ``H`` and ``∂g/∂z`` sum over the kept ones only.
    The correspondences are taken as fixed. With numba installed this runs compiled
    (:func:`slamkit.scanmatch.kernel_covariance.point_to_line_cov`), else
    :func:`point_to_line_covariance_numpy`: the same numbers to rounding.
    """
    return _covariance(current, ref_a, ref_b, index_a, index_b, n_reference, pose, kept)


def point_to_line_covariance_numpy(
    current: FloatArray,
    ref_a: FloatArray,
    ref_b: FloatArray,
    index_a: NDArray[np.intp],
    index_b: NDArray[np.intp],
    n_reference: int,
    pose: FloatArray,
    kept: NDArray[np.bool_],
) -> FloatArray:
    """:func:`point_to_line_covariance` in NumPy: the path without numba and the oracle of
    the compiled :func:`~slamkit.scanmatch.kernel_covariance.point_to_line_cov` (to 1e-9 of
    the largest entry: BLAS sums the products in another order)."""
    tx, ty, th = float(pose[0]), float(pose[1]), float(pose[2])
    rot_t, drot_t = _rotations(th)
    both_rot = np.hstack([rot_t, drot_t])  # one product gives R q and R' q
    rq_drq = current @ both_rot
    rq, drq = rq_drq[:, :2], rq_drq[:, 2:]
    d = ref_b - ref_a
    seg_len = np.hypot(d[:, 0], d[:, 1])
    tau = d / seg_len[:, None]
    n = tau @ np.array([[0.0, 1.0], [-1.0, 0.0]])  # τ turned by +90°
    rel = rq + np.array([tx, ty]) - ref_a
    e = np.einsum("ij,ij->i", n, rel)
    s_along = np.einsum("ij,ij->i", tau, rel) / seg_len
    n_drq = np.einsum("ij,ij->i", n, drq)
    tau_drq = np.einsum("ij,ij->i", tau, drq)
    jac = np.column_stack([n, n_drq])
    # Current ranges: ∂e/∂r = nᵀ R u, ∂J/∂r = [0, 0, nᵀ R' u].
    u = current / np.hypot(current[:, 0], current[:, 1])[:, None]
    ru_dru = u @ both_rot
    n_ru = np.einsum("ij,ij->i", n, ru_dru[:, :2])
    n_dru = np.einsum("ij,ij->i", n, ru_dru[:, 2:])
    # Reference ranges of both segment ends at once (axis 0: a, b).
    ends = np.stack([ref_a, ref_b])
    n_w = np.einsum("ij,kij->ki", n, ends) / np.hypot(ends[..., 0], ends[..., 1])
    de = np.stack([1.0 - s_along, s_along]) * n_w  # -∂e/∂ρ
    dn = np.array([[1.0], [-1.0]]) * n_w / seg_len  # ∂n/∂ρ = dn · τ
    sigma = 1.4826 * float(np.median(np.abs(e) / np.sqrt(n_ru**2 + (de**2).sum(axis=0))))
    # Only the kept pairs enter H and ∂g/∂z.
    jac, e, n_ru, n_dru, rq = jac[kept], e[kept], n_ru[kept], n_dru[kept], rq[kept]
    tau, n, tau_drq, de, dn = tau[kept], n[kept], tau_drq[kept], de[:, kept], dn[:, kept]
    h = 2.0 * (jac.T @ jac)
    h[2, 2] -= 2.0 * float(e @ np.einsum("ij,ij->i", n, rq))  # ∂²e/∂θ² = -nᵀ R q
    g_cur = 2.0 * n_ru[:, None] * jac
    g_cur[:, 2] += 2.0 * e * n_dru
    g_end = -2.0 * de[:, :, None] * jac[None]  # (2, m, 3)
    e_dn = 2.0 * e * dn
    g_end[:, :, :2] += e_dn[:, :, None] * tau[None]
    g_end[:, :, 2] += e_dn * tau_drq
    index = np.concatenate([index_a[kept], index_b[kept]])
    flat = g_end.reshape(-1, 3)
    g_ref = np.column_stack(
        [np.bincount(index, flat[:, c], minlength=n_reference) for c in range(3)]
    )  # Σ over the correspondences that share a reference point
    return _sandwich(h, g_cur.T @ g_cur + g_ref.T @ g_ref, sigma * sigma)


_covariance = SEAM.pair(compiled=point_to_line_cov, oracle=point_to_line_covariance_numpy)
"""The covariance, compiled under numba, else in NumPy (:mod:`slamkit.backend`)."""


def normal_distance_covariance(
    jacobian: FloatArray, residuals: FloatArray, kept: NDArray[np.bool_]
) -> FloatArray:
    """``σ̂² H⁻¹`` of the normal-distance model (module docstring), for the point-to-point
    matcher: ``H = Σ J_iᵀ J_i`` over the kept rows of ``jacobian (m, 3)`` and ``σ̂ = 1.4826 ·
    median |e_i|`` over all ``residuals (m,)`` (robust, and not shrunk by the trimming)."""
    jk = jacobian[kept]
    sigma = 1.4826 * median(np.abs(residuals))
    h = jk.T @ jk
    cov = sigma * sigma * np.linalg.solve(h, np.eye(3))
    return 0.5 * (cov + cov.T)  # symmetric to rounding
