"""The compiled covariance of point-to-line ICP; its NumPy oracle is
:func:`slamkit.scanmatch.covariance.point_to_line_covariance_numpy` (see there for the
maths)."""

from __future__ import annotations

import math

import numpy as np

from slamkit._validation import FloatArray
from slamkit.backend import jit
from slamkit.scanmatch.compiled import median_in_place

__all__ = ["add_outer", "point_to_line_cov", "sandwich"]


@jit
def point_to_line_cov(
    current: FloatArray,
    ref_a: FloatArray,
    ref_b: FloatArray,
    index_a: np.ndarray,
    index_b: np.ndarray,
    n_reference: int,
    pose: FloatArray,
    kept: np.ndarray,
) -> FloatArray:
    """Compiled form of :func:`slamkit.scanmatch.covariance.point_to_line_covariance` (same
    arguments, same formulas; see there)."""
    m = current.shape[0]
    tx, ty, th = pose[0], pose[1], pose[2]
    c, s = np.cos(th), np.sin(th)
    ratio = np.empty(m)
    h = np.zeros((3, 3))
    gram = np.zeros((3, 3))
    g_ref = np.zeros((n_reference, 3))
    e2_nrq = 0.0
    for i in range(m):
        qx, qy = current[i, 0], current[i, 1]
        rqx, rqy = qx * c + qy * -s, qx * s + qy * c  # R q
        drqx, drqy = qx * -s + qy * -c, qx * c + qy * -s  # R' q
        ax, ay = ref_a[i, 0], ref_a[i, 1]
        bx, by = ref_b[i, 0], ref_b[i, 1]
        dx, dy = bx - ax, by - ay
        seg_len = math.hypot(dx, dy)
        taux, tauy = dx / seg_len, dy / seg_len
        nx, ny = -tauy, taux  # τ turned by +90°
        relx, rely = rqx + tx - ax, rqy + ty - ay
        e = nx * relx + ny * rely
        s_along = (taux * relx + tauy * rely) / seg_len
        n_drq = nx * drqx + ny * drqy
        tau_drq = taux * drqx + tauy * drqy
        rr = math.hypot(qx, qy)
        ux, uy = qx / rr, qy / rr
        n_ru = nx * (ux * c + uy * -s) + ny * (ux * s + uy * c)
        n_dru = nx * (ux * -s + uy * -c) + ny * (ux * c + uy * -s)
        n_wa = (nx * ax + ny * ay) / math.hypot(ax, ay)
        n_wb = (nx * bx + ny * by) / math.hypot(bx, by)
        de_a, de_b = (1.0 - s_along) * n_wa, s_along * n_wb  # -∂e/∂ρ
        dn_a, dn_b = n_wa / seg_len, -n_wb / seg_len  # ∂n/∂ρ = dn τ
        ratio[i] = abs(e) / math.sqrt(n_ru**2 + (de_a**2 + de_b**2))
        if not kept[i]:
            continue
        jac0, jac1, jac2 = nx, ny, n_drq
        add_outer(h, jac0, jac1, jac2)
        e2_nrq += e * (nx * rqx + ny * rqy)
        g0, g1 = 2.0 * n_ru * jac0, 2.0 * n_ru * jac1
        g2 = 2.0 * n_ru * jac2 + 2.0 * e * n_dru
        add_outer(gram, g0, g1, g2)
        for end in range(2):
            de, dn, idx = (de_a, dn_a, index_a[i]) if end == 0 else (de_b, dn_b, index_b[i])
            e_dn = 2.0 * e * dn
            g_ref[idx, 0] += -2.0 * de * jac0 + e_dn * taux
            g_ref[idx, 1] += -2.0 * de * jac1 + e_dn * tauy
            g_ref[idx, 2] += -2.0 * de * jac2 + e_dn * tau_drq
    sigma = 1.4826 * median_in_place(ratio)
    for j in range(n_reference):
        add_outer(gram, g_ref[j, 0], g_ref[j, 1], g_ref[j, 2])
    h *= 2.0
    h[2, 2] -= 2.0 * e2_nrq  # ∂²e/∂θ² = -nᵀ R q
    return sandwich(h, gram, sigma)


@jit
def add_outer(m: FloatArray, g0: float, g1: float, g2: float) -> None:
    """``m += g gᵀ`` on the upper triangle of ``m (3, 3)``, entry by entry."""
    m[0, 0] += g0 * g0
    m[0, 1] += g0 * g1
    m[0, 2] += g0 * g2
    m[1, 1] += g1 * g1
    m[1, 2] += g1 * g2
    m[2, 2] += g2 * g2


@jit
def sandwich(h: FloatArray, gram: FloatArray, sigma: float) -> FloatArray:
    """``σ² H⁻¹ G H⁻ᵀ`` from the upper triangles of ``h`` and ``gram (3, 3)`` (both made
    symmetric here)."""
    for a in range(3):
        for b in range(a):
            h[a, b] = h[b, a]
            gram[a, b] = gram[b, a]
    # H⁻¹ = adj(H) / det H (3×3, symmetric, non-singular after the degeneracy test).
    inv = np.empty((3, 3))
    inv[0, 0] = h[1, 1] * h[2, 2] - h[1, 2] * h[2, 1]
    inv[0, 1] = h[0, 2] * h[2, 1] - h[0, 1] * h[2, 2]
    inv[0, 2] = h[0, 1] * h[1, 2] - h[0, 2] * h[1, 1]
    inv[1, 1] = h[0, 0] * h[2, 2] - h[0, 2] * h[2, 0]
    inv[1, 2] = h[0, 2] * h[1, 0] - h[0, 0] * h[1, 2]
    inv[2, 2] = h[0, 0] * h[1, 1] - h[0, 1] * h[1, 0]
    inv[1, 0], inv[2, 0], inv[2, 1] = inv[0, 1], inv[0, 2], inv[1, 2]
    det = h[0, 0] * inv[0, 0] + h[0, 1] * inv[1, 0] + h[0, 2] * inv[2, 0]
    cov = np.empty((3, 3))
    s2 = sigma * sigma / (det * det)
    for a in range(3):  # σ² H⁻¹ G H⁻ᵀ, symmetric to rounding
        for b in range(a, 3):
            acc = 0.0
            for k in range(3):
                for l in range(3):
                    acc += inv[a, k] * gram[k, l] * inv[b, l]
            cov[a, b] = cov[b, a] = s2 * acc
    return cov
