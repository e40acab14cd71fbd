"""SE(2) poses as plain ``(..., 3)`` arrays ``(x, y, theta)``: the canonical compose (⊕),
inverse and between (⊖) used throughout slamkit.

These are the head-to-tail compounding operators of Smith, Self & Cheeseman. They work on any
number of leading batch axes and broadcast against each other, so composing 10⁶ poses is one
vectorised call. The object-oriented :class:`slamkit.geometry.SE2` wraps the same maths for
code that prefers group values; both must agree (a test checks it).

Frames in names: ``T_a_b`` is the pose of frame ``b`` expressed in frame ``a``, so
``compose(T_w_r, T_r_s) = T_w_s`` and ``between(T_w_a, T_w_b) = T_a_b``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError
from slamkit.geometry.angles import wrap_angle

__all__ = [
    "POSE_TIME_TOL",
    "between",
    "compose",
    "interpolate_poses",
    "inverse",
    "inverse_transform_points",
    "transform_points",
]


def _arr(x: ArrayLike) -> FloatArray:
    return np.asarray(x, dtype=np.float64)


def _out(*arrays: FloatArray) -> FloatArray:
    shape = np.broadcast_shapes(*(x.shape[:-1] for x in arrays))
    return np.empty((*shape, 3))


def compose(T_a_b: ArrayLike, T_b_c: ArrayLike) -> FloatArray:
    """``T_a_c = T_a_b ⊕ T_b_c``: rotate the second translation by the first heading, add."""
    a, b = _arr(T_a_b), _arr(T_b_c)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    out = _out(a, b)
    out[..., 0] = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    out[..., 1] = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    out[..., 2] = wrap_angle(a[..., 2] + b[..., 2])
    return out


def inverse(T_a_b: ArrayLike) -> FloatArray:
    """``T_b_a = ⊖T_a_b``: ``(-Rᵀ t, -theta)``."""
    a = _arr(T_a_b)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    out = _out(a)
    out[..., 0] = -c * a[..., 0] - s * a[..., 1]
    out[..., 1] = s * a[..., 0] - c * a[..., 1]
    out[..., 2] = wrap_angle(-a[..., 2])
    return out


def between(T_w_a: ArrayLike, T_w_b: ArrayLike) -> FloatArray:
    """``T_a_b = (⊖T_w_a) ⊕ T_w_b``: the pose of ``b`` seen from ``a`` (relative motion)."""
    a, b = _arr(T_w_a), _arr(T_w_b)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    out = _out(a, b)
    out[..., 0] = c * dx + s * dy
    out[..., 1] = -s * dx + c * dy
    out[..., 2] = wrap_angle(b[..., 2] - a[..., 2])
    return out


def transform_points(T_a_b: ArrayLike, p_b: ArrayLike) -> FloatArray:
    """Points ``p_b (..., 2)`` expressed in frame ``b`` mapped into frame ``a``: ``R p + t``.

    ``T_a_b`` of shape ``(..., 3)`` broadcasts against ``p_b``'s leading axes; to map ``N``
    points by one pose pass ``T_a_b[None]`` or rely on broadcasting of a ``(3,)`` pose.
    """
    T, p = _arr(T_a_b), _arr(p_b)
    c, s = np.cos(T[..., 2]), np.sin(T[..., 2])
    x = T[..., 0] + c * p[..., 0] - s * p[..., 1]
    y = T[..., 1] + s * p[..., 0] + c * p[..., 1]
    return np.stack([x, y], axis=-1)


def inverse_transform_points(T_a_b: ArrayLike, p_a: ArrayLike) -> FloatArray:
    """Points expressed in frame ``a`` mapped into frame ``b``: ``Rᵀ (p - t)``."""
    T, p = _arr(T_a_b), _arr(p_a)
    c, s = np.cos(T[..., 2]), np.sin(T[..., 2])
    dx, dy = p[..., 0] - T[..., 0], p[..., 1] - T[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)


POSE_TIME_TOL = 1e-9
"""[s] A time within this of a recorded pose's time takes that pose (:func:`interpolate_poses`)."""


def interpolate_poses(times: ArrayLike, poses: ArrayLike, t: ArrayLike) -> FloatArray:
    """Poses ``(..., 3)`` at times ``t`` from a trajectory ``times (N,)``, ``poses (N, 3)``:
    the recorded pose where a time matches (to 1 ns), else linear interpolation of the
    position and of the wrapped heading difference between the two neighbours. A time
    outside the trajectory raises :class:`InputError`."""
    T = as_array(times, "trajectory times", (None,))
    P = as_array(poses, "trajectory poses", (T.size, 3))
    q = np.asarray(t, dtype=np.float64)
    if T.size == 0:
        raise InputError("known poses: the trajectory is empty")
    if np.any(q < T[0] - POSE_TIME_TOL) or np.any(q > T[-1] + POSE_TIME_TOL):
        raise InputError(
            f"known poses: times {float(q.min()):.6g}..{float(q.max()):.6g} s reach outside "
            f"the trajectory's {T[0]:.6g}..{T[-1]:.6g} s"
        )
    hi = np.clip(np.searchsorted(T, q, side="left"), 0, T.size - 1)
    lo = np.clip(hi - 1, 0, T.size - 1)
    exact_hi = np.abs(T[hi] - q) <= POSE_TIME_TOL
    span = T[hi] - T[lo]
    w = np.where(span > 0, (q - T[lo]) / np.where(span > 0, span, 1.0), 1.0)
    w = np.where(exact_hi, 1.0, np.clip(w, 0.0, 1.0))
    xy = P[lo, :2] + w[..., None] * (P[hi, :2] - P[lo, :2])
    th = wrap_angle(P[lo, 2] + w * wrap_angle(P[hi, 2] - P[lo, 2]))
    return np.concatenate([xy, th[..., None]], axis=-1)
