"""The smeared log-likelihood lookup grid of correlative scan matching, and its max pyramid.

A reference (a scan's points or a map) becomes a table ``L`` over a fine grid: the
log-likelihood of a current-scan point that lands in a cell. With ``d`` the distance from the
cell to the nearest reference obstacle and ``sigma`` the range noise, a point is a hit with
Gaussian error or a miss of constant likelihood ``f`` (``floor_likelihood``, relative to a
perfect hit):

    L(d) = log( f + (1 - f) exp(-d² / (2 sigma²)) )   in [log f, 0].

This is the Gaussian smear of Olson's rasterised cost table, computed from one Euclidean
distance transform (:func:`scipy.ndimage.distance_transform_edt`); ``max`` over overlapping
kernels and the distance to the *nearest* point give the same table. With the compiled
kernels the quantised table (below) is stamped instead, a small kernel per marked cell: once
quantised, ``L`` is a function of the squared cell distance ``dr² + dc²`` alone and is the
floor beyond a few cells (checked once per resolution, sigma and floor, with the transform's
own arithmetic; where it is not, the transform is used), so the stamps give the transform's
table to the last bit, without a pass over every cell.

For branch and bound the grid carries a pyramid of max tables. With ``w = 2^h``,

    M_h[r, c] = max { L[r + a, c + b] : 0 <= a, b < w },

so that ``sum_p M_h[cell_p + (i, j)]`` bounds the score of every translation offset in the
block ``[i, i + w) × [j, j + w)`` from above. ``M_h`` follows from ``M_{h-1}`` by the max of
four shifted copies (shift ``w / 2``), indices past the last row or column reading the last
one (the same rule as clipping an index into the table).

Every table is padded by ``pad`` cells of value ``log f`` on each side (at least the
coarsest block, ``2^(levels-1)`` cells, so the max tables hold every block that begins
before the reference and reaches into it), and a read outside the table is a "miss" of
value ``log f`` too: the search checks each read's row and column instead of padding the
tables by its whole window (see :meth:`LookupGrid.cells`), so a table's size does not depend
on the window searched.

**Exact scores.** Every table value is rounded to a multiple of ``QUANTUM = 2^-12`` (a
quarter of a thousandth of a nat, far below any difference between two poses that matters).
A score is then a sum of integers times a power of two, exact in float64 as long as the
integer sum stays below ``2^53`` (``N |log f| 2^12`` is about ``10^8`` for ten thousand
points): it no longer depends on the order of summation, so NumPy's pairwise sum, a compiled
loop and another machine's SIMD width give the same score to the last bit, and ties between
poses (the max tables repeat values, so exact ties are common) are broken by the documented
rule rather than by rounding.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import distance_transform_edt

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.backend import SEAM
from slamkit.errors import InputError, MatchError
from slamkit.scanmatch.compiled import stamp_max

__all__ = [
    "QUANTUM",
    "LookupGrid",
    "join_consecutive",
    "log_likelihood_of_distance",
    "lookup_from_log_table",
    "lookup_from_points",
    "marked_lookup_edt",
    "marked_lookup_stamped",
]

IntArray = NDArray[np.int64]

QUANTUM = 2.0**-12
"""Table values are multiples of this (module docstring: exact scores)."""


def quantize(values: FloatArray) -> FloatArray:
    """``values`` rounded to the nearest multiple of :data:`QUANTUM`."""
    out: FloatArray = np.round(np.asarray(values, dtype=np.float64) / QUANTUM) * QUANTUM
    return out


def log_likelihood_of_distance(d: FloatArray, sigma: float, floor_likelihood: float) -> FloatArray:
    """``L(d) = log(f + (1 - f) exp(-d² / (2 sigma²)))`` with ``f = floor_likelihood``: the
    log-likelihood, relative to a perfect hit, of a point ``d`` metres from the reference."""
    f = float(floor_likelihood)
    out: FloatArray = np.log(f + (1.0 - f) * np.exp(-0.5 * (np.asarray(d) / sigma) ** 2))
    return out


@dataclass(frozen=True, eq=False)
class LookupGrid:
    """A padded log-likelihood table and its max pyramid.

    * ``tables``: ``tables[0]`` is the fine table ``L (rows, cols)``; ``tables[h]`` is the max
      table ``M_h`` over blocks of ``2^h × 2^h`` cells (module docstring). All share one shape
      and include the padding.
    * ``resolution`` (m): the cell side.
    * ``origin_xy`` (m): world position of the lower-left corner of padded cell ``(0, 0)``;
      cell ``(row, col)`` covers ``origin + (col, row) · resolution`` plus one cell, as in
      :class:`~slamkit.maps.OccupancyGrid`.
    * ``pad`` (cells): width of the border of value ``floor`` around the reference.
    * ``floor``: the table value of a miss (the minimum of every table).
    * ``inlier_log``: a point whose table value is at least this counts as an inlier.
    * ``counts``: the same tables in units of :data:`QUANTUM`, as ``int16`` (or ``int32``
      when a value does not fit), when every value is such a multiple; None otherwise.
      Integer sums of them are the float sums exactly (module docstring), and a table a
      quarter the size and an integer add are what the compiled scoring reads. Derived
      from ``tables`` when not given (:func:`lookup_from_log_table` gives them: it builds
      the pyramid on the counts).

    Arrays are read-only; build with :func:`lookup_from_points` or :func:`lookup_from_log_table`.
    """

    tables: tuple[FloatArray, ...]
    resolution: float
    origin_xy: FloatArray
    pad: int
    floor: float
    inlier_log: float
    counts: tuple[NDArray[np.integer], ...] | None = field(default=None, repr=False)
    _dilated: dict[tuple[int, int], NDArray[np.integer]] = field(
        default_factory=dict, init=False, repr=False
    )

    def __post_init__(self) -> None:
        if not self.tables:
            raise InputError("tables: expected at least the fine table, got none")
        shape = self.tables[0].shape
        for t in self.tables:
            if t.shape != shape or t.ndim != 2:
                raise InputError(f"tables: expected 2-D tables of one shape, got {t.shape}")
            t.flags.writeable = False
        object.__setattr__(self, "resolution", as_positive(self.resolution, "resolution"))
        object.__setattr__(self, "origin_xy", as_array(self.origin_xy, "origin_xy", (2,)))
        if self.counts is None:
            object.__setattr__(self, "counts", _quanta(self.tables))
        elif len(self.counts) != len(self.tables) or any(c.shape != shape for c in self.counts):
            raise InputError("counts: expected one table of counts per table, of one shape")
        else:
            for c in self.counts:
                c.flags.writeable = False

    @property
    def levels(self) -> int:
        """Number of tables (the fine one and ``levels - 1`` max tables)."""
        return len(self.tables)

    @property
    def shape(self) -> tuple[int, int]:
        rows, cols = self.tables[0].shape
        return int(rows), int(cols)

    def dilated_counts(self, level: int, spread: int) -> NDArray[np.integer]:
        """``counts[level]`` dilated by ``spread`` cells: ``D[r, c] = max C[r + a, c + b]``
        over ``|a|, |b| <= spread`` (a read outside ``C`` is the floor), stored padded by
        ``spread + 1`` cells (``D``'s cell ``(r + spread + 1, c + spread + 1)`` is ``C``'s
        ``(r, c)``, its corner is the floor). A sum over it bounds the sums over ``C`` of
        points each moved by at most ``spread`` cells per axis (the screen of
        :func:`~slamkit.scanmatch.compiled.group_bounds`). Built on first use and kept;
        read-only. Requires :attr:`counts`."""
        if self.counts is None:
            raise InputError("dilated_counts: the lookup grid has no integer counts")
        key = (int(level), int(spread))
        if key not in self._dilated:
            self._dilated[key] = _dilate(self.counts[key[0]], key[1])
        return self._dilated[key]

    def cells(self, points: FloatArray) -> tuple[IntArray, IntArray]:
        """Row and column indices ``(...,)`` of the cells of world points ``(..., 2)``, not
        clipped to the table: a read at ``(row + di, col + dj)`` outside it is a miss
        (``floor``). Indices are clipped to ``±2^30`` only, far outside any table and any
        offset a search adds. Requires ``pad >= 2^(levels-1)`` (module docstring)."""
        top = 1 << (self.levels - 1)
        if self.pad < top:
            raise InputError(
                f"lookup grid padded by {self.pad} cells; its {self.levels} levels need "
                f"{top}: rebuild the reference with the larger padding"
            )
        u = (points[..., 0] - self.origin_xy[0]) / self.resolution
        v = (points[..., 1] - self.origin_xy[1]) / self.resolution
        far = float(1 << 30)
        col = np.clip(np.floor(u), -far, far).astype(np.int64)
        row = np.clip(np.floor(v), -far, far).astype(np.int64)
        return row, col


def _quanta(tables: tuple[FloatArray, ...]) -> tuple[NDArray[np.integer], ...] | None:
    """``tables`` in units of :data:`QUANTUM` as the smallest of ``int16``/``int32`` that holds
    them, read-only; None when a value is not a multiple of it (or is not finite)."""
    lo = min(float(t.min()) for t in tables) / QUANTUM
    hi = max(float(t.max()) for t in tables) / QUANTUM
    if not (math.isfinite(lo) and math.isfinite(hi)) or max(-lo, hi) >= 2**31:
        return None
    small = max(-lo, hi) < 2**15
    out: list[NDArray[np.integer]] = []
    for t in tables:
        q = np.round(t / QUANTUM)
        if not np.array_equal(q * QUANTUM, t):
            return None
        c: NDArray[np.integer] = q.astype(np.int16 if small else np.int32)
        c.flags.writeable = False
        out.append(c)
    return tuple(out)


def _dilate(table: NDArray[np.integer], spread: int) -> NDArray[np.integer]:
    """:meth:`LookupGrid.dilated_counts` of ``table``: the max over a window of ``w = 2
    spread + 1`` cells, taken over rows, then columns, each by doubling (windows of 2, 4, ...
    cells, then two overlapping ones cover ``w``), on the table padded by ``w`` cells of its
    corner value (the floor)."""
    w = 2 * spread + 1
    out = np.pad(table, w, mode="constant", constant_values=table[0, 0])
    for axis in (0, 1):
        m = np.moveaxis(out, axis, 0)
        span = 1
        while 2 * span <= w:
            m = m.copy()
            np.maximum(m[:-span], m[span:], out=m[:-span])  # m[x] = max over [x, x + 2 span)
            span *= 2
        cover = np.maximum(m[: m.shape[0] - (w - span)], m[w - span :])  # [x, x + w)
        out = np.moveaxis(cover, 0, axis)
    # Row y of ``out`` is the max over padded rows [y, y + w), table rows [y - w, y - 1]:
    # centred on table row y - spread - 1, as documented.
    out = np.ascontiguousarray(out[: table.shape[0] + w + 1, : table.shape[1] + w + 1])
    out.flags.writeable = False
    return out


def join_consecutive(points: FloatArray, max_gap: float, spacing: float) -> FloatArray:
    """``points (M, 2)`` (in scan order) plus samples at most ``spacing`` apart along every
    segment between consecutive points closer than ``max_gap``.

    A scan samples a wall at a spacing that grows with range and incidence; marking only the
    end points leaves the smeared table rippled along the wall, and the summed log-likelihood
    of a whole scan turns those ripples into false peaks (a corridor would look constrained
    along its axis). Joining neighbours makes the reference a polyline, as the wall is.
    """
    pts = as_array(points, "points", (None, 2))
    if pts.shape[0] < 2:
        return pts
    a, b = pts[:-1], pts[1:]
    length = np.sqrt(((b - a) ** 2).sum(axis=1))
    keep = (length < max_gap) & (length > spacing)
    a, b, length = a[keep], b[keep], length[keep]
    if a.shape[0] == 0:
        return pts
    # n_s interior samples per segment at t = 1/(n_s+1), ..., n_s/(n_s+1).
    n = np.ceil(length / spacing).astype(np.int64) - 1
    seg = np.repeat(np.arange(a.shape[0]), n)
    first = np.cumsum(n) - n  # index of each segment's first sample
    t = (np.arange(seg.size) - first[seg] + 1) / (n[seg] + 1)
    inner = a[seg] + t[:, None] * (b[seg] - a[seg])
    return np.concatenate([pts, inner])


def _max_pyramid(fine: np.ndarray, levels: int) -> tuple[np.ndarray, ...]:
    """``(L, M_1, ..., M_{levels-1})``: ``M_h`` is the max of four copies of ``M_{h-1}``
    shifted by ``s = 2^(h-1)`` rows/columns, edge values repeated past the end. The max over
    the 2 × 2 shifts is taken as one over rows, then one over columns (the same values)."""
    out = [fine]
    for h in range(1, levels):
        s = 1 << (h - 1)
        prev = out[-1]
        rows, cols = prev.shape
        # Over rows: row r with row min(r + s, last) (the edge repeated past the end) ...
        a, m = max(rows - s, 0), np.empty_like(prev)
        np.maximum(prev[:a], prev[s:], out=m[:a])
        np.maximum(prev[a:], prev[-1], out=m[a:])
        # ... then over columns, the same way.
        b, r = max(cols - s, 0), np.empty_like(prev)
        np.maximum(m[:, :b], m[:, s:], out=r[:, :b])
        np.maximum(m[:, b:], m[:, -1:], out=r[:, b:])
        out.append(r)
    return tuple(out)


def lookup_from_log_table(
    log_table: FloatArray,
    origin_xy: FloatArray,
    resolution: float,
    *,
    floor: float,
    inlier_log: float,
    levels: int,
    pad: int,
) -> LookupGrid:
    """A lookup grid from a per-cell log-likelihood table ``(rows, cols)`` whose cell
    ``(0, 0)`` has its lower-left corner at ``origin_xy``: values are clipped below at
    ``floor``, rounded to multiples of :data:`QUANTUM` (so are ``floor`` and ``inlier_log``),
    the table is padded by ``pad`` cells of ``floor`` and the max pyramid of ``levels``
    tables is built."""
    table = as_array(log_table, "log-likelihood table", (None, None))
    if table.size == 0:
        raise MatchError("reference lookup table is empty", "too_few_points")
    if int(levels) != levels or levels < 1:
        raise InputError(f"levels: expected an integer >= 1, got {levels!r}")
    if int(pad) != pad or pad < 1:
        raise InputError(f"pad: expected an integer >= 1, got {pad!r}")
    floor = float(quantize(np.array(floor)))
    # The pyramid is built on the integer counts (max commutes with the scaling), and the
    # float tables are the counts times the quantum: the same values as quantising each.
    low = round(floor / QUANTUM)
    scaled = np.round(np.maximum(table, floor) / QUANTUM)
    high = float(scaled.max())
    if not math.isfinite(high) or max(-low, high) >= 2**31:
        raise InputError(f"log-likelihood table: values must lie within ±2^19 nat, got {high}")
    dtype = np.int16 if max(-low, high) < 2**15 else np.int32
    return _lookup_from_counts(
        scaled.astype(dtype), origin_xy, resolution, floor=floor, inlier_log=inlier_log,
        levels=levels, pad=pad,
    )  # fmt: skip


def _lookup_from_counts(
    fine_counts: NDArray[np.integer],
    origin_xy: FloatArray,
    resolution: float,
    *,
    floor: float,
    inlier_log: float,
    levels: int,
    pad: int,
) -> LookupGrid:
    """:func:`lookup_from_log_table` from the table already in quanta (``floor`` and
    ``inlier_log`` are rounded here)."""
    floor = float(quantize(np.array(floor)))
    inlier = float(quantize(np.array(inlier_log)))
    low = round(floor / QUANTUM)
    fine = np.pad(fine_counts, int(pad), mode="constant", constant_values=low)
    counts = _max_pyramid(fine, int(levels))
    tables = tuple(c * QUANTUM for c in counts)
    origin = as_array(origin_xy, "origin_xy", (2,)) - int(pad) * resolution
    return LookupGrid(tables, resolution, origin, int(pad), floor, inlier, counts)


def lookup_from_points(
    points: FloatArray,
    resolution: float,
    sigma: float,
    floor_likelihood: float,
    *,
    levels: int,
    pad: int,
    join_gap: float | None = None,
) -> LookupGrid:
    """The lookup grid of reference points ``(M, 2)``: the points are marked in a grid of
    ``resolution`` covering them plus a margin of ``4 sigma``, a distance transform gives
    each cell's distance (centre to the nearest marked centre) and ``L(d)`` the table
    (compiled: stamped, the same table; module docstring).
    Inliers are points within ``3 sigma`` of the reference. With ``join_gap`` (m), points in
    scan order closer than that to their successor are joined by a segment first
    (:func:`join_consecutive`)."""
    pts = as_array(points, "reference points", (None, 2))
    if pts.shape[0] == 0:
        raise MatchError("reference scan has no valid points", "too_few_points")
    res = as_positive(resolution, "resolution")
    if join_gap is not None:
        pts = join_consecutive(pts, as_positive(join_gap, "join_gap"), 0.5 * res)
    margin = int(np.ceil(4.0 * sigma / res)) + 1
    lo = np.floor(pts.min(axis=0) / res) - margin  # cell-aligned origin: rebuilds agree
    cells = np.floor(pts / res - lo).astype(np.int64)  # (col, row) per point
    cols, rows = (cells.max(axis=0) + margin + 1).tolist()
    free = np.ones((rows, cols), dtype=bool)
    free[cells[:, 1], cells[:, 0]] = False
    return _marked_lookup(free, lo * res, res, sigma, floor_likelihood, levels=levels, pad=pad)


def marked_lookup_edt(
    free: NDArray[np.bool_],
    origin_xy: FloatArray,
    resolution: float,
    sigma: float,
    floor_likelihood: float,
    *,
    levels: int,
    pad: int,
) -> LookupGrid:
    """The lookup grid of the cells marked ``False`` in ``free (rows, cols)`` (its corner
    cell's corner at ``origin_xy``) by the distance transform: the path without numba and
    the oracle of :func:`marked_lookup_stamped` (bit for bit)."""
    floor = float(np.log(floor_likelihood))
    inlier = float(log_likelihood_of_distance(np.array(3.0 * sigma), sigma, floor_likelihood))
    # EDT: for every non-zero (free) cell, the distance to the nearest zero (marked) cell.
    dist = np.asarray(distance_transform_edt(free, sampling=resolution), dtype=np.float64)
    table = log_likelihood_of_distance(dist, sigma, floor_likelihood)
    return lookup_from_log_table(
        table, origin_xy, resolution, floor=floor, inlier_log=inlier, levels=levels, pad=pad
    )


def marked_lookup_stamped(
    free: NDArray[np.bool_],
    origin_xy: FloatArray,
    resolution: float,
    sigma: float,
    floor_likelihood: float,
    *,
    levels: int,
    pad: int,
) -> LookupGrid:
    """:func:`marked_lookup_edt` by stamping the quantised table around each marked cell
    (compiled :func:`~slamkit.scanmatch.compiled.stamp_max`; module docstring); by the
    transform where the table is not a function of the squared cell distance alone."""
    stamp = _stamp(resolution, float(sigma), float(floor_likelihood))
    if stamp is None:
        return marked_lookup_edt(
            free, origin_xy, resolution, sigma, floor_likelihood, levels=levels, pad=pad
        )
    floor = float(np.log(floor_likelihood))
    inlier = float(log_likelihood_of_distance(np.array(3.0 * sigma), sigma, floor_likelihood))
    # The quantised table is a function of the squared cell distance alone, the floor
    # beyond a few cells: stamped around each marked cell (the same counts as the
    # distance transform's table, quantised).
    low = round(float(quantize(np.array(floor))) / QUANTUM)
    counts = np.full(free.shape, low, dtype=stamp[2].dtype)
    marked_rows, marked_cols = np.nonzero(~free)
    stamp_max(counts, marked_rows, marked_cols, *stamp)
    return _lookup_from_counts(
        counts, origin_xy, resolution, floor=floor, inlier_log=inlier, levels=levels, pad=pad
    )


_marked_lookup = SEAM.pair(compiled=marked_lookup_stamped, oracle=marked_lookup_edt)
"""The lookup grid of marked cells, stamped under numba, else by the distance transform
(:mod:`slamkit.backend`)."""


@functools.lru_cache(maxsize=16)
def _stamp(
    resolution: float, sigma: float, floor_likelihood: float
) -> tuple[IntArray, IntArray, NDArray[np.integer]] | None:
    """The offsets ``(d_rows, d_cols)`` and quantised table values (counts) of every cell
    whose table value is above the floor, around a marked cell, when the quantised table
    of :func:`lookup_from_points` is a function of the squared cell distance ``D = dr² +
    dc²`` alone, non-increasing in it, and the floor beyond those offsets; None otherwise.
    Checked with the distance transform's arithmetic (``sqrt((dr res)² + (dc res)²)``), for
    every ``(dr, dc)`` out to where ``exp(-d² / (2 sigma²))`` is 0 (the floor exactly)."""
    reach = math.ceil(math.sqrt(2.0 * 750.0) * sigma / resolution) + 1
    if reach > 400:
        return None
    a = np.arange(reach)
    dr, dc = np.meshgrid(a, a, indexing="ij")
    squared = (dr**2 + dc**2).ravel()
    scaled = np.stack([dr, dc]).astype(np.float64) * resolution
    dist = np.sqrt(np.add.reduce(scaled * scaled, axis=0)).ravel()
    floor = float(quantize(np.array(float(np.log(floor_likelihood)))))
    low = round(floor / QUANTUM)
    table = log_likelihood_of_distance(np.append(dist, 1e6), sigma, floor_likelihood)
    counts = np.round(np.maximum(table, floor) / QUANTUM).astype(np.int64)
    if counts[-1] != low or max(-low, int(counts.max())) >= 2**15:
        return None
    counts = counts[:-1]
    order = np.argsort(squared, kind="stable")
    d2, c = squared[order], counts[order]
    same = d2[1:] == d2[:-1]
    if np.any(same & (c[1:] != c[:-1])) or np.any(c[1:] > c[:-1]):
        return None  # not a function of D, or not non-increasing
    inside = squared <= reach * reach - 2 * reach  # a quarter disc, every D in it complete
    if np.any(counts[~inside] != low):
        return None
    cut = squared[counts > low].max(initial=-1)
    r = math.isqrt(max(cut, 0))
    o = np.arange(-r, r + 1)
    d_rows, d_cols = (x.ravel() for x in np.meshgrid(o, o, indexing="ij"))
    near = d_rows**2 + d_cols**2 <= cut
    value = np.zeros(int(squared.max()) + 1, dtype=np.int64)
    value[squared] = counts  # by D (consistent, checked above)
    values = value[d_rows[near] ** 2 + d_cols[near] ** 2].astype(np.int16)
    return d_rows[near], d_cols[near], values
