"""The normal equations' bookkeeping: the sparsity pattern and slots of
:meth:`NormalPattern.from_blocks` against their definition, the cached ``H x``, the deferred
forming of ``H`` and ``g``, the shortcut of the connectivity check, and the opt-out of the
objective values. The speed-ups behind them must not change a number: the checks are
exact."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse

from slamkit.errors import GeometryError
from slamkit.geometry import pose2
from slamkit.optim import EdgeSet, GraphData, GraphProblem, OptimizerConfig, RobustConfig, optimize
from slamkit.optim.sparse import NormalPattern, SingularSystem, cholmod_available, factor_spd


def _products(rng: np.random.Generator, sizes: np.ndarray) -> list:
    """Random binary blocks as the problem emits them: ``AᵀA``, ``AᵀB``, ``BᵀB`` per edge set,
    variables of one size per end, some ends fixed (``-1``), no edge from a variable to
    itself."""
    products = []
    for _ in range(int(rng.integers(1, 5))):
        E = int(rng.integers(0, 30))
        sa, sb = rng.choice(sizes), rng.choice(sizes)
        va = rng.choice(np.flatnonzero(sizes == sa), size=E)
        vb = rng.choice(np.flatnonzero(sizes == sb), size=E)
        va[rng.random(E) < 0.1] = -1
        vb[(rng.random(E) < 0.1) | (va == vb)] = -1
        products += [
            (va, va, int(sa), int(sa), True),
            (va, vb, int(sa), int(sb), False),
            (vb, vb, int(sb), int(sb), True),
        ]
    return products


@pytest.mark.parametrize("seed", range(40))
def test_pattern_slots_place_every_entry_at_its_row_and_column(seed: int) -> None:
    """Each kept entry ``(p, q)`` of a product ``A_vaᵀ A_vb`` lands at row ``off[va] + p``,
    column ``off[vb] + q`` (mirrored into the lower triangle); entries of fixed variables and
    the upper triangle of diagonal blocks go to the dropped slot ``nnz``; the pattern is
    lower-triangular CSC with sorted, distinct rows and holds no entry no product emits."""
    rng = np.random.default_rng(seed)
    sizes = rng.choice([1, 2, 3, 6] if seed % 2 else [2, 3], size=int(rng.integers(1, 25)))
    off = np.concatenate([[0], np.cumsum(sizes)])
    products = _products(rng, sizes)
    pattern, slots = NormalPattern.from_blocks(sizes, products)
    col_of = np.repeat(np.arange(pattern.n), np.diff(pattern.indptr))
    assert (pattern.indices >= col_of).all()
    for c in range(pattern.n):
        rows = pattern.indices[pattern.indptr[c] : pattern.indptr[c + 1]]
        assert rows[0] == c and (np.diff(rows) > 0).all()
    used = np.zeros(pattern.nnz, dtype=bool)
    used[pattern.diag] = True  # every variable owns its diagonal block
    for (va, vb, da, db, diagonal), slot in zip(products, slots, strict=True):
        assert slot.shape == (da, db, va.shape[0]) and slot.dtype == np.int64
        for p, q, e in np.ndindex(slot.shape):
            if va[e] < 0 or vb[e] < 0 or (diagonal and p < q):
                assert slot[p, q, e] == pattern.nnz
                continue
            r, c = off[va[e]] + p, off[vb[e]] + q
            r, c = max(r, c), min(r, c)
            assert (pattern.indices[slot[p, q, e]], col_of[slot[p, q, e]]) == (r, c)
            used[slot[p, q, e]] = True
    # Off-diagonal blocks are stored whole, so only their own entries need a product.
    for v in range(sizes.shape[0]):
        cols = np.arange(off[v], off[v + 1])
        block = np.isin(col_of, cols) & np.isin(pattern.indices, cols)
        used[block] = True
    assert used.all()


def test_pattern_of_fixed_variables_only() -> None:
    """No free variable: an empty pattern and every emitted entry dropped."""
    va = np.array([-1, -1])
    pattern, slots = NormalPattern.from_blocks(np.zeros(0, np.int64), [])
    assert pattern.n == 0 and pattern.nnz == 0 and slots == []
    pattern, slots = NormalPattern.from_blocks(
        np.array([3]), [(va, va, 3, 3, True), (np.zeros(0, np.int64),) * 2 + (3, 3, True)]
    )
    assert pattern.nnz == 6 and (slots[0] == 6).all() and slots[1].shape == (3, 3, 0)


def test_matvec_equals_the_full_matrix_product() -> None:
    """``H x`` from the lower triangle, on repeated calls with new values (the matrices over
    the pattern are built once and take each call's values)."""
    rng = np.random.default_rng(3)
    sizes = np.array([3, 3, 2, 3])
    products = _products(rng, sizes)
    pattern, _ = NormalPattern.from_blocks(sizes, products)
    for _ in range(3):
        data = rng.normal(size=pattern.nnz)
        x = rng.normal(size=pattern.n)
        expected = pattern.full_matrix(data) @ x
        np.testing.assert_allclose(pattern.matvec(data, x), expected, rtol=1e-13, atol=1e-13)


def _chain(n: int = 30, closures: tuple[tuple[int, int], ...] = ((0, 15), (7, 29))) -> GraphData:
    rng = np.random.default_rng(8)
    truth = np.cumsum(rng.normal(size=(n, 3)) * [1.0, 0.5, 0.2], axis=0)
    pairs = [(k, k + 1) for k in range(n - 1)] + list(closures)
    i = np.array([p[0] for p in pairs], dtype=np.int64)
    j = np.array([p[1] for p in pairs], dtype=np.int64)
    z = pose2.between(truth[i], truth[j]) + rng.normal(size=(i.size, 3)) * 0.05
    info = np.tile(np.diag([50.0, 40.0, 300.0]), (i.size, 1, 1))
    start = truth + rng.normal(size=truth.shape) * 0.1
    return GraphData(
        dim=2,
        pose_ids=np.arange(n, dtype=np.int64),
        poses=start,
        edges=(EdgeSet("se2", i, j, z, info, np.zeros(i.size, dtype=np.int64)),),
    )


@pytest.mark.parametrize("kernel", ["none", "cauchy"])
def test_deferred_linearization_forms_the_same_normal_equations(kernel: str) -> None:
    """``deferred=True`` returns the cost at once and forms ``H`` and ``g`` on first read,
    bit-identical to forming them at once; its clock reports the time it took."""
    data = _chain()
    problem = GraphProblem.from_data(data)
    cfg = OptimizerConfig(robust=RobustConfig(kernel=kernel))  # type: ignore[arg-type]
    eager = problem.linearize(data.poses, np.zeros((0, 2)), cfg.kernel)
    lazy = problem.linearize(data.poses, np.zeros((0, 2)), cfg.kernel, deferred=True)
    spent: list[float] = []
    lazy.on_formed = spent.append
    assert (lazy.cost, lazy.chi2) == (eager.cost, eager.chi2)
    assert eager.H is not None and eager.g is not None
    assert lazy.g is not None and lazy.H is not None
    assert np.array_equal(lazy.g, eager.g) and np.array_equal(lazy.H, eager.H)
    assert len(spent) == 1 and lazy.H is lazy.H  # formed once
    cost_only = problem.linearize(data.poses, np.zeros((0, 2)), cfg.kernel, jacobians=False)
    assert cost_only.cost == eager.cost and cost_only.H is None and cost_only.g is None


def test_objectives_can_be_skipped_without_changing_the_solution() -> None:
    """``objectives=False`` leaves g2o's χ² and SE-Sync's F unset (NaN) and every other
    number of the result as it was."""
    data = _chain()
    full = optimize(data)
    bare = optimize(data, objectives=False)
    assert np.array_equal(full.poses, bare.poses)
    assert (full.cost, full.initial_cost, full.iterations) == (
        bare.cost,
        bare.initial_cost,
        bare.iterations,
    )
    assert np.isfinite(full.g2o_chi2) and np.isfinite(full.sesync_objective)
    assert np.isnan(bare.g2o_chi2) and np.isnan(bare.sesync_objective)


def test_connectivity_shortcut_and_full_search_agree() -> None:
    """A chain (each pose tied to an earlier one) passes without a graph search; a connected
    graph that is not a chain in row order passes through the search; a piece without a
    fixed pose still raises."""
    GraphProblem.from_data(_chain())
    data = _chain(6, closures=())
    es = data.edges[0]
    order = np.array([2, 0, 1, 3, 4, 5], dtype=np.int64)  # row 0 is pose 2: no earlier tie
    shuffled = GraphData(dim=2, pose_ids=order, poses=data.poses, edges=data.edges)
    GraphProblem.from_data(shuffled)
    keep = np.arange(len(es)) != 2  # drop 2 → 3: poses 3..5 float free
    cut = EdgeSet("se2", es.i[keep], es.j[keep], es.measurement[keep], es.information[keep],
                  es.lines[keep])  # fmt: skip
    broken = GraphData(dim=2, pose_ids=data.pose_ids, poses=data.poses, edges=(cut,))
    with pytest.raises(GeometryError, match="disconnected"):
        GraphProblem.from_data(broken)


@pytest.mark.skipif(not cholmod_available(), reason="cvxopt (CHOLMOD) is not installed")
def test_simplicial_cholmod_is_a_definiteness_test() -> None:
    """Small systems are factored by CHOLMOD's simplicial L D Lᵀ, which does not stop at a
    negative pivot by itself: the factoriser reads D and refuses an indefinite matrix, names
    the column whose pivot failed, and solves a definite one as dense Cholesky does."""
    rng = np.random.default_rng(7)
    M = rng.normal(size=(12, 12))
    spd = M @ M.T + 12 * np.eye(12)
    fac = factor_spd(scipy.sparse.csc_matrix(spd), "cholmod")
    b = rng.normal(size=12)
    np.testing.assert_allclose(fac.solve(b), np.linalg.solve(spd, b), rtol=1e-12)
    indefinite = spd.copy()
    indefinite[5, 5] = -50.0  # a negative diagonal entry: not positive definite
    with pytest.raises(SingularSystem) as err:
        factor_spd(scipy.sparse.csc_matrix(indefinite), "cholmod")
    assert err.value.column is not None and 0 <= err.value.column < 12
