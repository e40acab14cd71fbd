"""Incremental 2D pose-graph optimisation: poses and edges arrive in time order, the estimate
is kept current after every update, and periodic batch steps relinearise everything.

The problem as it grows (``━`` odometry, ``┄`` loop closures)::

      last batch step          held fixed           the window: last window_updates updates
   X0 ━ X1 ━ X2 ━ X3 ━ X4 ━ X5 ━ X6 ━ X7 ━ X8 ━━━━━ X9 ━ X10 ━ X11
         ┆                                          ┆          ┆
         └┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┘ X1 touched: in the window too

Each update (:meth:`IncrementalOptimizer.update`) brings new poses and the edges whose later
end is one of them. The work is of two kinds, iSAM's split between cheap incremental steps
and periodic relinearisation with a fresh variable ordering:

* **Window step** (an update with a loop closure). The *window* holds the poses of the last
  ``window_updates`` updates and every older pose that their edges touch (``X1`` above);
  every other pose is held at its current value. One Gauss-Newton step
  (``window_iterations``) on the window poses, ``H_W δ = -g_W`` over every edge incident to
  them, linearised at the current estimate, corrects the recent trajectory. The system has
  ``3 |W|`` unknowns whatever the size of the graph, so an update costs the same on the
  10,000th pose as on the 10th (dense Cholesky up to 96 unknowns, the sparse back-end above).
  New poses start from the guess given, or by composing an edge of the update with the
  current estimate of its other end (odometry chaining). An update whose new poses each hang
  on the graph by one chained edge (plain odometry) fits that edge exactly and changes no
  other pose's optimum, so its window step is skipped.
* **Batch step** (every ``relinearize_every`` updates; when a window step moves some pose by
  more than ``relinearize_threshold``, a sign that the correction is too large and too
  nonlinear to stay local; when the first prior arrives and the gauge moves): the whole graph
  so far becomes a :class:`~slamkit.optim.graph.GraphProblem`; its normal-equation pattern
  and CHOLMOD's symbolic analysis (AMD ordering, elimination tree, supernodes) are computed
  once and reused by every Gauss-Newton iteration of the step, which runs from the current
  estimate until the cost changes by at most ``relative_tolerance`` (with backtracking, and
  Levenberg-Marquardt as the fallback, if a step raises the cost). After a batch step the
  estimate is the batch optimum of the graph so far (to that tolerance), and
  :meth:`IncrementalOptimizer.finish` ends with one at ``final_relative_tolerance``, so the
  end result equals :func:`~slamkit.optim.optimize` on the whole graph (the tests check 1e-6
  in the poses).

**Why not update the Cholesky factor between batch steps.** iSAM keeps the square-root
information factor and updates it by Givens rotations; CHOLMOD can do rank updates
(``cholmod_updown``) but ``cvxopt.cholmod`` exposes only ``symbolic``, ``numeric``,
``solve``, ``spsolve``, ``diag``, ``getfactor``, ``linsolve`` and ``splinsolve``. Keeping the
batch factor and folding new edges in exactly (the Schur complement of the new rows, with the
marginal covariance of each touched old pose taken from the factor) needs one full solve per
touched old pose, which on a large graph costs tens of window steps per touched pose (the
measurement is in ``docs/estimators/optim.md``), and a graph like city10000 closes a loop
at nearly every pose. So the window step is the cheap local update, and the
batch step restores exactness periodically; between batch steps the numeric factor is not
kept at all.

**Time order and ids.** The order of :meth:`~IncrementalOptimizer.update` calls is time.
Pose ids must increase (a pose id not above every id already added raises
:class:`~slamkit.errors.InputError` naming both): graph files number poses in time order,
and a smaller id is almost always a feeding mistake. An edge may refer only to poses added
earlier or in the same update; anything else raises :class:`~slamkit.errors.InputError`
naming the edge and the unknown pose. Every new pose must be tied to the graph by the
update's edges (a chain of edges to a pose added earlier, or a prior); only the very first
pose may stand alone (its guess defaults to the origin).

**Gauge.** As in batch: with no prior edge, the first pose is held fixed at its initial
value; once a ``se2_prior`` edge arrives every pose is free (a batch step follows at once).

Edge kinds: ``se2`` (relative pose) and ``se2_prior`` (absolute pose), with the information
matrices of the g2o objective; landmarks and 3D graphs are batch-only for now.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace
from itertools import chain

import numpy as np

from slamkit.errors import (
    ConfigError,
    ConvergenceError,
    GeometryError,
    InputError,
    ShapeError,
)
from slamkit.geometry import pose2
from slamkit.optim import factors
from slamkit.optim.compiled2d import compiled_window
from slamkit.optim.data import EdgeSet, FloatArray, GraphData, IntArray
from slamkit.optim.graph import GraphProblem
from slamkit.optim.loop import Estimate, SolverContext, run_least_squares
from slamkit.optim.robust import RobustKernel
from slamkit.optim.settings import LmConfig, StoppingConfig
from slamkit.optim.sparse import LinearSolverName, SingularSystem, make_factorizer
from slamkit.optim.steps import BacktrackingGaussNewtonStep, LevenbergMarquardtStep
from slamkit.optim.updates import (
    GraphUpdate,
    check_guesses,
    check_update_edges,
    edge_name,
    time_ordered_updates,
)
from slamkit.optim.window import (
    DENSE_MAX,
    solve_window,
    window_normal_equations,
    window_terms,
)

__all__ = [
    "GraphUpdate",
    "IncrementalConfig",
    "IncrementalOptimizer",
    "IncrementalResult",
    "UpdateInfo",
    "time_ordered_updates",
]


@dataclass(frozen=True)
class IncrementalConfig:
    """Settings of :class:`IncrementalOptimizer`. Costs are χ² ``Σ eᵀ Ω e`` (no factor ½);
    steps ``δ`` are SE(2) tangent vectors ``(δx, δy, δθ)`` in metres and radians."""

    relinearize_every: int = 200
    """A batch step after this many updates since the last one (1: batch after every update)."""
    window_updates: int = 10
    """The window: the poses of the last this-many updates and the older poses their edges
    touch."""
    relinearize_threshold: float = 0.5
    """A batch step when a window step moves some pose by more than this (max ``|δ|``)."""
    window_iterations: int = 1
    """Gauss-Newton iterations of a window step (each relinearises the window's edges)."""
    batch_max_iterations: int = 30
    """At most this many linearisations per batch step."""
    relative_tolerance: float = 1e-3
    """A batch step stops after a Gauss-Newton step with ``|f_old - f_new| ≤ tol · f_old``
    (from the warm start of the window steps, typically after two factorisations)."""
    final_relative_tolerance: float = 1e-12
    """The same rule for the last batch step, in :meth:`IncrementalOptimizer.finish`."""
    step_tolerance: float = 1e-12
    """A batch step also stops after a step with ``max |δ| ≤ step_tolerance``."""
    linear_solver: LinearSolverName = "auto"
    """Sparse Cholesky of the batch steps (see :class:`~slamkit.optim.OptimizerConfig`)."""

    def __post_init__(self) -> None:
        for name in ("relinearize_every", "window_updates", "batch_max_iterations"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")
        if not (isinstance(self.window_iterations, int) and self.window_iterations >= 0):
            raise ConfigError(
                f"window_iterations: expected an integer >= 0, got {self.window_iterations!r}"
            )
        for name in ("relative_tolerance", "final_relative_tolerance", "step_tolerance"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: expected a finite number >= 0, got {v!r}")
        if not self.relinearize_threshold > 0:
            raise ConfigError(
                f"relinearize_threshold: expected > 0, got {self.relinearize_threshold!r}"
            )
        if self.linear_solver not in ("auto", "cholmod", "superlu", "dense"):
            raise ConfigError(f"linear_solver: unknown back-end {self.linear_solver!r}")


@dataclass(frozen=True)
class UpdateInfo:
    """What one :meth:`IncrementalOptimizer.update` did."""

    update: int  # 1-based number of this update
    n_poses: int  # poses in the graph after the update
    n_edges: int  # edges in the graph after the update
    batch_step: bool
    reason: str  # why a batch step ran ("" when none did)
    window_poses: int  # free window poses after the update (0 after a batch step)
    step_norm: float  # max |δ| of the window step's first iteration (0 when none ran)
    batch_iterations: int  # linearisations of the batch step (0 when none ran)
    seconds: float  # wall time of the whole update


@dataclass(frozen=True)
class IncrementalResult:
    """The estimate after :meth:`IncrementalOptimizer.finish`; ``poses`` rows follow
    ``pose_ids`` (arrival order)."""

    pose_ids: IntArray
    poses: FloatArray
    chi2: float  # g2o χ² of the final estimate
    converged: bool  # the final batch step met final_relative_tolerance
    updates: int
    batch_steps: int  # including the final one
    batch_iterations: int  # linearisations over all batch steps
    update_seconds: FloatArray  # (updates,) wall time of each update
    finish_seconds: float  # the final batch step


class IncrementalOptimizer:
    """An SE(2) pose graph optimised as it grows (see the module docstring).

    ``update(pose_ids, edges, initial_poses)`` adds poses and edges and returns an
    :class:`UpdateInfo`; ``estimate()`` gives the current poses; ``finish()`` runs the final
    batch step and returns an :class:`IncrementalResult`; ``graph()`` gives everything so far
    as a :class:`~slamkit.optim.data.GraphData` for batch tools.
    """

    def __init__(self, config: IncrementalConfig | None = None, *, compiled: bool = True) -> None:
        self.config = config if config is not None else IncrementalConfig()
        # The window step in one compiled pass when numba is installed (compiled=False: NumPy).
        self._compiled = compiled_window() if compiled else None
        cap = 256
        self._n = 0  # poses
        self._ids = np.zeros(cap, dtype=np.int64)
        self._X = np.zeros((cap, 3))
        self._local = np.full(cap, -1, dtype=np.int64)  # window index of a pose row, -1 if none
        self._row_of: dict[int, int] = {}
        self._adj: list[list[int]] = []  # edges incident to each pose row
        self._m = 0  # edges
        self._ea = np.zeros(cap, dtype=np.int64)  # row of the first pose
        self._eb = np.zeros(cap, dtype=np.int64)  # row of the second pose, -1 for priors
        self._ez = np.zeros((cap, 3))
        self._einfo = np.zeros((cap, 3, 3))
        self._eU = np.zeros((cap, 3, 3))  # U with Uᵀ U = Ω (whitening)
        self._elines = np.zeros(cap, dtype=np.int64)
        self._count = np.zeros(cap, dtype=np.int64)  # window updates that hold a pose row
        self._recent: deque[list[int]] = deque()  # rows each window update holds, oldest first
        self._window: dict[int, None] = {}  # free pose rows of the window, in arrival order
        self._has_prior = False
        self._since_batch = 0
        self._updates = 0
        self._batch_steps = 0
        self._batch_iterations = 0
        self._last_converged = True
        self._last_chi2 = 0.0
        self._update_seconds: list[float] = []

    # ------------------------------------------------------------------ accessors
    @property
    def n_poses(self) -> int:
        return self._n

    @property
    def n_edges(self) -> int:
        return self._m

    def estimate(self) -> tuple[IntArray, FloatArray]:
        """``(pose_ids, poses)`` of the current estimate (copies; rows in arrival order)."""
        return self._ids[: self._n].copy(), self._X[: self._n].copy()

    def window_pose_ids(self) -> IntArray:
        """Ids of the poses the next window step moves (arrival order)."""
        rows = np.fromiter(self._window, dtype=np.int64, count=len(self._window))
        return self._ids[rows].copy()

    def pose(self, pose_id: int) -> FloatArray:
        """The current estimate ``(x, y, θ)`` of one pose (a copy)."""
        row = self._row_of.get(int(pose_id))
        if row is None:
            raise InputError(f"pose {pose_id} is not in the graph")
        return self._X[row].copy()

    def graph(self) -> GraphData:
        """Every pose (at its current estimate) and edge so far, for batch tools."""
        n, m = self._n, self._m
        edges = []
        prior = self._eb[:m] < 0
        for kind, sel in (("se2", np.flatnonzero(~prior)), ("se2_prior", np.flatnonzero(prior))):
            if not sel.shape[0]:
                continue
            j = np.full(sel.shape[0], -1, dtype=np.int64)
            if kind == "se2":
                j = self._ids[self._eb[sel]]
            edges.append(
                EdgeSet(
                    kind,  # type: ignore[arg-type]
                    self._ids[self._ea[sel]].copy(),
                    j.copy(),
                    self._ez[sel].copy(),
                    self._einfo[sel].copy(),
                    self._elines[sel].copy(),
                )
            )
        return GraphData(
            dim=2,
            pose_ids=self._ids[:n].copy(),
            poses=self._X[:n].copy(),
            edges=tuple(edges),
            family="memory",
            source="<incremental>",
        )

    # ------------------------------------------------------------------ updates
    def update(
        self,
        pose_ids: Sequence[int] | IntArray,
        edges: Sequence[EdgeSet] = (),
        initial_poses: FloatArray | None = None,
    ) -> UpdateInfo:
        """Add poses (ids increasing, above every id so far) and edges (ends among the poses
        added so far, this update included); keep the estimate current (module docstring).

        ``initial_poses`` ``(K, 3)`` are guesses for ``pose_ids``; without them each new pose
        is chained from an edge of this update and the current estimate of its other end.
        Raises :class:`~slamkit.errors.InputError` subclasses naming the pose or edge.
        """
        t0 = time.perf_counter()
        new_ids = self._check_new_ids(pose_ids)
        guesses = check_guesses(initial_poses, new_ids)
        whiten = None if self._compiled is None else self._compiled.whitening
        checked = [check_update_edges(es, whiten) for es in edges]
        new_row = {pid: self._n + k for k, pid in enumerate(new_ids.tolist())}
        resolved = [self._resolve(es, new_row) for es in checked]
        X_new = self._initial_guesses(new_ids, new_row, guesses, resolved)
        self._append_poses(new_ids, X_new)
        gauge_moves = False
        touched: list[int] = []
        for es, U, a, b in resolved:
            first = self._m
            self._append_edges(es, U, a, b)
            if b is None and not self._has_prior:
                self._has_prior = True
                gauge_moves = self._n > new_ids.shape[0]  # poses were anchored before
            touched.extend(range(first, self._m))
        self._extend_window(list(new_row.values()), touched)
        # Poses hung on the graph by one chained edge each fit it exactly (zero error) and
        # move nothing else: the window's optimum is unchanged, so its step is skipped.
        leaf_only = (
            guesses is None
            and all(b is not None for _, _, _, b in resolved)
            and len(touched) == new_ids.shape[0]
        )
        self._updates += 1
        self._since_batch += 1
        cfg = self.config
        reason = ""
        step = 0.0
        if gauge_moves:
            reason = "the first prior arrived (the gauge moves from the first pose)"
        elif self._since_batch >= cfg.relinearize_every:
            reason = f"{cfg.relinearize_every} updates since the last batch step"
        elif not leaf_only:
            step = self._window_step()
            if step > cfg.relinearize_threshold:
                reason = f"window step {step:.3g} > relinearize_threshold"
        iterations = 0
        if reason:
            iterations = self._batch_step(cfg.relative_tolerance)
        seconds = time.perf_counter() - t0
        self._update_seconds.append(seconds)
        return UpdateInfo(
            self._updates,
            self._n,
            self._m,
            bool(reason),
            reason,
            len(self._window),
            step,
            iterations,
            seconds,
        )

    def relinearize(self) -> int:
        """Run a batch step now; returns its number of linearisations."""
        return self._batch_step(self.config.relative_tolerance)

    def finish(self) -> IncrementalResult:
        """The final batch step (at ``final_relative_tolerance``) and the result."""
        t0 = time.perf_counter()
        if self._n == 0:
            raise InputError("the graph has no poses: call update() first")
        self._batch_step(self.config.final_relative_tolerance)
        seconds = time.perf_counter() - t0
        ids, poses = self.estimate()
        return IncrementalResult(
            ids,
            poses,
            self._last_chi2,
            self._last_converged,
            self._updates,
            self._batch_steps,
            self._batch_iterations,
            np.array(self._update_seconds),
            seconds,
        )

    # ------------------------------------------------------------------ validation
    def _check_new_ids(self, pose_ids: Sequence[int] | IntArray) -> IntArray:
        raw = np.asarray(pose_ids)
        if raw.ndim != 1:
            raise ShapeError(f"pose_ids: expected shape (K,), got {raw.shape}")
        if raw.shape[0] and not np.issubdtype(raw.dtype, np.integer):
            raise InputError(f"pose_ids: expected integers, got dtype {raw.dtype}")
        ids = raw.astype(np.int64)
        last = int(self._ids[self._n - 1]) if self._n else None
        prev = last
        for pid in ids.tolist():
            if pid in self._row_of:
                raise InputError(f"pose {pid} is already in the graph")
            if prev is not None and pid <= prev:
                raise InputError(
                    f"pose {pid} arrives after pose {prev}: pose ids must increase in time order"
                )
            prev = pid
        return ids

    def _resolve(
        self, checked: tuple[EdgeSet, FloatArray], new_row: dict[int, int]
    ) -> tuple[EdgeSet, FloatArray, IntArray, IntArray | None]:
        """Rows of each edge's poses; unknown poses and self-loops are errors."""
        es, U = checked

        def rows(ids: IntArray) -> IntArray:
            out = np.empty(ids.shape[0], dtype=np.int64)
            for k, pid in enumerate(ids.tolist()):
                r = self._row_of.get(pid, new_row.get(pid))
                if r is None:
                    raise InputError(
                        f"{edge_name(es, k)}: pose {pid} is not in the graph (add it in this "
                        "update or an earlier one)"
                    )
                out[k] = r
            return out

        a = rows(np.asarray(es.i, dtype=np.int64))
        if es.kind == "se2_prior":
            return es, U, a, None
        b = rows(np.asarray(es.j, dtype=np.int64))
        if (a == b).any():
            k = int(np.flatnonzero(a == b)[0])
            raise InputError(f"{edge_name(es, k)}: edge from a pose to itself")
        return es, U, a, b

    def _initial_guesses(
        self,
        ids: IntArray,
        new_row: dict[int, int],
        guesses: FloatArray | None,
        resolved: list[tuple[EdgeSet, FloatArray, IntArray, IntArray | None]],
    ) -> FloatArray:
        """Given guesses, or poses chained through this update's edges from known poses:
        ``X_j = X_i ⊕ Z`` or ``X_i = X_j ⊕ Z⁻¹``; a prior gives its measurement. Also checks
        that every new pose is tied to the graph."""
        K = ids.shape[0]
        first_row = self._n
        X = np.zeros((K, 3)) if guesses is None else guesses.copy()
        known = np.zeros(K, dtype=bool)  # reached from the graph (and given a value)
        # new row → (other row, Z, reversed): X_new = X_other ⊕ Z, or ⊕ Z⁻¹ when reversed
        links: dict[int, list[tuple[int, FloatArray, bool]]] = {}
        queue: deque[int] = deque()
        for es, _, a, b in resolved:
            if b is None:
                for k, r in enumerate(a.tolist()):
                    if r >= first_row and not known[r - first_row]:
                        known[r - first_row] = True
                        queue.append(r)
                        if guesses is None:
                            X[r - first_row] = es.measurement[k]
                continue
            for k, (ra, rb) in enumerate(zip(a.tolist(), b.tolist(), strict=True)):
                z = es.measurement[k]
                if rb >= first_row:
                    links.setdefault(rb, []).append((ra, z, False))
                if ra >= first_row:
                    links.setdefault(ra, []).append((rb, z, True))
        if self._n == 0 and K and not known[0]:
            known[0] = True  # the very first pose may stand alone (default guess: the origin)
            queue.append(first_row)

        # Breadth-first from the poses with a value: old poses first, then new ones reached.
        def chained(x_src: FloatArray, z: FloatArray, rev: bool) -> FloatArray:
            if self._compiled is not None:
                return self._compiled.chain(x_src, z, rev)
            return pose2.compose(x_src, pose2.inverse(z) if rev else z)

        for dst, srcs in links.items():
            for src, z, rev in srcs:
                if src < first_row and not known[dst - first_row]:
                    known[dst - first_row] = True
                    queue.append(dst)
                    if guesses is None:
                        X[dst - first_row] = chained(self._X[src], z, rev)
        # src row → (new row, Z, reversed) for the links between new poses
        reverse: dict[int, list[tuple[int, FloatArray, bool]]] = {}
        for dst, srcs in links.items():
            for src, z, rev in srcs:
                if src >= first_row:
                    reverse.setdefault(src, []).append((dst, z, rev))
        while queue:
            src = queue.popleft()
            for dst, z, rev in reverse.get(src, []):
                if not known[dst - first_row]:
                    known[dst - first_row] = True
                    queue.append(dst)
                    if guesses is None:
                        X[dst - first_row] = chained(X[src - first_row], z, rev)
        if not known.all():
            pid = int(ids[int(np.flatnonzero(~known)[0])])
            raise InputError(
                f"pose {pid}: no edge of this update ties it to the graph (an edge to a pose "
                "added earlier, a chain of them, or a prior is needed)"
            )
        return X

    # ------------------------------------------------------------------ storage
    def _grow_poses(self, need: int) -> None:
        cap = self._ids.shape[0]
        if need <= cap:
            return
        new = max(need, 2 * cap)
        self._ids = np.concatenate([self._ids, np.zeros(new - cap, dtype=np.int64)])
        self._X = np.concatenate([self._X, np.zeros((new - cap, 3))])
        self._local = np.concatenate([self._local, np.full(new - cap, -1, dtype=np.int64)])
        self._count = np.concatenate([self._count, np.zeros(new - cap, dtype=np.int64)])

    def _grow_edges(self, need: int) -> None:
        cap = self._ea.shape[0]
        if need <= cap:
            return
        new = max(need, 2 * cap)
        pad = new - cap
        self._ea = np.concatenate([self._ea, np.zeros(pad, dtype=np.int64)])
        self._eb = np.concatenate([self._eb, np.zeros(pad, dtype=np.int64)])
        self._ez = np.concatenate([self._ez, np.zeros((pad, 3))])
        self._einfo = np.concatenate([self._einfo, np.zeros((pad, 3, 3))])
        self._eU = np.concatenate([self._eU, np.zeros((pad, 3, 3))])
        self._elines = np.concatenate([self._elines, np.zeros(pad, dtype=np.int64)])

    def _append_poses(self, ids: IntArray, X: FloatArray) -> None:
        K = ids.shape[0]
        self._grow_poses(self._n + K)
        self._ids[self._n : self._n + K] = ids
        self._X[self._n : self._n + K] = X
        for k, pid in enumerate(ids.tolist()):
            self._row_of[pid] = self._n + k
            self._adj.append([])
        self._n += K

    def _append_edges(self, es: EdgeSet, U: FloatArray, a: IntArray, b: IntArray | None) -> None:
        E = a.shape[0]
        m = self._m
        self._grow_edges(m + E)
        self._ea[m : m + E] = a
        self._eb[m : m + E] = -1 if b is None else b
        self._ez[m : m + E] = es.measurement
        self._einfo[m : m + E] = es.information
        self._eU[m : m + E] = U
        self._elines[m : m + E] = es.lines if es.lines.shape[0] == E else 0
        for k in range(E):
            self._adj[int(a[k])].append(m + k)
            if b is not None:
                self._adj[int(b[k])].append(m + k)
        self._m += E

    def _fixed(self, row: int) -> bool:
        return row == 0 and not self._has_prior

    def _extend_window(self, new_rows: list[int], new_edges: list[int]) -> None:
        """Hold the new poses and every pose the new edges touch for ``window_updates``
        updates; release the poses of the update that falls out."""
        held = list(new_rows)
        for e in new_edges:
            held.append(int(self._ea[e]))
            if self._eb[e] >= 0:
                held.append(int(self._eb[e]))
        held = [r for r in dict.fromkeys(held) if not self._fixed(r)]
        self._recent.append(held)
        for r in held:
            self._count[r] += 1
            self._window[r] = None
        if len(self._recent) > self.config.window_updates:
            for r in self._recent.popleft():
                self._count[r] -= 1
                if self._count[r] == 0:
                    del self._window[r]

    def _clear_window(self) -> None:
        if self._window:
            self._count[np.fromiter(self._window, dtype=np.int64)] = 0
        self._recent.clear()
        self._window = {}
        self._since_batch = 0

    # ------------------------------------------------------------------ window step
    def _window_step(self) -> float:
        """Gauss-Newton on the window poses, the rest held fixed; returns max |δ| of the
        first iteration."""
        w = len(self._window)
        if w == 0 or self.config.window_iterations == 0:
            return 0.0
        rows = np.fromiter(self._window, dtype=np.int64, count=w)
        eidx = np.unique(np.fromiter(chain.from_iterable(self._adj[r] for r in rows), np.int64))
        self._local[rows] = np.arange(w)
        a, b = self._ea[eidx], self._eb[eidx]
        prior = b < 0
        z, U = self._ez[eidx], self._eU[eidx]
        la = self._local[a]
        lb = np.where(prior, -1, self._local[np.maximum(b, 0)])
        self._local[rows] = -1
        l6 = np.repeat(np.concatenate([la[:, None], lb[:, None]], axis=1), 3, axis=1)
        cols = np.where(l6 >= 0, 3 * l6 + np.tile(np.arange(3), 2), -1)  # (E, 6)
        first_step = 0.0
        fast = self._compiled if 3 * w <= DENSE_MAX and not prior.any() else None
        for it in range(self.config.window_iterations):
            X = self._X
            try:
                if fast is not None:  # the same step in one compiled pass
                    found = fast.step(X, rows, a, b, z, U, cols)
                    if found is None:
                        raise SingularSystem("not positive definite")
                    delta = found
                else:
                    r, J = window_terms(X, a, b, z, U, prior)
                    flat, vals, g = window_normal_equations(3 * w, cols, r, J)
                    delta = solve_window(3 * w, flat, vals, g, self.config.linear_solver)
            except SingularSystem:
                names = ", ".join(str(int(self._ids[q])) for q in rows[:8].tolist())
                raise GeometryError(
                    f"the window system is singular: poses {names}{' …' if w > 8 else ''} are "
                    "not determined by their edges"
                ) from None
            if not np.isfinite(delta).all():
                raise ConvergenceError("non-finite window step", step=self._updates)
            step = float(np.abs(delta).max())
            if it == 0:
                first_step = step
            if fast is not None:
                self._X[rows] = fast.retract(X[rows], delta)
            else:
                self._X[rows] = factors.retract_poses(X[rows], delta.reshape(w, 3))
        return first_step

    # ------------------------------------------------------------------ batch step
    def _batch_step(self, rtol: float) -> int:
        """The loop of :func:`~slamkit.optim.loop.run_least_squares` on the whole graph from
        the current estimate, with Gauss-Newton and backtracking
        (:class:`~slamkit.optim.steps.BacktrackingGaussNewtonStep`; one symbolic analysis,
        reused by every iteration), then Levenberg-Marquardt from where it stalls; returns
        the number of linearisations (LM's: factorisations)."""
        self._clear_window()
        self._batch_steps += 1
        data = self.graph()
        problem = GraphProblem.from_data(data)
        x = problem.to_internal(data.poses)
        if problem.n == 0:  # every pose fixed: nothing to solve
            current = Estimate(x, np.zeros((0, 2)), problem.linearize(x, np.zeros((0, 2))))
            iterations, converged = 1, True
        else:
            current, iterations, converged = self._batch_solve(problem, x, rtol)
        self._X[: self._n] = problem.to_external(current.poses)
        self._batch_iterations += iterations
        self._last_converged = converged
        self._last_chi2 = current.lin.chi2
        return iterations

    def _batch_solve(
        self, problem: GraphProblem, x: FloatArray, rtol: float
    ) -> tuple[Estimate, int, bool]:
        """Backtracking Gauss-Newton from ``x`` until ``|f_old - f_new| ≤ rtol · f_old`` or
        ``max |δ| ≤ step_tolerance`` (no gradient test), then LM from where it stalls.
        Returns the estimate, the linearisations (LM's: factorisations) and convergence."""
        cfg = self.config
        ctx = SolverContext(
            problem, RobustKernel(), make_factorizer(cfg.linear_solver, problem.pattern)
        )
        start = ctx.linearize(x, np.zeros((0, 2)))
        rule = StoppingConfig(
            max_iterations=cfg.batch_max_iterations,
            relative_tolerance=rtol,
            absolute_tolerance=0.0,
            step_tolerance=cfg.step_tolerance,
        )
        gn = BacktrackingGaussNewtonStep(rtol, self._updates)
        out = run_least_squares(ctx, start, gn, rule, [], check_gradient=False)
        iterations = ctx.linearizations
        if out.stalled and not out.converged:
            # No decrease along the Gauss-Newton direction: Levenberg-Marquardt from here,
            # with the same problem and tolerance.
            lm_rule = replace(rule, absolute_tolerance=StoppingConfig().absolute_tolerance)
            before = ctx.factorizations
            # Levenberg's D = I: the Gauss-Newton direction just failed, so its shortened
            # copy (damping="hessian") would fail too.
            lm = LevenbergMarquardtStep(LmConfig(damping="levenberg", schedule="fixed"))
            out = run_least_squares(ctx, out.estimate, lm, lm_rule, [])
            iterations += ctx.factorizations - before
        return out.estimate, iterations, out.converged
