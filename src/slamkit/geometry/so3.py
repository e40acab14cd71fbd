"""SO(3): rotations in space as unit quaternions in ``wxyz`` order.

Parameters ``(..., 4)``: ``(qw, qx, qy, qz)`` (Hamilton convention, scalar first; ``q`` and
``-q`` are the same rotation). Tangent ``(..., 3)``: the rotation vector ``ω = θ·axis`` in
radians. Points ``(..., 3)``. Roll-pitch-yaw follows the aerospace/ROS convention
``R = Rz(yaw) Ry(pitch) Rx(roll)``.

The quaternion kernels are module functions on plain arrays so that :mod:`se3` shares them.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.geometry._lie import (
    SMALL_ANGLE,
    BatchShape,
    LieGroup,
    batch_tuple,
    broadcast_batch,
    check_rng,
    check_rotation_matrix,
    unit_normalized,
)
from slamkit.geometry.angles import wrap_angle

__all__ = ["SO3"]


# --------------------------------------------------------------------- array kernels (wxyz)


def quat_multiply(q1: FloatArray, q2: FloatArray) -> FloatArray:
    """Hamilton product ``q1 q2`` of ``(..., 4)`` wxyz quaternions (batch axes broadcast)."""
    w1, x1, y1, z1 = (q1[..., i] for i in range(4))
    w2, x2, y2, z2 = (q2[..., i] for i in range(4))
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=-1,
    )


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a × b`` of ``(..., 3)`` vectors with broadcasting batch axes."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def quat_rotate(q: FloatArray, p: FloatArray) -> FloatArray:
    """Rotate points ``p (..., 3)`` by unit quaternions ``q (..., 4)``."""
    w, u = q[..., :1], q[..., 1:]
    # q p q* expanded for a unit q: p + 2w (u × p) + 2 u × (u × p).
    uxp = cross(u, p)
    return p + 2.0 * (w * uxp + cross(u, uxp))


def quat_to_matrix(q: FloatArray) -> FloatArray:
    """``(..., 3, 3)`` rotation matrices of unit quaternions ``(..., 4)``."""
    w, x, y, z = (q[..., i] for i in range(4))
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def matrix_to_quat(R: FloatArray) -> FloatArray:
    """Unit quaternions ``(..., 4)`` of rotation matrices ``(..., 3, 3)``.

    Row ``k`` of the symmetric matrix ``K`` below equals ``4 q_k q``. Taking the row with the
    largest diagonal entry (``4 q_k² >= 1``) and normalising it is exact and never divides by
    a small number, whatever the rotation (Shepperd's method without branches).
    """
    r = R
    d0, d1, d2 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    a = r[..., 2, 1] - r[..., 1, 2]
    b = r[..., 0, 2] - r[..., 2, 0]
    c = r[..., 1, 0] - r[..., 0, 1]
    xy = r[..., 0, 1] + r[..., 1, 0]
    xz = r[..., 0, 2] + r[..., 2, 0]
    yz = r[..., 1, 2] + r[..., 2, 1]
    K = np.stack(
        [
            np.stack([1 + d0 + d1 + d2, a, b, c], axis=-1),
            np.stack([a, 1 + d0 - d1 - d2, xy, xz], axis=-1),
            np.stack([b, xy, 1 - d0 + d1 - d2, yz], axis=-1),
            np.stack([c, xz, yz, 1 - d0 - d1 + d2], axis=-1),
        ],
        axis=-2,
    )
    k = np.argmax(np.diagonal(K, axis1=-2, axis2=-1), axis=-1)
    row = np.take_along_axis(K, k[..., None, None], axis=-2)[..., 0, :]
    return row / np.linalg.norm(row, axis=-1, keepdims=True)


def quat_exp(omega: FloatArray) -> FloatArray:
    """Unit quaternions of rotation vectors ``(..., 3)``: ``(cos(θ/2), sin(θ/2)/θ · ω)``."""
    t2 = np.sum(omega * omega, axis=-1)
    theta = np.sqrt(t2)
    small = theta < SMALL_ANGLE
    t = np.where(small, 1.0, theta)  # a safe divisor; the small entries take the series
    # sin(θ/2)/θ is 0/0 at θ = 0: use 1/2 - θ²/48 + θ⁴/3840 there.
    k = np.where(small, 0.5 - t2 / 48.0 + t2 * t2 / 3840.0, np.sin(t / 2.0) / t)
    return np.concatenate([np.cos(theta / 2.0)[..., None], k[..., None] * omega], axis=-1)


def quat_log(q: FloatArray) -> FloatArray:
    """Rotation vectors ``(..., 3)`` of unit quaternions, with angle ``|ω|`` in ``[0, π]``."""
    # q and -q are the same rotation; pick the one with w >= 0 so θ = 2 atan2(|u|, w) <= π.
    sign = np.where(q[..., 0] < 0.0, -1.0, 1.0)
    w = sign * q[..., 0]
    u = sign[..., None] * q[..., 1:]
    n = np.linalg.norm(u, axis=-1)
    small = n < SMALL_ANGLE
    n_safe = np.where(small, 1.0, n)
    w_safe = np.where(small, w, 1.0)  # w ≈ 1 wherever |u| is small
    r2 = (n / w_safe) ** 2
    # θ/|u| = 2 atan(|u|/w)/|u| is 0/0 at u = 0: use its series (2/w)(1 - r²/3 + r⁴/5), r = |u|/w.
    k = np.where(
        small,
        (2.0 / w_safe) * (1.0 - r2 / 3.0 + r2 * r2 / 5.0),
        2.0 * np.arctan2(n, w) / n_safe,
    )
    return k[..., None] * u


def hat(omega: FloatArray) -> FloatArray:
    """Skew matrices ``[ω]×`` ``(..., 3, 3)`` with ``[ω]× p = ω × p``."""
    x, y, z = omega[..., 0], omega[..., 1], omega[..., 2]
    zero = np.zeros_like(x)
    return np.stack(
        [
            np.stack([zero, -z, y], axis=-1),
            np.stack([z, zero, -x], axis=-1),
            np.stack([-y, x, zero], axis=-1),
        ],
        axis=-2,
    )


# --------------------------------------------------------------------- the group value


class SO3(LieGroup):
    """A batch of 3-D rotations over unit quaternions ``wxyz (..., 4) = (qw, qx, qy, qz)``.

    ``SO3(wxyz)`` and :meth:`from_quaternion_wxyz` validate the quaternion and normalise it if
    its norm is within ``1e-6`` of one (else :class:`~slamkit.errors.InputError`). Tangent
    vectors are rotation vectors ``(ωx, ωy, ωz)``; :meth:`log` returns the one of angle in
    ``[0, π]`` whichever of ``q``, ``-q`` is stored.
    """

    __slots__ = ()
    matrix_dim: ClassVar[int] = 3
    parameters_dim: ClassVar[int] = 4
    tangent_dim: ClassVar[int] = 3
    space_dim: ClassVar[int] = 3
    parameters_name: ClassVar[str] = "wxyz"

    @classmethod
    def _checked_parameters(cls, params: FloatArray, name: str) -> FloatArray:
        return unit_normalized(params, name)

    # ----------------------------------------------------------------- constructors

    @classmethod
    def identity(cls, batch_shape: BatchShape = ()) -> SO3:
        params = np.zeros((*batch_tuple(batch_shape), 4))
        params[..., 0] = 1.0
        return cls.from_parameters_unchecked(params)

    @classmethod
    def from_quaternion_wxyz(cls, quat_wxyz: ArrayLike) -> SO3:
        """From quaternions ``(..., 4)`` in wxyz order; the same as ``SO3(quat_wxyz)``."""
        return cls(quat_wxyz)

    @classmethod
    def from_quaternion_xyzw(cls, quat_xyzw: ArrayLike) -> SO3:
        """From quaternions ``(..., 4)`` in xyzw order (ROS, SciPy, TUM trajectories)."""
        q = as_array(quat_xyzw, "quat_xyzw", (..., 4))
        return cls(np.roll(q, 1, axis=-1))

    @classmethod
    def from_rpy_radians(cls, rpy: ArrayLike) -> SO3:
        """From ``(..., 3) = (roll, pitch, yaw)`` in radians: ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
        a = as_array(rpy, "rpy", (..., 3)) / 2.0
        cr, sr = np.cos(a[..., 0]), np.sin(a[..., 0])
        cp, sp = np.cos(a[..., 1]), np.sin(a[..., 1])
        cy, sy = np.cos(a[..., 2]), np.sin(a[..., 2])
        # q = q_z(yaw) q_y(pitch) q_x(roll), multiplied out.
        return cls.from_parameters_unchecked(
            np.stack(
                [
                    cr * cp * cy + sr * sp * sy,
                    sr * cp * cy - cr * sp * sy,
                    cr * sp * cy + sr * cp * sy,
                    cr * cp * sy - sr * sp * cy,
                ],
                axis=-1,
            )
        )

    @classmethod
    def from_matrix(cls, matrix: ArrayLike) -> SO3:
        R = as_array(matrix, "SO3 matrix", (..., 3, 3))
        check_rotation_matrix(R, "SO3 matrix")
        return cls.from_parameters_unchecked(matrix_to_quat(R))

    @classmethod
    def sample_uniform(cls, rng: np.random.Generator, batch_shape: BatchShape = ()) -> SO3:
        """Uniform (Haar) rotations: a normalised 4-D standard normal is uniform on S³."""
        q = check_rng(rng).standard_normal(size=(*batch_tuple(batch_shape), 4))
        return cls.from_parameters_unchecked(q / np.linalg.norm(q, axis=-1, keepdims=True))

    # ----------------------------------------------------------------- accessors

    @property
    def wxyz(self) -> FloatArray:
        """The read-only parameters ``(..., 4) = (qw, qx, qy, qz)``."""
        return self._params

    def quaternion_wxyz(self) -> FloatArray:
        """A copy of the quaternions ``(..., 4)`` in wxyz order."""
        return np.array(self._params)

    def quaternion_xyzw(self) -> FloatArray:
        """The quaternions ``(..., 4)`` in xyzw order (ROS, SciPy, TUM trajectories)."""
        return np.roll(self._params, -1, axis=-1)

    def as_rpy_radians(self) -> FloatArray:
        """``(..., 3) = (roll, pitch, yaw)`` with ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

        Roll and yaw lie in ``[-π, π)``, pitch in ``[-π/2, π/2]``. At pitch ±π/2 (gimbal lock)
        only roll ± yaw is determined and the split between them is arbitrary.
        """
        w, x, y, z = (self._params[..., i] for i in range(4))
        r00 = 1 - 2 * (y * y + z * z)
        r10 = 2 * (x * y + w * z)
        r20 = 2 * (x * z - w * y)
        r21 = 2 * (y * z + w * x)
        r22 = 1 - 2 * (x * x + y * y)
        roll = np.arctan2(r21, r22)
        # atan2 against cos(pitch) = |(r00, r10)| is accurate near ±π/2, unlike asin(-r20).
        pitch = np.arctan2(-r20, np.hypot(r00, r10))
        yaw = np.arctan2(r10, r00)
        return wrap_angle(np.stack([roll, pitch, yaw], axis=-1))

    def as_matrix(self) -> FloatArray:
        return quat_to_matrix(self._params)

    # ----------------------------------------------------------------- group operations

    def compose(self, other: SO3) -> SO3:
        self._check_same_group(other, "compose")
        broadcast_batch(self.batch_shape, other.batch_shape, "SO3 compose")
        return self.from_parameters_unchecked(quat_multiply(self._params, other.parameters))

    def inverse(self) -> SO3:
        # The conjugate is the inverse of a unit quaternion.
        return self.from_parameters_unchecked(self._params * np.array([1.0, -1.0, -1.0, -1.0]))

    def apply(self, points: ArrayLike) -> FloatArray:
        p = as_array(points, "points", (..., 3))
        broadcast_batch(self.batch_shape, p.shape[:-1], "SO3 apply")
        return quat_rotate(self._params, p)

    @classmethod
    def exp(cls, tangent: ArrayLike) -> SO3:
        return cls.from_parameters_unchecked(quat_exp(as_array(tangent, "SO3 tangent", (..., 3))))

    def log(self) -> FloatArray:
        return quat_log(self._params)

    def adjoint(self) -> FloatArray:
        # R exp(ω) Rᵀ = exp(R ω), so Ad = R.
        return self.as_matrix()

    def normalize(self) -> SO3:
        return self.from_parameters_unchecked(
            self._params / np.linalg.norm(self._params, axis=-1, keepdims=True)
        )
