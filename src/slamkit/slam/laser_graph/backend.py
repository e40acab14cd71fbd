"""The pose graph of graph-based laser SLAM: keyframe poses, relative-pose edges, and the
batch optimisation of :func:`slamkit.optim.optimize` over them.

Every edge ``i → j`` measures ``Z = X_i⁻¹ X_j`` (``between``) with an information matrix
``Ω``; its residual is ``e = Z⁻¹ ⊕ (X_i⁻¹ X_j)`` (the angle wrapped) and its cost
``eᵀ Ω e``. The first keyframe is held fixed (the optimiser's ``anchor_first`` gauge), so
the map stays in the frame the run started in.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
import scipy.stats

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError, ShapeError
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.pose2 import between
from slamkit.optim.data import EdgeSet, GraphData
from slamkit.optim.settings import OptimizerConfig, RobustConfig, StoppingConfig
from slamkit.optim.solvers import optimize

__all__ = [
    "MAX_CHI2",
    "MAX_EDGE_CHI2",
    "EdgeKind",
    "OptimizationRecord",
    "PoseGraph",
    "RefusedClosure",
    "default_optimizer",
    "edge_chi2",
    "optimize_consistent",
    "rejudge",
    "restore_consistent",
    "retract_inconsistent",
]

# Constants that were settings until 2026-12-07 (docs/estimators/laser_graph.md, "Settings").
# The consistency check (optimize_consistent, rejudge): optimising the graph with new closures
# may raise its total Σ eᵀ Ω e by at most MAX_CHI2 per closure (generous: the front end's edges
# are treated as independent, so a long chain looks surer than it is), and may move no earlier
# edge's residual by more than MAX_EDGE_CHI2 in its own metric, Δeᵀ Ω Δe (10 standard
# deviations).
MAX_CHI2 = 100.0
MAX_EDGE_CHI2 = 100.0
# The whole-graph check (retract_inconsistent): a group of closures whose removal lowers the
# optimum's Σ eᵀ Ω e by more than the 99.9 % point of χ² with 3 degrees of freedom per closure
# is taken out (the statistic and why its bound needs no tuning: the function's docstring).
RETRACT_CHI2 = float(scipy.stats.chi2.ppf(0.999, 3))


def default_optimizer() -> OptimizerConfig:
    """The back end's optimiser: Levenberg-Marquardt on plain least squares (closures are
    checked for consistency instead, which a robust kernel would blur: it gives a correct
    closure that must pull a long drift too little weight to close the loop), at most 20
    iterations from the warm start."""
    return OptimizerConfig(
        robust=RobustConfig(kernel="none"),
        stopping=StoppingConfig(max_iterations=20, relative_tolerance=1e-5),
    )


EdgeKind = Literal["odometry", "loop"]
"""Where an edge came from: the scan match to the previous keyframe (or the wheels when it
failed), a match to an earlier neighbour, or a verified loop closure."""


def edge_chi2(
    poses: FloatArray,
    i: np.ndarray,
    j: np.ndarray,
    measurement: FloatArray,
    information: FloatArray,
) -> FloatArray:
    """``eᵀ Ω e`` of each edge ``(E,)`` at ``poses (N, 3)``, with ``e = between(Z, X_i⁻¹ X_j)``
    (``i``, ``j``: row indices into ``poses``)."""
    if len(i) == 0:
        return np.zeros(0)
    predicted = between(poses[i], poses[j])
    return _weighted(between(measurement, predicted), information)


@dataclass(frozen=True)
class OptimizationRecord:
    """One solve: keyframes and edges at the time, LM iterations, cost before and after,
    wall time [s], whether the solver converged and the start it used (``"given"``: the
    current estimate, the last optimum extended by the front end; no start is chosen)."""

    keyframes: int
    edges: int
    iterations: int
    initial_cost: float
    cost: float
    seconds: float
    converged: bool = True
    start: str = "given"


class PoseGraph:
    """Keyframe poses ``(K, 3)`` (the current estimate) and edges, grown one at a time.

    Poses and edges live in arrays that double their capacity when full, so reading them
    all (each solve, each χ² check) is a slice, not a conversion of one list per edge."""

    def __init__(self, optimizer: OptimizerConfig) -> None:
        self.optimizer = optimizer
        self._n_poses = 0
        self._pose_buf = np.zeros((16, 3))
        self._n_edges = 0
        self._i_buf = np.zeros(16, dtype=np.int64)
        self._j_buf = np.zeros(16, dtype=np.int64)
        self._z_buf = np.zeros((16, 3))
        self._info_buf = np.zeros((16, 3, 3))
        self._kind: list[EdgeKind] = []
        self._off: set[int] = set()  # edges left out of the solve (optimize_consistent)
        self.solves: list[OptimizationRecord] = []

    def __len__(self) -> int:
        return self._n_poses

    @property
    def poses(self) -> FloatArray:
        """The current estimate of every keyframe ``(K, 3)`` (a copy)."""
        return self._pose_buf[: self._n_poses].copy()

    def pose(self, k: int) -> FloatArray:
        """The current estimate of keyframe ``k`` ``(3,)`` (a copy)."""
        if not -self._n_poses <= k < self._n_poses:
            raise IndexError(f"keyframe {k} of {self._n_poses}")
        return self._pose_buf[k % self._n_poses].copy()

    def set_poses(self, poses: FloatArray) -> None:
        """Replace the estimate of every keyframe ``(K, 3)``."""
        if poses.shape != (self._n_poses, 3):
            raise ShapeError(f"poses: expected ({self._n_poses}, 3), got {poses.shape}")
        self._pose_buf[: self._n_poses] = np.asarray(poses, dtype=np.float64)

    def add_pose(self, pose: FloatArray) -> int:
        """A new keyframe at ``pose``; its index."""
        if self._n_poses == self._pose_buf.shape[0]:
            self._pose_buf = _grown(self._pose_buf)
        self._pose_buf[self._n_poses] = np.asarray(pose, dtype=np.float64)
        self._n_poses += 1
        return self._n_poses - 1

    def add_edge(
        self, i: int, j: int, measurement: FloatArray, information: FloatArray, kind: EdgeKind
    ) -> int:
        """An edge ``i → j`` measuring ``T_i_j``; its index."""
        e = self._n_edges
        if e == self._i_buf.shape[0]:
            self._i_buf, self._j_buf = _grown(self._i_buf), _grown(self._j_buf)
            self._z_buf, self._info_buf = _grown(self._z_buf), _grown(self._info_buf)
        self._i_buf[e] = int(i)
        self._j_buf[e] = int(j)
        self._z_buf[e] = np.asarray(measurement, dtype=np.float64)
        self._info_buf[e] = np.asarray(information, dtype=np.float64)
        self._kind.append(kind)
        self._n_edges += 1
        return e

    def disable_edges(self, indices: list[int]) -> None:
        """Leave the edges at ``indices`` out of :meth:`optimize` (until removed)."""
        self._off = set(indices)

    def remove_edges(self, indices: list[int]) -> None:
        """Drop the edges at ``indices``."""
        self._off = set()
        if not indices:
            return
        keep = np.ones(self._n_edges, dtype=bool)
        keep[list(indices)] = False
        n = int(keep.sum())
        for name in ("_i_buf", "_j_buf", "_z_buf", "_info_buf"):
            buf = getattr(self, name)
            buf[:n] = buf[: self._n_edges][keep]
        self._kind = [kind for kind, k in zip(self._kind, keep, strict=True) if k]
        self._n_edges = n

    def edge_kinds(self) -> list[EdgeKind]:
        return list(self._kind)

    def loop_pairs(self) -> list[tuple[int, int]]:
        """The ends ``(i, j)`` of every loop-closure edge."""
        loops = np.flatnonzero(np.array([kind == "loop" for kind in self._kind], dtype=bool))
        return list(zip(self._i_buf[loops].tolist(), self._j_buf[loops].tolist(), strict=True))

    def loop_chi2(self) -> FloatArray:
        """``eᵀ Ω e`` of every loop-closure edge at the current estimate ``(L,)``."""
        loops = np.flatnonzero(np.array([kind == "loop" for kind in self._kind], dtype=bool))
        return edge_chi2(
            self.poses, self._i_buf[loops], self._j_buf[loops], self._z_buf[loops],
            self._info_buf[loops],
        )  # fmt: skip

    def edges(self) -> tuple[np.ndarray, np.ndarray, FloatArray, FloatArray]:
        """``i (E,)``, ``j (E,)``, measurements ``(E, 3)``, information ``(E, 3, 3)`` (copies)."""
        n = self._n_edges
        return (
            self._i_buf[:n].copy(),
            self._j_buf[:n].copy(),
            self._z_buf[:n].copy(),
            self._info_buf[:n].copy(),
        )

    def chi2(self) -> FloatArray:
        """``eᵀ Ω e`` of every edge at the current estimate ``(E,)``."""
        n = self._n_edges  # views of the buffers: edge_chi2 only reads them
        return edge_chi2(
            self._pose_buf[: self._n_poses],
            self._i_buf[:n],
            self._j_buf[:n],
            self._z_buf[:n],
            self._info_buf[:n],
        )

    def residuals(self) -> FloatArray:
        """The residual ``e = Z⁻¹ ⊕ (X_i⁻¹ X_j)`` of every edge at the current estimate
        ``(E, 3)`` (the angle wrapped)."""
        n = self._n_edges
        if n == 0:
            return np.zeros((0, 3))
        p = self._pose_buf[: self._n_poses]
        return between(self._z_buf[:n], between(p[self._i_buf[:n]], p[self._j_buf[:n]]))

    def graph_data(self) -> GraphData:
        """The graph as :class:`~slamkit.optim.GraphData` (ids = keyframe indices, the
        first keyframe fixed), at the current estimate."""
        i, j, z, info = self.edges()
        if self._off:
            on = np.ones(i.size, dtype=bool)
            on[list(self._off)] = False
            i, j, z, info = i[on], j[on], z[on], info[on]
        edges = (EdgeSet("se2", i, j, z, info, np.zeros(i.size, dtype=np.int64)),)
        n = self._n_poses
        return GraphData(
            dim=2,
            pose_ids=np.arange(n, dtype=np.int64),
            poses=self.poses,
            edges=edges if i.size else (),
            fixed_ids=np.zeros(1 if n else 0, dtype=np.int64),
        )

    def optimize(self, keep: bool = True) -> OptimizationRecord:
        """Optimise every keyframe pose from the current estimate (the first held fixed);
        the estimate becomes the optimum, and the solve is kept in :attr:`solves` unless
        ``keep`` is False (a trial solve, as the whole-graph check's). Raises
        :class:`ConvergenceError` when the solver returns non-finite poses."""
        tic = time.perf_counter()
        data = self.graph_data()
        # objectives=False: the record keeps the cost; g2o's χ² and SE-Sync's F go unread.
        result = optimize(data, self.optimizer, initial_poses=data.poses, objectives=False)
        if not np.isfinite(result.poses).all():
            raise ConvergenceError(
                f"pose-graph optimisation over {len(self)} keyframes returned non-finite poses"
            )
        self._pose_buf[: self._n_poses] = np.asarray(result.poses, dtype=np.float64)
        record = OptimizationRecord(
            keyframes=len(self),
            edges=data.n_edges,
            iterations=result.iterations,
            initial_cost=float(result.initial_cost),
            cost=float(result.cost),
            seconds=time.perf_counter() - tic,
            converged=result.converged,
            start=result.initialization,
        )
        if keep:
            self.solves.append(record)
        return record


def _grown(buf: np.ndarray) -> np.ndarray:
    """``buf`` copied into twice the rows."""
    out = np.zeros((2 * buf.shape[0], *buf.shape[1:]), dtype=buf.dtype)
    out[: buf.shape[0]] = buf
    return out


def optimize_consistent(
    graph: PoseGraph, pending: list[int], max_chi2: float, max_edge_chi2: float = np.inf
) -> list[int]:
    """Optimise ``graph`` with the new closures ``pending`` (edge indices), keeping only
    closures consistent with the rest: the total ``Σ eᵀ Ω e`` may grow by at most
    ``max_chi2`` per kept closure over its value without them (at the current estimate,
    the last optimum extended by the front end). While it grows more, the pending closure
    with the largest residual is removed and the graph solved again from the same start.

    The growth is the closure's Mahalanobis distance from what the graph predicts (its
    error against the relative pose, weighted by the closure's and the graph's
    uncertainty), so a wrong closure that the graph can only absorb by bending many edges
    is refused even when its own residual becomes small. A solve that moves any earlier
    edge's residual by more than ``max_edge_chi2`` in its own metric, ``Δeᵀ Ω Δe``, counts
    as inconsistent too: many closures that each fit, together, may tear the chain they
    were added to. (The change, not the value: an edge already strained by earlier
    closures that a new one strains a little more has not been torn by it.) Returns the
    removed edges' indices (as they were on entry)."""
    information = graph.edges()[3]
    residuals = graph.residuals()
    chi2 = _weighted(residuals, information)
    earlier = np.ones(chi2.size, dtype=bool)
    earlier[pending] = False
    before = float(chi2[earlier].sum())
    residuals = residuals[earlier]
    start = graph.poses
    alive = list(pending)
    removed: list[int] = []
    while True:
        graph.optimize()
        now = graph.residuals()
        chi2 = _weighted(now, information)
        kept = np.ones(chi2.size, dtype=bool)
        kept[removed] = False
        growth = float(chi2[kept].sum()) - before
        if not alive or (
            growth <= max_chi2 * len(alive)
            and _largest_change(now[earlier] - residuals, information[earlier]) <= max_edge_chi2
        ):
            break
        worst = max(alive, key=lambda e: chi2[e])
        alive.remove(worst)
        removed.append(worst)
        graph.set_poses(start)
        graph.disable_edges(removed)
    graph.remove_edges(removed)
    return removed


def _weighted(e: FloatArray, information: FloatArray) -> FloatArray:
    """``eᵀ Ω e`` of every row ``(E, 3)``, ``(E, 3, 3)`` (as :func:`edge_chi2`)."""
    return np.einsum("ea,eab,eb->e", e, information, e)


def _largest_change(change: FloatArray, information: FloatArray) -> float:
    """The largest ``Δeᵀ Ω Δe`` over edges ``(E, 3)``, ``(E, 3, 3)`` (0 with no edge; the
    heading change wrapped, in place)."""
    if change.shape[0] == 0:
        return 0.0
    change[:, 2] = wrap_angle(change[:, 2])
    return float(_weighted(change, information).max())


@dataclass(frozen=True)
class RefusedClosure:
    """A verified closure ``i → j`` that the Δχ² check took out of the graph, kept to be
    judged again (:func:`rejudge`)."""

    i: int
    j: int
    measurement: FloatArray
    information: FloatArray


def rejudge(
    graph: PoseGraph,
    pool: list[RefusedClosure],
    window: int,
    max_chi2: float,
    max_edge_chi2: float = np.inf,
) -> tuple[list[RefusedClosure], int, int]:
    """Judge the closures in ``graph`` that the refused ``pool`` contests again, together
    with the pool: a decision of :func:`optimize_consistent` is not final when more
    evidence against it arrives.

    A closure in the graph is *contested* when a refused one joins the same two places
    (both ends within ``window`` keyframes of its own). When the pool outnumbers the
    closures it contests, they are all offered to :func:`optimize_consistent` at once,
    which removes the worst residual until the rest agree with the graph: a wrong closure
    taken early (an aliased corridor, say, absorbed by a loose stretch of the chain) then
    gives way to the many consistent ones that kept being refused because of it. They are
    judged from the graph solved without the contested closures: judged from the estimate
    those strained, the chain's relief when they go would count for the offered ones, and
    in the simulated bare hallway that let a majority of aliased closures in. Returns the
    new pool (the refused again and the contested that lost) and the counts of closures
    readmitted from the pool and taken out of the graph."""
    i, j, z, info = graph.edges()
    loops = np.flatnonzero(np.array([kind == "loop" for kind in graph.edge_kinds()], bool))
    ends = np.array([(c.i, c.j) for c in pool], dtype=np.int64).reshape(-1, 2)
    near = (np.abs(i[loops, None] - ends[None, :, 0]) <= window) & (
        np.abs(j[loops, None] - ends[None, :, 1]) <= window
    )
    contested = loops[near.any(axis=1)].tolist()
    if not contested or len(pool) <= len(contested):
        return pool, 0, 0
    # Judged from the graph without the contested closures: where they strained the chain,
    # taking them out relaxes it, and that relief is no credit to the ones offered instead.
    graph.disable_edges(contested)
    graph.optimize()
    graph.disable_edges([])
    offered = [graph.add_edge(c.i, c.j, c.measurement, c.information, "loop") for c in pool]
    removed = set(optimize_consistent(graph, contested + offered, max_chi2, max_edge_chi2))
    out = [c for c, e in zip(pool, offered, strict=True) if e in removed]
    lost = [RefusedClosure(int(i[e]), int(j[e]), z[e], info[e]) for e in contested if e in removed]
    return out + lost, len(pool) - len(out), len(lost)


def closure_groups(graph: PoseGraph, window: int) -> list[list[int]]:
    """The loop-closure edges of ``graph`` in groups that join the same two places: two
    closures are in one group when both their ends lie within ``window`` keyframes of each
    other's (and groups are closed under that relation). Edge indices, each group sorted."""
    i, j, _, _ = graph.edges()
    loops = np.flatnonzero(np.array([kind == "loop" for kind in graph.edge_kinds()], bool))
    return [loops[g].tolist() for g in _groups(i[loops], j[loops], window)]


def _groups(a: np.ndarray, b: np.ndarray, window: int) -> list[np.ndarray]:
    """Closures ``a[n] → b[n]`` grouped as :func:`closure_groups` does (positions into
    ``a``, ``b``, each group sorted)."""
    if a.size == 0:
        return []
    near = (np.abs(a[:, None] - a[None, :]) <= window) & (np.abs(b[:, None] - b[None, :]) <= window)
    n, label = scipy.sparse.csgraph.connected_components(scipy.sparse.csr_matrix(near))
    return [np.flatnonzero(label == c) for c in range(n)]


def restore_consistent(
    graph: PoseGraph, pool: list[RefusedClosure], window: int, bound: float = RETRACT_CHI2
) -> list[RefusedClosure]:
    """Offer closures refused during the run (``pool``) to the final graph once more, by
    the statistic that takes closures out (:func:`retract_inconsistent`), so that a
    refusal is as revisable as an acceptance.

    The pool's closures are grouped as :func:`closure_groups` groups those of a graph. A
    group ``G`` of ``n`` is scored by how much the optimum's cost rises when it is added,
    ``Δ = min Σ_{all ∪ G} eᵀ Ω e − min Σ_all eᵀ Ω e``, divided by the graph's a-posteriori
    variance factor when that exceeds 1, and by ``n``: the same ``Δ / n`` the whole-graph
    check bounds, read from the other side. Groups within ``bound`` are added; the caller
    then judges every closure together (:func:`retract_inconsistent`), which takes out any
    that only fit alone. A closure refused on arrival was judged against the chain of its
    moment, often bent by a wrong closure since retracted or loose before later loops
    fixed it. Solves start from the current optimum. Returns the closures added (in the
    pool's order); the graph's estimate is left at its optimum without them."""
    if not pool:
        return []
    graph.optimize(keep=False)
    start = graph.poses
    base = float(graph.chi2().sum())
    redundancy = 3 * (graph.edges()[0].size - len(graph) + 1)
    factor = max(1.0, base / redundancy) if redundancy > 0 else 1.0
    ends = np.array([(c.i, c.j) for c in pool], dtype=np.int64)
    added: list[int] = []
    for group in _groups(ends[:, 0], ends[:, 1], window):
        graph.set_poses(start)
        new = [
            graph.add_edge(pool[n].i, pool[n].j, pool[n].measurement, pool[n].information, "loop")
            for n in group.tolist()
        ]
        graph.optimize(keep=False)
        delta = float(graph.chi2().sum()) - base
        graph.remove_edges(new)
        if delta / factor / group.size <= bound:
            added += group.tolist()
    graph.set_poses(start)
    restored = [pool[n] for n in sorted(added)]
    for c in restored:
        graph.add_edge(c.i, c.j, c.measurement, c.information, "loop")
    return restored


def retract_inconsistent(
    graph: PoseGraph, window: int, bound: float = RETRACT_CHI2
) -> list[tuple[int, int]]:
    """Judge every group of closures (:func:`closure_groups`) against the whole graph, and
    take out those the rest of the graph contradicts.

    A group ``G`` of ``n`` closures is judged by how much the optimum's cost falls without
    it, ``Δ = min Σ_all eᵀ Ω e − min Σ_{all∖G} eᵀ Ω e``: with the graph's stated
    uncertainties right and ``G`` true, ``Δ`` is χ² with ``3n`` degrees of freedom when the
    closures are independent and ``n`` times χ² with 3 when they measure the same relation,
    so ``Δ / n`` beyond the 99.9 % point of χ² with 3 degrees of freedom refuses a true group
    less than once in a thousand in either case. ``Δ`` is divided first by the graph's
    a-posteriori variance factor (its cost per degree of freedom of redundancy, without
    ``G``) when that exceeds 1: a graph whose stated uncertainties are too tight everywhere
    does not make every group look wrong. (It is not raised when below 1: a graph that is
    loose on average may be tight in the stretch a group strains.)

    Every group is scored once; those beyond the bound are then taken out worst first, each
    scored again just before, without the ones already out: a true group strained only by
    a wrong one that was worse is kept. (Groups below the bound are not scored again: one
    solve per group, and one or two per suspect, keep this to a few seconds on Intel.)

    Unlike :func:`optimize_consistent`, which judges new closures against the graph as it
    is when they arrive, this sees every closure found since: a group taken early, while
    the chain it bent was loose, is judged again once later loops have fixed that chain.
    Solves start from the current optimum; the graph ends at the optimum without the
    retracted groups. Returns their ends ``(i, j)``."""
    groups = closure_groups(graph, window)
    if not groups:
        return []
    graph.optimize()
    scores = _group_scores(graph, groups, [])
    off: list[int] = []
    for g in sorted(np.flatnonzero(scores > bound), key=lambda g: -scores[g]):
        if off and _group_scores(graph, [groups[g]], off)[0] <= bound:
            continue
        off += groups[g]
        graph.disable_edges(off)
        graph.optimize()
    i, j, _, _ = graph.edges()
    ends = [(int(i[e]), int(j[e])) for e in off]
    graph.remove_edges(off)
    return ends


def _group_scores(graph: PoseGraph, groups: list[list[int]], off: list[int]) -> FloatArray:
    """``Δ / n`` of each group (:func:`retract_inconsistent`), at the graph's current
    estimate (the optimum without the edges ``off``), which it leaves as it found it."""
    start = graph.poses
    cost = graph.chi2()
    kept = np.ones(cost.size, dtype=bool)
    kept[off] = False
    total = float(cost[kept].sum())
    scores = np.zeros(len(groups))
    for g, group in enumerate(groups):
        graph.set_poses(start)
        graph.disable_edges(off + group)
        graph.optimize(keep=False)
        rest = kept.copy()
        rest[group] = False
        without = float(graph.chi2()[rest].sum())
        redundancy = 3 * (int(rest.sum()) - len(graph) + 1)
        factor = max(1.0, without / redundancy) if redundancy > 0 else 1.0
        scores[g] = (total - without) / factor / len(group)
    graph.set_poses(start)
    graph.disable_edges(off)
    return scores
