"""SE(3): rigid motions in space as a group value.

Parameters ``(..., 7)``: ``(qw, qx, qy, qz, x, y, z)`` — a unit quaternion in wxyz order, then
the translation. Tangent ``(..., 6)``: ``(vx, vy, vz, ωx, ωy, ωz)``, translation first; this is
the order of g2o's ``EDGE_SE3:QUAT`` information matrices (x, y, z, rx, ry, rz). Points
``(..., 3)``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError
from slamkit.geometry._lie import (
    SMALL_ANGLE,
    BatchShape,
    LieGroup,
    batch_tuple,
    broadcast_batch,
    check_homogeneous_row,
    check_rng,
    check_rotation_matrix,
    unit_normalized,
)
from slamkit.geometry.so3 import (
    SO3,
    cross,
    hat,
    matrix_to_quat,
    quat_exp,
    quat_log,
    quat_multiply,
    quat_rotate,
    quat_to_matrix,
)

__all__ = ["SE3"]


class SE3(LieGroup):
    """A batch of 3-D rigid motions over ``wxyz_xyz (..., 7) = (qw, qx, qy, qz, x, y, z)``.

    ``SE3(wxyz_xyz)`` validates its argument and normalises the quaternion if its norm is within
    ``1e-6`` of one (else :class:`~slamkit.errors.InputError`). Tangent vectors are
    ``(vx, vy, vz, ωx, ωy, ωz)``; ``x.box_plus(δ) = x @ exp(δ)`` perturbs in the body frame.
    """

    __slots__ = ()
    matrix_dim: ClassVar[int] = 4
    parameters_dim: ClassVar[int] = 7
    tangent_dim: ClassVar[int] = 6
    space_dim: ClassVar[int] = 3
    parameters_name: ClassVar[str] = "wxyz_xyz"

    @classmethod
    def _checked_parameters(cls, params: FloatArray, name: str) -> FloatArray:
        q = unit_normalized(params[..., :4], f"{name} quaternion")
        return np.concatenate([q, params[..., 4:]], axis=-1)

    # ----------------------------------------------------------------- constructors

    @classmethod
    def identity(cls, batch_shape: BatchShape = ()) -> SE3:
        params = np.zeros((*batch_tuple(batch_shape), 7))
        params[..., 0] = 1.0
        return cls.from_parameters_unchecked(params)

    @classmethod
    def from_rotation_and_translation(cls, rotation: SO3, translation: ArrayLike) -> SE3:
        """``T = (R, t)``: rotate, then translate by ``translation (..., 3)``; batches broadcast."""
        if not isinstance(rotation, SO3):
            raise InputError(f"rotation: expected an SO3, got {type(rotation).__name__}")
        t = as_array(translation, "translation", (..., 3))
        shape = broadcast_batch(rotation.batch_shape, t.shape[:-1], "SE3 rotation and translation")
        return cls.from_parameters_unchecked(
            np.concatenate(
                [
                    np.broadcast_to(rotation.parameters, (*shape, 4)),
                    np.broadcast_to(t, (*shape, 3)),
                ],
                axis=-1,
            )
        )

    @classmethod
    def from_translation(cls, translation: ArrayLike) -> SE3:
        """Pure translations by ``translation (..., 3)``."""
        t = as_array(translation, "translation", (..., 3))
        return cls.from_rotation_and_translation(SO3.identity(t.shape[:-1]), t)

    @classmethod
    def from_quaternion_wxyz_and_translation(cls, quat_wxyz: ArrayLike, xyz: ArrayLike) -> SE3:
        """From quaternions ``(..., 4)`` in wxyz order and translations ``(..., 3)``."""
        return cls.from_rotation_and_translation(SO3.from_quaternion_wxyz(quat_wxyz), xyz)

    @classmethod
    def from_matrix(cls, matrix: ArrayLike) -> SE3:
        M = as_array(matrix, "SE3 matrix", (..., 4, 4))
        check_homogeneous_row(M, "SE3 matrix")
        check_rotation_matrix(M[..., :3, :3], "SE3 matrix rotation block")
        return cls.from_parameters_unchecked(
            np.concatenate([matrix_to_quat(M[..., :3, :3]), M[..., :3, 3]], axis=-1)
        )

    @classmethod
    def sample_uniform(cls, rng: np.random.Generator, batch_shape: BatchShape = ()) -> SE3:
        """Uniform (Haar) rotations, translations uniform on the cube ``[-1, 1]³``."""
        shape = batch_tuple(batch_shape)
        rotation = SO3.sample_uniform(rng, shape)
        t = check_rng(rng).uniform(-1.0, 1.0, size=(*shape, 3))
        return cls.from_parameters_unchecked(np.concatenate([rotation.parameters, t], axis=-1))

    # ----------------------------------------------------------------- accessors

    @property
    def wxyz_xyz(self) -> FloatArray:
        """The read-only parameters ``(..., 7) = (qw, qx, qy, qz, x, y, z)``."""
        return self._params

    def rotation(self) -> SO3:
        return SO3.from_parameters_unchecked(self._params[..., :4])

    def translation(self) -> FloatArray:
        """``(..., 3)``: ``(x, y, z)``."""
        return np.array(self._params[..., 4:])

    def quaternion_wxyz(self) -> FloatArray:
        """A copy of the rotation quaternions ``(..., 4)`` in wxyz order."""
        return np.array(self._params[..., :4])

    def as_matrix(self) -> FloatArray:
        M = np.zeros((*self.batch_shape, 4, 4))
        M[..., :3, :3] = quat_to_matrix(self._params[..., :4])
        M[..., :3, 3] = self._params[..., 4:]
        M[..., 3, 3] = 1.0
        return M

    # ----------------------------------------------------------------- group operations

    def compose(self, other: SE3) -> SE3:
        self._check_same_group(other, "compose")
        broadcast_batch(self.batch_shape, other.batch_shape, "SE3 compose")
        q1, t1 = self._params[..., :4], self._params[..., 4:]
        q2, t2 = other.parameters[..., :4], other.parameters[..., 4:]
        # (R1, t1)(R2, t2) = (R1 R2, R1 t2 + t1).
        return self.from_parameters_unchecked(
            np.concatenate([quat_multiply(q1, q2), quat_rotate(q1, t2) + t1], -1)
        )

    def inverse(self) -> SE3:
        q_inv = self._params[..., :4] * np.array([1.0, -1.0, -1.0, -1.0])
        # (R, t)⁻¹ = (Rᵀ, -Rᵀ t).
        return self.from_parameters_unchecked(
            np.concatenate([q_inv, -quat_rotate(q_inv, self._params[..., 4:])], -1)
        )

    def apply(self, points: ArrayLike) -> FloatArray:
        p = as_array(points, "points", (..., 3))
        broadcast_batch(self.batch_shape, p.shape[:-1], "SE3 apply")
        return quat_rotate(self._params[..., :4], p) + self._params[..., 4:]

    @classmethod
    def exp(cls, tangent: ArrayLike) -> SE3:
        xi = as_array(tangent, "SE3 tangent", (..., 6))
        v, omega = xi[..., :3], xi[..., 3:]
        t2 = np.sum(omega * omega, axis=-1)
        theta = np.sqrt(t2)
        small = theta < SMALL_ANGLE
        t = np.where(small, 1.0, theta)  # a safe divisor; the small entries take the series
        # t = V v with V = I + B [ω]× + C [ω]×², B = (1 - cos θ)/θ², C = (θ - sin θ)/θ³. Both
        # are 0/0 at θ = 0 (and lose digits to cancellation near it): Taylor series there.
        B = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, 2.0 * np.sin(t / 2.0) ** 2 / t**2)
        C = np.where(small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0, (t - np.sin(t)) / t**3)
        wxv = cross(omega, v)
        trans = v + B[..., None] * wxv + C[..., None] * cross(omega, wxv)
        return cls.from_parameters_unchecked(np.concatenate([quat_exp(omega), trans], axis=-1))

    def log(self) -> FloatArray:
        omega = quat_log(self._params[..., :4])
        trans = self._params[..., 4:]
        t2 = np.sum(omega * omega, axis=-1)
        theta = np.sqrt(t2)
        small = theta < SMALL_ANGLE
        half = np.where(small, 1.0, theta / 2.0)
        # v = V⁻¹ t with V⁻¹ = I - ½[ω]× + D [ω]×², D = (1 - α)/θ², α = (θ/2) cot(θ/2); D is
        # 0/0 at θ = 0 (series 1/12 + θ²/720 + θ⁴/30240) and equals 1/π² at θ = π.
        alpha = half * np.cos(half) / np.sin(half)
        D = np.where(
            small, 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0, (1.0 - alpha) / (4 * half**2)
        )
        wxt = cross(omega, trans)
        v = trans - 0.5 * wxt + D[..., None] * cross(omega, wxt)
        return np.concatenate([v, omega], axis=-1)

    def adjoint(self) -> FloatArray:
        # For ξ = (v, ω): T ξ^ T⁻¹ = (R v + t × R ω, R ω), so Ad = [[R, [t]× R], [0, R]].
        R = quat_to_matrix(self._params[..., :4])
        Ad = np.zeros((*self.batch_shape, 6, 6))
        Ad[..., :3, :3] = R
        Ad[..., :3, 3:] = hat(self._params[..., 4:]) @ R
        Ad[..., 3:, 3:] = R
        return Ad

    def normalize(self) -> SE3:
        q = self._params[..., :4]
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
        return self.from_parameters_unchecked(np.concatenate([q, self._params[..., 4:]], axis=-1))
