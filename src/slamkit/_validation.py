"""Checks run at public entry points: shapes, finiteness, covariances.

Every check returns the array it validated (as a float64 ``ndarray``) so that callers can write
``x = as_array(x, "pose", shape=(..., 3))`` and go on. Messages name the argument, what was
expected and what arrived.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit.errors import CovarianceError, DatasetFormatError, NonFiniteError, ShapeError

FloatArray = NDArray[np.float64]

__all__ = [
    "FloatArray",
    "as_array",
    "as_covariance",
    "as_positive",
    "check_unique_ids",
    "describe_shape",
]


def check_unique_ids(ids: ArrayLike, lines: ArrayLike, what: str, path: str | Path) -> None:
    """Raise :class:`~slamkit.errors.DatasetFormatError` at the line of the first id of
    ``ids (N,)`` that repeats an earlier one (``lines (N,)``: each id's line in the file at
    ``path``): ``"{path}:{line}: {what} {id} is listed twice (first on line {first})"``.
    The one check of every reader of a landmark, beacon or ground-truth map file."""
    first: dict[int, int] = {}
    for i, line in zip(np.asarray(ids).tolist(), np.asarray(lines).tolist(), strict=True):
        seen = first.setdefault(int(i), int(line))
        if seen != int(line):
            raise DatasetFormatError(
                f"{what} {int(i)} is listed twice (first on line {seen})", path, int(line)
            )


def describe_shape(shape: Sequence[int | type(Ellipsis) | None]) -> str:  # type: ignore[valid-type]
    parts = ["..." if s is Ellipsis else ("n" if s is None else str(s)) for s in shape]
    return "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"


def _dims_match(actual: tuple[int, ...], expected: Sequence[object]) -> bool:
    if len(actual) != len(expected):
        return False
    return all(e is None or e == a for a, e in zip(actual, expected, strict=True))


def _shape_matches(actual: tuple[int, ...], expected: Sequence[object]) -> bool:
    # Called on every public entry point, so kept to plain tuple work (no recursion).
    for i, e in enumerate(expected):
        if e is Ellipsis:
            head, tail = expected[:i], expected[i + 1 :]
            if len(actual) < len(head) + len(tail):
                return False
            return _dims_match(actual[: len(head)], head) and _dims_match(
                actual[len(actual) - len(tail) :], tail
            )
    return _dims_match(actual, expected)


def as_array(
    value: ArrayLike,
    name: str,
    shape: Sequence[object] | None = None,
    *,
    finite: bool = True,
) -> FloatArray:
    """Convert ``value`` to a float64 array and check its shape and finiteness.

    ``shape`` uses ``None`` for "any size" and ``...`` for "any number of leading axes",
    e.g. ``(..., 3)`` for a batch of SE(2) poses.
    """
    if type(value) is np.ndarray and value.dtype == np.float64:
        arr = value  # the common case: no conversion
    else:
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ShapeError(f"{name}: expected numbers, got {type(value).__name__}") from exc
    if shape is not None and not _shape_matches(arr.shape, shape):
        raise ShapeError(f"{name}: expected shape {describe_shape(shape)}, got {arr.shape}")
    # isfinite(sum) is one pass without a boolean temporary; overflow to inf in the sum of
    # finite values is possible only near 1e308, so fall back to the exact check then.
    with np.errstate(over="ignore", invalid="ignore"):  # the sum may overflow: checked below
        total = np.sum(arr) if finite else 0.0
    if finite and not np.isfinite(total) and not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise NonFiniteError(f"{name}: expected finite numbers, got {bad} NaN/inf value(s)")
    return arr


def as_positive(value: float, name: str, *, allow_zero: bool = False) -> float:
    """A finite scalar that is > 0 (or >= 0 with ``allow_zero``)."""
    v = float(value)
    ok = np.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        expected = "a finite number >= 0" if allow_zero else "a finite number > 0"
        raise ShapeError(f"{name}: expected {expected}, got {value!r}")
    return v


def as_covariance(
    value: ArrayLike,
    name: str,
    dim: int | None = None,
    *,
    semidefinite: bool = False,
    rtol: float = 1e-9,
) -> FloatArray:
    """Check a (batch of) covariance matrices: square, symmetric, positive definite.

    Positive definiteness is tested by a Cholesky factorisation, which is also what every
    solver downstream relies on. With ``semidefinite`` a zero eigenvalue is allowed (a known
    start pose has zero covariance).
    """
    arr = as_array(value, name, (..., dim, dim))
    if arr.shape[-1] != arr.shape[-2]:
        raise ShapeError(f"{name}: expected a square matrix, got shape {arr.shape}")
    scale = max(float(np.max(np.abs(arr))) if arr.size else 0.0, 1.0)
    if not np.allclose(arr, np.swapaxes(arr, -1, -2), rtol=rtol, atol=rtol * scale):
        raise CovarianceError(f"{name}: expected a symmetric matrix")
    if semidefinite:
        eig = np.linalg.eigvalsh(arr)
        if np.any(eig < -1e-9 * scale):
            raise CovarianceError(
                f"{name}: expected a positive semi-definite matrix, smallest eigenvalue "
                f"{float(eig.min()):.3g}"
            )
        return arr
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError as exc:
        eig = np.linalg.eigvalsh(arr)
        raise CovarianceError(
            f"{name}: expected a positive definite matrix, smallest eigenvalue "
            f"{float(eig.min()):.3g}"
        ) from exc
    return arr
