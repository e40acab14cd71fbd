"""Bresenham's line algorithm: the grid cells a ray crosses, in integer arithmetic.

A line from cell ``a = (row0, col0)`` to cell ``b = (row1, col1)`` takes
``n = max(|drow|, |dcol|)`` steps along its *major* axis (the one with the larger change;
columns on a tie). Step ``i = 0 .. n`` moves ``i`` cells along the major axis and
``q_i = floor((2 i m + n) / (2 n))`` cells along the minor one, ``m`` being the minor axis's
absolute change — i.e. the minor coordinate of the exact line rounded to the nearest cell,
halves rounded away from the start. Both end cells are included; ``a == b`` gives one cell.

:func:`bresenham_line` is the classic incremental form (one integer error term updated per
step, no multiplication or division), :func:`bresenham_rays` the closed form above for many
rays at once with NumPy. They return the same cells; the tests hold them to that in all eight
octants.

:func:`bresenham_segments` is the form the mapper's hot path uses: given, per ray, its major
and minor step as *flat* offsets in a row-major grid, it returns the flat indices of any run
of consecutive steps ``first .. first + length - 1`` of many rays at once. It computes ``q_i``
in floating point as ``floor(i m/n + 1/2 + eps)``, which is exact for rays of fewer than
:data:`MAX_SEGMENT_STEPS` steps (see the function), and spreads each ray's constants with one
``np.repeat`` per constant — about ten passes over the cells in all.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit.errors import ShapeError

__all__ = [
    "MAX_SEGMENT_STEPS",
    "RayCells",
    "bresenham_line",
    "bresenham_rays",
    "bresenham_segments",
    "minor_steps",
]

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]

MAX_SEGMENT_STEPS = 1 << 20
"""Longest ray (in steps ``n``) for which :func:`minor_steps` is exact."""

# q_i = floor((2 i m + n) / (2 n)) = floor(i s + 1/2) with s = m / n. The exact value i s + 1/2
# is a multiple of 1/(2n) >= 2^-21; in floating point i * fl(s) + 1/2 is off by less than
# 2^-31 for i <= n < 2^20. Adding eps = 2^-26 (far above the error, far below 1/(2n)) lifts
# a value that should be an exact integer k but came out as k - 1e-10 back to k, and moves no
# other value across an integer.
_ROUND_UP = 0.5 + 2.0**-26


def bresenham_line(row0: int, col0: int, row1: int, col1: int) -> IntArray:
    """Cells ``(n + 1, 2)`` as ``(row, col)`` from ``(row0, col0)`` to ``(row1, col1)``
    inclusive, by the incremental integer algorithm (see the module docstring)."""
    r0, c0, r1, c1 = int(row0), int(col0), int(row1), int(col1)
    d_row, d_col = r1 - r0, c1 - c0
    s_row = 1 if d_row > 0 else (-1 if d_row < 0 else 0)
    s_col = 1 if d_col > 0 else (-1 if d_col < 0 else 0)
    a_row, a_col = abs(d_row), abs(d_col)
    col_major = a_col >= a_row
    n, m = (a_col, a_row) if col_major else (a_row, a_col)
    out = np.empty((n + 1, 2), dtype=np.int64)
    # The error term ``num`` is the numerator 2*i*m + n of q_i, kept below 2n by carrying.
    num = n
    q = 0
    for i in range(n + 1):
        if col_major:
            out[i, 0], out[i, 1] = r0 + q * s_row, c0 + i * s_col
        else:
            out[i, 0], out[i, 1] = r0 + i * s_row, c0 + q * s_col
        num += 2 * m
        if num >= 2 * n and n > 0:
            q += 1
            num -= 2 * n
    return out


class RayCells:
    """The cells of many Bresenham rays, flattened ray after ray: ``rows (N,)`` and
    ``cols (N,)`` of the cells, ``step (N,)`` each cell's step index ``0 .. n_r`` along its
    ray and ``n_steps (R,)`` the number of steps ``n_r`` of each ray (ray ``r`` has
    ``n_r + 1`` cells). ``ray (N,)`` says which ray each cell belongs to; per-ray values are
    spread over the cells with ``np.repeat(values, n_steps + 1)``."""

    __slots__ = ("cols", "n_steps", "rows", "step")

    def __init__(self, rows: IntArray, cols: IntArray, step: IntArray, n_steps: IntArray) -> None:
        self.rows = rows
        self.cols = cols
        self.step = step
        self.n_steps = n_steps

    @property
    def ray(self) -> IntArray:
        return np.repeat(np.arange(self.n_steps.size, dtype=np.int64), self.n_steps + 1)

    @property
    def cells(self) -> IntArray:
        """``(N, 2)`` ``(row, col)``."""
        return np.stack([self.rows, self.cols], axis=1)

    def __len__(self) -> int:
        return int(self.step.size)


def bresenham_rays(starts: ArrayLike, ends: ArrayLike) -> RayCells:
    """All cells of the lines ``starts[r] → ends[r]`` (integer ``(R, 2)`` ``(row, col)``
    arrays), computed for every ray at once in integer arithmetic (module docstring).

    Per-ray constants are spread over the ray's cells with ``np.repeat`` (a block copy, much
    cheaper than fancy indexing); the arithmetic runs in int64 on the cells, one integer
    division per cell for ``q_i``.
    """
    a = np.asarray(starts)
    b = np.asarray(ends)
    if a.ndim != 2 or a.shape[1] != 2 or b.shape != a.shape:
        raise ShapeError(f"starts/ends: expected two (R, 2) arrays, got {a.shape}, {b.shape}")
    if not (np.issubdtype(a.dtype, np.integer) and np.issubdtype(b.dtype, np.integer)):
        raise ShapeError("starts/ends: expected integer cell indices")
    a = a.astype(np.int64, copy=False)
    b = b.astype(np.int64, copy=False)
    d_row = b[:, 0] - a[:, 0]
    d_col = b[:, 1] - a[:, 1]
    col_major = np.abs(d_col) >= np.abs(d_row)
    n = np.where(col_major, np.abs(d_col), np.abs(d_row))
    m = np.where(col_major, np.abs(d_row), np.abs(d_col))
    # Per ray: the (row, col) change of one major step and of one minor step.
    s_row, s_col = np.sign(d_row), np.sign(d_col)
    major_row = np.where(col_major, 0, s_row)
    major_col = np.where(col_major, s_col, 0)
    counts = n + 1
    total = int(counts.sum())

    def spread(values: IntArray) -> IntArray:
        return np.repeat(values, counts)

    step = np.arange(total, dtype=np.int64) - spread(np.cumsum(counts) - counts)
    # q_i = floor((2 i m + n) / (2 n)); a zero-length ray (n = 0) has the single step i = 0.
    q = (step * spread(2 * m) + spread(n)) // spread(np.maximum(2 * n, 1))
    rows = step * spread(major_row) + q * spread(s_row - major_row)
    cols = step * spread(major_col) + q * spread(s_col - major_col)
    if a.shape[0] and np.all(a == a[0]):  # one start cell (a scan): add it as a scalar
        rows += a[0, 0]
        cols += a[0, 1]
    else:
        rows += spread(a[:, 0])
        cols += spread(a[:, 1])
    return RayCells(rows, cols, step, n)


def minor_steps(steps: FloatArray, slope: FloatArray) -> FloatArray:
    """Bresenham's minor coordinate ``q_i = floor((2 i m + n) / (2 n))`` of steps ``i`` of
    rays with ``slope = m / n`` (broadcast), as floats holding exact integers. Exact for
    ``0 <= i <= n < MAX_SEGMENT_STEPS`` (the comment at ``_ROUND_UP`` gives the bound)."""
    q = np.multiply(steps, slope)
    q += _ROUND_UP
    return np.floor(q, out=q)


def bresenham_segments(
    lengths: IntArray,
    first: FloatArray,
    slope: FloatArray,
    major: FloatArray,
    minor: FloatArray,
    base: FloatArray,
) -> IntArray:
    """Flat indices of runs of consecutive Bresenham steps of many rays in a row-major grid.

    Segment ``k`` covers steps ``first[k] .. first[k] + lengths[k] - 1`` of a ray with
    ``slope = m / n`` (``n`` its number of steps, ``n < MAX_SEGMENT_STEPS``) that starts at
    flat index ``base[k]`` and whose major and minor steps move the flat index by ``major[k]``
    and ``minor[k]`` (e.g. ``±1`` and ``±n_cols`` for a ray along the columns); step ``i`` is
    the cell ``base + i * major + q_i * minor``. Returns all the segments' cells one after the
    other ``(sum(lengths),)``. All arguments are ``(K,)``; the floats hold exact integers
    (flat indices below 2^53).
    """
    counts = np.asarray(lengths, dtype=np.int64)
    total = int(counts.sum())
    if total == 0:
        return np.empty(0, dtype=np.int64)
    # Each segment's constants spread over its cells (np.repeat is a block copy); the step i
    # of a cell is its position in the output minus the segment's offset, plus ``first``.
    offset = np.cumsum(counts) - counts - np.asarray(first, dtype=np.float64)
    steps = np.arange(total, dtype=np.float64)
    steps -= np.repeat(offset, counts)
    q = minor_steps(steps, np.repeat(slope, counts))
    q *= np.repeat(minor, counts)
    steps *= np.repeat(major, counts)
    steps += q
    steps += np.repeat(base, counts)
    return steps.astype(np.int64)
