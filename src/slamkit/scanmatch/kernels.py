"""Compiled kernels of point-to-line ICP (numba), each the twin of a NumPy implementation in
:mod:`slamkit.scanmatch.plicp`, :mod:`~slamkit.scanmatch.icp` and
:mod:`~slamkit.scanmatch.covariance` that gives the same numbers to rounding.

Which runs is decided at one seam, :data:`slamkit.backend.SEAM`: :mod:`~slamkit.scanmatch.
plicp`, :mod:`~slamkit.scanmatch.icp` and :mod:`~slamkit.scanmatch.covariance` declare each
kernel and its NumPy oracle as a pair there, and the pair runs the kernel when numba is
installed (``pip install slamkit[fast]``), the oracle otherwise or inside ``with
SEAM.use(Backend.NUMPY)`` (how tests and benchmarks run both paths in one process). The
kernels are compiled on their first call (about 10 s of CPU for all of them) and cached on
disk (``cache=True``, next to this file), so later processes only load them.

**What is compiled.** One call runs the whole PLICP loop (:func:`plicp_loop`, in the steps
its docstring names: correspondences, trimming, the closed-form step, the stopping rules,
both degeneracy checks and the covariance), one call prepares a reference scan (segment
normals, gaps, point normals) and one computes the covariance
(:mod:`slamkit.scanmatch.kernel_covariance`; the small numeric helpers are in
:mod:`slamkit.scanmatch.compiled`, re-exported here). The arithmetic of each line is that of
the NumPy oracle, written as scalar loops over the points, so there are no temporaries and
no per-call Python overhead per iteration.

**Nearest reference point without a KD-tree.** A reference point ``p`` at bearing ``φ``
(seen from the reference sensor, the origin) lies on the ray from the origin at that angle,
so for a query ``q`` at range ``r_q`` and bearing ``φ_q``, with ``Δ = |φ - φ_q|``,

    |q - p| >= r_q sin Δ = |q × u|   (Δ <= 90°, u the unit direction of p: the distance
                                       from q to the line of the ray),
    |q - p| >= r_q                   (Δ >= 90°: p is behind the line through the origin
                                       perpendicular to q),

a lower bound that grows with ``Δ`` up to 180°. Censi's CSM uses this bound to search the
reference scan in beam order from the beam at ``φ_q``. Here the points are sorted once by
bearing instead (a cheap monotone function of it, so no ``atan2`` per point; a scan is
sorted already, or a rotation of sorted). That makes the search exact for any point set in
any order. For each query the search takes the best of a guess (this current point's match
at the previous iteration, else the previous current point's match), then walks the sorted
points up and down from ``φ_q``. Each walk stops at the first point whose bound exceeds the
best distance so far: if that point is within 180° the points beyond it are farther still,
and if it is past 180° its half of the circle is covered and the other walk covers the rest.
The answer is exactly the KD-tree's (ties go to the smaller index), after about 1-3 distance
evaluations per query on a 180-beam scan instead of a tree descent.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from slamkit._validation import FloatArray
from slamkit.backend import jit
from slamkit.scanmatch.compiled import ieee_remainder, min_eigenvalue_sym3, select_kth
from slamkit.scanmatch.kernel_covariance import point_to_line_cov

__all__ = [
    "CONVERGED",
    "DEGENERATE_END",
    "DEGENERATE_START",
    "DEGENERATE_STEP",
    "NO_CONVERGENCE",
    "TOO_FEW",
    "Pairs",
    "PlicpSettings",
    "ReferenceArrays",
    "closed_form_step",
    "correspond",
    "ieee_remainder",
    "line_covariance",
    "min_eigenvalue_sym3",
    "nearest_points",
    "new_pairs",
    "plicp_loop",
    "point_to_line_cov",
    "repeated",
    "root_of_multiplier",
    "scan_tables",
    "select_kth",
    "settings_from_array",
    "small_step",
    "step_sums",
    "trim",
]

# Status codes of plicp_loop.
CONVERGED = 0
"""The loop stopped on a small step or a repeated correspondence set."""
TOO_FEW = 1
"""Fewer than ``min_correspondences`` pairs after trimming."""
DEGENERATE_START = 2
"""The normalised Hessian at the initial guess is below half ``min_eigenvalue``."""
DEGENERATE_STEP = 3
"""The normals of the kept pairs do not span the plane (the step's ``A`` is singular)."""
NO_CONVERGENCE = 4
"""``max_iterations`` were used up."""
DEGENERATE_END = 5
"""The normalised Hessian at the solution is below ``min_eigenvalue``."""

_TWO_PI = 2.0 * math.pi


@jit
def root_of_multiplier(s11: float, s12: float, s22: float, h1: float, h2: float) -> float:
    """Compiled twin of :func:`slamkit.scanmatch.plicp.largest_real_root` (the same Newton
    iteration, operation for operation)."""
    mid, rad = 0.5 * (s11 + s22), math.hypot(0.5 * (s11 - s22), s12)
    e1, e2 = mid - rad, mid + rad
    phi = 0.5 * math.atan2(2.0 * s12, s11 - s22)
    v2x, v2y = math.cos(phi), math.sin(phi)
    g2 = h1 * v2x + h2 * v2y
    g1 = -h1 * v2y + h2 * v2x
    norm_h = math.hypot(h1, h2)
    scale = max(abs(e1), abs(e2), norm_h, 1e-300)
    eps = 1e-12 * scale
    lam = max(norm_h - e2, -e1 + eps)
    for _ in range(60):
        u1, u2 = e1 + lam, e2 + lam
        c2 = (g1 / u1) ** 2 + (g2 / u2) ** 2
        if c2 <= 1.0 and lam <= -e1 + eps and abs(g1) <= eps:
            return -e1
        norm_c = math.sqrt(c2)
        psi = 1.0 / norm_c - 1.0
        dpsi = (g1 * g1 / u1**3 + g2 * g2 / u2**3) / (c2 * norm_c)
        if not dpsi > 0.0:
            return lam
        step = -psi / dpsi
        lam += step
        if abs(step) <= eps:
            return lam
    return lam


# --- the reference ---------------------------------------------------------------------------


@jit
def scan_tables(
    points: FloatArray, window: int, max_spacing: float
) -> tuple[FloatArray, np.ndarray, FloatArray, FloatArray]:
    """``(normals (M, 2), has_normal (M,), gaps (M - 1,), segment_normals (M - 1, 2))`` of a
    scan: the twin of :func:`slamkit.scanmatch.covariance.scan_order_normals` followed by the
    gaps and segment normals of :func:`slamkit.scanmatch.icp.prepare_scan`."""
    m = points.shape[0]
    normals = np.zeros((m, 2))
    ok = np.zeros(m, dtype=np.bool_)
    gaps = np.empty(max(m - 1, 0))
    seg = np.zeros((max(m - 1, 0), 2))
    for j in range(m - 1):
        tx = points[j + 1, 0] - points[j, 0]
        ty = points[j + 1, 1] - points[j, 1]
        g = math.hypot(tx, ty)
        gaps[j] = g
        if g > 0.0:
            inv = 1.0 / g
            seg[j, 0] = -ty * inv
            seg[j, 1] = tx * inv
    k = min(window | 1, m if m % 2 else m - 1)
    if m < 3 or k < 3:
        return normals, ok, gaps, seg
    cx = 0.0
    cy = 0.0
    for j in range(m):
        cx += points[j, 0]
        cy += points[j, 1]
    cx /= m
    cy /= m
    # Prefix sums of x, y, x², xy, y² (centroid-relative) and of the spacings > max_spacing.
    prefix = np.zeros((m + 1, 5))
    too_far = np.zeros(m, dtype=np.int64)
    for j in range(m):
        x = points[j, 0] - cx
        y = points[j, 1] - cy
        prefix[j + 1, 0] = prefix[j, 0] + x
        prefix[j + 1, 1] = prefix[j, 1] + y
        prefix[j + 1, 2] = prefix[j, 2] + x * x
        prefix[j + 1, 3] = prefix[j, 3] + x * y
        prefix[j + 1, 4] = prefix[j, 4] + y * y
        if j > 0:
            dx = x - (points[j - 1, 0] - cx)
            dy = y - (points[j - 1, 1] - cy)
            too_far[j] = too_far[j - 1] + (1 if math.hypot(dx, dy) > max_spacing else 0)
    half = k // 2
    for j in range(m):
        start = min(max(j - half, 0), m - k)
        if too_far[start + k - 1] - too_far[start] != 0:
            continue
        sx = (prefix[start + k, 0] - prefix[start, 0]) / k
        sy = (prefix[start + k, 1] - prefix[start, 1]) / k
        sxx = (prefix[start + k, 2] - prefix[start, 2]) / k - sx**2
        sxy = (prefix[start + k, 3] - prefix[start, 3]) / k - sx * sy
        syy = (prefix[start + k, 4] - prefix[start, 4]) / k - sy**2
        phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
        normals[j, 0] = -math.sin(phi)
        normals[j, 1] = math.cos(phi)
        ok[j] = True
    return normals, ok, gaps, seg


# --- nearest neighbours by bearing -----------------------------------------------------------


@jit
def _sift_down(keys: FloatArray, idx: np.ndarray, root: int, end: int) -> None:
    while True:
        child = 2 * root + 1
        if child >= end:
            return
        if child + 1 < end and keys[idx[child + 1]] > keys[idx[child]]:
            child += 1
        if keys[idx[child]] <= keys[idx[root]]:
            return
        idx[root], idx[child] = idx[child], idx[root]
        root = child


@jit
def _argsort(keys: FloatArray) -> np.ndarray:
    """Indices that sort ``keys`` (ties in any order). A scan's bearings are sorted already,
    or a rotation of sorted ones (a full turn starting anywhere): found in one pass; anything
    else is heap-sorted."""
    m = keys.shape[0]
    descents, at = 0, 0
    for j in range(1, m):
        if keys[j] < keys[j - 1]:
            descents += 1
            at = j
    idx = np.empty(m, dtype=np.int64)
    if descents == 0 or (descents == 1 and keys[m - 1] <= keys[0]):
        for k in range(m):
            idx[k] = (at + k) % m
        return idx
    for k in range(m):
        idx[k] = k
    for root in range(m // 2 - 1, -1, -1):
        _sift_down(keys, idx, root, m)
    for end in range(m - 1, 0, -1):
        idx[0], idx[end] = idx[end], idx[0]
        _sift_down(keys, idx, 0, end)
    return idx


@jit
def _count_below(ascending: FloatArray, value: float) -> int:
    """How many entries of ``ascending`` are below ``value`` (bisection;
    ``np.searchsorted(ascending, value, side="left")``)."""
    lo, hi = 0, ascending.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if ascending[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@jit
def _pseudo_bearing(x: float, y: float) -> float:
    """A cheap strictly increasing function of ``atan2(y, x)``, in ``(-2, 2]`` (0 at the
    origin): ``±(1 - x / (|x| + |y|))`` with the sign of ``y``. Sorting by it is sorting by
    bearing, without a ``atan2`` per point."""
    s = abs(x) + abs(y)
    if s == 0.0:
        return 0.0
    t = 1.0 - x / s
    return t if y >= 0.0 else -t


@jit
def _bearing_index(points: FloatArray) -> tuple[np.ndarray, FloatArray, FloatArray]:
    """``(order, key, table)``: the points sorted by bearing from the origin (``key`` their
    :func:`_pseudo_bearing`), and per sorted point ``(x, y, u_x, u_y)`` with ``u`` its unit
    direction (``(1, 0)`` at the origin)."""
    m = points.shape[0]
    ang = np.empty(m)
    for j in range(m):
        ang[j] = _pseudo_bearing(points[j, 0], points[j, 1])
    order = _argsort(ang)
    key = ang[order]
    table = np.empty((m, 4))
    for k in range(m):
        x, y = points[order[k], 0], points[order[k], 1]
        r = math.hypot(x, y)
        table[k, 0] = x
        table[k, 1] = y
        table[k, 2] = x / r if r > 0.0 else 1.0
        table[k, 3] = y / r if r > 0.0 else 0.0
    return order, key, table


@jit
def _nearest(
    order: np.ndarray,
    key: FloatArray,
    table: FloatArray,
    points: FloatArray,
    x: float,
    y: float,
    guess: int,
    max_d2: float,
) -> int:
    """Index of the reference point nearest ``(x, y)`` with squared distance below ``max_d2``
    (ties: the smaller index), or ``M`` when none is; the bearing walk of the module
    docstring, started from the point ``guess`` (any index; ``M`` for none).

    The bound of a point with unit direction ``u`` is ``|q × u|`` (``= r_q sin Δ``) when
    ``q · u > 0``, else ``r_q``. Each walk may stop at the first point whose bound exceeds the
    best distance while its ``Δ`` is at most 180° (the bound grows with ``Δ`` up to there);
    a walk that stops beyond 180° has covered its half of the circle, and the other walk
    covers the rest."""
    m = points.shape[0]
    best_d2 = max_d2
    best_j = m
    if guess < m:
        dx = x - points[guess, 0]
        dy = y - points[guess, 1]
        d2 = dx * dx + dy * dy
        if d2 < best_d2:
            best_d2, best_j = d2, guess
    best_d = math.sqrt(best_d2)
    rq = math.sqrt(x * x + y * y)
    margin = 1e-9 * (1.0 + rq)  # rounding of the bound, far above it, far below any spacing
    start = _count_below(key, _pseudo_bearing(x, y))
    for side in range(2):  # up: increasing bearings from φ_q; down: decreasing
        for step in range(m):
            k = start + step if side == 0 else start - 1 - step
            if k >= m:
                k -= m
            elif k < 0:
                k += m
            ux, uy = table[k, 2], table[k, 3]
            bound = abs(x * uy - y * ux) if x * ux + y * uy > 0.0 else rq
            if bound > best_d + margin:
                break
            dx = x - table[k, 0]
            dy = y - table[k, 1]
            d2 = dx * dx + dy * dy
            j = order[k]
            if d2 < best_d2 or (d2 == best_d2 and j < best_j < m):  # strict at the bound
                best_d2, best_j = d2, j
                best_d = math.sqrt(d2)
    return best_j


@jit
def nearest_points(points: FloatArray, queries: FloatArray, max_distance: float) -> np.ndarray:
    """For each of ``queries (K, 2)``, the index of the nearest of ``points (M, 2)`` closer
    than ``max_distance`` (ties: the smaller index), else ``M``: what
    ``cKDTree(points).query(queries, distance_upper_bound=max_distance)[1]`` returns, found by
    the bearing walk of the module docstring (each query starts from the previous query's
    answer)."""
    order, key, table = _bearing_index(points)
    m = points.shape[0]
    out = np.empty(queries.shape[0], dtype=np.int64)
    guess = m
    for i in range(queries.shape[0]):
        guess = _nearest(
            order,
            key,
            table,
            points,
            queries[i, 0],
            queries[i, 1],
            guess,
            max_distance * max_distance,
        )
        out[i] = guess
    return out


# --- the PLICP loop --------------------------------------------------------------------------


@jit
def _min_eigenvalue(
    q: FloatArray,
    normals: FloatArray,
    has_normal: np.ndarray,
    j1: np.ndarray,
    keep: np.ndarray,
    theta: float,
) -> float:
    """Twin of ``normalised_min_eigenvalue(line_jacobian(q[use], normals[j1[use]], θ),
    q[use])`` (:mod:`slamkit.scanmatch.covariance`) for ``use = keep & has_normal[j1]``
    (a kept pair has ``j1 < M``)."""
    c, s = np.cos(theta), np.sin(theta)
    h = np.zeros((3, 3))
    sq = 0.0
    count = 0
    for i in range(q.shape[0]):
        if not (keep[i] and has_normal[j1[i]]):
            continue
        qx, qy = q[i, 0], q[i, 1]
        nx, ny = normals[j1[i], 0], normals[j1[i], 1]
        r = nx * (-s * qx - c * qy) + ny * (c * qx - s * qy)
        h[0, 0] += nx * nx
        h[0, 1] += nx * ny
        h[0, 2] += nx * r
        h[1, 1] += ny * ny
        h[1, 2] += ny * r
        h[2, 2] += r * r
        sq += qx * qx + qy * qy
        count += 1
    if count == 0:
        return 0.0
    inv_len = 1.0 / max(math.sqrt(sq / count), 1e-9)
    h[0, 2] *= inv_len
    h[1, 2] *= inv_len
    h[2, 2] *= inv_len * inv_len
    h[1, 0], h[2, 0], h[2, 1] = h[0, 1], h[0, 2], h[1, 2]
    h /= count
    return min_eigenvalue_sym3(h)


class PlicpSettings(NamedTuple):
    """:class:`~slamkit.scanmatch.plicp.PlIcpConfig`'s numbers as the compiled steps read
    them (the fields are the config's, with ``max_distance`` its
    ``max_correspondence_distance``). :func:`plicp_loop` takes them as one float array in
    this order (:func:`settings_from_array`): numba types an array argument in a fraction of
    the time it takes for a tuple of nine numbers."""

    max_iterations: int
    max_distance: float
    outlier_multiplier: float
    outlier_floor: float
    trim_fraction: float
    min_correspondences: int
    translation_tolerance: float
    rotation_tolerance: float
    min_eigenvalue: float


class ReferenceArrays(NamedTuple):
    """A :class:`~slamkit.scanmatch.icp.PreparedScan`'s arrays as the compiled loop reads
    them: ``joined (M - 1,)`` marks the segments no longer than ``max_gap`` and not of zero
    length."""

    points: FloatArray
    segment_normals: FloatArray
    joined: np.ndarray
    has_normal: np.ndarray
    normals: FloatArray


class Pairs(NamedTuple):
    """One iteration's correspondences, one entry per current point (buffers the steps of
    :func:`plicp_loop` fill): ``j1`` the nearest reference point (``M``: none), ``use_next``
    whether the segment goes to ``j1 + 1`` (else ``j1 - 1``), ``valid`` whether ``j1`` has a
    segment, ``keep`` whether the pair survived the trimming, ``err`` its line distance
    (``inf`` when not valid), ``work`` scratch for the order statistics, ``nrm (n, 2)`` the
    segment's normal."""

    j1: np.ndarray
    use_next: np.ndarray
    valid: np.ndarray
    keep: np.ndarray
    err: FloatArray
    work: FloatArray
    nrm: FloatArray


@jit
def settings_from_array(values: FloatArray) -> PlicpSettings:
    """The :class:`PlicpSettings` of ``values (9,)``, the fields in order (the two counts
    as whole numbers)."""
    return PlicpSettings(
        int(values[0]), values[1], values[2], values[3], values[4], int(values[5]),
        values[6], values[7], values[8],
    )  # fmt: skip


@jit
def new_pairs(n: int, m: int) -> Pairs:
    """Empty :class:`Pairs` for ``n`` current points and ``m`` reference points."""
    return Pairs(
        np.full(n, m, dtype=np.int64),
        np.zeros(n, dtype=np.bool_),
        np.zeros(n, dtype=np.bool_),
        np.zeros(n, dtype=np.bool_),
        np.empty(n),
        np.empty(n),
        np.zeros((n, 2)),
    )


@jit
def correspond(
    ref: ReferenceArrays,
    index: tuple[np.ndarray, FloatArray, FloatArray],
    q: FloatArray,
    pose: tuple[float, float, float],
    max_d2: float,
    pairs: Pairs,
) -> int:
    """Pair every current point of ``q`` moved by ``pose = (x, y, θ)`` with its nearest
    reference point within ``√max_d2`` (the bearing walk over ``index``, the reference's
    :func:`_bearing_index`, each search started at the point's previous match, else the
    previous point's) and the closer of its joined neighbours; fill ``pairs`` and return
    the count of valid pairs."""
    points = ref.points
    m = points.shape[0]
    order, key, table = index
    tx, ty, th = pose
    c, s = math.cos(th), math.sin(th)
    guess = m
    n_valid = 0
    for i in range(q.shape[0]):
        qx, qy = q[i, 0], q[i, 1]
        mx = (qx * c + qy * -s) + tx
        my = (qx * s + qy * c) + ty
        start = pairs.j1[i] if pairs.j1[i] < m else guess
        j = _nearest(order, key, table, points, mx, my, start, max_d2)
        pairs.j1[i] = j
        if j < m:
            guess = j
        has_prev = j < m and j >= 1 and ref.joined[j - 1]
        has_next = j < m - 1 and ref.joined[j]
        nxt = False
        if has_next and has_prev:
            dx = points[j - 1, 0] - mx
            dy = points[j - 1, 1] - my
            d_prev = dx * dx + dy * dy
            dx = points[j + 1, 0] - mx
            dy = points[j + 1, 1] - my
            nxt = dx * dx + dy * dy < d_prev
        elif has_next:
            nxt = True
        pairs.use_next[i] = nxt
        pairs.valid[i] = has_prev or has_next
        if has_prev or has_next:
            n_valid += 1
            seg = j if nxt else j - 1
            nx, ny = ref.segment_normals[seg, 0], ref.segment_normals[seg, 1]
            pairs.nrm[i, 0], pairs.nrm[i, 1] = nx, ny
            pairs.err[i] = abs(nx * (mx - points[j, 0]) + ny * (my - points[j, 1]))
        else:
            pairs.nrm[i, 0], pairs.nrm[i, 1] = 0.0, 0.0
            pairs.err[i] = np.inf
    return n_valid


@jit
def trim(pairs: Pairs, n_valid: int, settings: PlicpSettings) -> int:
    """Keep the pairs whose line distance is within ``outlier_multiplier`` times the
    median of the valid ones (at least ``outlier_floor``), then the ``trim_fraction`` of
    those with the smallest; return how many are kept. By order statistics (the NumPy
    oracle reads them from a sorted copy): the invalid errors are ``+inf``, above all."""
    err, work = pairs.err, pairs.work
    n = err.shape[0]
    thr = -1.0
    if n_valid:
        for i in range(n):
            work[i] = err[i]
        median = select_kth(work, (n_valid - 1) // 2)
        limit = max(settings.outlier_multiplier * median, settings.outlier_floor)
        n_lim = 0
        for i in range(n):
            n_lim += err[i] <= limit
        n_t = math.ceil(settings.trim_fraction * n_lim)
        if n_t:
            thr = select_kth(work, n_t - 1)
    n_keep = 0
    for i in range(n):
        pairs.keep[i] = err[i] <= thr
        n_keep += pairs.keep[i]
    return n_keep


@jit
def repeated(history: np.ndarray, it: int, pairs: Pairs) -> bool:
    """Record iteration ``it``'s correspondences (``j1``, the side, kept) in row ``it - 1``
    of ``history`` and say whether an earlier iteration had the same set: the steps would
    then repeat (a cycle), so the loop stops."""
    row = history[it - 1]
    n = row.shape[0]
    for i in range(n):
        row[i] = 4 * pairs.j1[i] + 2 * pairs.use_next[i] + pairs.keep[i]
    for past in range(it - 1):
        same = True
        for i in range(n):
            if history[past, i] != row[i]:
                same = False
                break
        if same:
            return True
    return False


@jit
def step_sums(points: FloatArray, q: FloatArray, pairs: Pairs) -> tuple[float, ...]:
    """The closed-form step's sums over the kept pairs: the upper triangle of ``M = Σ φ
    φᵀ`` row by row, then ``v = Σ φ b`` (:mod:`slamkit.scanmatch.plicp`'s docstring)."""
    m00 = m01 = m02 = m03 = m11 = m12 = m13 = m22 = m23 = m33 = 0.0
    vt0 = vt1 = vc0 = vc1 = 0.0
    for i in range(q.shape[0]):
        if not pairs.keep[i]:
            continue
        nx, ny = pairs.nrm[i, 0], pairs.nrm[i, 1]
        qx, qy = q[i, 0], q[i, 1]
        p2 = nx * qx + ny * qy
        p3 = ny * qx - nx * qy
        b = nx * points[pairs.j1[i], 0] + ny * points[pairs.j1[i], 1]
        m00 += nx * nx
        m01 += nx * ny
        m02 += nx * p2
        m03 += nx * p3
        m11 += ny * ny
        m12 += ny * p2
        m13 += ny * p3
        m22 += p2 * p2
        m23 += p2 * p3
        m33 += p3 * p3
        vt0 += nx * b
        vt1 += ny * b
        vc0 += p2 * b
        vc1 += p3 * b
    return (m00, m01, m02, m03, m11, m12, m13, m22, m23, m33, vt0, vt1, vc0, vc1)


@jit
def closed_form_step(
    points: FloatArray, q: FloatArray, pairs: Pairs
) -> tuple[bool, float, float, float]:
    """Censi's closed-form step over the kept pairs, operation for operation
    :func:`slamkit.scanmatch.plicp.point_to_line_step`: ``(ok, x, y, θ)``, ``ok`` false
    when the normals do not span the plane (``A`` singular)."""
    m00, m01, m02, m03, m11, m12, m13, m22, m23, m33, vt0, vt1, vc0, vc1 = step_sums(
        points, q, pairs
    )
    det_a = m00 * m11 - m01 * m01
    if not det_a > 1e-12 * (m00 + m11) ** 2:
        return False, 0.0, 0.0, 0.0
    i00, i01, i11 = m11 / det_a, -m01 / det_a, m00 / det_a
    k00, k01 = i00 * m02 + i01 * m12, i00 * m03 + i01 * m13
    k10, k11 = i01 * m02 + i11 * m12, i01 * m03 + i11 * m13
    s11 = m22 - (m02 * k00 + m12 * k10)
    s12 = m23 - (m02 * k01 + m12 * k11)
    s22 = m33 - (m03 * k01 + m13 * k11)
    h1 = vc0 - (k00 * vt0 + k10 * vt1)
    h2 = vc1 - (k01 * vt0 + k11 * vt1)
    lam = root_of_multiplier(s11, s12, s22, h1, h2)
    c0 = (s22 + lam) * h1 - s12 * h2
    c1 = -s12 * h1 + (s11 + lam) * h2
    if c0 == 0.0 and c1 == 0.0:
        c0 = 1.0
    theta = math.atan2(c1, c0)
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    r0 = vt0 - (m02 * cos_t + m03 * sin_t)
    r1 = vt1 - (m12 * cos_t + m13 * sin_t)
    return True, i00 * r0 + i01 * r1, i01 * r0 + i11 * r1, theta


@jit
def small_step(dx: float, dy: float, dth: float, settings: PlicpSettings) -> bool:
    """The stopping rule on the step ``(dx, dy, dθ)``: below both tolerances."""
    return (
        math.hypot(dx, dy) < settings.translation_tolerance
        and abs(dth) < settings.rotation_tolerance
    )


@jit
def line_covariance(
    points: FloatArray, q: FloatArray, pairs: Pairs, pose: FloatArray
) -> FloatArray:
    """The covariance at ``pose`` over the pairs with a segment (its ends ``j1`` and ``j1 ±
    1``), the kept ones in ``H``: :func:`~slamkit.scanmatch.kernel_covariance.
    point_to_line_cov` of them."""
    m = points.shape[0]
    n_valid = 0
    for i in range(q.shape[0]):
        n_valid += pairs.valid[i]
    cur = np.empty((n_valid, 2))
    end_a = np.empty((n_valid, 2))
    end_b = np.empty((n_valid, 2))
    index_a = np.empty(n_valid, dtype=np.int64)
    index_b = np.empty(n_valid, dtype=np.int64)
    kept = np.empty(n_valid, dtype=np.bool_)
    v = 0
    for i in range(q.shape[0]):
        if not pairs.valid[i]:
            continue
        ja = pairs.j1[i]
        jb = ja + 1 if pairs.use_next[i] else ja - 1
        cur[v, 0], cur[v, 1] = q[i, 0], q[i, 1]
        end_a[v, 0], end_a[v, 1] = points[ja, 0], points[ja, 1]
        end_b[v, 0], end_b[v, 1] = points[jb, 0], points[jb, 1]
        index_a[v], index_b[v], kept[v] = ja, jb, pairs.keep[i]
        v += 1
    return point_to_line_cov(cur, end_a, end_b, index_a, index_b, m, pose, kept)


@jit
def plicp_loop(
    points: FloatArray,
    segment_normals: FloatArray,
    joined: np.ndarray,
    has_normal: np.ndarray,
    normals: FloatArray,
    q: FloatArray,
    initial: FloatArray,
    settings_values: FloatArray,
) -> tuple[int, int, int, FloatArray, FloatArray, float]:
    """The loop of :func:`slamkit.scanmatch.plicp.plicp` after validation, and the covariance,
    compiled, on the reference's arrays (:class:`ReferenceArrays`) and the settings'
    numbers (:func:`settings_from_array`): from ``initial = (x, y, θ)``, each iteration
    :func:`correspond`, :func:`trim`, the degeneracy check at the start, :func:`repeated`,
    :func:`closed_form_step`, :func:`small_step`; then the check at the solution and
    :func:`line_covariance`. Returns ``(status, iterations, n_kept, pose (3,), cov (3, 3),
    eigenvalue)`` with ``status`` one of the codes of this module, ``n_kept`` the pairs kept
    at the last iteration and ``eigenvalue`` the smallest normalised eigenvalue behind a
    ``DEGENERATE_*`` status (else 0). ``pose`` (θ wrapped) and ``cov`` are the solution
    when ``status == CONVERGED`` (``cov`` is zero otherwise)."""
    ref = ReferenceArrays(points, segment_normals, joined, has_normal, normals)
    settings = settings_from_array(settings_values)
    n = q.shape[0]
    index = _bearing_index(ref.points)
    pairs = new_pairs(n, ref.points.shape[0])
    max_d2 = settings.max_distance * settings.max_distance
    history = np.empty((settings.max_iterations, n), dtype=np.int64)
    cov = np.zeros((3, 3))
    tx, ty, th = initial[0], initial[1], initial[2]
    n_keep = 0
    converged = False
    it = 0
    while it < settings.max_iterations:
        it += 1
        n_valid = correspond(ref, index, q, (tx, ty, th), max_d2, pairs)
        n_keep = trim(pairs, n_valid, settings)
        if n_keep < settings.min_correspondences:
            return TOO_FEW, it, n_keep, np.array([tx, ty, th]), cov, 0.0
        if it == 1:
            lam = _min_eigenvalue(q, ref.normals, ref.has_normal, pairs.j1, pairs.keep, th)
            if lam < 0.5 * settings.min_eigenvalue:
                return DEGENERATE_START, it, n_keep, np.array([tx, ty, th]), cov, lam
        if repeated(history, it, pairs):
            converged = True
            break
        ok, new_x, new_y, theta = closed_form_step(ref.points, q, pairs)
        if not ok:
            return DEGENERATE_STEP, it, n_keep, np.array([tx, ty, th]), cov, 0.0
        dth = ieee_remainder(theta - th, _TWO_PI)
        small = small_step(new_x - tx, new_y - ty, dth, settings)
        tx, ty, th = new_x, new_y, th + dth
        if small:
            converged = True
            break
    if not converged:
        return NO_CONVERGENCE, it, n_keep, np.array([tx, ty, th]), cov, 0.0
    th = ieee_remainder(th, _TWO_PI)
    pose = np.array([tx, ty, th])
    lam = _min_eigenvalue(q, ref.normals, ref.has_normal, pairs.j1, pairs.keep, th)
    if lam < settings.min_eigenvalue:
        return DEGENERATE_END, it, n_keep, pose, cov, lam
    return CONVERGED, it, n_keep, pose, line_covariance(ref.points, q, pairs, pose), 0.0
