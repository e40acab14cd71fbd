"""Least-squares alignment of two ordered point sets (the "feature transform").

Given corresponding points ``source[i] ↔ target[i]`` in ``D`` dimensions and non-negative
weights ``w_i``, :func:`align_points` returns the similarity ``x ↦ s R x + t`` (``R`` a proper
rotation, ``s > 0``) that minimises

    E(s, R, t) = Σ_i w_i ‖target_i − (s R source_i + t)‖².

Derivation (Umeyama 1991, "Least-squares estimation of transformation parameters between two
point patterns", IEEE PAMI 13(4)), written with normalised weights ``p_i = w_i / Σ w``:

* Setting ∂E/∂t = 0 gives ``t = μ_t − s R μ_s`` with the weighted centroids ``μ_s``, ``μ_t``;
  what is left is the same problem on centred points ``a_i = source_i − μ_s``,
  ``b_i = target_i − μ_t``.
* Expanding the centred cost, ``R`` only enters through ``−2 s tr(Rᵀ Σ)`` with the
  cross-covariance ``Σ = Σ_i p_i b_i a_iᵀ``. With the SVD ``Σ = U diag(d) Vᵀ`` the trace is
  largest for ``R = U S Vᵀ``, where ``S = diag(1, …, 1, det(U) det(V))``: the last sign flip
  turns the unconstrained optimum (a reflection when ``det(U Vᵀ) = −1``) into the best proper
  rotation, sacrificing the smallest singular value.
* ∂E/∂s = 0 gives ``s = tr(diag(d) S) / σ_s²`` with ``σ_s² = Σ_i p_i ‖a_i‖²``.

The rotation is determined when ``rank Σ ≥ D − 1``, which needs two distinct points in 2-D and
three non-collinear points in 3-D (with positive weight, and sets that are not uncorrelated).
Otherwise :class:`~slamkit.errors.GeometryError` is raised.

**Scale.** The notes estimate the scale as the ratio of spreads ``sqrt(Σ‖b‖² / Σ‖a‖²)``
(Horn's symmetric estimate). That value does *not* minimise ``E``: it ignores how well the
two sets correlate, so with noisy data it gives a larger residual than the optimum. We return
Umeyama's least-squares scale ``tr(diag(d) S) / σ_s²``, the one that belongs to the objective
above; for noise-free data both agree exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import GeometryError, InputError, ShapeError
from slamkit.geometry.angles import wrap_angle

__all__ = ["Similarity", "align_points", "align_points_2d"]

# A rotation matrix must satisfy RᵀR = I to this absolute tolerance to be accepted.
_ORTHO_TOL = 1e-9
# Relative size (w.r.t. σ_s σ_t, an upper bound of every singular value of Σ) below which a
# singular value of the cross-covariance counts as zero.
_RANK_RTOL = 1e-10
# |scale − 1| below which a similarity is treated as rigid by :meth:`Similarity.as_pose`.
_UNIT_SCALE_TOL = 1e-12


def _frozen(a: FloatArray) -> FloatArray:
    """A private, read-only copy, so a frozen value cannot be changed through its arrays."""
    out = np.array(a, dtype=np.float64, copy=True)
    out.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False)
class Similarity:
    """The map ``x ↦ scale · rotation @ x + translation`` in ``D`` dimensions.

    ``rotation`` is a proper rotation matrix ``(D, D)`` (orthonormal, determinant +1),
    ``translation`` has shape ``(D,)`` and ``scale`` is a positive float (1 for a rigid
    transform). Arrays are copied and made read-only on construction.
    """

    rotation: FloatArray
    translation: FloatArray
    scale: float = 1.0

    def __post_init__(self) -> None:
        R = as_array(self.rotation, "rotation", (None, None))
        dim = R.shape[0]
        if R.shape != (dim, dim) or dim < 1:
            raise ShapeError(f"rotation: expected a square (D, D) matrix, got {R.shape}")
        t = as_array(self.translation, "translation", (dim,))
        if np.max(np.abs(R.T @ R - np.eye(dim))) > _ORTHO_TOL or np.linalg.det(R) <= 0:
            raise InputError("rotation: expected an orthonormal matrix with determinant +1")
        s = float(self.scale)
        if not (np.isfinite(s) and s > 0):
            raise InputError(f"scale: expected a finite number > 0, got {self.scale!r}")
        object.__setattr__(self, "rotation", _frozen(R))
        object.__setattr__(self, "translation", _frozen(t))
        object.__setattr__(self, "scale", s)

    # ----------------------------------------------------------------- constructors
    @classmethod
    def identity(cls, dim: int = 2) -> Similarity:
        """The identity map in ``dim`` dimensions."""
        return cls(np.eye(dim), np.zeros(dim), 1.0)

    @classmethod
    def from_pose(cls, pose: ArrayLike, scale: float = 1.0) -> Similarity:
        """The 2-D similarity with rotation ``pose[2]`` and translation ``pose[:2]``.

        With ``scale == 1`` its action on points equals
        :func:`slamkit.geometry.pose2.transform_points` with ``pose``.
        """
        p = as_array(pose, "pose", (3,))
        c, s = np.cos(p[2]), np.sin(p[2])
        return cls(np.array([[c, -s], [s, c]]), p[:2], scale)

    # ------------------------------------------------------------------ properties
    @property
    def dim(self) -> int:
        """The dimension ``D`` of the space the similarity acts on."""
        return int(self.rotation.shape[0])

    @property
    def angle(self) -> float:
        """Rotation angle in radians, in ``[-pi, pi)`` (2-D only)."""
        self._require_2d("angle")
        return float(wrap_angle(np.arctan2(self.rotation[1, 0], self.rotation[0, 0])))

    def as_matrix(self) -> FloatArray:
        """The homogeneous matrix ``[[s R, t], [0, 1]]`` of shape ``(D + 1, D + 1)``."""
        d = self.dim
        m = np.eye(d + 1)
        m[:d, :d] = self.scale * self.rotation
        m[:d, d] = self.translation
        return m

    def as_pose(self) -> FloatArray:
        """The SE(2) pose ``(tx, ty, angle)`` of a rigid 2-D similarity (``scale == 1``)."""
        self._require_2d("as_pose")
        if abs(self.scale - 1.0) > _UNIT_SCALE_TOL:
            raise InputError(
                f"as_pose: a pose has no scale; this similarity has scale {self.scale!r}"
            )
        return np.array([self.translation[0], self.translation[1], self.angle])

    # -------------------------------------------------------------------- algebra
    def inverse(self) -> Similarity:
        """The inverse map ``y ↦ (1/s) Rᵀ (y − t)``."""
        R_inv = self.rotation.T
        s_inv = 1.0 / self.scale
        return Similarity(R_inv, -s_inv * (R_inv @ self.translation), s_inv)

    def __matmul__(self, other: Similarity) -> Similarity:
        """Composition ``self ∘ other``: apply ``other`` first, then ``self``."""
        if not isinstance(other, Similarity):
            return NotImplemented
        if other.dim != self.dim:
            raise ShapeError(f"compose: dimensions differ ({self.dim} and {other.dim})")
        # s1 R1 (s2 R2 x + t2) + t1 = (s1 s2) (R1 R2) x + (s1 R1 t2 + t1)
        return Similarity(
            self.rotation @ other.rotation,
            self.scale * (self.rotation @ other.translation) + self.translation,
            self.scale * other.scale,
        )

    # ------------------------------------------------------------------- actions
    def apply_to_points(self, points: ArrayLike) -> FloatArray:
        """Map points ``(..., D)``: ``s R p + t`` for every point."""
        p = as_array(points, "points", (..., self.dim))
        return self.scale * (p @ self.rotation.T) + self.translation

    def apply_to_poses(self, poses: ArrayLike) -> FloatArray:
        """Map SE(2) poses ``(..., 3)`` (2-D only).

        Positions are scaled, rotated and translated like points; headings are rotated by
        :attr:`angle` and wrapped to ``[-pi, pi)``. The scale does not touch headings.
        """
        self._require_2d("apply_to_poses")
        p = as_array(poses, "poses", (..., 3))
        xy = self.scale * (p[..., :2] @ self.rotation.T) + self.translation
        theta = wrap_angle(p[..., 2] + self.angle)
        return np.concatenate([xy, theta[..., None]], axis=-1)

    def _require_2d(self, what: str) -> None:
        if self.dim != 2:
            raise ShapeError(
                f"{what}: defined for 2-D similarities only, this one has D={self.dim}"
            )


def align_points(
    source: ArrayLike,
    target: ArrayLike,
    weights: ArrayLike | None = None,
    with_scale: bool = False,
) -> Similarity:
    """The similarity that maps ``source (N, D)`` onto ``target (N, D)`` in least squares.

    Minimises ``Σ_i w_i ‖target_i − (s R source_i + t)‖²`` over proper rotations ``R``,
    translations ``t`` and, if ``with_scale``, scales ``s > 0`` (otherwise ``s = 1``); see the
    module docstring for the derivation. ``weights (N,)`` are non-negative and need not be
    normalised; points with zero weight have no influence. ``D ≥ 2``.

    Raises :class:`~slamkit.errors.GeometryError` when the answer is not determined: no
    point with positive weight, coincident source or target points, fewer than two distinct
    points in 2-D, collinear points in 3-D (in general: cross-covariance of rank < D − 1).
    """
    src = as_array(source, "source", (None, None))
    dst = as_array(target, "target", (None, None))
    if src.shape != dst.shape:
        raise ShapeError(f"target: expected the shape of source {src.shape}, got {dst.shape}")
    n, dim = src.shape
    if dim < 2:
        raise ShapeError(f"source: expected points of dimension D >= 2, got D={dim}")
    if n == 0:
        raise GeometryError("align_points: expected at least one pair of points, got none")
    if weights is None:
        p = np.full(n, 1.0 / n)
    else:
        w = as_array(weights, "weights", (n,))
        if np.any(w < 0):
            raise InputError("weights: expected non-negative weights")
        total = float(w.sum())
        if not total > 0:
            raise GeometryError("align_points: all weights are zero, nothing to align")
        p = w / total

    mu_s = p @ src
    mu_t = p @ dst
    a = src - mu_s
    b = dst - mu_t
    var_s = float(p @ np.einsum("ij,ij->i", a, a))
    var_t = float(p @ np.einsum("ij,ij->i", b, b))
    if var_s == 0.0 or var_t == 0.0:
        which = "source" if var_s == 0.0 else "target"
        raise GeometryError(
            f"align_points: the {which} points (with positive weight) all coincide; "
            f"the rotation is not determined"
        )

    # Σ = Σ_i p_i b_i a_iᵀ, the weighted cross-covariance (D, D).
    sigma = (b * p[:, None]).T @ a
    U, d, Vt = np.linalg.svd(sigma)
    if d[dim - 2] <= _RANK_RTOL * np.sqrt(var_s * var_t):
        need = "two distinct points" if dim == 2 else f"{dim} points spanning {dim - 1} dims"
        raise GeometryError(
            f"align_points: the rotation is not determined (cross-covariance of rank < {dim - 1}"
            f"); a {dim}-D alignment needs at least {need} with positive weight, not collinear "
            f"or uncorrelated"
        )
    # Reflection correction: flip the axis of the smallest singular value if U Vᵀ is improper.
    signs = np.ones(dim)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        signs[-1] = -1.0
    R = (U * signs) @ Vt
    scale = float(d @ signs) / var_s if with_scale else 1.0
    if not scale > 0:  # only if the best proper rotation anti-correlates the sets
        raise GeometryError(
            f"align_points: the least-squares scale is {scale:.3g} <= 0; the point sets do not "
            f"correspond under a proper rotation"
        )
    t = mu_t - scale * (R @ mu_s)
    return Similarity(R, t, scale)


def align_points_2d(
    source: ArrayLike,
    target: ArrayLike,
    weights: ArrayLike | None = None,
    with_scale: bool = False,
) -> Similarity:
    """:func:`align_points` for 2-D points ``(N, 2)``, rejecting any other dimension.

    The result supports :attr:`Similarity.angle`, :meth:`Similarity.apply_to_poses` and (when
    rigid) :meth:`Similarity.as_pose`.
    """
    as_array(source, "source", (None, 2))
    as_array(target, "target", (None, 2))
    return align_points(source, target, weights, with_scale)
