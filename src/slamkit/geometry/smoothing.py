"""Kernel smoothing of point and pose sequences (e.g. to tidy a dead-reckoned path for display
or to pre-filter noisy ground truth).

One pass replaces each sample by a weighted average of its neighbours along the sequence,

    out[i] = Σ_k kernel[k] · x[clamp(i + k − h)],   h = (len(kernel) − 1) / 2,

with indices clamped to ``[0, N − 1]``: the end values are replicated, so the ends are not
pulled towards zero. ``kernel[0]`` weights the earliest neighbour (for an asymmetric kernel
this is a correlation, i.e. a convolution with the reversed kernel; for the usual symmetric
kernels the two are the same). A kernel that sums to 1 leaves constant sequences unchanged;
a non-negative one, with clamping, also keeps every output inside the range of the input.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import GeometryError, InputError, ShapeError
from slamkit.geometry.angles import wrap_angle

__all__ = ["smooth_points", "smooth_poses"]

_KERNEL_SUM_TOL = 1e-9
# Below this length the mean heading vector no longer defines a direction (opposite headings
# cancelled out), so a smoothed heading would be arbitrary.
_MIN_RESULTANT = 1e-12


def _check_kernel(kernel: ArrayLike) -> FloatArray:
    k = as_array(kernel, "kernel", (None,))
    if k.size % 2 != 1:
        raise ShapeError(f"kernel: expected an odd length so it has a centre, got {k.size}")
    total = float(k.sum())
    if abs(total - 1.0) > _KERNEL_SUM_TOL:
        raise InputError(f"kernel: expected weights summing to 1 (±1e-9), got sum {total!r}")
    return k


def _check_iterations(iterations: int) -> int:
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer):
        raise InputError(f"iterations: expected an integer >= 0, got {iterations!r}")
    if iterations < 0:
        raise InputError(f"iterations: expected an integer >= 0, got {iterations}")
    return int(iterations)


def _smooth(x: FloatArray, kernel: FloatArray, iterations: int) -> FloatArray:
    """Apply the clamped-edge kernel ``iterations`` times along axis 0 of ``x (N, D)``."""
    n = x.shape[0]
    h = (kernel.size - 1) // 2
    out = x.copy()
    for _ in range(iterations):
        # Edge padding replicates x[0] and x[N-1], which is the index clamping above; it works
        # for any h, also h >= N.
        padded = np.pad(out, ((h, h), (0, 0)), mode="edge")
        acc = np.zeros_like(out)
        for k, w in enumerate(kernel):  # len(kernel) is small; each term is one array op
            acc += w * padded[k : k + n]
        out = acc
    return out


def smooth_points(points: ArrayLike, kernel: ArrayLike, iterations: int = 1) -> FloatArray:
    """Smooth a sequence of points ``(N, D)`` with ``kernel`` applied ``iterations`` times.

    ``kernel`` is 1-D with odd length and sums to 1 (e.g. ``[0.25, 0.5, 0.25]``); ends are
    clamped (see the module docstring). ``iterations = 0`` returns a copy. The input is not
    modified.
    """
    p = as_array(points, "points", (None, None))
    k = _check_kernel(kernel)
    it = _check_iterations(iterations)
    if p.shape[0] == 0:
        raise InputError("points: expected at least one point, got none")
    return _smooth(p, k, it)


def smooth_poses(poses: ArrayLike, kernel: ArrayLike, iterations: int = 1) -> FloatArray:
    """Smooth a sequence of SE(2) poses ``(N, 3)``.

    ``x`` and ``y`` are smoothed directly. Headings are smoothed through their unit vectors
    ``(cos θ, sin θ)`` and recovered with ``atan2`` and wrapped to ``[-pi, pi)``, so
    +179° and −179° average to 180°, not 0°. Raises :class:`~slamkit.errors.GeometryError`
    if neighbouring headings cancel out (a smoothed heading vector of length ~0).
    """
    p = as_array(poses, "poses", (None, 3))
    k = _check_kernel(kernel)
    it = _check_iterations(iterations)
    if p.shape[0] == 0:
        raise InputError("poses: expected at least one pose, got none")
    lifted = np.column_stack([p[:, 0], p[:, 1], np.cos(p[:, 2]), np.sin(p[:, 2])])
    sm = _smooth(lifted, k, it)
    resultant = np.hypot(sm[:, 2], sm[:, 3])
    if np.any(resultant < _MIN_RESULTANT):
        i = int(np.argmin(resultant))
        raise GeometryError(
            f"smooth_poses: headings around pose {i} cancel out; the smoothed heading is undefined"
        )
    theta = wrap_angle(np.arctan2(sm[:, 3], sm[:, 2]))
    return np.column_stack([sm[:, 0], sm[:, 1], theta])
