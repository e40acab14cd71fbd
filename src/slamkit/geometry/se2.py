"""SE(2): planar rigid motions as a group value.

Parameters ``(..., 4)``: ``(cos θ, sin θ, x, y)``. Tangent ``(..., 3)``: ``(vx, vy, ω)``,
translation first (the order of slamkit's ``(x, y, θ)`` pose arrays). Points ``(..., 2)``.

:mod:`slamkit.geometry.pose2` implements the same group on plain ``(..., 3)`` ``(x, y, θ)``
arrays; :meth:`SE2.from_xy_theta` and :meth:`SE2.xy_theta` convert between the two, and a test
checks that both compose, invert and transform alike.
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
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.so2 import SO2

__all__ = ["SE2"]


def _sinc_and_cosc(theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``A = sin θ / θ`` and ``B = (1 - cos θ) / θ``, finite and accurate for every θ."""
    small = np.abs(theta) < SMALL_ANGLE
    t = np.where(small, 1.0, theta)  # a safe divisor; the small entries take the series
    t2 = theta * theta
    # Near θ = 0 both are 0/0: use their Taylor series instead.
    A = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, np.sin(t) / t)
    # 1 - cos θ = 2 sin²(θ/2) avoids the cancellation of 1 - cos θ for small θ.
    B = np.where(
        small,
        theta / 2.0 - theta * t2 / 24.0 + theta * t2 * t2 / 720.0,
        2.0 * np.sin(t / 2) ** 2 / t,
    )
    return A, B


def _half_theta_cot(theta: FloatArray) -> FloatArray:
    """``(θ/2) cot(θ/2)``, finite for |θ| <= π; the diagonal of the inverse V matrix."""
    small = np.abs(theta) < SMALL_ANGLE
    half = np.where(small, 1.0, theta / 2.0)
    t2 = theta * theta
    # 0/0 at θ = 0: x cot x = 1 - x²/3 - x⁴/45 - ... with x = θ/2.
    return np.where(small, 1.0 - t2 / 12.0 - t2 * t2 / 720.0, half * np.cos(half) / np.sin(half))


class SE2(LieGroup):
    """A batch of planar rigid motions over ``unit_complex_xy (..., 4) = (cos θ, sin θ, x, y)``.

    ``SE2(unit_complex_xy)`` validates its argument and normalises ``(cos θ, sin θ)`` if its norm
    is within ``1e-6`` of one (else :class:`~slamkit.errors.InputError`). Tangent vectors are
    ``(vx, vy, ω)``; ``x.box_plus(δ) = x @ exp(δ)`` perturbs in the body frame.
    """

    __slots__ = ()
    matrix_dim: ClassVar[int] = 3
    parameters_dim: ClassVar[int] = 4
    tangent_dim: ClassVar[int] = 3
    space_dim: ClassVar[int] = 2
    parameters_name: ClassVar[str] = "unit_complex_xy"

    @classmethod
    def _checked_parameters(cls, params: FloatArray, name: str) -> FloatArray:
        rot = unit_normalized(params[..., :2], f"{name} (cos, sin)")
        return np.concatenate([rot, params[..., 2:]], axis=-1)

    # ----------------------------------------------------------------- constructors

    @classmethod
    def identity(cls, batch_shape: BatchShape = ()) -> SE2:
        params = np.zeros((*batch_tuple(batch_shape), 4))
        params[..., 0] = 1.0
        return cls.from_parameters_unchecked(params)

    @classmethod
    def from_xy_theta(cls, xy_theta: ArrayLike) -> SE2:
        """From pose arrays ``(..., 3) = (x, y, θ)`` as used by :mod:`~slamkit.geometry.pose2`."""
        p = as_array(xy_theta, "xy_theta", (..., 3))
        theta = p[..., 2]
        return cls.from_parameters_unchecked(
            np.stack([np.cos(theta), np.sin(theta), p[..., 0], p[..., 1]], axis=-1)
        )

    @classmethod
    def from_rotation_and_translation(cls, rotation: SO2, translation: ArrayLike) -> SE2:
        """``T = (R, t)``: rotate, then translate by ``translation (..., 2)``; batches broadcast."""
        if not isinstance(rotation, SO2):
            raise InputError(f"rotation: expected an SO2, got {type(rotation).__name__}")
        t = as_array(translation, "translation", (..., 2))
        shape = broadcast_batch(rotation.batch_shape, t.shape[:-1], "SE2 rotation and translation")
        return cls.from_parameters_unchecked(
            np.concatenate(
                [
                    np.broadcast_to(rotation.parameters, (*shape, 2)),
                    np.broadcast_to(t, (*shape, 2)),
                ],
                axis=-1,
            )
        )

    @classmethod
    def from_translation(cls, translation: ArrayLike) -> SE2:
        """Pure translations by ``translation (..., 2)``."""
        t = as_array(translation, "translation", (..., 2))
        return cls.from_rotation_and_translation(SO2.identity(t.shape[:-1]), t)

    @classmethod
    def from_matrix(cls, matrix: ArrayLike) -> SE2:
        M = as_array(matrix, "SE2 matrix", (..., 3, 3))
        check_homogeneous_row(M, "SE2 matrix")
        check_rotation_matrix(M[..., :2, :2], "SE2 matrix rotation block")
        rotation = SO2.from_matrix(M[..., :2, :2])
        return cls.from_parameters_unchecked(
            np.concatenate([rotation.parameters, M[..., :2, 2]], axis=-1)
        )

    @classmethod
    def sample_uniform(cls, rng: np.random.Generator, batch_shape: BatchShape = ()) -> SE2:
        """Headings uniform on ``[-π, π)``, translations uniform on the square ``[-1, 1]²``."""
        shape = batch_tuple(batch_shape)
        rotation = SO2.sample_uniform(rng, shape)
        t = check_rng(rng).uniform(-1.0, 1.0, size=(*shape, 2))
        return cls.from_parameters_unchecked(np.concatenate([rotation.parameters, t], axis=-1))

    # ----------------------------------------------------------------- accessors

    @property
    def unit_complex_xy(self) -> FloatArray:
        """The read-only parameters ``(..., 4) = (cos θ, sin θ, x, y)``."""
        return self._params

    def rotation(self) -> SO2:
        return SO2.from_parameters_unchecked(self._params[..., :2])

    def translation(self) -> FloatArray:
        """``(..., 2)``: ``(x, y)``."""
        return np.array(self._params[..., 2:])

    def xy_theta(self) -> FloatArray:
        """Pose arrays ``(..., 3) = (x, y, θ)`` with θ wrapped to ``[-π, π)``."""
        p = self._params
        theta = wrap_angle(np.arctan2(p[..., 1], p[..., 0]))
        return np.stack([p[..., 2], p[..., 3], theta], axis=-1)

    def as_matrix(self) -> FloatArray:
        c, s, x, y = (self._params[..., i] for i in range(4))
        M = np.zeros((*self.batch_shape, 3, 3))
        M[..., 0, 0], M[..., 0, 1], M[..., 0, 2] = c, -s, x
        M[..., 1, 0], M[..., 1, 1], M[..., 1, 2] = s, c, y
        M[..., 2, 2] = 1.0
        return M

    # ----------------------------------------------------------------- group operations

    def compose(self, other: SE2) -> SE2:
        self._check_same_group(other, "compose")
        broadcast_batch(self.batch_shape, other.batch_shape, "SE2 compose")
        c1, s1, x1, y1 = (self._params[..., i] for i in range(4))
        c2, s2, x2, y2 = (other.parameters[..., i] for i in range(4))
        # (R1, t1)(R2, t2) = (R1 R2, R1 t2 + t1).
        return self.from_parameters_unchecked(
            np.stack(
                [
                    c1 * c2 - s1 * s2,
                    s1 * c2 + c1 * s2,
                    c1 * x2 - s1 * y2 + x1,
                    s1 * x2 + c1 * y2 + y1,
                ],
                axis=-1,
            )
        )

    def inverse(self) -> SE2:
        c, s, x, y = (self._params[..., i] for i in range(4))
        # (R, t)⁻¹ = (Rᵀ, -Rᵀ t).
        return self.from_parameters_unchecked(
            np.stack([c, -s, -c * x - s * y, s * x - c * y], axis=-1)
        )

    def apply(self, points: ArrayLike) -> FloatArray:
        p = as_array(points, "points", (..., 2))
        broadcast_batch(self.batch_shape, p.shape[:-1], "SE2 apply")
        c, s, x, y = (self._params[..., i] for i in range(4))
        return np.stack(
            [c * p[..., 0] - s * p[..., 1] + x, s * p[..., 0] + c * p[..., 1] + y], axis=-1
        )

    @classmethod
    def exp(cls, tangent: ArrayLike) -> SE2:
        xi = as_array(tangent, "SE2 tangent", (..., 3))
        vx, vy, theta = xi[..., 0], xi[..., 1], xi[..., 2]
        # t = V(θ) v with V = [[A, -B], [B, A]], A = sin θ/θ, B = (1 - cos θ)/θ: the end point of
        # a constant-velocity arc.
        A, B = _sinc_and_cosc(theta)
        return cls.from_parameters_unchecked(
            np.stack([np.cos(theta), np.sin(theta), A * vx - B * vy, B * vx + A * vy], axis=-1)
        )

    def log(self) -> FloatArray:
        c, s, x, y = (self._params[..., i] for i in range(4))
        theta = wrap_angle(np.arctan2(s, c))
        # v = V(θ)⁻¹ t with V⁻¹ = [[α, θ/2], [-θ/2, α]], α = (θ/2) cot(θ/2) (finite up to |θ| = π).
        alpha = _half_theta_cot(theta)
        half = theta / 2.0
        return np.stack([alpha * x + half * y, -half * x + alpha * y, theta], axis=-1)

    def adjoint(self) -> FloatArray:
        c, s, x, y = (self._params[..., i] for i in range(4))
        # For ξ = (v, ω): Ad = [[R, (y, -x)ᵀ], [0, 1]] since T ξ^ T⁻¹ = (R v + ω (y, -x), ω).
        Ad = np.zeros((*self.batch_shape, 3, 3))
        Ad[..., 0, 0], Ad[..., 0, 1], Ad[..., 0, 2] = c, -s, y
        Ad[..., 1, 0], Ad[..., 1, 1], Ad[..., 1, 2] = s, c, -x
        Ad[..., 2, 2] = 1.0
        return Ad

    def normalize(self) -> SE2:
        rot = self._params[..., :2]
        rot = rot / np.linalg.norm(rot, axis=-1, keepdims=True)
        return self.from_parameters_unchecked(np.concatenate([rot, self._params[..., 2:]], axis=-1))
