"""The node scores of correlative matching (:mod:`slamkit.scanmatch.correlative`): for
nodes ``u`` (a rotation ``k_u`` and a translation offset ``(i_u, j_u)`` in cells), the sum
over the scan's points of a level's lookup table at each point's cell shifted by the
offset, reads outside the table the floor.

Two forms, one pair on :data:`slamkit.backend.SEAM`: compiled, a bounded gather-sum per
node (:func:`~slamkit.scanmatch.compiled.bounded_counts` on the integer tables, exact)
that stops once a sum is below the threshold; in NumPy, gathers in chunks and one sum per
node. The tables are quantised (:mod:`slamkit.scanmatch.lookup`), so both give the same
score to the last bit, whatever the order of summation.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.backend import SEAM
from slamkit.scanmatch import compiled
from slamkit.scanmatch.lookup import QUANTUM, LookupGrid

__all__ = [
    "CHUNK_ELEMENTS",
    "Cells",
    "level_values",
    "node_scores",
    "node_scores_compiled",
    "node_scores_numpy",
    "quanta_below",
]

IntArray = NDArray[np.int64]

Cells = tuple[IntArray, IntArray]
"""Row and column indices ``(K, N)`` of every point at every rotation."""

CHUNK_ELEMENTS = 1 << 18
"""Gathers run in chunks of at most this many (node, point) pairs: 2^18 int64 indices and
float64 values are 2 MB each, small enough to stay in cache-friendly temporaries."""


def quanta_below(threshold: float) -> int:
    """The integer ``c`` with ``n < c ⇔ n · QUANTUM < threshold`` for every integer ``n``:
    ``ceil(threshold / QUANTUM)``, clamped far beyond any sum for infinite thresholds."""
    if math.isinf(threshold):
        return -(2**62) if threshold < 0 else 2**62
    return math.ceil(threshold / QUANTUM)


def level_values(table: FloatArray, floor: float, rows: IntArray, cols: IntArray) -> FloatArray:
    """``table`` at cells ``(rows, cols)`` (any shape), ``floor`` outside it."""
    inside = (rows >= 0) & (rows < table.shape[0]) & (cols >= 0) & (cols < table.shape[1])
    out: FloatArray = np.where(
        inside, table[np.where(inside, rows, 0), np.where(inside, cols, 0)], floor
    )
    return out


def node_scores_compiled(
    lookup: LookupGrid, level: int, cells: Cells, k: IntArray, i: IntArray, j: IntArray,
    threshold: float,
) -> FloatArray:  # fmt: skip
    """Every node's score at ``level`` by the compiled bounded sums (in integer quanta when
    the grid has them: exact), ``-inf`` where it is below ``threshold`` (each sum stopped
    there: every table value is ``<= 0``)."""
    rows, cols = cells
    out = np.empty(k.size)
    if lookup.counts is not None:  # the same sums in integer quanta (exact)
        compiled.bounded_counts(
            lookup.counts[level], rows, cols, k, i, j, quanta_below(threshold), QUANTUM, out,
        )  # fmt: skip
    else:
        compiled.bounded_sums(lookup.tables[level], rows, cols, k, i, j, threshold, out)
    return out


def node_scores_numpy(
    lookup: LookupGrid, level: int, cells: Cells, k: IntArray, i: IntArray, j: IntArray,
    threshold: float,
) -> FloatArray:  # fmt: skip
    """:func:`node_scores_compiled` by NumPy gathers in chunks: the path without numba and
    its oracle (to the last bit: the scores are exact sums)."""
    table = lookup.tables[level]
    rows, cols = cells
    out = np.empty(k.size)
    step = max(1, CHUNK_ELEMENTS // max(rows.shape[1], 1))
    for a in range(0, k.size, step):
        b = min(a + step, k.size)
        values = level_values(
            table, lookup.floor, rows[k[a:b]] + i[a:b, None], cols[k[a:b]] + j[a:b, None]
        )
        np.sum(values, axis=1, out=out[a:b])
    out[out < threshold] = -np.inf
    return out


node_scores = SEAM.pair(compiled=node_scores_compiled, oracle=node_scores_numpy)
"""Node scores, compiled under numba, else in NumPy (:mod:`slamkit.backend`)."""
