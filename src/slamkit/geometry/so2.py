"""SO(2): planar rotations as unit complex numbers.

Parameters ``(..., 2)``: ``(cos θ, sin θ)``. Tangent ``(..., 1)``: the angle ``ω`` in radians.
Points ``(..., 2)``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.geometry._lie import (
    BatchShape,
    LieGroup,
    batch_tuple,
    broadcast_batch,
    check_rng,
    check_rotation_matrix,
    unit_normalized,
)
from slamkit.geometry.angles import wrap_angle

__all__ = ["SO2"]


class SO2(LieGroup):
    """A batch of planar rotations over ``unit_complex (..., 2) = (cos θ, sin θ)``.

    ``SO2(unit_complex)`` validates its argument and normalises it if its norm is within
    ``1e-6`` of one (else :class:`~slamkit.errors.InputError`). Tangent vectors are ``(..., 1)``
    angles in radians; :meth:`log` and :meth:`angle` return them wrapped to ``[-π, π)``.
    """

    __slots__ = ()
    matrix_dim: ClassVar[int] = 2
    parameters_dim: ClassVar[int] = 2
    tangent_dim: ClassVar[int] = 1
    space_dim: ClassVar[int] = 2
    parameters_name: ClassVar[str] = "unit_complex"

    @classmethod
    def _checked_parameters(cls, params: FloatArray, name: str) -> FloatArray:
        return unit_normalized(params, name)

    # ----------------------------------------------------------------- constructors

    @classmethod
    def identity(cls, batch_shape: BatchShape = ()) -> SO2:
        params = np.zeros((*batch_tuple(batch_shape), 2))
        params[..., 0] = 1.0
        return cls.from_parameters_unchecked(params)

    @classmethod
    def from_angle(cls, theta: ArrayLike) -> SO2:
        """Rotations by ``theta`` radians (any shape; that shape becomes the batch shape)."""
        t = as_array(theta, "theta")
        return cls.from_parameters_unchecked(np.stack([np.cos(t), np.sin(t)], axis=-1))

    @classmethod
    def from_unit_complex(cls, unit_complex: ArrayLike) -> SO2:
        """From ``(cos θ, sin θ)`` pairs ``(..., 2)``; the same as ``SO2(unit_complex)``."""
        return cls(unit_complex)

    @classmethod
    def from_matrix(cls, matrix: ArrayLike) -> SO2:
        R = as_array(matrix, "SO2 matrix", (..., 2, 2))
        check_rotation_matrix(R, "SO2 matrix")
        # Average the two copies of cos and sin in R = [[c, -s], [s, c]], then renormalise.
        c = 0.5 * (R[..., 0, 0] + R[..., 1, 1])
        s = 0.5 * (R[..., 1, 0] - R[..., 0, 1])
        params = np.stack([c, s], axis=-1)
        return cls.from_parameters_unchecked(
            params / np.linalg.norm(params, axis=-1, keepdims=True)
        )

    @classmethod
    def sample_uniform(cls, rng: np.random.Generator, batch_shape: BatchShape = ()) -> SO2:
        """Angles uniform on ``[-π, π)``."""
        theta = check_rng(rng).uniform(-np.pi, np.pi, size=batch_tuple(batch_shape))
        return cls.from_parameters_unchecked(np.stack([np.cos(theta), np.sin(theta)], axis=-1))

    # ----------------------------------------------------------------- accessors

    @property
    def unit_complex(self) -> FloatArray:
        """The read-only parameters ``(..., 2) = (cos θ, sin θ)``."""
        return self._params

    def angle(self) -> FloatArray:
        """The rotation angle ``(...)`` in radians, wrapped to ``[-π, π)``."""
        return wrap_angle(np.arctan2(self._params[..., 1], self._params[..., 0]))

    def as_matrix(self) -> FloatArray:
        c, s = self._params[..., 0], self._params[..., 1]
        return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)

    # ----------------------------------------------------------------- group operations

    def compose(self, other: SO2) -> SO2:
        self._check_same_group(other, "compose")
        broadcast_batch(self.batch_shape, other.batch_shape, "SO2 compose")
        a, b = self._params, other.parameters
        # Complex multiplication (c1 + i s1)(c2 + i s2).
        c = a[..., 0] * b[..., 0] - a[..., 1] * b[..., 1]
        s = a[..., 1] * b[..., 0] + a[..., 0] * b[..., 1]
        return self.from_parameters_unchecked(np.stack([c, s], axis=-1))

    def inverse(self) -> SO2:
        return self.from_parameters_unchecked(self._params * np.array([1.0, -1.0]))

    def apply(self, points: ArrayLike) -> FloatArray:
        p = as_array(points, "points", (..., 2))
        broadcast_batch(self.batch_shape, p.shape[:-1], "SO2 apply")
        c, s = self._params[..., 0], self._params[..., 1]
        return np.stack([c * p[..., 0] - s * p[..., 1], s * p[..., 0] + c * p[..., 1]], axis=-1)

    @classmethod
    def exp(cls, tangent: ArrayLike) -> SO2:
        omega = as_array(tangent, "SO2 tangent", (..., 1))[..., 0]
        return cls.from_parameters_unchecked(np.stack([np.cos(omega), np.sin(omega)], axis=-1))

    def log(self) -> FloatArray:
        return self.angle()[..., None]

    def adjoint(self) -> FloatArray:
        # Rotations in the plane commute: Ad = 1.
        return np.ones((*self.batch_shape, 1, 1))

    def normalize(self) -> SO2:
        return self.from_parameters_unchecked(
            self._params / np.linalg.norm(self._params, axis=-1, keepdims=True)
        )
