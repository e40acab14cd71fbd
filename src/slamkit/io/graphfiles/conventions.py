"""The one place for the orderings and noise parameterisations of graph files.

Every converter here is a pair (file → slamkit, slamkit → file) over batches, array in and
array out, with no validation (the reader and the writer check before and after):

* **upper triangles**: ``n(n+1)/2`` entries of a symmetric ``n × n`` matrix, row-major
  (``I11 I12 … I1n I22 …``): g2o's information, iSAM's square-root information, GTSAM's
  covariances, hog-man's 3D information.
* **TORO 2D** information ``Ixx Ixy Iyy Itt Ixt Iyt`` (TORO's ``m00 m01 m11 m22 m02 m12``,
  see ``README-hogman-fileformat-2D.txt``: ``inf_ff inf_fs inf_ss inf_rr inf_fr inf_sr``).
* **square-root information** ``R`` (upper triangular, iSAM): information ``Λ = RᵀR``; the
  writer takes ``R`` as the transposed lower Cholesky factor of ``Λ`` (positive diagonal).
* **covariance** (GTSAM's Victoria Park file): ``Λ = Σ⁻¹``.
* **standard deviations** ``σ`` of independent readings (``BR`` lines): ``Λ = diag(1/σ²)``.
* **quaternions**: files write ``qx qy qz qw``; slamkit keeps ``qw qx qy qz``.
* **roll-pitch-yaw** (hog-man ``VERTEX3``/``EDGE3``, iSAM ``EDGE3``):
  ``R = Rz(yaw) Ry(pitch) Rx(roll)`` — :meth:`slamkit.geometry.SO3.from_rpy_radians`; the
  quaternion made from angles is given ``qw >= 0``.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from slamkit._validation import FloatArray
from slamkit.geometry import SO3

__all__ = [
    "TORO2D_FROM_UPPER",
    "UPPER_FROM_TORO2D",
    "covariance_to_information",
    "information_to_covariance",
    "information_to_sigmas",
    "information_to_sqrt_information",
    "quat_to_rpy",
    "rpy_to_quat",
    "sigmas_to_information",
    "sqrt_information_to_information",
    "symmetric_to_upper",
    "triangle_size",
    "upper_to_symmetric",
    "upper_to_triangular",
    "wxyz_to_xyzw",
    "xyzw_to_wxyz",
]

#: Column ``k`` of the row-major upper triangle (``I11 I12 I13 I22 I23 I33``) is column
#: ``UPPER_FROM_TORO2D[k]`` of TORO's ``Ixx Ixy Iyy Itt Ixt Iyt``.
UPPER_FROM_TORO2D = np.array([0, 1, 4, 2, 5, 3])
#: The inverse permutation: TORO's order from the upper triangle.
TORO2D_FROM_UPPER = np.argsort(UPPER_FROM_TORO2D)


def triangle_size(n: int) -> int:
    """How many entries the upper triangle of an ``n × n`` matrix has."""
    return n * (n + 1) // 2


@cache
def _triu(n: int) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.triu_indices(n)  # row-major: (0,0) (0,1) … (0,n-1) (1,1) …
    return rows, cols


def upper_to_symmetric(values: FloatArray, n: int) -> FloatArray:
    """``(E, n(n+1)/2)`` row-major upper triangles → ``(E, n, n)`` symmetric matrices."""
    r, c = _triu(n)
    out = np.zeros((values.shape[0], n, n))
    out[:, r, c] = values
    out[:, c, r] = values
    return out


def upper_to_triangular(values: FloatArray, n: int) -> FloatArray:
    """``(E, n(n+1)/2)`` row-major upper triangles → ``(E, n, n)`` upper-triangular matrices."""
    r, c = _triu(n)
    out = np.zeros((values.shape[0], n, n))
    out[:, r, c] = values
    return out


def symmetric_to_upper(matrices: FloatArray) -> FloatArray:
    """``(E, n, n)`` → their row-major upper triangles ``(E, n(n+1)/2)``."""
    r, c = _triu(matrices.shape[-1])
    return np.ascontiguousarray(matrices[:, r, c])


def _symmetrize(m: FloatArray) -> FloatArray:
    # Exact (a no-op) for a matrix that is already symmetric bit for bit.
    return 0.5 * (m + np.swapaxes(m, -1, -2))


def sqrt_information_to_information(values: FloatArray, n: int) -> FloatArray:
    """iSAM's upper-triangular square-root information ``R`` → ``Λ = RᵀR``."""
    R = upper_to_triangular(values, n)
    return _symmetrize(np.einsum("eki,ekj->eij", R, R))


def information_to_sqrt_information(information: FloatArray) -> FloatArray:
    """``Λ`` (positive definite) → the upper triangle of ``R = Lᵀ``, ``Λ = L Lᵀ`` (Cholesky).

    ``R`` has a positive diagonal; a file's ``R`` with negative diagonal entries gives the same
    ``Λ`` and comes back with those rows' signs flipped. A diagonal ``R`` comes back exactly
    (``sqrt(s·s) == |s|`` in IEEE arithmetic).
    """
    L = np.linalg.cholesky(information)
    return symmetric_to_upper(np.swapaxes(L, -1, -2))


def covariance_to_information(values: FloatArray, n: int) -> FloatArray:
    """Upper triangles of covariances ``Σ`` (positive definite) → ``Λ = Σ⁻¹``."""
    inv = np.asarray(np.linalg.inv(upper_to_symmetric(values, n)), dtype=np.float64)
    return _symmetrize(inv)


def information_to_covariance(information: FloatArray) -> FloatArray:
    """``Λ`` (positive definite) → the upper triangles of ``Σ = Λ⁻¹``."""
    inv = np.asarray(np.linalg.inv(information), dtype=np.float64)
    return symmetric_to_upper(_symmetrize(inv))


def sigmas_to_information(sigmas: FloatArray) -> FloatArray:
    """``(E, k)`` standard deviations (positive) → diagonal ``(E, k, k)`` ``Λ = diag(1/σ²)``."""
    k = sigmas.shape[1]
    out = np.zeros((sigmas.shape[0], k, k))
    idx = np.arange(k)
    out[:, idx, idx] = 1.0 / (sigmas * sigmas)
    return out


def information_to_sigmas(information: FloatArray) -> FloatArray:
    """Diagonal ``Λ`` → ``σ = 1/sqrt(diag Λ)`` (the caller checks the matrix is diagonal)."""
    return 1.0 / np.sqrt(np.diagonal(information, axis1=-2, axis2=-1))


def xyzw_to_wxyz(q: FloatArray) -> FloatArray:
    """File quaternions ``(…, 4) = (qx, qy, qz, qw)`` → slamkit's ``(qw, qx, qy, qz)``."""
    return np.ascontiguousarray(q[..., [3, 0, 1, 2]])


def wxyz_to_xyzw(q: FloatArray) -> FloatArray:
    """slamkit's ``(qw, qx, qy, qz)`` → the files' ``(qx, qy, qz, qw)``."""
    return np.ascontiguousarray(q[..., [1, 2, 3, 0]])


def rpy_to_quat(rpy: FloatArray) -> FloatArray:
    """``(E, 3)`` roll, pitch, yaw (``R = Rz Ry Rx``) → unit ``wxyz`` quaternions, ``qw >= 0``."""
    q = np.array(SO3.from_rpy_radians(rpy).wxyz)
    q[q[:, 0] < 0.0] *= -1.0  # q and -q are one rotation: a fixed sign for stable round trips
    return q


def quat_to_rpy(q_wxyz: FloatArray) -> FloatArray:
    """``(E, 4)`` quaternions (near unit; normalised here) → roll, pitch, yaw ``(E, 3)``."""
    q = q_wxyz / np.linalg.norm(q_wxyz, axis=-1, keepdims=True)
    return SO3(q).as_rpy_radians()
