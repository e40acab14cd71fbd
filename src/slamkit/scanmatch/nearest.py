"""The nearest reference point within a distance, by a uniform grid: the same answer as
``cKDTree.query(x, k=1, distance_upper_bound=d)``, index for index, for the correspondence
search of :func:`~slamkit.scanmatch.normal_icp.normal_icp`.

Why not the KD-tree: ICP asks for the nearest map point of ~180 scan points once per
iteration, against a map of ~800 points that is queried a few dozen times before it is
rebuilt. For batches this small, the KD-tree's per-call cost (argument checks, a heap per
query point) is most of the time. A grid over the map's bounding box, its points sorted by
cell, answers a query by scanning the few cells within ``d`` of it, its own cell first,
skipping a cell whose box is farther than the best pair so far: on the Intel log's
queries about a third of the KD-tree's time.

Exactly the same answer, because the arithmetic and the rules are the KD-tree's
(``scipy/spatial/ckdtree``, p = 2):

* the squared distance of point ``p`` and query ``x`` is ``(p₀ − x₀)² + (p₁ − x₁)²``, each
  difference and square rounded, summed left to right (the KD-tree's ``r = 0; r += r₁²``
  twice; ``0 + a`` is exact, and the sign of a difference does not change its square);
* the bound is compared squared, ``d * d`` rounded, and strictly: a point at exactly ``d``
  is no pair (index ``M``, the number of points, as the KD-tree returns);
* a point replaces the best only when strictly nearer;
* numba compiles without fast-math: no fused multiply-add, no reassociation.

(The KD-tree also prunes a subtree when its box, at a distance it updates incrementally
with rounding, is farther than the best so far; a point on the box's edge within a few
units in the last place of the best could in principle be skipped there and not here. Over
all 17 million queries of the Intel log, the two agree on every index.)

The one thing a grid cannot reproduce is which of several points at *exactly* the same
least distance the KD-tree returns (the first its traversal meets). The kernel flags those
queries and :meth:`NearestGrid.query` answers them with the KD-tree itself, so ties cost
time, never a different answer. (Over the Intel log's queries there are none.)

Cells are only an index: a query scans every cell that its ``d``-box touches, widened by a
margin far above rounding, and the cell-box test that skips a cell is likewise loosened, so
neither can drop a point the exact comparison would keep.

numba is optional: without it, or inside ``SEAM.use(Backend.NUMPY)``
(:mod:`slamkit.backend`), queries go to the KD-tree (:func:`kdtree_query`, the grid's
oracle).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from slamkit._validation import FloatArray
from slamkit.backend import SEAM, jit, writable

__all__ = [
    "CELL_SIDE",
    "CellIndex",
    "GridShape",
    "NearestGrid",
    "grid_nearest",
    "grid_query",
    "kdtree_nearest",
    "kdtree_query",
]

#: A grid cell's side in correspondence distances ``d``. Larger cells mean fewer cells to
#: visit and more points per cell to scan; on the Intel log's queries (``d`` = 0.5 m, maps
#: of ~800 points) sides from 1.3 d to 2 d are the fastest, 3x the KD-tree, and d/3 no
#: faster than the KD-tree.
CELL_SIDE = 1.5

#: At most this many cells per reference point (plus a constant): a sparse map over a
#: large box gets larger cells instead of a large empty table.
MAX_CELLS_PER_POINT = 16

#: Relative margin (of the coordinates' size) by which the cell ranges are widened and the
#: cell-box gaps shrunk: far above rounding (~1e-16), far below anything that costs time.
MARGIN = 1e-9


def kdtree_nearest(tree: cKDTree, x: FloatArray, bound: float) -> NDArray[np.intp]:
    """``tree.query(x, k=1, distance_upper_bound=bound)``'s indices (``tree.n``: none)."""
    _, j = tree.query(x, k=1, distance_upper_bound=bound)
    return np.asarray(j, dtype=np.intp)


CellIndex = tuple[FloatArray, FloatArray, NDArray[np.intp], NDArray[np.intp]]
"""The grid's points sorted by cell, as :func:`grid_nearest` takes them: ``(xs, ys, order,
start)``, ``xs``, ``ys (M,)`` their coordinates, ``order (M,)`` each one's reference
index, ``start (cells + 1,)`` where each cell's run starts (row-major cells). A plain tuple,
not a named one: numba types a named tuple argument about 1 µs slower per call, and the
grid is queried once per ICP iteration."""

GridShape = tuple[tuple[float, float, float], tuple[int, int]]
"""The grid's geometry, as :func:`grid_nearest` takes it: ``((ox, oy, cell), (n_rows,
n_cols))``, the lower-left corner and the cell side [m], the cells per axis."""


class NearestGrid:
    """Reference points ``(M, 2)`` sorted into square cells of side ``cell`` [m] over their
    bounding box, for :meth:`query`; the queries it leaves to a KD-tree (ties, no numba) go
    to :meth:`kdtree`."""

    def __init__(self, points: FloatArray, cell: float) -> None:
        m = points.shape[0]
        self.n_points = m
        self.points = points
        self._tree: cKDTree | None = None
        lo = points.min(axis=0) if m else np.zeros(2)
        hi = points.max(axis=0) if m else np.zeros(2)
        span = float(max(hi[0] - lo[0], hi[1] - lo[1], 0.0))
        # Enough cells per axis for the span, but not more cells than the cap allows.
        cap = MAX_CELLS_PER_POINT * m + 64
        cell = max(float(cell), span / math.sqrt(cap))
        self.cell = cell
        self.origin = np.array(lo, dtype=np.float64)
        self.shape = (
            int((hi[1] - lo[1]) // cell) + 1,  # rows: y
            int((hi[0] - lo[0]) // cell) + 1,  # columns: x
        )
        col = np.minimum(((points[:, 0] - lo[0]) // cell).astype(np.intp), self.shape[1] - 1)
        row = np.minimum(((points[:, 1] - lo[1]) // cell).astype(np.intp), self.shape[0] - 1)
        key = row * self.shape[1] + col
        order = np.argsort(key, kind="stable")
        self.index = order  # the reference index of each sorted point
        self.xs = np.ascontiguousarray(points[order, 0])
        self.ys = np.ascontiguousarray(points[order, 1])
        counts = np.bincount(key, minlength=self.shape[0] * self.shape[1])
        self.start = np.zeros(counts.size + 1, dtype=np.intp)
        np.cumsum(counts, out=self.start[1:])
        self.cells: CellIndex = (self.xs, self.ys, self.index, self.start)
        self.geometry: GridShape = (
            (float(self.origin[0]), float(self.origin[1]), self.cell),
            self.shape,
        )

    def kdtree(self) -> cKDTree:
        """The KD-tree over the points (built on first use), as
        :attr:`~slamkit.scanmatch.normal_icp.NormalCloud.tree` builds it (``leafsize=8``): a
        tie's answer depends on the tree's shape."""
        if self._tree is None:
            self._tree = cKDTree(self.points, leafsize=8)
        return self._tree

    def query(self, x: FloatArray, bound: float) -> NDArray[np.intp]:
        """The index of the nearest reference point strictly within ``bound`` [m] of each
        query point ``x (K, 2)``, ``M`` where there is none: ``cKDTree.query(x, k=1,
        distance_upper_bound=bound)[1]`` exactly (see the module docstring). ``x`` finite."""
        return _query(self, x, bound)


def kdtree_query(grid: NearestGrid, x: FloatArray, bound: float) -> NDArray[np.intp]:
    """:meth:`NearestGrid.query` by the grid's KD-tree: the path without numba and the
    oracle of :func:`grid_query` (index for index)."""
    return kdtree_nearest(grid.kdtree(), x, bound)


def grid_query(grid: NearestGrid, x: FloatArray, bound: float) -> NDArray[np.intp]:
    """:meth:`NearestGrid.query` by the compiled grid (:func:`grid_nearest`), ties and an
    empty grid by the KD-tree."""
    if grid.n_points == 0:
        return kdtree_query(grid, x, bound)
    out = np.empty(x.shape[0], dtype=np.intp)
    tied = grid_nearest(grid.cells, grid.geometry, writable(x), bound, out)
    if tied:  # equal least distances: the KD-tree's choice among them
        rows = np.flatnonzero(out < 0)
        out[rows] = kdtree_nearest(grid.kdtree(), x[rows], bound)
    return out


@jit
def grid_nearest(
    cells: CellIndex, shape: GridShape, x: FloatArray, bound: float, out: NDArray[np.intp]
) -> bool:
    """The kernel of :meth:`NearestGrid.query`: ``out[i]`` the index of the nearest point,
    ``len(index)`` when none is strictly within ``bound``, ``-1`` when two or more are at
    the same least distance (returns whether any is)."""
    xs, ys, index, start = cells
    (ox, oy, cell), (n_rows, n_cols) = shape
    m = index.shape[0]
    limit = bound * bound  # squared, as the KD-tree compares
    scale = cell + abs(ox) + abs(oy)
    any_tie = False
    for i in range(x.shape[0]):
        x0, x1 = x[i, 0], x[i, 1]
        # Far above the rounding of any coordinate difference here (~1e-16 of the
        # coordinates' size): what the cell ranges are widened by and cell gaps shrunk by.
        tol = MARGIN * (scale + abs(x0) + abs(x1) + bound)
        reach = bound + tol
        c0 = max(math.floor((x0 - reach - ox) / cell), 0)
        c1 = min(math.floor((x0 + reach - ox) / cell), n_cols - 1)
        r0 = max(math.floor((x1 - reach - oy) / cell), 0)
        r1 = min(math.floor((x1 + reach - oy) / cell), n_rows - 1)
        best = limit
        found = m
        tie = False
        if c0 <= c1 and r0 <= r1:
            # The query's own cell first (clamped into the range), then the rest.
            hc = min(max(math.floor((x0 - ox) / cell), c0), c1)
            hr = min(max(math.floor((x1 - oy) / cell), r0), r1)
            for step in range(-1, (r1 - r0 + 1) * (c1 - c0 + 1)):
                if step < 0:
                    r, c = hr, hc
                else:
                    r = r0 + step // (c1 - c0 + 1)
                    c = c0 + step % (c1 - c0 + 1)
                    if r == hr and c == hc:
                        continue
                    # The cell's box: skip it when surely farther than the best so far.
                    gx = max(ox + c * cell - x0, x0 - (ox + (c + 1) * cell)) - tol
                    gy = max(oy + r * cell - x1, x1 - (oy + (r + 1) * cell)) - tol
                    gx = max(gx, 0.0)
                    gy = max(gy, 0.0)
                    if gx * gx + gy * gy > best:
                        continue
                k = r * n_cols + c
                for p in range(start[k], start[k + 1]):
                    d0 = xs[p] - x0
                    d1 = ys[p] - x1
                    d = d0 * d0
                    d = d + d1 * d1
                    if d < best:
                        best = d
                        found = p
                        tie = False
                    elif d == best and found != m:
                        tie = True
        if found == m:
            out[i] = m
        elif tie:
            out[i] = -1
            any_tie = True
        else:
            out[i] = index[found]
    return any_tie


_query = SEAM.pair(compiled=grid_query, oracle=kdtree_query)
"""The nearest points by the compiled grid under numba, else by the KD-tree
(:mod:`slamkit.backend`)."""
