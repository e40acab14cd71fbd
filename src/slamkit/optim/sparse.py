"""The fixed sparsity pattern of the normal equations and the sparse Cholesky back-ends.

The normal matrix ``H = Σ_k J_kᵀ J_k`` of a graph has one dense block per pair of variables
that share an edge. Its pattern does not change between iterations, so it is computed once
(:class:`NormalPattern`): every entry of every per-edge block product is given a *slot* in the
lower triangle of ``H`` stored column-major (CSC, rows sorted), and an iteration's values are
``np.bincount(slots, weights=block_products)``. Entries that touch a fixed variable, and the
strict upper triangle of diagonal blocks, go to one extra dummy slot that is dropped.

Back-ends (:func:`make_factorizer`) factor ``H + D`` for a diagonal ``D`` (the LM damping):

* ``"cholmod"``: CHOLMOD's Cholesky through ``cvxopt.cholmod`` (an optional
  dependency). The symbolic analysis (AMD fill-reducing ordering, elimination tree,
  supernodes) runs once; each iteration only refactors numerically.
* ``"superlu"``: SciPy's SuperLU in symmetric mode (minimum-degree ordering on ``H + Hᵀ``,
  no pivoting since ``H`` is positive definite); SuperLU has no separate symbolic step, so the
  ordering is recomputed inside each factorisation.
* ``"dense"``: LAPACK Cholesky of the dense matrix, for tests and tiny graphs.

``"auto"`` is CHOLMOD when ``cvxopt`` imports, SuperLU otherwise.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal, Protocol

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from slamkit.errors import ConfigError
from slamkit.optim.data import FloatArray, IntArray

__all__ = [
    "Factorizer",
    "LinearSolverName",
    "NormalPattern",
    "SingularSystem",
    "cholmod_available",
    "factor_spd",
    "make_factorizer",
]

LinearSolverName = Literal["auto", "cholmod", "superlu", "dense"]


class SingularSystem(Exception):
    """Internal: the factorisation met a zero or negative pivot.

    ``column`` is the column of ``H`` (in the problem's variable order, before the
    fill-reducing permutation) whose pivot failed, when the back-end says which: that column
    depends linearly on the columns eliminated before it.
    """

    def __init__(self, message: str, column: int | None = None) -> None:
        super().__init__(message)
        self.column = column


@dataclass(frozen=True)
class NormalPattern:
    """Lower-triangular CSC pattern of ``H`` (``n x n``) and the slot of every block entry.

    ``slots[k]`` is the position in ``data`` of the ``k``-th block-product entry (``nnz`` for
    a dropped entry); ``grad_slots`` likewise for the gradient (``n`` when dropped);
    ``diag`` the positions of the diagonal entries.
    """

    n: int
    indptr: IntArray
    indices: IntArray
    slots: IntArray
    grad_slots: IntArray
    diag: IntArray

    @property
    def nnz(self) -> int:
        return int(self.indices.shape[0])

    @classmethod
    def from_blocks(
        cls, sizes: IntArray, products: list[tuple[IntArray, IntArray, int, int, bool]]
    ) -> tuple[NormalPattern, list[IntArray]]:
        """Pattern of ``H`` for variables of ``sizes`` (columns in variable order) and the slots
        of the block products that :meth:`GraphProblem.linearize` emits.

        ``products[k] = (va, vb, da, db, diagonal)``: per edge, the variables (``-1`` = fixed)
        of the product ``A_vaᵀ A_vb`` (a diagonal block when ``diagonal``), emitted edge-last
        as a ``(da, db, E)`` array. Returns the pattern and one ``(size_a, size_b, E)`` slot
        array per product. Block-level bookkeeping first (one ``np.unique`` over block pairs),
        then the scalar entries by arithmetic: column ``c = off[v] + q`` of variable ``v``
        holds the diagonal block's rows ``q…size-1`` and then every lower block's rows.
        """
        sizes = np.asarray(sizes, dtype=np.int64)
        V = sizes.shape[0]
        off = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        n = int(off[-1])
        # Block pairs as keys min·V + max: every diagonal block, then the off-diagonal blocks
        # of the products (an entry with va == vb is the diagonal block of va).
        keys = [np.arange(V, dtype=np.int64) * (V + 1)]
        oks, pairs = [], []
        for va, vb, _, _, _ in products:
            ok = (va >= 0) & (vb >= 0)
            pair = ok & (va != vb)
            oks.append(ok)
            pairs.append(pair)
            keys.append(np.minimum(va, vb)[pair] * V + np.maximum(va, vb)[pair])
        every = np.concatenate(keys)
        # The distinct blocks (one sort), then each pair's block by binary search: cheaper
        # than np.unique with return_inverse.
        ordered = np.sort(every)
        distinct = np.ones(ordered.shape[0], dtype=bool)
        distinct[1:] = ordered[1:] != ordered[:-1]
        uniq = ordered[distinct]
        inverse = np.searchsorted(uniq, every[V:])
        bc, br = uniq // V, uniq % V  # block column (smaller var) and row
        is_diag = bc == br
        row_size = np.where(is_diag, 0, sizes[br])
        excl = np.concatenate([[0], np.cumsum(row_size)[:-1]])
        first = np.searchsorted(bc, np.arange(V))  # the diagonal block opens each column
        pre = excl - excl[first[bc]]  # rows of earlier off-diagonal blocks in the column
        offdiag_rows = np.bincount(bc, weights=row_size, minlength=V).astype(np.int64)
        var_of_col = np.repeat(np.arange(V), sizes)
        q_of_col = np.arange(n) - off[var_of_col]
        lengths = sizes[var_of_col] - q_of_col + offdiag_rows[var_of_col]
        indptr = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        # base[b, pc] + pr is the position of entry (pr, pc) of block b: in column
        # off[bc] + pc the diagonal block holds rows pc…size-1 first, then each lower block.
        pcs = np.arange(int(sizes.max()) if V else 1)
        colptr = indptr[np.minimum(off[bc][:, None] + pcs[None, :], n)]
        base = colptr - pcs[None, :]
        base = np.where(is_diag[:, None], base, base + sizes[bc][:, None] + pre[:, None])

        # Column c = off[v] + q of variable v lists the rows R_v[q:], with R_v the rows of v's
        # diagonal block and then of each lower block (blocks in key order, which is by
        # column and then by row, the diagonal block first).
        block_rows = sizes[br]
        starts = np.concatenate([[0], np.cumsum(block_rows)])  # of each block's rows in R
        rows = np.repeat(off[br] - starts[:-1], block_rows) + np.arange(int(starts[-1]))
        at_col = starts[first[var_of_col]] + q_of_col - indptr[:-1]
        indices = rows[np.repeat(at_col, lengths) + np.arange(int(indptr[-1]))]
        nnz = indices.shape[0]
        slots: list[IntArray] = []
        at = 0
        for (va, vb, da, db, diagonal), ok, pair in zip(products, oks, pairs, strict=True):
            if not va.shape[0]:
                slots.append(np.zeros((da, db, 0), dtype=np.int64))
                continue
            b = first[np.maximum(va, 0)]  # the diagonal block of va (right where va == vb)
            k = int(pair.sum())
            if k:
                b[pair] = inverse[at : at + k]
            at += k
            p = np.arange(da)[:, None, None]
            q = np.arange(db)[None, :, None]
            bt = base[b].T  # (max size, E): the column starts of each edge's block
            swap = (va < vb)[None, None, :]  # the row block is vb: entry (p, q) is (q, p)
            pos = bt[None, :db, :] + p
            if swap.any():
                pos = np.where(swap, bt[:da, None, :] + q, pos)
            valid = ok[None, None, :] & ~(diagonal & (p < q))
            slots.append(pos if valid.all() else np.where(valid, pos, nnz))
        diag = indptr[:-1].copy()  # the first entry of each column is its diagonal
        return cls(n, indptr, indices, np.zeros(0, np.int64), np.zeros(0, np.int64), diag), slots

    def values(self, weights: FloatArray) -> FloatArray:
        """Lower-triangle values of ``H`` from the concatenated block products."""
        out = np.bincount(self.slots, weights=weights, minlength=self.nnz + 1)
        return out[: self.nnz].astype(np.float64, copy=False)

    def gradient(self, weights: FloatArray) -> FloatArray:
        """``g = Jᵀ r`` from the concatenated per-edge gradient blocks."""
        out = np.bincount(self.grad_slots, weights=weights, minlength=self.n + 1)
        return out[: self.n].astype(np.float64, copy=False)

    def with_slots(self, slots: IntArray, grad_slots: IntArray) -> NormalPattern:
        return NormalPattern(self.n, self.indptr, self.indices, slots, grad_slots, self.diag)

    def lower_matrix(self, data: FloatArray) -> scipy.sparse.csc_matrix:
        return scipy.sparse.csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))

    def full_matrix(self, data: FloatArray) -> scipy.sparse.csc_matrix:
        """The symmetric ``H`` (both triangles) as a SciPy CSC matrix."""
        L = self.lower_matrix(data)
        return (L + L.T - scipy.sparse.diags(data[self.diag])).tocsc()

    def matvec(self, data: FloatArray, x: FloatArray) -> FloatArray:
        """``H x`` using the lower triangle only: ``L x + Lᵀ x - diag ⊙ x``."""
        L, Lt = self._lower_and_transpose
        # The same SciPy kernels as on freshly built matrices, without re-checking the index
        # arrays on every call (the step strategies call this once per trial step).
        L.data = Lt.data = np.asarray(data, dtype=np.float64)
        return np.asarray(L @ x + Lt @ x - data[self.diag] * x)

    @cached_property
    def _lower_and_transpose(self) -> tuple[scipy.sparse.csc_matrix, scipy.sparse.csr_matrix]:
        """``L`` (CSC) and ``Lᵀ`` (CSR) over this pattern, built once; :meth:`matvec` sets
        their values (they keep those of its last call)."""
        L = self.lower_matrix(np.zeros(self.nnz))
        return L, L.T


class Factorizer(Protocol):
    """Factor ``H`` (lower-triangle values in a fixed pattern) and solve with the factor."""

    name: str

    def factor(self, data: FloatArray) -> None:
        """Factor ``H``; raise :class:`SingularSystem` when it is not positive definite."""
        ...

    def solve(self, b: FloatArray) -> FloatArray:
        """``H⁻¹ b`` for ``b`` of shape ``(n,)`` or ``(n, k)``."""
        ...


def cholmod_available() -> bool:
    """Whether ``cvxopt`` (which bundles CHOLMOD) can be imported."""
    try:
        importlib.import_module("cvxopt.cholmod")
    except ImportError:
        return False
    return True


SIMPLICIAL_MAX_NNZ = 50_000
"""CHOLMOD factors ``H`` with at most this many stored (lower-triangle) entries by the
simplicial method: faster than supernodal on the small 2D graphs (intel's 33k entries, MIT,
CSAIL), slower on larger ones (manhattan's 70k, city10000, the 3D graphs); the
measurements are in ``docs/estimators/optim.md``."""


class _CholmodFactorizer:
    """CHOLMOD through cvxopt: one symbolic analysis, a numeric refactorisation per call."""

    name = "cholmod"

    def __init__(self, pattern: NormalPattern) -> None:
        self._cvx: Any = importlib.import_module("cvxopt")
        self._chol: Any = importlib.import_module("cvxopt.cholmod")
        n = pattern.n
        cols = np.repeat(np.arange(n), np.diff(pattern.indptr))
        # cvxopt stores CCS with sorted rows, exactly our pattern order, so ``A.V`` can be
        # overwritten in place on every iteration (checked below once).
        ones = self._cvx.matrix(np.ones(pattern.nnz))
        self._A = self._cvx.spmatrix(
            ones,
            self._cvx.matrix(np.ascontiguousarray(pattern.indices, dtype=np.int64)),
            self._cvx.matrix(np.ascontiguousarray(cols, dtype=np.int64)),
            (n, n),
        )
        ccs = self._A.CCS
        if not (
            np.array_equal(np.asarray(ccs[0]).ravel(), pattern.indptr)
            and np.array_equal(np.asarray(ccs[1]).ravel(), pattern.indices)
        ):
            raise AssertionError("cvxopt changed the CCS pattern")  # internal invariant
        self._symbolic: Any = None
        self._simplicial = False
        self._diag = pattern.diag
        self._perm: IntArray | None = None

    def factor(self, data: FloatArray) -> None:
        self._A.V = self._cvx.matrix(data)
        if self._symbolic is None:
            # Simplicial below SIMPLICIAL_MAX_NNZ (CHOLMOD's own choice is supernodal there,
            # slower for these small factors); the numeric phase follows the analysis's kind.
            options = self._chol.options
            before = options.get("supernodal", 2)
            self._simplicial = self._A.V.size[0] <= SIMPLICIAL_MAX_NNZ
            options["supernodal"] = 0 if self._simplicial else before
            try:
                self._symbolic = self._chol.symbolic(self._A, uplo="L")
            finally:
                options["supernodal"] = before
        minor: int | None = None
        try:
            self._chol.numeric(self._A, self._symbolic)
        except ArithmeticError as exc:
            minor = exc.args[0] if exc.args and isinstance(exc.args[0], int) else -1
        if minor is None and self._simplicial:
            # The simplicial factor is L D Lᵀ, which goes on past a negative pivot: H is
            # positive definite iff every d_k > 0, read as D⁻¹ 1 (sys=6 solves D x = b).
            inv_d = self._cvx.matrix(np.ones(self._A.size[0]))
            self._chol.solve(self._symbolic, inv_d, sys=6)
            bad = ~(np.array(inv_d).ravel() > 0)  # 1/d: NaN or ±inf fail as well
            bad |= ~np.isfinite(np.array(inv_d).ravel())
            if bad.any():
                minor = int(np.flatnonzero(bad)[0])
        if minor is not None:
            column = None if minor < 0 else int(self._permutation()[minor])
            where = f"pivot {minor} of the permuted matrix" if minor >= 0 else "a pivot"
            raise SingularSystem(f"not positive definite (CHOLMOD {where})", column)

    def _permutation(self) -> IntArray:
        """CHOLMOD's fill-reducing permutation ``p`` (row ``k`` of ``P H Pᵀ`` is row ``p[k]``
        of ``H``), read once by factoring the identity in the same pattern and applying ``P``
        to ``0 … n-1``; only needed to name the column of a failed pivot."""
        if self._perm is None:
            eye = np.zeros(self._A.V.size[0])
            eye[self._diag] = 1.0
            self._A.V = self._cvx.matrix(eye)
            self._chol.numeric(self._A, self._symbolic)
            B = self._cvx.matrix(np.arange(float(self._A.size[0])))
            self._chol.solve(self._symbolic, B, sys=7)  # B ← P B
            self._perm = np.rint(np.array(B).ravel()).astype(np.int64)
        return self._perm

    def solve(self, b: FloatArray) -> FloatArray:
        B = self._cvx.matrix(np.asarray(b, dtype=np.float64))
        self._chol.solve(self._symbolic, B)
        return np.array(B).reshape(b.shape)


class _SuperLUFactorizer:
    """SciPy SuperLU in symmetric mode on the full matrix (no pivoting: ``H`` is SPD)."""

    name = "superlu"

    def __init__(self, pattern: NormalPattern) -> None:
        self._pattern = pattern
        full = pattern.full_matrix(np.arange(1.0, pattern.nnz + 1.0))
        full.sort_indices()
        # Gather map from the lower-triangle values to the full pattern's values: the fake
        # values 1..nnz identify each stored entry.
        self._gather = np.rint(full.data).astype(np.int64) - 1
        self._indices = full.indices
        self._indptr = full.indptr
        self._lu: Any = None

    def factor(self, data: FloatArray) -> None:
        n = self._pattern.n
        full = scipy.sparse.csc_matrix((data[self._gather], self._indices, self._indptr), (n, n))
        try:
            self._lu = scipy.sparse.linalg.splu(
                full,
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        except RuntimeError as exc:
            raise SingularSystem(f"singular ({exc})") from exc
        pivots = self._lu.U.diagonal()
        if not np.all(pivots > 0):
            # Pr H Pc = L U: column k of U is column perm_c[k] of H.
            k = int(np.flatnonzero(~(pivots > 0))[0])
            raise SingularSystem(
                "not positive definite (a non-positive pivot in SuperLU)",
                int(self._lu.perm_c[k]),
            )

    def solve(self, b: FloatArray) -> FloatArray:
        return np.asarray(self._lu.solve(np.asarray(b, dtype=np.float64)))


class _DenseFactorizer:
    """LAPACK Cholesky of the dense ``H`` (tests and tiny graphs only)."""

    name = "dense"

    def __init__(self, pattern: NormalPattern) -> None:
        self._pattern = pattern
        self._cho: Any = None

    def factor(self, data: FloatArray) -> None:
        H = self._pattern.full_matrix(data).toarray()
        try:
            self._cho = scipy.linalg.cho_factor(H, lower=True)
        except np.linalg.LinAlgError as exc:
            # LAPACK: "k-th leading minor of the array is not positive definite" (1-based).
            head = str(exc).split("-", 1)[0]
            column = int(head) - 1 if head.isdigit() else None
            raise SingularSystem(f"not positive definite ({exc})", column) from exc

    def solve(self, b: FloatArray) -> FloatArray:
        return np.asarray(scipy.linalg.cho_solve(self._cho, b))


def make_factorizer(name: LinearSolverName, pattern: NormalPattern) -> Factorizer:
    """The back-end ``name`` for ``pattern`` (``"auto"``: CHOLMOD if available, else SuperLU)."""
    if name == "auto":
        name = "cholmod" if cholmod_available() else "superlu"
    if name == "cholmod":
        if not cholmod_available():
            raise ConfigError(
                "linear_solver 'cholmod' needs the optional package cvxopt (pip install cvxopt)"
            )
        return _CholmodFactorizer(pattern)
    if name == "superlu":
        return _SuperLUFactorizer(pattern)
    if name == "dense":
        return _DenseFactorizer(pattern)
    raise ConfigError(f"linear_solver: unknown back-end {name!r}")


def factor_spd(A: scipy.sparse.spmatrix, name: LinearSolverName = "auto") -> Factorizer:
    """The factorisation of a one-off sparse symmetric ``A`` (both triangles given).

    Raises :class:`SingularSystem` when ``A`` is not (numerically) positive definite, so a
    successful call is also a definiteness test (the optimality certificate uses it so).
    """
    L = scipy.sparse.tril(A, format="csc")
    L.sort_indices()
    n = L.shape[0]
    cols = np.repeat(np.arange(n), np.diff(L.indptr))
    pattern = NormalPattern(
        n,
        L.indptr.astype(np.int64),
        L.indices.astype(np.int64),
        np.zeros(0, dtype=np.int64),
        np.zeros(0, dtype=np.int64),
        np.flatnonzero(L.indices == cols).astype(np.int64),
    )
    fac = make_factorizer(name, pattern)
    fac.factor(np.asarray(L.data, dtype=np.float64))
    return fac


def solve_spd(
    A: scipy.sparse.spmatrix, B: FloatArray, name: LinearSolverName = "auto"
) -> FloatArray:
    """``A⁻¹ B`` for a one-off sparse symmetric positive definite ``A`` (both triangles given).

    Used by the linear initialisations; the same back-ends as the solvers.
    """
    return factor_spd(A, name).solve(B)
