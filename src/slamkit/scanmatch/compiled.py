"""The small compiled numeric helpers of the scan matchers (order statistics, the IEEE
remainder, a 3×3 eigenvalue) and the correlative search's bounded gather-sums and
depth-first branch and bound (:mod:`slamkit.scanmatch.correlative`, its NumPy forms there).

Compiled with :func:`slamkit.backend.jit` (numba when it is installed); the matchers reach
them through the kernel pairs declared on :data:`slamkit.backend.SEAM`, never directly
choosing between them and NumPy.
"""

from __future__ import annotations

import math

import numpy as np

from slamkit._validation import FloatArray
from slamkit.backend import jit

__all__ = [
    "BELOW",
    "NO_BOUND",
    "bounded_counts",
    "bounded_sums",
    "depth_first",
    "group_bounds",
    "ieee_remainder",
    "median_in_place",
    "min_eigenvalue_sym3",
    "select_kth",
    "stamp_max",
]


@jit
def bounded_sums(
    table: FloatArray,
    rows: np.ndarray,
    cols: np.ndarray,
    k: np.ndarray,
    di: np.ndarray,
    dj: np.ndarray,
    threshold: float,
    out: FloatArray,
) -> None:
    """``out[u] = sum_p T[rows[k[u], p] + di[u], cols[k[u], p] + dj[u]]`` with ``T = table``
    inside it and ``T[0, 0]`` (the floor: the corner of a padded table) outside, or ``-inf``
    when that sum is below ``threshold``: the node scores of correlative matching
    (:mod:`slamkit.scanmatch.correlative`) without the ``(nodes, points)`` index and value
    temporaries of the NumPy gather, and without a table padded by the whole search window.
    Every value must be ``<= 0`` (a partial sum then only falls, so the sum stops as soon
    as it is below ``threshold``; ``-inf``: every sum is complete)."""
    n_rows, n_cols = table.shape
    flat = table.reshape(-1)
    floor = flat[0]
    nr = np.uint64(n_rows)
    nc = np.uint64(n_cols)
    for u in range(k.shape[0]):
        row = k[u]
        a, b = di[u], dj[u]
        total = 0.0
        for p in range(rows.shape[1]):
            r = rows[row, p] + a
            c = cols[row, p] + b
            # Unsigned, a negative index is huge: one comparison per axis.
            if np.uint64(r) < nr and np.uint64(c) < nc:
                total += flat[r * n_cols + c]
                if total < threshold:
                    break
            else:
                total += floor
        out[u] = -np.inf if total < threshold else total


@jit
def bounded_counts(
    table: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    k: np.ndarray,
    di: np.ndarray,
    dj: np.ndarray,
    threshold: int,
    quantum: float,
    out: FloatArray,
) -> None:
    """:func:`bounded_sums` on an integer ``table`` of quanta (``value = count × quantum``),
    summed in ``int64`` and compared with the integer ``threshold`` (in quanta; a sum of
    integers is below a real ``t`` exactly when it is below ``ceil(t)``): ``out[u]`` is the
    sum times ``quantum``, the float sum of the quantised values to the last bit (every
    partial sum is exact in both), or ``-inf`` below the threshold. The integer add is a
    shorter dependency chain than the float one, and the table a quarter of the bytes."""
    n_rows, n_cols = table.shape
    flat = table.reshape(-1)
    for u in range(k.shape[0]):
        total = _bounded_total(flat, n_rows, n_cols, rows, cols, k[u], di[u], dj[u], threshold)
        out[u] = -np.inf if total < threshold else total * quantum


@jit
def _bounded_total(
    flat: np.ndarray,
    n_rows: int,
    n_cols: int,
    rows: np.ndarray,
    cols: np.ndarray,
    k: int,
    a: int,
    b: int,
    threshold: int,
) -> np.int64:
    """One node's sum of :func:`bounded_counts` (``flat``: the table raveled, its first
    value the floor), stopped once below ``threshold``."""
    floor = np.int64(flat[0])
    nr = np.uint64(n_rows)
    nc = np.uint64(n_cols)
    total = np.int64(0)
    for p in range(rows.shape[1]):
        r = rows[k, p] + a
        c = cols[k, p] + b
        if np.uint64(r) < nr and np.uint64(c) < nc:
            total += np.int64(flat[r * n_cols + c])
            if total < threshold:
                break
        else:
            total += floor
    return total


NO_BOUND = 2**62
""":func:`group_bounds`' value for a group it cannot bound (any sum may reach it)."""
BELOW = -(2**62)
""":func:`group_bounds`' value for a bound below the threshold."""


@jit
def group_bounds(
    dilated: np.ndarray,
    spread: int,
    near: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    di: np.ndarray,
    dj: np.ndarray,
    threshold: int,
    out: np.ndarray,
) -> None:
    """Upper bounds of :func:`bounded_counts` over groups of rotations, in quanta
    (``out``: ``int64``): the rotations of ``rows``, ``cols`` in groups ``g`` of ``2 spread
    + 1`` (the last may be smaller), ``out[(g · len(di) + a) · len(dj) + b]`` at least the
    sum of every rotation of group ``g`` at offset ``(di[a], dj[b])``. Where ``near[g]`` (no
    point's cell at any rotation of the group lies more than ``spread`` cells per axis from
    its cell at the group's middle rotation) the bound is the middle rotation's sum over
    ``dilated`` (the table dilated by ``spread``,
    :meth:`~slamkit.scanmatch.lookup.LookupGrid.dilated_counts`; every value ``<= 0``),
    :data:`BELOW` when below ``threshold``; elsewhere :data:`NO_BOUND`. One sum bounds
    ``2 spread + 1`` nodes."""
    d_rows, d_cols = dilated.shape
    d_flat = dilated.reshape(-1)
    shift = spread + 1  # the dilated table's padding
    n_k = rows.shape[0]
    n_i, n_j = di.shape[0], dj.shape[0]
    size = 2 * spread + 1
    for g in range(near.shape[0]):
        mid = (g * size + min(g * size + size, n_k) - 1) // 2
        for ii in range(n_i):
            for jj in range(n_j):
                u = (g * n_i + ii) * n_j + jj
                if not near[g]:
                    out[u] = NO_BOUND
                    continue
                total = _bounded_total(
                    d_flat, d_rows, d_cols, rows, cols, mid, di[ii] + shift, dj[jj] + shift,
                    threshold,
                )  # fmt: skip
                out[u] = BELOW if total < threshold else total


@jit
def depth_first(
    tables: tuple[np.ndarray, ...],
    rows: np.ndarray,
    cols: np.ndarray,
    n: int,
    spread: int,
    bounds: np.ndarray,
    starts: np.ndarray,
    best: np.ndarray,
    box: np.ndarray,
) -> None:
    """Branch and bound of correlative matching, depth first, from the rotation groups of
    :func:`group_bounds` (``bounds``, in quanta, at the top-level offsets ``starts ×
    starts``) down to the leaves: ``best = [score, k, i, j]`` (``int64``, the score in
    quanta) starts as a leaf already scored and ends as the best leaf of the whole window,
    ties to the smallest ``(k, i, j)``.

    ``tables``: the integer tables of every level (:attr:`~slamkit.scanmatch.lookup.
    LookupGrid.counts`, every value ``<= 0``); a node ``(k, i, j)`` at level ``h`` stands
    for the translations ``[i, i + 2^h) × [j, j + 2^h)`` with ``|i|, |j| <= n`` at rotation
    ``k``. Entries are taken from a stack, the best bound on top: a group whose bound still
    reaches the best leaf is split into its rotations' top-level nodes, a node into its four
    children, each scored against the best leaf (:func:`_bounded_total`: a sum below it is
    cut short, and the entry dropped), and a leaf that beats the best becomes it. So every
    entry is scored against the best leaf reached *by then*, not the best of an earlier
    level, and the search's order, best bounds first, finds the optimum early. An entry is
    dropped only when its bound is below a leaf's score, so the optimum and its tie rule
    are those of the exhaustive search.

    ``box = [i0, i1, j0, j1]`` (``int64``, inclusive): translations left out of the search
    (at every rotation); a node wholly inside is dropped, and so is a leaf inside. An empty
    box (``i0 > i1``) leaves nothing out."""
    levels = len(tables)
    i0, i1, j0, j1 = box[0], box[1], box[2], box[3]
    n_k = rows.shape[0]
    size = 2 * spread + 1
    n_s = starts.shape[0]
    m = bounds.shape[0]
    # A pop pushes at most `size` (a group) or four (a node) entries, a level lower.
    cap = m + size + 4 * levels
    stack = (np.empty(cap, np.int64), np.empty(cap, np.int64), np.empty(cap, np.int64),
             np.empty(cap, np.int64), np.empty(cap, np.int64))  # fmt: skip
    s_level, s_k, s_i, s_j, s_bound = stack
    top = 0
    for u in np.argsort(bounds, kind="mergesort"):  # ascending: the best ends on top
        if bounds[u] < best[0]:
            continue
        g, offset = divmod(u, n_s * n_s)
        # a group: one above the top level
        top = _push(stack, top, (levels, g, starts[offset // n_s], starts[offset % n_s]), bounds[u])
    c_k = np.empty(size, np.int64)
    c_i = np.empty(size, np.int64)
    c_j = np.empty(size, np.int64)
    c_bound = np.empty(size, np.int64)
    children = (c_k, c_i, c_j, c_bound)
    while top > 0:
        top -= 1
        level, k, i, j, bound = s_level[top], s_k[top], s_i[top], s_j[top], s_bound[top]
        if bound < best[0]:
            continue
        if level == 0:  # a leaf: its bound is its score
            if i0 <= i <= i1 and j0 <= j <= j1:
                continue
            if bound > best[0] or (k, i, j) < (best[1], best[2], best[3]):
                best[0], best[1], best[2], best[3] = bound, k, i, j
            continue
        table = tables[levels - 1 if level == levels else level - 1]
        n_rows, n_cols = table.shape
        flat = table.reshape(-1)
        found = 0
        count = min(k * size + size, n_k) - k * size if level == levels else 4
        side = 1 << (levels - 1 if level == levels else level - 1)  # a child's side
        for a in range(count):
            if level == levels:
                ck, ci, cj = k * size + a, i, j
            else:
                ck, ci, cj = k, i + (side if a >= 2 else 0), j + (side if a % 2 else 0)
                if ci > n or cj > n:
                    continue
            if i0 <= ci and ci + side - 1 <= i1 and j0 <= cj and cj + side - 1 <= j1:
                continue
            total = _bounded_total(flat, n_rows, n_cols, rows, cols, ck, ci, cj, best[0])
            if total < best[0]:
                continue
            _insert_sorted(children, found, ck, ci, cj, total)
            found += 1
        for a in range(found):
            top = _push(stack, top, (level - 1, c_k[a], c_i[a], c_j[a]), c_bound[a])


@jit
def _push(
    stack: tuple[np.ndarray, ...], top: int, entry: tuple[int, int, int, int], bound: int
) -> int:
    """Put ``entry = (level, k, i, j)`` with its ``bound`` on :func:`depth_first`'s stack
    (five arrays: level, k, i, j, bound) at ``top``; return the new top."""
    s_level, s_k, s_i, s_j, s_bound = stack
    s_level[top], s_k[top], s_i[top], s_j[top] = entry
    s_bound[top] = bound
    return top + 1


@jit
def _insert_sorted(
    children: tuple[np.ndarray, ...], found: int, k: int, i: int, j: int, total: np.int64
) -> None:
    """Insert child ``(k, i, j)`` of bound ``total`` into the first ``found`` entries of
    ``children = (k, i, j, bound)``, kept sorted by bound, ascending (after its equals)."""
    c_k, c_i, c_j, c_bound = children
    p = found
    while p > 0 and c_bound[p - 1] > total:
        c_k[p], c_i[p], c_j[p] = c_k[p - 1], c_i[p - 1], c_j[p - 1]
        c_bound[p] = c_bound[p - 1]
        p -= 1
    c_k[p], c_i[p], c_j[p], c_bound[p] = k, i, j, total


@jit
def stamp_max(
    counts: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    d_rows: np.ndarray,
    d_cols: np.ndarray,
    values: np.ndarray,
) -> None:
    """``counts[r + d_rows[o], c + d_cols[o]] = max(itself, values[o])`` for every marked
    cell ``(r, c) = (rows[m], cols[m])`` and stamp offset ``o``, those inside ``counts``:
    with ``values`` the table at each offset's distance, the table of the distance to the
    nearest marked cell where it is above the floor
    (:func:`~slamkit.scanmatch.lookup.lookup_from_points`)."""
    n_rows, n_cols = counts.shape
    for m in range(rows.shape[0]):
        for o in range(d_rows.shape[0]):
            r = rows[m] + d_rows[o]
            c = cols[m] + d_cols[o]
            if 0 <= r < n_rows and 0 <= c < n_cols and counts[r, c] < values[o]:
                counts[r, c] = values[o]


@jit
def ieee_remainder(x: float, y: float) -> float:
    """``math.remainder(x, y)`` (the IEEE remainder ``x - n y``, ``n`` the integer nearest
    ``x / y``, ties to even), exact, for finite ``x`` and ``y != 0``: ``fmod`` is exact, and so
    is the choice between ``m`` and ``m - |y|``."""
    ax, ay = abs(x), abs(y)
    m = np.fmod(ax, ay)
    c = ay - m
    if m < c:
        r = m
    elif m > c:
        r = -c
    else:  # half-way: keep the even multiple
        r = m - 2.0 * np.fmod(0.5 * (ax - m), ay)
    return math.copysign(1.0, x) * r


@jit
def select_kth(a: FloatArray, k: int) -> float:
    """The ``k``-th smallest entry of ``a`` (0-based; ``np.sort(a)[k]``), by quickselect
    (Hoare partitions around a median of three): ``a`` is permuted so that ``a[:k] <= a[k] <=
    a[k + 1:]``. Expected time linear, no sort needed for an order statistic."""
    lo, hi = 0, a.shape[0] - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] < a[lo]:
            a[mid], a[lo] = a[lo], a[mid]
        if a[hi] < a[lo]:
            a[hi], a[lo] = a[lo], a[hi]
        if a[hi] < a[mid]:
            a[hi], a[mid] = a[mid], a[hi]
        pivot = a[mid]
        i, j = lo, hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while a[j] > pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break  # a[j + 1 : i] all equal the pivot
    return a[k]


@jit
def median_in_place(a: FloatArray) -> float:
    """``np.median`` of a non-empty ``a`` (the middle value, or the mean of the two middle
    ones for an even count) by :func:`select_kth`, permuting ``a``: after the selection the
    lower middle value is the largest of ``a[:n // 2]``."""
    n = a.shape[0]
    h = n // 2
    upper = select_kth(a, h)
    if n % 2:
        return upper
    lower = a[0]
    for i in range(1, h):
        lower = max(lower, a[i])
    return 0.5 * (lower + upper)


@jit
def min_eigenvalue_sym3(h: FloatArray) -> float:
    """The smallest eigenvalue of a symmetric ``h (3, 3)`` by cyclic Jacobi rotations (each
    zeroes one off-diagonal entry; convergence is quadratic, a few sweeps), accurate to
    rounding of ``|h|`` like ``np.linalg.eigvalsh(h)[0]``."""
    a = h.copy()
    scale = 0.0
    for row in range(3):
        for col in range(3):
            scale += a[row, col] * a[row, col]
    for _ in range(30):
        off = a[0, 1] ** 2 + a[0, 2] ** 2 + a[1, 2] ** 2
        if off <= 1e-34 * scale:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = a[p, q]
            if apq == 0.0:
                continue
            theta = (a[q, q] - a[p, p]) / (2.0 * apq)
            if abs(theta) > 1e150:
                t = 0.5 / theta
            else:
                t = math.copysign(1.0, theta) / (abs(theta) + math.sqrt(theta * theta + 1.0))
            c = 1.0 / math.sqrt(t * t + 1.0)
            s = t * c
            a[p, p] -= t * apq
            a[q, q] += t * apq
            a[p, q] = a[q, p] = 0.0
            r = 3 - p - q  # the third index
            arp, arq = a[r, p], a[r, q]
            a[r, p] = a[p, r] = c * arp - s * arq
            a[r, q] = a[q, r] = s * arp + c * arq
    return min(a[0, 0], a[1, 1], a[2, 2])
