"""The hot loops of a plain 2D pose graph compiled with numba: one pass over the
relative-pose edges gives χ², ``H`` (in the pattern's slots) and ``g``; one pass retracts
every pose; and the incremental optimiser's window step, whitening and odometry chaining.

At the size of intel (1728 poses, 2512 edges) the NumPy path of
:meth:`~slamkit.optim.graph.GraphProblem.linearize` spends its time in the fixed cost of some
sixty array operations per linearisation (kernels, whitening ``einsum``, the block products,
``bincount``), each on arrays of a few thousand numbers, and a window step of
:class:`~slamkit.optim.incremental.IncrementalOptimizer` in some forty on arrays of a few
dozen; the compiled passes do the same arithmetic in one loop per stage (the measurements
are in ``docs/estimators/optim.md``).

**Where it applies** (decided once, when the problem or the optimiser is built:
:func:`compiled_se2` returns a :class:`CompiledSe2` or ``None``, :func:`compiled_window` a
:class:`CompiledWindow` or ``None``, and the owner keeps it): a 2D graph of relative-pose
edges only (one ``se2`` edge set, no priors, no landmarks, no ``EQUIV`` aliases) with g2o's
objective, and numba installed (``pip install slamkit[fast]``); a window of at most
``window.DENSE_MAX`` unknowns without prior edges. Robust kernels, SE-Sync's objective and
every other graph or window take the NumPy path.

**The same numbers.** Per edge the formulas of
:func:`~slamkit.optim.factors.se2_between_error` (with ``d = R_iᵀ (t_j - t_i)``,
``e_t = R_zᵀ (d - t_z)``, ``e_θ = wrap(θ_j - θ_i - θ_z)`` and its Jacobians), whitened as
``r = U e``, ``A = U ∂e/∂δ_i``, ``B = U ∂e/∂δ_j``; each entry of ``H`` sums its block-product
terms in the order ``np.bincount`` does on the NumPy path (every edge's ``AᵀA``, then
``AᵀB``, then ``BᵀB``, entry by entry, edges in order), and the retraction is
:func:`~slamkit.optim.factors.retract_poses` (``X · Exp(δ)``, θ wrapped). The tests
(``tests/optim/test_optim_compiled2d.py``) hold ``H`` and ``g`` bit for bit, χ² to 1e-13,
the retraction to 1e-14 (``libm``'s sine against NumPy's) and whole solves, batch and
incremental, to 1e-10 in the poses.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from slamkit.backend import SEAM, jit
from slamkit.geometry.angles import wrap_angle_float
from slamkit.optim.data import FloatArray, IntArray
from slamkit.optim.linearization import Linearization
from slamkit.optim.sparse import NormalPattern

__all__ = ["CompiledSe2", "CompiledWindow", "compiled_se2", "compiled_window"]


class GraphProblem(Protocol):
    """What the compiled pass reads of :class:`slamkit.optim.graph.GraphProblem` (a
    protocol, so that this module, which the problem imports, does not import it back)."""

    @property
    def dim(self) -> int: ...
    @property
    def objective(self) -> str: ...
    @property
    def pose_ids(self) -> IntArray: ...
    @property
    def landmark_ids(self) -> IntArray: ...
    @property
    def alias(self) -> IntArray: ...
    @property
    def pose_var(self) -> IntArray: ...
    @property
    def n_free_poses(self) -> int: ...
    @property
    def blocks(self) -> Sequence[Any]: ...
    @property
    def pattern(self) -> NormalPattern: ...


_jit = jit
"""slamkit's ``numba.njit(cache=True)`` (:func:`slamkit.backend.jit`; a plain function
without numba)."""


_SMALL_ANGLE = 1e-3  # below it the SE(2) exponential takes its Taylor series (as geometry)


_wrap = jit(wrap_angle_float)
"""``a`` wrapped to ``[-π, π)``, unchanged when already there, compiled."""


@_jit
def _edge_terms(
    poses: FloatArray,
    a: IntArray,
    b: IntArray,
    z: FloatArray,
    U: FloatArray,
    jacobians: bool,
    r: FloatArray,
    A: FloatArray,
    B: FloatArray,
) -> float:
    """Fill ``r (E, 3)``, ``A``, ``B (E, 3, 3)`` (whitened residual and Jacobians; ``U`` is
    edge-last ``(3, 3, E)``) and return ``χ² = Σ ‖r‖²``; ``jacobians=False``: ``r`` only."""
    chi2 = 0.0
    e = np.empty(3)
    Ji = np.zeros((3, 3))
    Jj = np.zeros((3, 3))
    Ji[2, 2] = -1.0
    Jj[2, 2] = 1.0
    for k in range(a.shape[0]):
        i, j = a[k], b[k]
        ci, si = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        cz, sz = math.cos(z[k, 2]), math.sin(z[k, 2])
        dx0, dy0 = poses[j, 0] - poses[i, 0], poses[j, 1] - poses[i, 1]
        dx = ci * dx0 + si * dy0  # d = R_iᵀ (t_j - t_i)
        dy = -si * dx0 + ci * dy0
        ux, uy = dx - z[k, 0], dy - z[k, 1]
        phi = poses[j, 2] - poses[i, 2] - z[k, 2]
        e[0] = cz * ux + sz * uy  # R_zᵀ (d - t_z)
        e[1] = -sz * ux + cz * uy
        e[2] = _wrap(phi)
        s = 0.0
        for p in range(3):
            rp = U[p, 0, k] * e[0] + U[p, 1, k] * e[1] + U[p, 2, k] * e[2]
            r[k, p] = rp
            s += rp * rp
        chi2 += s
        if not jacobians:
            continue
        Ji[0, 0] = -cz
        Ji[0, 1] = -sz
        Ji[1, 0] = sz
        Ji[1, 1] = -cz
        Ji[0, 2] = cz * dy - sz * dx  # -R_zᵀ S d with S d = (-d_y, d_x)
        Ji[1, 2] = -sz * dy - cz * dx
        cp, sp = math.cos(phi), math.sin(phi)
        Jj[0, 0] = cp
        Jj[0, 1] = -sp
        Jj[1, 0] = sp
        Jj[1, 1] = cp
        for p in range(3):
            for q in range(3):
                A[k, p, q] = U[p, 0, k] * Ji[0, q] + U[p, 1, k] * Ji[1, q] + U[p, 2, k] * Ji[2, q]
                B[k, p, q] = U[p, 0, k] * Jj[0, q] + U[p, 1, k] * Jj[1, q] + U[p, 2, k] * Jj[2, q]
    return chi2


@_jit
def _normal_equations(
    A: FloatArray,
    B: FloatArray,
    r: FloatArray,
    slots: IntArray,
    grad_slots: IntArray,
    H: FloatArray,
    g: FloatArray,
) -> None:
    """Add the block products to ``H`` and ``g`` at the pattern's slots (dropped entries
    carry ``len(H)`` / ``len(g)``), in ``np.bincount``'s order over the NumPy path's list:
    ``AᵀA``, ``AᵀB``, ``BᵀB`` as ``(3, 3, E)``, then ``Aᵀr``, ``Bᵀr`` as ``(3, E)``."""
    E = A.shape[0]
    nnz, n = H.shape[0], g.shape[0]
    at = 0
    for prod in range(3):
        X = A if prod < 2 else B
        Y = A if prod == 0 else B
        for p in range(3):
            for q in range(3):
                for k in range(E):
                    s = slots[at]
                    at += 1
                    if s < nnz:
                        H[s] += (
                            X[k, 0, p] * Y[k, 0, q]
                            + X[k, 1, p] * Y[k, 1, q]
                            + (X[k, 2, p] * Y[k, 2, q])
                        )
    at = 0
    for half in range(2):
        X = A if half == 0 else B
        for p in range(3):
            for k in range(E):
                s = grad_slots[at]
                at += 1
                if s < n:
                    g[s] += X[k, 0, p] * r[k, 0] + X[k, 1, p] * r[k, 1] + X[k, 2, p] * r[k, 2]


@_jit
def _retract(poses: FloatArray, pose_var: IntArray, delta: FloatArray, out: FloatArray) -> None:
    """``out = X · Exp(δ)`` per free pose (``pose_var >= 0``; its step at ``3 var``), fixed
    poses copied; θ wrapped."""
    for i in range(poses.shape[0]):
        v = pose_var[i]
        if v < 0:
            out[i, 0], out[i, 1], out[i, 2] = poses[i, 0], poses[i, 1], poses[i, 2]
            continue
        vx, vy, th = delta[3 * v], delta[3 * v + 1], delta[3 * v + 2]
        t2 = th * th
        if abs(th) < _SMALL_ANGLE:  # sin θ/θ and (1 - cos θ)/θ are 0/0 at 0: their series
            sa = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
            cb = th / 2.0 - th * t2 / 24.0 + th * t2 * t2 / 720.0
        else:
            sa = math.sin(th) / th
            cb = 2.0 * math.sin(th / 2) ** 2 / th
        tx, ty = sa * vx - cb * vy, cb * vx + sa * vy  # t = V(θ) v
        dth = _wrap(math.atan2(math.sin(th), math.cos(th)))
        c, s = math.cos(poses[i, 2]), math.sin(poses[i, 2])
        out[i, 0] = poses[i, 0] + c * tx - s * ty
        out[i, 1] = poses[i, 1] + s * tx + c * ty
        out[i, 2] = _wrap(poses[i, 2] + dth)


@_jit
def _pose_pattern(V: int, va: IntArray, vb: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """:meth:`NormalPattern.from_blocks <slamkit.optim.sparse.NormalPattern.from_blocks>`
    for ``V`` free poses of 3 columns and relative-pose edges between variables ``va``,
    ``vb`` (-1: fixed): ``indptr``, ``indices`` and the slots of the products ``AᵀA``,
    ``AᵀB``, ``BᵀB`` raveled ``(3, 3, E)`` one after the other (``nnz`` when dropped).
    Column ``3 v + q`` holds rows ``3 v + q … 3 v + 2`` of the diagonal block, then the three
    rows of each later neighbour ``u > v`` in increasing order."""
    E = va.shape[0]
    count = np.zeros(V + 1, dtype=np.int64)
    for k in range(E):
        if va[k] >= 0 and vb[k] >= 0:
            count[min(va[k], vb[k]) + 1] += 1
    start = np.cumsum(count)
    nb = np.empty(start[V], dtype=np.int64)
    fill = start[:V].copy()
    for k in range(E):
        if va[k] >= 0 and vb[k] >= 0:
            lo = min(va[k], vb[k])
            nb[fill[lo]] = max(va[k], vb[k])
            fill[lo] += 1
    # Sort each variable's later neighbours and drop repeats (parallel edges).
    deg = np.zeros(V, dtype=np.int64)
    for v in range(V):
        seg = np.sort(nb[start[v] : start[v + 1]])
        m = 0
        for t in range(seg.shape[0]):
            if m == 0 or seg[t] != nb[start[v] + m - 1]:
                nb[start[v] + m] = seg[t]
                m += 1
        deg[v] = m
    n = 3 * V
    indptr = np.zeros(n + 1, dtype=np.int64)
    for v in range(V):
        for q in range(3):
            indptr[3 * v + q + 1] = indptr[3 * v + q] + (3 - q) + 3 * deg[v]
    nnz = indptr[n]
    indices = np.empty(nnz, dtype=np.int64)
    for v in range(V):
        for q in range(3):
            at = indptr[3 * v + q]
            for r in range(q, 3):
                indices[at] = 3 * v + r
                at += 1
            for t in range(deg[v]):
                u = nb[start[v] + t]
                for r in range(3):
                    indices[at] = 3 * u + r
                    at += 1
    slots = np.empty(27 * E, dtype=np.int64)
    for prod in range(3):
        for p in range(3):
            for q in range(3):
                base = prod * 9 * E + (3 * p + q) * E
                for k in range(E):
                    a_, b_ = va[k], vb[k]
                    pos = nnz
                    if prod != 1:  # a diagonal block: entry (row p, column q), p >= q kept
                        v = a_ if prod == 0 else b_
                        if v >= 0 and p >= q:
                            pos = indptr[3 * v + q] + (p - q)
                    elif a_ >= 0 and b_ >= 0:
                        # H[3 a + p, 3 b + q]: stored in the column of the smaller variable.
                        col, row, pc, pr = (b_, a_, q, p) if a_ > b_ else (a_, b_, p, q)
                        t = 0
                        while nb[start[col] + t] != row:
                            t += 1
                        pos = indptr[3 * col + pc] + (3 - pc) + 3 * t + pr
                    slots[base + k] = pos
    return indptr, indices, slots


class CompiledSe2:
    """The compiled pass over one problem's relative-pose edges (module docstring); build
    with :func:`compiled_se2`."""

    def __init__(self, problem: GraphProblem) -> None:
        blk = problem.blocks[0]
        assert blk.b is not None and blk.sqrt_info is not None
        self._a = np.ascontiguousarray(blk.a, dtype=np.int64)
        self._b = np.ascontiguousarray(blk.b, dtype=np.int64)
        self._z = np.ascontiguousarray(blk.measurement, dtype=np.float64)
        self._U = np.ascontiguousarray(blk.sqrt_info, dtype=np.float64)
        self._pose_var = np.ascontiguousarray(problem.pose_var, dtype=np.int64)
        self._problem = problem
        E = self._a.shape[0]
        self._r = np.empty((E, 3))
        self._A = np.empty((E, 3, 3))
        self._B = np.empty((E, 3, 3))

    def pattern_and_slots(self) -> tuple[NormalPattern, list[IntArray]]:
        """The pattern of ``H`` and the slots of the products (``AᵀA``, ``AᵀB``, ``BᵀB``),
        as :meth:`NormalPattern.from_blocks <slamkit.optim.sparse.NormalPattern.from_blocks>`
        gives them (the slots as one flat array)."""
        blk = self._problem.blocks[0]
        assert blk.b_var is not None
        V = self._problem.n_free_poses
        va = np.ascontiguousarray(blk.a_var, dtype=np.int64)
        vb = np.ascontiguousarray(blk.b_var, dtype=np.int64)
        indptr, indices, slots = _pose_pattern(V, va, vb)
        empty = np.zeros(0, dtype=np.int64)
        return NormalPattern(3 * V, indptr, indices, empty, empty, indptr[:-1].copy()), [slots]

    def chi2(self, poses: FloatArray) -> float:
        """``Σ ‖U e‖²`` at ``poses`` ``(N, 3)``."""
        x = np.ascontiguousarray(poses, dtype=np.float64)
        return float(
            _edge_terms(x, self._a, self._b, self._z, self._U, False, self._r, self._A, self._B)
        )

    def system(self, poses: FloatArray) -> tuple[float, FloatArray, FloatArray]:
        """``(χ², H, g)`` at ``poses``: ``H`` as lower-triangle values in the problem's
        pattern, ``g = Jᵀ r``."""
        x = np.ascontiguousarray(poses, dtype=np.float64)
        chi2 = _edge_terms(x, self._a, self._b, self._z, self._U, True, self._r, self._A, self._B)
        pattern = self._problem.pattern
        H = np.zeros(pattern.nnz)
        g = np.zeros(pattern.n)
        _normal_equations(self._A, self._B, self._r, pattern.slots, pattern.grad_slots, H, g)
        return float(chi2), H, g

    def linearize(self, poses: FloatArray, *, jacobians: bool, deferred: bool) -> Linearization:
        """:meth:`GraphProblem.linearize <slamkit.optim.graph.GraphProblem.linearize>`
        without a robust kernel (cost = χ²): ``jacobians=False`` the cost only;
        ``deferred=True`` the cost now and ``H``, ``g`` on first read (from a copy of
        ``poses``)."""
        t0 = time.perf_counter()
        if not jacobians or deferred:
            c = self.chi2(poses)
            at = np.array(poses, dtype=np.float64)
            later = (lambda: self.system(at)[1:]) if jacobians else None
            return Linearization(c, c, None, None, time.perf_counter() - t0, pending=later)
        c, H, g = self.system(poses)
        return Linearization(c, c, H, g, time.perf_counter() - t0)

    def retract(self, poses: FloatArray, delta: FloatArray) -> FloatArray:
        """``X ⊕ δ`` for every free pose (fixed poses unchanged)."""
        out = np.empty_like(poses, dtype=np.float64)
        _retract(
            np.ascontiguousarray(poses, dtype=np.float64),
            self._pose_var,
            np.ascontiguousarray(delta, dtype=np.float64),
            out,
        )
        return out


def compiled_se2(problem: GraphProblem) -> CompiledSe2 | None:
    """The compiled pass for ``problem`` when it applies (module docstring), else ``None``
    (always ``None`` on the NumPy backend, :mod:`slamkit.backend`)."""
    return _se2_pass(problem)


def _se2_pass_compiled(problem: GraphProblem) -> CompiledSe2 | None:
    """The compiled pass when the graph is one it covers (module docstring)."""
    if problem.dim != 2 or problem.objective != "g2o":
        return None
    if problem.landmark_ids.shape[0] or len(problem.blocks) != 1:
        return None
    if (problem.alias != np.arange(problem.pose_ids.shape[0])).any():
        return None
    blk = problem.blocks[0]
    if blk.kind != "se2" or blk.b is None or blk.sqrt_info is None or blk.batch_first:
        return None
    return CompiledSe2(problem)


def _numpy_path(problem: GraphProblem) -> CompiledSe2 | None:
    """No compiled pass: the problem's own NumPy linearisation runs."""
    return None


@_jit
def _window_delta(
    X: FloatArray,
    a: IntArray,
    b: IntArray,
    z: FloatArray,
    U: FloatArray,
    cols: IntArray,
    H: FloatArray,
    g: FloatArray,
) -> bool:
    """The Gauss-Newton step ``δ = -H⁻¹ g`` of a window (:mod:`slamkit.optim.window`) over
    relative-pose edges ``a → b`` (``U`` batch-first ``(E, 3, 3)``, ``cols (E, 6)`` the window
    columns of both poses, -1 when held fixed) into ``g``; ``H`` ``(n, n)`` is scratch (its
    lower triangle ends as the Cholesky factor). False when ``H`` is not positive definite."""
    n = g.shape[0]
    H[:, :] = 0.0
    g[:] = 0.0
    e = np.empty(3)
    J = np.zeros((3, 6))  # ∂e/∂(δ_a, δ_b)
    W = np.empty((3, 6))  # U J
    r = np.empty(3)
    J[2, 2] = -1.0
    J[2, 5] = 1.0
    for k in range(a.shape[0]):
        i, j = a[k], b[k]
        ci, si = math.cos(X[i, 2]), math.sin(X[i, 2])
        cz, sz = math.cos(z[k, 2]), math.sin(z[k, 2])
        dx0, dy0 = X[j, 0] - X[i, 0], X[j, 1] - X[i, 1]
        dx = ci * dx0 + si * dy0
        dy = -si * dx0 + ci * dy0
        ux, uy = dx - z[k, 0], dy - z[k, 1]
        phi = X[j, 2] - X[i, 2] - z[k, 2]
        e[0] = cz * ux + sz * uy
        e[1] = -sz * ux + cz * uy
        e[2] = _wrap(phi)
        J[0, 0] = -cz
        J[0, 1] = -sz
        J[1, 0] = sz
        J[1, 1] = -cz
        J[0, 2] = cz * dy - sz * dx
        J[1, 2] = -sz * dy - cz * dx
        cp, sp = math.cos(phi), math.sin(phi)
        J[0, 3] = cp
        J[0, 4] = -sp
        J[1, 3] = sp
        J[1, 4] = cp
        for p in range(3):
            r[p] = U[k, p, 0] * e[0] + U[k, p, 1] * e[1] + U[k, p, 2] * e[2]
            for q in range(6):
                W[p, q] = U[k, p, 0] * J[0, q] + U[k, p, 1] * J[1, q] + U[k, p, 2] * J[2, q]
        for p in range(6):
            cp_ = cols[k, p]
            if cp_ < 0:
                continue
            g[cp_] += W[0, p] * r[0] + W[1, p] * r[1] + W[2, p] * r[2]
            for q in range(6):
                cq = cols[k, q]
                if cq >= 0:
                    H[cp_, cq] += W[0, p] * W[0, q] + W[1, p] * W[1, q] + W[2, p] * W[2, q]
    # Cholesky H = L Lᵀ in the lower triangle, then L y = -g and Lᵀ δ = y.
    for c in range(n):
        d = H[c, c]
        for q in range(c):
            d -= H[c, q] * H[c, q]
        if not d > 0.0:
            return False
        d = math.sqrt(d)
        H[c, c] = d
        for row in range(c + 1, n):
            v = H[row, c]
            for q in range(c):
                v -= H[row, q] * H[c, q]
            H[row, c] = v / d
    for row in range(n):
        v = -g[row]
        for q in range(row):
            v -= H[row, q] * g[q]
        g[row] = v / H[row, row]
    for row in range(n - 1, -1, -1):
        v = g[row]
        for q in range(row + 1, n):
            v -= H[q, row] * g[q]
        g[row] = v / H[row, row]
    return True


@_jit
def _whitening(info: FloatArray, U: FloatArray) -> bool:
    """``U = Lᵀ`` with ``L Lᵀ = Ω`` (``L`` lower, as ``np.linalg.cholesky``) for each
    ``(3, 3)`` information matrix; False when one is not finite, not symmetric (``max |Ω - Ωᵀ| >
    1e-9 max |Ω|``, the NumPy check) or not positive definite."""
    for k in range(info.shape[0]):
        big = 0.0
        skew = 0.0
        for p in range(3):
            for q in range(3):
                v = info[k, p, q]
                if not math.isfinite(v):
                    return False
                big = max(big, abs(v))
                skew = max(skew, abs(v - info[k, q, p]))
        if skew > 1e-9 * big:
            return False
        d0 = info[k, 0, 0]
        if not d0 > 0.0:
            return False
        l00 = math.sqrt(d0)
        l10 = info[k, 1, 0] / l00
        l20 = info[k, 2, 0] / l00
        d1 = info[k, 1, 1] - l10 * l10
        if not d1 > 0.0:
            return False
        l11 = math.sqrt(d1)
        l21 = (info[k, 2, 1] - l20 * l10) / l11
        d2 = info[k, 2, 2] - (l20 * l20 + l21 * l21)
        if not d2 > 0.0:
            return False
        U[k, 0, 0], U[k, 0, 1], U[k, 0, 2] = l00, l10, l20
        U[k, 1, 0], U[k, 1, 1], U[k, 1, 2] = 0.0, l11, l21
        U[k, 2, 0], U[k, 2, 1], U[k, 2, 2] = 0.0, 0.0, math.sqrt(d2)
    return True


@_jit
def _chain(x: FloatArray, z: FloatArray, reverse: bool, out: FloatArray) -> None:
    """``out = x ⊕ z`` (``reverse``: ``x ⊕ z⁻¹``), θ wrapped, as ``pose2.compose``."""
    zx, zy, zt = z[0], z[1], z[2]
    if reverse:  # z⁻¹ = (-R_zᵀ t_z, -θ_z)
        cz, sz = math.cos(zt), math.sin(zt)
        zx, zy, zt = -cz * z[0] - sz * z[1], sz * z[0] - cz * z[1], _wrap(-zt)
    c, s = math.cos(x[2]), math.sin(x[2])
    out[0] = x[0] + c * zx - s * zy
    out[1] = x[1] + s * zx + c * zy
    out[2] = _wrap(x[2] + zt)


class CompiledWindow:
    """The window step of :class:`~slamkit.optim.incremental.IncrementalOptimizer` over
    relative-pose edges in one compiled pass: normal equations, dense Cholesky and
    retraction (build with :func:`compiled_window`)."""

    def step(
        self,
        X: FloatArray,
        rows: IntArray,
        a: IntArray,
        b: IntArray,
        z: FloatArray,
        U: FloatArray,
        cols: IntArray,
    ) -> FloatArray | None:
        """``δ`` ``(3 |rows|,)`` of the window poses ``rows`` (``None`` when ``H`` is not
        positive definite); see :func:`~slamkit.optim.window.window_normal_equations` for
        ``cols``."""
        n = 3 * rows.shape[0]
        H = np.empty((n, n))
        delta = np.empty(n)
        ok = _window_delta(X, a, b, z, U, cols, H, delta)
        return delta if ok else None

    def whitening(self, information: FloatArray) -> FloatArray | None:
        """``U`` ``(E, 3, 3)`` with ``Uᵀ U = Ω`` per edge, or ``None`` when an information
        matrix fails the checks of :func:`~slamkit.optim.updates.check_update_edges` (which
        then names the edge)."""
        info = np.ascontiguousarray(information, dtype=np.float64)
        U = np.empty_like(info)
        return U if _whitening(info, U) else None

    def chain(self, x: FloatArray, z: FloatArray, reverse: bool) -> FloatArray:
        """``x ⊕ z`` (``reverse``: ``x ⊕ z⁻¹``) for one pose."""
        out = np.empty(3)
        _chain(np.asarray(x, dtype=np.float64), np.asarray(z, dtype=np.float64), reverse, out)
        return out

    def retract(self, X: FloatArray, delta: FloatArray) -> FloatArray:
        """``X ⊕ δ`` row by row (``δ`` of length ``3 len(X)``)."""
        out = np.empty_like(X)
        _retract(X, np.arange(X.shape[0], dtype=np.int64), delta, out)
        return out


def compiled_window() -> CompiledWindow | None:
    """The compiled window step, or ``None`` on the NumPy backend (without numba;
    :mod:`slamkit.backend`)."""
    return _window_step()


def _no_window() -> CompiledWindow | None:
    """No compiled window step: the optimiser's NumPy step runs."""
    return None


_se2_pass = SEAM.pair(compiled=_se2_pass_compiled, oracle=_numpy_path)
_window_step = SEAM.pair(compiled=CompiledWindow, oracle=_no_window)
