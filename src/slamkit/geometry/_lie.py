"""The shared base of slamkit's matrix Lie groups (:mod:`so2`, :mod:`se2`, :mod:`so3`, :mod:`se3`).

A group value wraps ONE float64 parameter array whose trailing axis holds the parameters of
one element and whose leading axes are batch axes: ``SE2`` of batch shape ``(N,)`` stores an
``(N, 4)`` array. Values are immutable (the array is read-only and attributes cannot be set),
so they can be shared freely.

Conventions, fixed here for every group:

* ``a @ b`` composes (``compose``), ``a @ points`` acts on points (``apply``).
* Tangent vectors use the *right* perturbation: ``x.box_plus(delta) = x @ exp(delta)`` and
  ``x.box_minus(y) = log(y⁻¹ @ x)``, so ``y.box_plus(x.box_minus(y)) == x``.
* ``adjoint()`` is the matrix with ``x @ exp(xi) == exp(x.adjoint() @ xi) @ x``.
* Unit complex numbers and quaternions given to a public constructor are normalised when
  their norm is within :data:`UNIT_NORM_TOL` of one and rejected with
  :class:`~slamkit.errors.InputError` otherwise; rotation matrices likewise must be
  orthonormal with determinant +1 to within that tolerance.
* Equality is object identity; compare values with ``np.allclose`` on ``as_matrix()``
  (quaternions ``q`` and ``-q`` are the same rotation).

Results of group operations are built by the unchecked constructor
:meth:`LieGroup.from_parameters_unchecked`, which skips validation: the inputs were validated
when they entered.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar, Self, overload

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError, ShapeError

__all__ = ["UNIT_NORM_TOL", "LieGroup"]

UNIT_NORM_TOL = 1e-6
"""How far from one the norm of a unit complex number or quaternion (and ``RᵀR`` from the
identity) may be before a public constructor rejects it instead of normalising it."""

# Below this rotation angle (radians) the closed forms such as sin(θ)/θ are replaced by their
# Taylor series. Those closed forms are 0/0 at θ = 0 and, for (1 - cos θ)/θ² and similar,
# lose all digits to cancellation well before that; with the series truncated after the θ⁴
# term the truncation error at θ = 1e-3 is below 1e-19, far under float64 resolution.
SMALL_ANGLE = 1e-3

BatchShape = int | tuple[int, ...]


def batch_tuple(batch_shape: BatchShape) -> tuple[int, ...]:
    """``batch_shape`` as a tuple of non-negative ints (an int ``n`` means ``(n,)``)."""
    shape = (batch_shape,) if isinstance(batch_shape, int | np.integer) else tuple(batch_shape)
    if not all(isinstance(n, int | np.integer) and n >= 0 for n in shape):
        raise ShapeError(f"batch_shape: expected non-negative integers, got {batch_shape!r}")
    return tuple(int(n) for n in shape)


def check_rng(rng: object) -> np.random.Generator:
    """The injected random generator, or an InputError naming what arrived instead."""
    if not isinstance(rng, np.random.Generator):
        raise InputError(
            f"rng: expected a numpy.random.Generator (np.random.default_rng(seed)), "
            f"got {type(rng).__name__}"
        )
    return rng


def unit_normalized(v: FloatArray, name: str) -> FloatArray:
    """``v / |v|`` along the last axis, if every norm is within :data:`UNIT_NORM_TOL` of one."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    if norm.size and float(np.max(np.abs(norm - 1.0))) > UNIT_NORM_TOL:
        worst = float(norm.flat[np.argmax(np.abs(norm - 1.0))])
        raise InputError(
            f"{name}: expected unit norm (within {UNIT_NORM_TOL:g}), got norm {worst:.9g}"
        )
    return v / norm


def check_rotation_matrix(R: FloatArray, name: str) -> None:
    """Raise InputError unless every ``R (..., n, n)`` is orthonormal with determinant +1."""
    if R.size == 0:
        return
    n = R.shape[-1]
    gram_error = float(np.max(np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(n))))
    if gram_error > UNIT_NORM_TOL:
        raise InputError(
            f"{name}: expected a rotation matrix (RᵀR = I within {UNIT_NORM_TOL:g}), "
            f"got |RᵀR - I| = {gram_error:.3g}"
        )
    if np.any(np.linalg.det(R) <= 0.0):
        raise InputError(f"{name}: expected a rotation (det R = +1), got a reflection")


def check_homogeneous_row(M: FloatArray, name: str) -> None:
    """Raise InputError unless the last row of every ``M (..., n, n)`` is ``(0, ..., 0, 1)``."""
    n = M.shape[-1]
    expected = np.zeros(n)
    expected[-1] = 1.0
    if M.size and float(np.max(np.abs(M[..., -1, :] - expected))) > UNIT_NORM_TOL:
        raise InputError(f"{name}: expected a homogeneous transform with last row (0, ..., 0, 1)")


def broadcast_batch(a: tuple[int, ...], b: tuple[int, ...], what: str) -> tuple[int, ...]:
    """The broadcast of two batch shapes, or a ShapeError saying which operands clashed."""
    try:
        return tuple(np.broadcast_shapes(a, b))
    except ValueError:
        raise ShapeError(f"{what}: batch shapes {a} and {b} do not broadcast") from None


def _readonly(params: FloatArray) -> FloatArray:
    params.flags.writeable = False
    return params


class LieGroup(abc.ABC):
    """A batch of elements of a matrix Lie group over one parameter array ``(..., P)``.

    Subclasses fix the class constants and implement the abstract methods; this base adds
    ``@``, the ⊞/⊟ operators, batch indexing, immutability and pickling.
    """

    __slots__ = ("_params",)
    _params: FloatArray

    matrix_dim: ClassVar[int]
    """Size ``n`` of the ``(n, n)`` matrix form."""
    parameters_dim: ClassVar[int]
    """Length ``P`` of the trailing axis of the parameter array."""
    tangent_dim: ClassVar[int]
    """Length of a tangent vector (degrees of freedom)."""
    space_dim: ClassVar[int]
    """Dimension of the points the group acts on."""
    parameters_name: ClassVar[str]
    """What the parameters are, in order, e.g. ``"wxyz_xyz"``; used in messages."""

    def __init__(self, parameters: ArrayLike) -> None:
        """Validate (shape, finiteness, unit norm) and normalise ``parameters (..., P)``."""
        name = f"{type(self).__name__} {self.parameters_name}"
        p = as_array(parameters, name, (..., self.parameters_dim))
        object.__setattr__(self, "_params", _readonly(self._checked_parameters(p, name)))

    @classmethod
    def from_parameters_unchecked(cls, params: FloatArray) -> Self:
        """Wrap an already valid parameter array without checks (for results of operations)."""
        obj = cls.__new__(cls)
        object.__setattr__(obj, "_params", _readonly(params))
        return obj

    @classmethod
    @abc.abstractmethod
    def _checked_parameters(cls, params: FloatArray, name: str) -> FloatArray:
        """A NEW array: ``params`` with its unit parts normalised, or an InputError."""

    # ----------------------------------------------------------------- value behaviour

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"{type(self).__name__} values are immutable")

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"{type(self).__name__} values are immutable")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (np.array(self._params),))

    def __repr__(self) -> str:
        # array2string elides the middle of large batches instead of printing 10⁶ rows.
        values = np.array2string(self._params, separator=", ")
        return f"{type(self).__name__}({self.parameters_name}={values})"

    @property
    def parameters(self) -> FloatArray:
        """The read-only parameter array ``(*batch_shape, P)`` (layout in the class docstring)."""
        return self._params

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The leading (batch) axes of the parameter array; ``()`` for a single element."""
        return self._params.shape[:-1]

    def __getitem__(self, index: Any) -> Self:
        """Index the batch axes like a NumPy array: ``x[0]``, ``x[1:3]``, ``x[mask]``."""
        if not self.batch_shape:
            raise IndexError(f"cannot index a single {type(self).__name__} (batch shape ())")
        key = index if isinstance(index, tuple) else (index,)
        params = self._params[(*key, slice(None))]
        if params.ndim == 0 or params.shape[-1] != self.parameters_dim:
            raise IndexError(f"index {index!r} reaches past the batch axes {self.batch_shape}")
        return self.from_parameters_unchecked(params)

    # ----------------------------------------------------------------- the group

    @classmethod
    @abc.abstractmethod
    def identity(cls, batch_shape: BatchShape = ()) -> Self:
        """The identity element, repeated over ``batch_shape``."""

    @classmethod
    @abc.abstractmethod
    def from_matrix(cls, matrix: ArrayLike) -> Self:
        """From the ``(..., n, n)`` matrix form; rejects matrices that are not in the group."""

    @abc.abstractmethod
    def as_matrix(self) -> FloatArray:
        """The ``(..., n, n)`` matrix form."""

    @abc.abstractmethod
    def compose(self, other: Self) -> Self:
        """``self ∘ other`` (batch shapes broadcast); the same as ``self @ other``."""

    @abc.abstractmethod
    def inverse(self) -> Self:
        """The inverse element."""

    @abc.abstractmethod
    def apply(self, points: ArrayLike) -> FloatArray:
        """Act on points ``(..., space_dim)``; batch axes broadcast against the points'."""

    @classmethod
    @abc.abstractmethod
    def exp(cls, tangent: ArrayLike) -> Self:
        """The exponential map of tangent vectors ``(..., tangent_dim)``."""

    @abc.abstractmethod
    def log(self) -> FloatArray:
        """The logarithm map: tangent vectors ``(..., tangent_dim)``, rotation part of norm <= π."""

    @abc.abstractmethod
    def adjoint(self) -> FloatArray:
        """The ``(..., tangent_dim, tangent_dim)`` adjoint: ``x @ exp(ξ) = exp(Ad ξ) @ x``."""

    @abc.abstractmethod
    def normalize(self) -> Self:
        """The same element with its unit complex number / quaternion renormalised."""

    @classmethod
    @abc.abstractmethod
    def sample_uniform(cls, rng: np.random.Generator, batch_shape: BatchShape = ()) -> Self:
        """Random elements drawn with the injected ``rng`` (see each group for the law)."""

    # ----------------------------------------------------------------- derived operations

    def _check_same_group(self, other: object, what: str) -> None:
        if type(other) is not type(self):
            raise InputError(
                f"{what}: expected a {type(self).__name__}, got {type(other).__name__}"
            )

    @overload
    def __matmul__(self, other: LieGroup) -> Self: ...

    @overload
    def __matmul__(self, other: ArrayLike) -> FloatArray: ...

    def __matmul__(self, other: LieGroup | ArrayLike) -> Self | FloatArray:
        """``group @ group`` composes; ``group @ points`` acts on the points."""
        if isinstance(other, LieGroup):
            self._check_same_group(other, "compose")
            return self.compose(other)  # type: ignore[arg-type]
        return self.apply(other)

    def box_plus(self, delta: ArrayLike) -> Self:
        """``self ⊞ δ = self @ exp(δ)``: a step ``δ`` taken in the body (right) frame."""
        return self.compose(self.exp(delta))

    def box_minus(self, other: Self) -> FloatArray:
        """``self ⊟ other = log(other⁻¹ @ self)``; inverts ``box_plus``:
        ``other.box_plus(self.box_minus(other)) == self``."""
        self._check_same_group(other, "box_minus")
        return other.inverse().compose(self).log()
