"""Angles: the one place where wrapping and circular means are defined.

Convention: every angle slamkit returns lies in ``[-pi, pi)``. Every other module calls
:func:`wrap_angle` instead of writing its own modulo.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError

__all__ = ["angle_diff", "circular_mean", "pose_mean", "wrap_angle", "wrap_angle_float"]

_TWO_PI = 2.0 * np.pi


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Wrap angles (radians) to ``[-pi, pi)``; works on scalars and arrays of any shape.
    Non-finite angles give NaN."""
    if isinstance(angle, float | int) or (isinstance(angle, np.ndarray) and angle.ndim == 0):
        # Filters call this once per reading: plain floats are ~10x cheaper than 0-d arrays.
        return np.float64(wrap_angle_float(float(angle)))  # type: ignore[return-value]
    a = np.asarray(angle, dtype=np.float64)
    # a - 2pi * floor((a + pi) / 2pi) is ~4x faster than np.mod on large arrays. Rounding can
    # leave a result a hair outside [-pi, pi) (e.g. a = pi - 1e-16 gives -pi - 4e-16), so
    # fold those few values back once.
    with np.errstate(invalid="ignore"):  # inf - inf: NaN, as documented
        w = a - _TWO_PI * np.floor((a + np.pi) / _TWO_PI)
    w = np.where(w < -np.pi, w + _TWO_PI, w)
    w = np.where(w >= np.pi, w - _TWO_PI, w)
    # Angles already in range come back bit-identical (1e-12 stays 1e-12, not a multiple
    # of ulp(pi)), which keeps exp/log round trips exact near zero.
    return np.where((a >= -np.pi) & (a < np.pi), a, w)


def wrap_angle_float(a: float) -> float:
    """:func:`wrap_angle` for one Python float (for per-reading kernels). A non-finite
    angle gives NaN, as in :func:`wrap_angle` (a filter that diverged reports it as such)."""
    if -math.pi <= a < math.pi:
        return a
    if not math.isfinite(a):
        return math.nan
    w = a - _TWO_PI * math.floor((a + math.pi) / _TWO_PI)
    if w < -math.pi:
        w += _TWO_PI
    if w >= math.pi:
        w -= _TWO_PI
    return w


def angle_diff(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """The signed difference ``a - b`` wrapped to ``[-pi, pi)``."""
    return wrap_angle(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64))


def circular_mean(
    angles: ArrayLike, weights: ArrayLike | None = None, axis: int = -1
) -> FloatArray:
    """Mean of angles through their unit vectors: ``atan2(sum w sin, sum w cos)``.

    350 deg and 10 deg average to 0 deg, not 180 deg. ``weights`` (non-negative, same shape as
    ``angles``) need not be normalised.
    """
    a = as_array(angles, "angles")
    if weights is None:
        s = np.sum(np.sin(a), axis=axis)
        c = np.sum(np.cos(a), axis=axis)
    else:
        w = as_array(weights, "weights")
        if w.shape != a.shape:
            w = np.broadcast_to(w, a.shape)
        s = np.sum(w * np.sin(a), axis=axis)
        c = np.sum(w * np.cos(a), axis=axis)
    return wrap_angle(np.arctan2(s, c))


def pose_mean(poses: ArrayLike, weights: ArrayLike | None = None) -> FloatArray:
    """Mean of SE(2) poses ``(N, 3)`` as ``(x, y, theta)``: positions averaged arithmetically,
    headings through their unit vectors. Optional non-negative ``weights`` of shape ``(N,)``."""
    p = as_array(poses, "poses", (None, 3))
    if p.shape[0] == 0:
        raise InputError("poses: expected at least one pose, got none")
    if weights is None:
        xy = p[:, :2].mean(axis=0)
        theta = circular_mean(p[:, 2])
    else:
        w = as_array(weights, "weights", (p.shape[0],))
        total = w.sum()
        if not total > 0 or np.any(w < 0):
            raise InputError("weights: expected non-negative weights with a positive sum")
        xy = (w[:, None] * p[:, :2]).sum(axis=0) / total
        theta = circular_mean(p[:, 2], w)
    return np.array([xy[0], xy[1], float(theta)])
