"""The optimiser's view of a :class:`~slamkit.optim.data.GraphData`: validated edges, variable
indexing, the gauge, whitening, and the vectorised linearisation ``(cost, H, g)``.

Variables are the poses (rows of ``pose_ids``) and, in 2D, landmarks (rows of
``landmark_ids``). A free SE(2) pose owns 3 columns of the normal matrix, a free SE(3) pose 6
(``δv, δω``), a landmark 2; fixed poses own none. 3D poses are held internally as
``(t, R row-major)`` rows of 12 (:meth:`GraphProblem.to_internal`). Each edge set is one
:class:`_Block`: the rows of the variables its edges touch, their variable indices, the
whitening ``U`` with ``Uᵀ U = Ω`` (upper Cholesky factor of the information), and the slots
of its block products in the fixed sparsity pattern
(:class:`~slamkit.optim.sparse.NormalPattern`), all computed once.

**Equivalences.** ``EQUIV a b`` (TORO) makes ``b`` the same pose as ``a``: both rows take one
value (the smaller row's), and edges between them are dropped.

**Gauge.** A pose graph's cost is invariant to moving the whole graph, so something must fix
it: the ids in ``GraphData.fixed_ids``, or ``se2_prior``/``se3_prior`` edges. When the file
has neither, the first pose (the first of ``pose_ids``; the smallest id when the file has no
vertices) is held fixed at its initial value (``gauge="anchor_first"``, the default);
``gauge="none"`` never anchors, so such a graph raises. Every
connected component of the graph must contain a fixed pose or a prior; otherwise
:class:`~slamkit.errors.GeometryError` names the variables of the first component that has
none.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from slamkit.errors import CovarianceError, GeometryError, InputError, NonFiniteError, ShapeError
from slamkit.optim import factors, factors3d, gps
from slamkit.optim.compiled2d import CompiledSe2, compiled_se2
from slamkit.optim.data import EdgeSet, FloatArray, GraphData, IntArray
from slamkit.optim.linearization import Linearization, WeightedBlock, normal_equations
from slamkit.optim.robust import RobustKernel, robust_rho_and_weight
from slamkit.optim.sparse import NormalPattern

__all__ = ["GaugeMode", "GraphProblem", "Linearization", "ObjectiveName", "edge_location"]

ObjectiveName = Literal["g2o", "sesync"]
GaugeMode = Literal["anchor_first", "none"]

# measurement width, information size, second variable ("pose", "landmark" or None)
_KINDS: dict[str, tuple[int, int, str | None]] = {
    "se2": (3, 3, "pose"),
    "se2_prior": (3, 3, None),
    "se3": (7, 6, "pose"),
    "se3_prior": (7, 6, None),
    "se2_xy": (2, 2, "landmark"),
    "range_bearing": (2, 2, "landmark"),
    "range": (1, 1, "landmark"),
    "bearing": (1, 1, "landmark"),
    "gps": (2, 2, "landmark"),  # the lever arm is a point of the landmark block (optim.gps)
}
_KINDS_3D = ["se3", "se3_prior"]
_PRIOR_KINDS = ("se2_prior", "se3_prior", "gps")  # "gps": absolute, fixes the gauge


def edge_location(data: GraphData, edges: EdgeSet, k: int) -> str:
    """``"file:line: kind edge i → j"`` (or ``"kind edge #k i → j"`` for in-memory graphs)."""
    line = int(edges.lines[k]) if edges.lines.shape[0] > k else 0
    j = int(edges.j[k])
    what = f"{edges.kind} edge {int(edges.i[k])}" + (f" → {j}" if j >= 0 else "")
    if line > 0:
        return f"{data.source or '<graph>'}:{line}: {what}"
    return f"{what} (#{k} of its set)"


def lookup_rows(ids: IntArray, query: IntArray) -> tuple[IntArray, IntArray]:
    """Rows of ``query`` in ``ids`` and a mask of the ones found."""
    order = np.argsort(ids, kind="stable")
    sorted_ids = ids[order]
    pos = np.searchsorted(sorted_ids, query)
    pos = np.minimum(pos, max(sorted_ids.shape[0] - 1, 0))
    found = (
        sorted_ids[pos] == query if sorted_ids.shape[0] else np.zeros(query.shape[0], dtype=bool)
    )
    rows = order[pos] if sorted_ids.shape[0] else np.zeros(query.shape[0], dtype=np.int64)
    return rows.astype(np.int64), found


def _check_unique(ids: IntArray, what: str) -> None:
    """``InputError`` naming the first id that appears more than once."""
    uniq, counts = np.unique(ids, return_counts=True)
    if (counts > 1).any():
        k = int(np.flatnonzero(counts > 1)[0])
        raise InputError(
            f"{what}_ids: {what} {int(uniq[k])} appears {int(counts[k])} times "
            f"(rows {', '.join(str(int(r)) for r in np.flatnonzero(ids == uniq[k]))})"
        )


def _check_edge_set(data: GraphData, es: EdgeSet) -> None:
    kinds = _KINDS_3D if data.dim == 3 else [k for k in _KINDS if k not in _KINDS_3D]
    if es.kind not in kinds:
        raise InputError(
            f"edge kind {es.kind!r} is not supported in a {data.dim}D graph; "
            f"supported: {', '.join(kinds)}"
        )
    m, r, _ = _KINDS[es.kind]
    n = len(es)
    for name, arr, shape in (
        ("i", es.i, (n,)),
        ("j", es.j, (n,)),
        ("measurement", es.measurement, (n, m)),
        ("information", es.information, (n, r, r)),
    ):
        if arr.shape != shape:
            raise ShapeError(f"{es.kind} edges: {name} has shape {arr.shape}, expected {shape}")
    # A finite sum has no NaN or infinity among its terms, so only a non-finite sum (or an
    # overflow) needs the search for the edge; the same for exactly symmetric matrices,
    # which pass the tolerance test below. Both shortcuts skip reductions over tiny axes.
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow just takes the search
        sums = np.array([es.measurement.sum(), es.information.sum()])
    if not np.isfinite(sums).all():
        bad = ~np.isfinite(es.measurement).all(axis=1) | ~np.isfinite(es.information).all(
            axis=(1, 2)
        )
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise NonFiniteError(f"{edge_location(data, es, k)}: NaN or infinity in the edge")
    info = es.information
    if np.array_equal(info, np.swapaxes(info, 1, 2)):
        return
    scale = np.maximum(np.abs(info).max(axis=(1, 2)), 1e-300)
    asym = np.abs(info - np.swapaxes(info, 1, 2)).max(axis=(1, 2)) > 1e-9 * scale
    if asym.any():
        k = int(np.flatnonzero(asym)[0])
        raise CovarianceError(f"{edge_location(data, es, k)}: information matrix not symmetric")


def _sqrt_information(data: GraphData, es: EdgeSet) -> FloatArray:
    """``U`` (E, r, r) upper triangular with ``Uᵀ U = Ω``, so ``‖U e‖² = eᵀ Ω e``."""
    try:
        L = np.linalg.cholesky(es.information)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(es.information)
        k = int(np.argmin(eig.min(axis=1)))
        raise CovarianceError(
            f"{edge_location(data, es, k)}: information matrix not positive definite "
            f"(smallest eigenvalue {float(eig[k].min()):.3g}); a file read with "
            "repair_information='clamp' has such matrices repaired, or repair them with "
            "slamkit.optim.repair.clamp_information"
        ) from None
    return np.ascontiguousarray(np.swapaxes(L, 1, 2))


@dataclass(frozen=True)
class _Block:
    """One edge set ready for vectorised linearisation."""

    kind: str
    edges: EdgeSet
    measurement: FloatArray  # (E, m) in the internal pose format (3D: (t, R row-major))
    a: IntArray  # (E,) pose rows
    b: IntArray | None  # (E,) rows of the second variable (pose or landmark), None for unary
    b_is_landmark: bool
    a_var: IntArray  # (E,) variable index of a (free poses, then landmarks), -1 when fixed
    b_var: IntArray | None
    sqrt_info: FloatArray | None  # U with UᵀU = Ω: (m, m, E) edge-last, (E, m, m) batch-first
    row_weights: FloatArray | None  # per-row weights (SE-Sync residual) instead of U
    da: int
    db: int
    m: int
    batch_first: bool  # 3D: kernels, U and products batch-first (stacked 6x6 matmuls)


class GraphProblem:
    """A validated 2D or 3D graph with its variables indexed and its sparse pattern
    precomputed.

    Build with :meth:`from_data`; evaluate with :meth:`linearize`; move with :meth:`retract`.
    """

    def __init__(
        self,
        data: GraphData,
        pose_ids: IntArray,
        landmark_ids: IntArray,
        blocks: list[_Block],
        fixed: np.ndarray,
        alias: IntArray,
        objective: ObjectiveName,
        anchored_first: bool,
    ) -> None:
        self.data = data
        self.pose_ids = pose_ids
        self.landmark_ids = landmark_ids
        self.blocks = blocks
        self.fixed = fixed  # (N,) bool
        self.alias = alias  # (N,) row whose value this row takes (itself unless EQUIV-merged)
        self.objective = objective
        self.anchored_first = anchored_first
        free = (~fixed) & (alias == np.arange(pose_ids.shape[0]))
        self.dim = data.dim
        self.pose_dof = 3 if data.dim == 2 else 6  # tangent size of a pose
        # Variable indices: free poses in row order, then landmarks; column = dof · var
        # (poses), dof · n_free_poses + 2 (var - n_free_poses) (landmarks).
        self.pose_var = np.where(free, np.cumsum(free) - 1, -1).astype(np.int64)
        self.n_free_poses = int(free.sum())
        self.landmark_var = self.n_free_poses + np.arange(landmark_ids.shape[0], dtype=np.int64)
        self.n = self.pose_dof * self.n_free_poses + 2 * landmark_ids.shape[0]
        self._pattern: NormalPattern | None = None
        self._other_blocks: list[_Block] | None = None  # the blocks of the other objective
        self.compiled: CompiledSe2 | None = None  # the compiled pass, when it applies

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_data(
        cls,
        data: GraphData,
        *,
        objective: ObjectiveName = "g2o",
        gauge: GaugeMode = "anchor_first",
        compiled: bool = True,
    ) -> GraphProblem:
        """Validate ``data`` and index its variables (see the module docstring for the gauge).
        ``compiled=False`` keeps the NumPy path where :mod:`~slamkit.optim.compiled2d` applies.

        Raises :class:`~slamkit.errors.InputError` subclasses naming the edge (file and line
        when known) for unknown edge kinds, wrong shapes, NaN, non-symmetric or non-positive
        definite information matrices, self-loops and ids without a vertex; and
        :class:`~slamkit.errors.GeometryError` when the gauge is not fixed or the graph falls
        apart into pieces.
        """
        if data.dim not in (2, 3):
            raise InputError(f"dim: expected 2 or 3, got {data.dim!r}")
        if objective not in ("g2o", "sesync"):
            raise InputError(f"objective: expected 'g2o' or 'sesync', got {objective!r}")
        for es in data.edges:
            _check_edge_set(data, es)
        pose_ids = cls._pose_ids(data)
        landmark_ids = cls._landmark_ids(data)
        alias = cls._aliases(data, pose_ids)
        blocks_raw: list[tuple[EdgeSet, IntArray, IntArray | None, bool]] = []
        for es in data.edges:
            _, _, second = _KINDS[es.kind]
            a, found = lookup_rows(pose_ids, es.i)
            if not found.all():
                k = int(np.flatnonzero(~found)[0])
                raise InputError(f"{edge_location(data, es, k)}: pose {int(es.i[k])} has no vertex")
            a = alias[a]
            b: IntArray | None = None
            if second == "pose":
                b, found = lookup_rows(pose_ids, es.j)
                if not found.all():
                    k = int(np.flatnonzero(~found)[0])
                    raise InputError(
                        f"{edge_location(data, es, k)}: pose {int(es.j[k])} has no vertex"
                    )
                same_id = es.i == es.j
                if same_id.any():
                    k = int(np.flatnonzero(same_id)[0])
                    raise InputError(f"{edge_location(data, es, k)}: edge from a pose to itself")
                b = alias[b]
                merged = a == b  # both ends made one pose by EQUIV lines: the edge is moot
                if merged.any():
                    keep = ~merged
                    es = EdgeSet(
                        es.kind,
                        es.i[keep],
                        es.j[keep],
                        es.measurement[keep],
                        es.information[keep],
                        es.lines[keep],
                    )
                    a, b = a[keep], b[keep]
            elif second == "landmark":
                b, found = lookup_rows(landmark_ids, es.j)
                if not found.all():
                    k = int(np.flatnonzero(~found)[0])
                    raise InputError(
                        f"{edge_location(data, es, k)}: landmark {int(es.j[k])} has no vertex"
                    )
            blocks_raw.append((es, a, b, second == "landmark"))
        n_poses = pose_ids.shape[0]
        fixed = np.zeros(n_poses, dtype=bool)
        if data.fixed_ids.shape[0]:
            rows, found = lookup_rows(pose_ids, data.fixed_ids)
            if not found.all():
                bad = int(data.fixed_ids[np.flatnonzero(~found)[0]])
                raise InputError(f"fixed pose {bad} has no vertex")
            fixed[alias[rows]] = True
        if gauge not in ("anchor_first", "none"):
            raise InputError(f"gauge: expected 'anchor_first' or 'none', got {gauge!r}")
        has_prior = any(es.kind in _PRIOR_KINDS and len(es) for es in data.edges)
        anchored_first = False
        if not fixed.any() and not has_prior and n_poses and gauge == "anchor_first":
            fixed[alias[0]] = True
            anchored_first = True
        # With gauge="none" and neither a fixed pose nor a prior, this raises naming the poses.
        cls._check_connected(data, pose_ids, landmark_ids, alias, fixed, blocks_raw)
        problem = cls(data, pose_ids, landmark_ids, [], fixed, alias, objective, anchored_first)
        problem.blocks = [problem._make_block(data, *raw) for raw in blocks_raw]
        problem.compiled = compiled_se2(problem) if compiled else None
        return problem

    @staticmethod
    def _pose_ids(data: GraphData) -> IntArray:
        if data.poses.shape[0]:
            ids = np.asarray(data.pose_ids, dtype=np.int64)
            width = 3 if data.dim == 2 else 7
            if data.poses.shape != (ids.shape[0], width):
                raise ShapeError(
                    f"poses: expected shape ({ids.shape[0]}, {width}), got {data.poses.shape}"
                )
            _check_unique(ids, "pose")
            if not np.isfinite(data.poses).all():
                k = int(np.flatnonzero(~np.isfinite(data.poses).all(axis=1))[0])
                raise NonFiniteError(f"pose {int(ids[k])}: NaN or infinity in its vertex")
            return ids
        refs = [es.i for es in data.edges] + [
            es.j for es in data.edges if _KINDS[es.kind][2] == "pose"
        ]
        if data.pose_ids.shape[0]:
            refs.append(np.asarray(data.pose_ids, dtype=np.int64))
        if not refs:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate(refs)).astype(np.int64)

    @staticmethod
    def _landmark_ids(data: GraphData) -> IntArray:
        if data.landmarks.shape[0]:
            ids = np.asarray(data.landmark_ids, dtype=np.int64)
            if data.landmarks.shape != (ids.shape[0], 2):
                raise ShapeError(
                    f"landmarks: expected shape ({ids.shape[0]}, 2), got {data.landmarks.shape}"
                )
            _check_unique(ids, "landmark")
            if not np.isfinite(data.landmarks).all():
                k = int(np.flatnonzero(~np.isfinite(data.landmarks).all(axis=1))[0])
                raise NonFiniteError(f"landmark {int(ids[k])}: NaN or infinity in its vertex")
            return ids
        refs = [es.j for es in data.edges if _KINDS[es.kind][2] == "landmark"]
        if not refs:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate(refs)).astype(np.int64)

    @staticmethod
    def _aliases(data: GraphData, pose_ids: IntArray) -> IntArray:
        """Row each pose row stands for: ``EQUIV a b`` makes ``b`` an alias of ``a``."""
        alias = np.arange(pose_ids.shape[0], dtype=np.int64)
        eq = np.asarray(data.equivalences, dtype=np.int64).reshape(-1, 2)
        if not eq.shape[0]:
            return alias
        ra, fa = lookup_rows(pose_ids, eq[:, 0])
        rb, fb = lookup_rows(pose_ids, eq[:, 1])
        if not (fa.all() and fb.all()):
            k = int(np.flatnonzero(~(fa & fb))[0])
            raise InputError(f"EQUIV {eq[k, 0]} {eq[k, 1]}: a pose has no vertex")
        # Union-find over the (few) equivalences; the smaller row represents the class.
        parent = alias.copy()

        def find(x: int) -> int:
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = int(parent[x])
            return x

        for x, y in zip(ra.tolist(), rb.tolist(), strict=True):
            px, py = find(x), find(y)
            if px != py:
                parent[max(px, py)] = min(px, py)
        return np.array([find(x) for x in range(alias.shape[0])], dtype=np.int64)

    @staticmethod
    def _check_connected(
        data: GraphData,
        pose_ids: IntArray,
        landmark_ids: IntArray,
        alias: IntArray,
        fixed: np.ndarray,
        blocks_raw: list[tuple[EdgeSet, IntArray, IntArray | None, bool]],
    ) -> None:
        n_p, n_l = pose_ids.shape[0], landmark_ids.shape[0]
        n = n_p + n_l
        if n == 0:
            raise InputError("the graph has no variables")
        src, dst = [alias], [np.arange(n_p)]  # aliases join their representative
        anchored = fixed.copy()
        for es, a, b, b_lm in blocks_raw:
            if b is None or es.kind == "gps":
                anchored[a] = True  # a prior (or a GPS fix) fixes the gauge of its component
            if b is None:
                continue
            src.append(a)
            dst.append(b + n_p if b_lm else b)
        if n_p and anchored[0] and _reaches_first_row(n_p, n_l, alias, blocks_raw):
            return
        s, d = np.concatenate(src), np.concatenate(dst)
        adj = scipy.sparse.coo_matrix((np.ones(s.shape[0]), (s, d)), shape=(n, n))
        n_comp, label = scipy.sparse.csgraph.connected_components(adj, directed=False)
        comp_anchored = np.zeros(n_comp, dtype=bool)
        comp_anchored[label[:n_p][anchored]] = True
        if comp_anchored.all():
            return
        bad = int(np.flatnonzero(~comp_anchored)[0])
        members = np.flatnonzero(label == bad)
        names = [
            f"pose {int(pose_ids[m])}" if m < n_p else f"landmark {int(landmark_ids[m - n_p])}"
            for m in members[:8]
        ]
        more = f" and {members.shape[0] - 8} more" if members.shape[0] > 8 else ""
        if n_comp == 1:
            raise GeometryError(
                f"the gauge is not fixed: the graph has no fixed pose and no prior, so "
                f"{', '.join(names)}{more} are only determined up to a rigid motion; add a "
                "prior or fix a pose (or use gauge='anchor_first')"
            )
        raise GeometryError(
            f"the graph is disconnected: {n_comp} pieces; {', '.join(names)}{more} are not "
            "connected to a fixed pose or a prior, so their position is not determined"
        )

    def _make_block(
        self, data: GraphData, es: EdgeSet, a: IntArray, b: IntArray | None, b_lm: bool
    ) -> _Block:
        m = _KINDS[es.kind][1]
        sqrt_info: FloatArray | None = None
        row_weights: FloatArray | None = None
        measurement = es.measurement
        if self.dim == 3:
            measurement = factors3d.poses_to_internal(es.measurement)
        if es.kind in ("se2", "se3") and self.objective == "sesync":
            m = 4 if es.kind == "se2" else 12
            weights = (
                sesync_row_weights(es.information)
                if es.kind == "se2"
                else factors3d.sesync_row_weights_3d(es.information)
            )
            if not (weights > 0).all():
                k = int(np.flatnonzero(~(weights > 0).all(axis=1))[0])
                raise CovarianceError(
                    f"{edge_location(data, es, k)}: SE-Sync weights κ, τ must be positive"
                )
            row_weights = np.ascontiguousarray(weights if self.dim == 3 else weights.T)
        elif self.dim == 3:
            sqrt_info = _sqrt_information(data, es)
        else:
            sqrt_info = np.ascontiguousarray(np.moveaxis(_sqrt_information(data, es), 0, -1))
        a_var = self.pose_var[a]
        b_var: IntArray | None = None
        db = 0
        if b is not None:
            b_var = self.landmark_var[b] if b_lm else self.pose_var[b]
            db = 2 if b_lm else self.pose_dof
        return _Block(
            es.kind,
            es,
            measurement,
            a,
            b,
            b_lm,
            a_var,
            b_var,
            sqrt_info,
            row_weights,
            self.pose_dof,
            db,
            m,
            self.dim == 3,
        )

    # ------------------------------------------------------------------ pose formats
    def to_internal(self, poses: FloatArray) -> FloatArray:
        """File-format poses (2D ``(N, 3)``; 3D ``(N, 7)`` ``(t, qw, qx, qy, qz)``) to the
        optimiser's rows (2D unchanged; 3D ``(N, 12)`` ``(t, R row-major)``)."""
        return poses if self.dim == 2 else factors3d.poses_to_internal(poses)

    def to_external(self, poses: FloatArray) -> FloatArray:
        """Inverse of :meth:`to_internal` (3D quaternions with ``w ≥ 0``)."""
        return poses if self.dim == 2 else factors3d.poses_to_external(poses)

    # ------------------------------------------------------------------ pattern
    @property
    def pattern(self) -> NormalPattern:
        """Lower-triangular CSC pattern of ``H`` and the slot of every emitted entry (cached).

        :meth:`linearize` emits, per block, ``H_aa``, then (binary edges) ``H_ab`` and
        ``H_bb``, each edge-last ``(d_a, d_b, E)``; and the gradient blocks ``g_a``, ``g_b``
        ``(d, E)``. ``slots`` follows that order.
        """
        if self._pattern is None:
            n_p = self.n_free_poses
            sizes = np.concatenate(
                [
                    np.full(n_p, self.pose_dof, np.int64),
                    np.full(self.landmark_ids.shape[0], 2, np.int64),
                ]
            )
            products: list[tuple[IntArray, IntArray, int, int, bool]] = []
            grads: list[IntArray] = []
            offsets = np.concatenate([[0], np.cumsum(sizes)])
            for blk in self.blocks:
                va, vb = blk.a_var, blk.b_var
                products.append((va, va, blk.da, blk.da, True))
                if vb is not None:
                    products.append((va, vb, blk.da, blk.db, False))
                    products.append((vb, vb, blk.db, blk.db, True))
                for v, d in ((va, blk.da), (vb, blk.db)):
                    if v is None:
                        continue
                    g = offsets[np.maximum(v, 0)][None, :] + np.arange(d)[:, None]
                    grads.append(np.where(v[None, :] >= 0, g, self.n).ravel())
            empty = np.zeros(0, dtype=np.int64)
            made = None if self.compiled is None else self.compiled.pattern_and_slots()
            pattern, slots = made or NormalPattern.from_blocks(sizes, products)  # the same
            self._pattern = pattern.with_slots(
                np.concatenate([s.ravel() for s in slots]) if slots else empty,
                np.concatenate(grads).astype(np.int64) if grads else empty,
            )
        return self._pattern

    # ------------------------------------------------------------------ evaluation
    def block_residuals(
        self, blk: _Block, poses: FloatArray, landmarks: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """Whitened residual ``U e`` and Jacobians ``U ∂e/∂δ``: edge-last ``(m, E)``,
        ``(m, d, E)`` in 2D, batch-first ``(E, m)``, ``(E, m, d)`` in 3D (``blk.batch_first``).

        The 2D kernels fill contiguous per-entry rows of length ``E`` (one vector operation
        per scalar entry; whitening and products are ``einsum`` over the small axes). The 3D
        kernels work on stacked 3x3 matrices, so their arrays are batch-first and whitening
        and products are stacked ``matmul`` (faster than ``einsum`` on strided views:
        ``docs/estimators/optim.md``).
        """
        z = blk.measurement
        xa = poses[blk.a]
        Jb: FloatArray | None
        if blk.kind in ("se2", "se3"):
            assert blk.b is not None
            xb = poses[blk.b]
            if blk.kind == "se3":
                fn3 = factors3d.se3_chordal_residual if blk.row_weights is not None else None
                e, Ja, Jb = (fn3 or factors3d.se3_between_error)(xa, xb, z)
            elif blk.row_weights is not None:
                e, Ja, Jb = factors.se2_chordal_residual(xa, xb, z)
            else:
                e, Ja, Jb = factors.se2_between_error(xa, xb, z)
        elif blk.kind == "se2_prior":
            e, Ja = factors.se2_prior_error(xa, z)
            Jb = None
        elif blk.kind == "se3_prior":
            e, Ja = factors3d.se3_prior_error(xa, z)
            Jb = None
        else:
            assert blk.b is not None
            fn = {
                "se2_xy": factors.se2_xy_error,
                "range_bearing": factors.range_bearing_error,
                "range": factors.range_error,
                "bearing": factors.bearing_error,
                "gps": gps.gps_error,
            }[blk.kind]
            e, Ja, Jb = fn(xa, landmarks[blk.b], z)
        if blk.batch_first:
            if blk.row_weights is not None:
                w3 = blk.row_weights
                return (
                    e * w3,
                    Ja * w3[:, :, None],
                    None if Jb is None else Jb * w3[:, :, None],
                )
            U3 = blk.sqrt_info
            assert U3 is not None
            r3 = np.matmul(U3, e[:, :, None])[:, :, 0]
            return r3, U3 @ Ja, None if Jb is None else U3 @ Jb
        # The 2D kernels build edge-last arrays and return batch-first views: undo the views.
        e, Ja = _edge_last(e), _edge_last(Ja)
        Jb = None if Jb is None else _edge_last(Jb)
        if blk.row_weights is not None:
            w = blk.row_weights
            return e * w, Ja * w[:, None, :], None if Jb is None else Jb * w[:, None, :]
        U = blk.sqrt_info
        assert U is not None
        r = np.einsum("ije,je->ie", U, e)
        A = np.einsum("ije,jqe->iqe", U, Ja)
        return r, A, None if Jb is None else np.einsum("ije,jqe->iqe", U, Jb)

    def linearize(
        self,
        poses: FloatArray,
        landmarks: FloatArray,
        kernel: RobustKernel | None = None,
        *,
        jacobians: bool = True,
        deferred: bool = False,
    ) -> Linearization:
        """Cost, ``H`` and ``g`` at ``(poses, landmarks)`` (rows as ``pose_ids``, ``landmark_ids``).

        Per edge, with the whitened residual ``r = U e``, ``s = ‖r‖²`` and the IRLS weight
        ``w = ρ'(s)``: ``H_ab += w A_aᵀ A_b`` and ``g_a += w A_aᵀ r`` where ``A = U ∂e/∂δ``.
        ``jacobians=False``: the cost only. ``deferred=True``: ``H`` and ``g`` are formed
        when first read (the same numbers; :mod:`slamkit.optim.linearization`).
        """
        t0 = time.perf_counter()
        cost = 0.0
        chi2 = 0.0
        weighted: list[WeightedBlock] = []
        robust = kernel is not None and kernel.name != "none"
        if self.compiled is not None and not robust:  # the same numbers in one compiled pass
            return self.compiled.linearize(poses, jacobians=jacobians, deferred=deferred)
        for blk in self.blocks:
            r, A, B = self.block_residuals(blk, poses, landmarks)
            s = _squared_norms(blk, r)
            s_sum = float(s.sum())
            chi2 += s_sum
            if robust:
                assert kernel is not None
                rho, w = robust_rho_and_weight(kernel, s)
                cost += float(rho.sum())
            else:
                cost += s_sum
            if not jacobians:
                continue
            if robust:
                sw = np.sqrt(w)
                if blk.batch_first:
                    r, A = r * sw[:, None], A * sw[:, None, None]
                    B = None if B is None else B * sw[:, None, None]
                else:
                    r = r * sw
                    A = A * sw
                    B = None if B is None else B * sw
            weighted.append(WeightedBlock(r, A, B, blk.batch_first))
        if not jacobians:
            return Linearization(cost, chi2, None, None, time.perf_counter() - t0)
        pattern = self.pattern
        if deferred:

            def form() -> tuple[FloatArray, FloatArray]:
                return normal_equations(pattern, weighted)

            return Linearization(cost, chi2, None, None, time.perf_counter() - t0, pending=form)
        H, g = normal_equations(pattern, weighted)
        return Linearization(cost, chi2, H, g, time.perf_counter() - t0)

    def block_terms(
        self, poses: FloatArray, landmarks: FloatArray, kind: str | None = None
    ) -> list[FloatArray]:
        """Per edge set (of ``kind``, or all), the terms ``‖U e‖²`` (χ² or SE-Sync terms)."""
        out = []
        for blk in self.blocks:
            if kind is None or blk.kind == kind:
                r, _, _ = self.block_residuals(blk, poses, landmarks)
                out.append(_squared_norms(blk, r))
        return out

    def objective_values(self, poses: FloatArray, landmarks: FloatArray) -> tuple[float, float]:
        """``(g2o χ², SE-Sync F)`` at internal-format ``poses`` and ``landmarks``, whichever
        objective the problem minimises: χ² over every edge with g2o's errors, ``F`` over the
        relative-pose edges (:mod:`slamkit.optim.objectives`). The other objective's blocks
        are built once from the validated edges (no second validation); each call costs one
        residual evaluation per objective."""
        if self._other_blocks is None:
            other: ObjectiveName = "sesync" if self.objective == "g2o" else "g2o"
            mine = self.objective
            self.objective = other  # _make_block reads the objective
            try:
                self._other_blocks = [
                    self._make_block(self.data, b.edges, b.a, b.b, b.b_is_landmark)
                    for b in self.blocks
                ]
            finally:
                self.objective = mine
        g2o_blocks = self.blocks if self.objective == "g2o" else self._other_blocks
        sesync_blocks = self._other_blocks if self.objective == "g2o" else self.blocks
        chi2 = 0.0 if self.compiled is None else self.compiled.chi2(poses)
        for blk in g2o_blocks if self.compiled is None else []:
            r, _, _ = self.block_residuals(blk, poses, landmarks)
            chi2 += float(_squared_norms(blk, r).sum())
        F = 0.0
        for blk in sesync_blocks:
            if blk.kind in ("se2", "se3"):
                r, _, _ = self.block_residuals(blk, poses, landmarks)
                F += float(_squared_norms(blk, r).sum())
        return chi2, F

    def retract(
        self, poses: FloatArray, landmarks: FloatArray, delta: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Apply a tangent step ``δ`` (length ``n``) to every free variable.

        Poses move by :func:`~slamkit.optim.factors.retract_poses`, landmarks additively;
        fixed poses keep their values and aliased rows copy their representative.
        """
        if self.compiled is not None:  # a plain pose graph: no landmarks, no aliases
            return self.compiled.retract(poses, delta), landmarks
        free = self.pose_var >= 0
        dof = self.pose_dof
        d = np.zeros((poses.shape[0], dof))
        d[free] = delta[: dof * self.n_free_poses].reshape(-1, dof)
        if self.dim == 2:
            new_poses = factors.retract_poses(poses, d)
        else:
            new_poses = factors3d.retract_poses3(poses, d)
        new_poses[~free] = poses[~free]
        if (self.alias != np.arange(poses.shape[0])).any():
            new_poses = new_poses[self.alias]
        new_lm = landmarks + delta[dof * self.n_free_poses :].reshape(-1, 2)
        return new_poses, new_lm

    def singular_blocks(self, H: FloatArray, rtol: float = 1e-9) -> list[str]:
        """Names of the variables whose own diagonal block of ``H`` (lower-triangle values in
        :attr:`pattern`) is singular: smallest eigenvalue ``≤ rtol ·`` the largest diagonal
        entry of ``H``. Such a variable is not determined by its edges even with all others
        held (a landmark seen by one bearing, one range, or one reading of either)."""
        pat = self.pattern
        scale = float(np.max(H[pat.diag])) if pat.n else 0.0
        dof = self.pose_dof
        groups = [
            (np.arange(self.n_free_poses) * dof, dof),
            (dof * self.n_free_poses + 2 * np.arange(self.landmark_ids.shape[0]), 2),
        ]
        bad_cols: list[int] = []
        for starts, d in groups:
            if not starts.shape[0]:
                continue
            # Column c = start + q stores the block's rows q … d-1 first (NormalPattern).
            B = np.zeros((starts.shape[0], d, d))
            for q in range(d):
                for r in range(q, d):
                    B[:, r, q] = B[:, q, r] = H[pat.indptr[starts + q] + (r - q)]
            low = np.linalg.eigvalsh(B)[:, 0] <= rtol * max(scale, 1e-300)
            bad_cols.extend(int(c) for c in starts[low])
        return [self.variable_of_column(c).split(" (")[0] for c in bad_cols]

    def variable_of_column(self, col: int) -> str:
        """``"pose 17 (θ)"`` / ``"landmark 3 (y)"`` for a column of ``H``."""
        dof = self.pose_dof
        if col < dof * self.n_free_poses:
            row = int(np.flatnonzero(self.pose_var == col // dof)[0])
            names = ("x", "y", "θ") if dof == 3 else ("x", "y", "z", "rx", "ry", "rz")
            return f"pose {int(self.pose_ids[row])} ({names[col % dof]})"
        k = col - dof * self.n_free_poses
        return f"landmark {int(self.landmark_ids[k // 2])} ({'xy'[k % 2]})"


def _edge_last(a: FloatArray) -> FloatArray:
    """``a`` with its first (edge) axis moved last, as ``np.moveaxis(a, 0, -1)`` (the same
    view) without its argument normalisation, which costs more than the view here."""
    return a.transpose(*range(1, a.ndim), 0)


def _reaches_first_row(
    n_p: int,
    n_l: int,
    alias: IntArray,
    blocks_raw: list[tuple[EdgeSet, IntArray, IntArray | None, bool]],
) -> bool:
    """Whether every variable is joined to pose row 0, by a sufficient test that needs no
    graph search (the common case of a chain of poses): every later pose row has an edge
    to, or is an alias of, an earlier row, and every landmark has a reading. ``False``
    says nothing; :meth:`GraphProblem._check_connected` then searches the graph."""
    earlier = alias < np.arange(n_p)
    seen = np.zeros(n_l, dtype=bool)
    for _es, a, b, b_lm in blocks_raw:
        if b is None:
            continue
        if b_lm:
            seen[b] = True
        else:
            earlier[np.maximum(a, b)] = True  # a != b: the larger row has the smaller before it
    return bool(earlier[1:].all() and seen.all())


def _squared_norms(blk: _Block, r: FloatArray) -> FloatArray:
    """``‖r_k‖²`` per edge of a whitened residual in the block's layout."""
    return np.einsum("em,em->e", r, r) if blk.batch_first else np.einsum("ie,ie->e", r, r)


def sesync_row_weights(information: FloatArray) -> FloatArray:
    """Per-row weights ``(√(2κ), √(2κ), √τ, √τ)`` of :func:`factors.se2_chordal_residual`.

    SE-Sync (2D): ``κ = Ω_θθ`` and ``τ = 2 / tr((Ω_tt)⁻¹)`` with ``Ω_tt`` the 2x2
    translational block of the information matrix.
    """
    kappa = information[:, 2, 2]
    a, b, d = information[:, 0, 0], information[:, 0, 1], information[:, 1, 1]
    # Information entries near the float range (1e200) overflow here: the weights then come
    # out non-finite and the caller's check names the edge; the arithmetic stays silent.
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        det = a * d - b * b
        tau = 2.0 * det / (a + d)  # tr(Ω_tt⁻¹) = (a + d) / det
    w = np.empty((information.shape[0], 4))
    w[:, 0] = w[:, 1] = np.sqrt(np.maximum(2.0 * kappa, 0.0))
    w[:, 2] = w[:, 3] = np.sqrt(np.maximum(tau, 0.0))
    w[~np.isfinite(w)] = 0.0
    w[(kappa <= 0) | ~(tau > 0), :] = 0.0
    return w
