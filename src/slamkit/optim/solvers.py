"""Batch optimisation of a graph: :func:`optimize` (start, then the nonlinear least-squares
loop with the configured solver) and the grown-prefix start of long landmark graphs.

The problem (drawn for a four-pose loop)::

      X0 ──Z01──▶ X1          cost f(x) = Σ_k ρ(‖U_k e_k(x)‖²)
      ▲            │          e_k: g2o error of Z⁻¹ X_i⁻¹ X_j, or SE-Sync's chordal residual
     Z30          Z12         U_k: upper Cholesky factor of the information Ω_k
      │            ▼          X0 fixed (gauge) unless the file fixes a pose or has a prior
      X3 ◀──Z23── X2

Each iteration linearises all edges at once (:meth:`GraphProblem.linearize`): ``H = Jᵀ W J``
and ``g = Jᵀ W r`` (``W`` the IRLS weights of the robust kernel) in a sparsity pattern fixed at
the start, factors ``H`` (or ``H + λD``) with a sparse Cholesky whose symbolic analysis is
done once, and moves the poses on the manifold by ``X ⊕ δ`` (SE(2) or SE(3)). The loop is
:func:`~slamkit.optim.loop.run_least_squares`; Gauss-Newton, Levenberg-Marquardt and
Powell's dogleg are its step strategies (:mod:`slamkit.optim.steps`), the settings are the
sections of :class:`~slamkit.optim.settings.OptimizerConfig`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np

from slamkit import runtime
from slamkit.errors import ConvergenceError, GeometryError, SlamkitError
from slamkit.geometry import pose2
from slamkit.optim.data import EdgeSet, FloatArray, GraphData, IntArray
from slamkit.optim.graph import GraphProblem, ObjectiveName
from slamkit.optim.init import initial_values
from slamkit.optim.loop import Callback as Callback  # re-exported: the old import path
from slamkit.optim.loop import IterationInfo, SolverContext, run_least_squares
from slamkit.optim.loop import indeterminate_error as indeterminate_error  # re-exported
from slamkit.optim.settings import InitName as InitName  # re-exported
from slamkit.optim.settings import MethodName, OptimizerConfig
from slamkit.optim.sparse import make_factorizer
from slamkit.optim.steps import make_step

__all__ = [
    "IterationInfo",
    "OptimizeResult",
    "OptimizerConfig",
    "StartChoice",
    "choose_start",
    "grow_initialization",
    "optimize",
    "resolve_initialization",
]

_NO_COSTS: Mapping[str, float] = MappingProxyType({})


@dataclass(frozen=True)
class StartChoice:
    """The starting values :func:`choose_start` picked, and why.

    ``name``: ``"vertices"``, ``"odometry"``, ``"chordal"`` or ``"grow"``; ``poses`` and
    ``landmarks`` in file formats (rows of the problem's ``pose_ids`` / ``landmark_ids``);
    ``costs``: the cost (the configured objective and robust kernel) of every candidate
    evaluated, by name (empty when a start was named, not chosen); ``reason``: one sentence.
    """

    name: str
    poses: FloatArray
    landmarks: FloatArray
    costs: Mapping[str, float]
    reason: str


@dataclass(frozen=True)
class OptimizeResult:
    """The optimum and how it was reached. ``poses`` rows follow ``pose_ids``."""

    pose_ids: IntArray
    poses: FloatArray
    landmark_ids: IntArray
    landmarks: FloatArray
    cost: float
    initial_cost: float
    chi2: float
    iterations: int
    factorizations: int
    converged: bool
    reason: str
    method: MethodName
    objective: ObjectiveName
    linear_solver: str
    anchored_first: bool
    setup_seconds: float
    assembly_seconds: float
    factor_seconds: float
    total_seconds: float
    history: tuple[IterationInfo, ...] = field(default=(), repr=False)
    initialization: str = "given"
    """The initialisation used (``"vertices"``, ``"odometry"``, ``"chordal"``, ``"grow"``),
    ``"given"`` when the caller passed the initial poses."""
    start_costs: Mapping[str, float] = field(default_factory=dict, repr=False)
    """``initialization="auto"``: the cost of every start it compared, by name
    (:class:`StartChoice`); empty otherwise."""
    start_reason: str = ""
    """Why this start was used (:attr:`StartChoice.reason`)."""
    g2o_chi2: float = float("nan")
    """g2o's χ² of the solution over every edge (:func:`slamkit.optim.g2o_chi2`), whatever
    the objective minimised (set by :func:`optimize` unless called with
    ``objectives=False``)."""
    sesync_objective: float = float("nan")
    """SE-Sync's ``F`` of the solution over the relative-pose edges
    (:func:`slamkit.optim.sesync_objective`; set by :func:`optimize` unless called with
    ``objectives=False``)."""

    def as_graph(self, data: GraphData) -> GraphData:
        """``data`` with its vertices replaced by the optimised values (for a writer)."""
        return replace(
            data,
            pose_ids=self.pose_ids.copy(),
            poses=self.poses.copy(),
            landmark_ids=self.landmark_ids.copy(),
            landmarks=self.landmarks.copy(),
        )


@runtime.blas_threads()  # the library's thread policy (docs/performance.md)
def optimize(
    data: GraphData,
    config: OptimizerConfig | None = None,
    *,
    initial_poses: FloatArray | None = None,
    initial_landmarks: FloatArray | None = None,
    callback: Callback | None = None,
    problem: GraphProblem | None = None,
    objectives: bool = True,
) -> OptimizeResult:
    """Minimise the graph's cost from the configured (or given) starting values.

    ``initial_poses`` ``(N, 3)`` (3D: ``(N, 7)``, ``(x, y, z, qw, qx, qy, qz)``) and
    ``initial_landmarks`` ``(L, 2)`` follow the problem's
    ``pose_ids`` / ``landmark_ids`` (the file's vertex order; sorted ids when the file has no
    vertices). ``callback(info)`` runs after every iteration; returning ``True`` stops.
    ``problem`` may pass a prebuilt :class:`GraphProblem` of ``data`` (built with the same
    objective and gauge) to skip validation. ``objectives=False`` skips evaluating g2o's χ²
    and SE-Sync's ``F`` of the solution (:attr:`OptimizeResult.g2o_chi2` and
    :attr:`OptimizeResult.sesync_objective` are then NaN): one residual evaluation per
    objective that a caller solving a growing graph after every change never reads.

    It runs with one BLAS thread unless a caller or the environment chose a count
    (:func:`slamkit.runtime.blas_threads`).
    """
    cfg = config if config is not None else OptimizerConfig()
    t_start = time.perf_counter()
    if problem is None:
        problem = GraphProblem.from_data(data, objective=cfg.objective, gauge=cfg.gauge)
    init_used, start_costs, start_reason = "given", _NO_COSTS, "initial values given"
    if initial_poses is None or (initial_landmarks is None and problem.landmark_ids.shape[0]):
        choice = choose_start(problem, cfg)
        init_used, start_costs, start_reason = choice.name, choice.costs, choice.reason
        if initial_poses is not None:
            init_used, start_costs = "given", _NO_COSTS
            start_reason = f"initial poses given; landmarks from the {choice.name} start"
        poses = choice.poses if initial_poses is None else np.array(initial_poses, float)
        landmarks = (
            choice.landmarks if initial_landmarks is None else np.array(initial_landmarks, float)
        )
    else:
        poses = np.array(initial_poses, dtype=np.float64)
        landmarks = (
            np.zeros((0, 2))
            if initial_landmarks is None
            else np.array(initial_landmarks, dtype=np.float64)
        )
    width = 3 if problem.dim == 2 else 7
    if poses.shape != (problem.pose_ids.shape[0], width):
        raise GeometryError(
            f"initial_poses: expected shape ({problem.pose_ids.shape[0]}, {width}), "
            f"got {poses.shape}"
        )
    if landmarks.shape != (problem.landmark_ids.shape[0], 2):
        raise GeometryError(
            f"initial_landmarks: expected shape ({problem.landmark_ids.shape[0]}, 2), "
            f"got {landmarks.shape}"
        )
    if not (np.isfinite(poses).all() and np.isfinite(landmarks).all()):
        raise GeometryError("initial values: NaN or infinity")
    poses = problem.to_internal(poses)
    ctx = SolverContext(problem, cfg.kernel, make_factorizer(cfg.linear_solver, problem.pattern))
    setup = time.perf_counter() - t_start
    start = ctx.linearize(poses, landmarks)
    if not np.isfinite(start.lin.cost):
        raise ConvergenceError("the cost at the initial values is not finite", step=0)
    history: list[IterationInfo] = []
    out = run_least_squares(ctx, start, make_step(cfg), cfg.stopping, history, callback)
    total = time.perf_counter() - t_start
    end = out.estimate
    g2o_value = sesync_value = float("nan")
    if objectives:
        g2o_value, sesync_value = problem.objective_values(end.poses, end.landmarks)
    return OptimizeResult(
        pose_ids=problem.pose_ids.copy(),
        poses=problem.to_external(end.poses),
        landmark_ids=problem.landmark_ids.copy(),
        landmarks=end.landmarks,
        cost=end.lin.cost,
        initial_cost=start.lin.cost,
        chi2=end.lin.chi2,
        iterations=out.iterations,
        factorizations=ctx.factorizations,
        converged=out.converged,
        reason=out.reason,
        method=cfg.solver,
        objective=cfg.objective,
        linear_solver=ctx.factorizer.name,
        anchored_first=problem.anchored_first,
        setup_seconds=setup,
        assembly_seconds=ctx.assembly_seconds,
        factor_seconds=ctx.factor_seconds,
        total_seconds=total,
        history=tuple(history),
        initialization=init_used,
        start_costs=start_costs,
        start_reason=start_reason,
        g2o_chi2=g2o_value,
        sesync_objective=sesync_value,
    )


def resolve_initialization(problem: GraphProblem, name: str) -> str:
    """The initialisation ``"auto"`` stands for before any cost is evaluated: the file's
    vertices when it has them, else ``"grow"`` for graphs with landmark readings (the
    odometry start of a long trajectory whose landmarks close loops lies in a bad basin, as
    on Victoria Park: see ``docs/estimators/optim.md``), else the odometry spanning tree.
    :func:`choose_start` compares that start of a pose graph with the chordal one."""
    if name != "auto":
        return name
    if problem.data.poses.shape[0]:
        return "vertices"
    if any(blk.b_is_landmark for blk in problem.blocks):
        return "grow"
    return "odometry"


def _start_values(
    problem: GraphProblem, name: str, cfg: OptimizerConfig
) -> tuple[FloatArray, FloatArray]:
    if name == "grow":
        return grow_initialization(problem, cfg)
    return initial_values(problem, name, cfg.linear_solver)


def _start_cost(
    problem: GraphProblem, poses: FloatArray, landmarks: FloatArray, cfg: OptimizerConfig
) -> float:
    lin = problem.linearize(problem.to_internal(poses), landmarks, cfg.kernel, jacobians=False)
    return float(lin.cost)


def choose_start(problem: GraphProblem, config: OptimizerConfig | None = None) -> StartChoice:
    """The starting values of ``config.initialization``, chosen by evidence for ``"auto"``.

    A named start is computed as asked. ``"auto"`` on a graph with landmark readings is the
    file's vertices, else the grown-prefix start (:func:`resolve_initialization`). On a pose
    graph it evaluates the cost (objective and robust kernel of ``config``) of two starts, the
    file's vertices (odometry chaining when the file has none) and the chordal relaxation,
    and takes the lower, the file's on a tie or when the chordal system is singular. Why: a
    start far from the optimum can leave the solver in another basin or short of its
    iteration limit, and the cost is the one evidence available before solving (a file
    whose vertices carry large rotation noise: ``docs/estimators/optim.md``).
    """
    cfg = config if config is not None else OptimizerConfig()
    base = resolve_initialization(problem, cfg.initialization)
    if cfg.initialization != "auto":
        p0, l0 = _start_values(problem, base, cfg)
        return StartChoice(base, p0, l0, _NO_COSTS, f"initialization {base!r} was asked for")
    if base == "grow" or any(blk.b_is_landmark for blk in problem.blocks):
        p0, l0 = _start_values(problem, base, cfg)
        why = (
            "the file's vertices (a landmark graph: the chordal start covers pose edges only)"
            if base == "vertices"
            else "a landmark graph without vertices: solves over growing prefixes"
        )
        return StartChoice(base, p0, l0, _NO_COSTS, why)
    p0, l0 = _start_values(problem, base, cfg)
    own = _start_cost(problem, p0, l0, cfg)
    costs = {base: own}
    label = "the file's vertices" if base == "vertices" else "odometry chaining"
    try:
        pc, lc = _start_values(problem, "chordal", cfg)
    except GeometryError as exc:
        reason = f"{label}: the chordal relaxation failed ({exc})"
        return StartChoice(base, p0, l0, MappingProxyType(costs), reason)
    chordal = _start_cost(problem, pc, lc, cfg)
    costs["chordal"] = chordal
    frozen = MappingProxyType(costs)
    if chordal < own:
        return StartChoice(
            "chordal", pc, lc, frozen, f"chordal: cost {chordal:.6g} < {own:.6g} of {label}"
        )
    return StartChoice(base, p0, l0, frozen, f"{label}: cost {own:.6g} <= {chordal:.6g} of chordal")


def _carry(X: FloatArray, X0: FloatArray, anchor: int, rows: slice, dim: int) -> FloatArray:
    """``T · X0[rows]`` with ``T = X[anchor] · X0[anchor]⁻¹`` (internal format): the
    not-yet-optimised rows follow the rigid correction of the last optimised pose."""
    if dim == 2:
        T = pose2.compose(X[anchor], pose2.inverse(X0[anchor]))
        return pose2.compose(T, X0[rows])
    R, R0 = X[anchor, 3:].reshape(3, 3), X0[anchor, 3:].reshape(3, 3)
    RT = R @ R0.T
    tT = X[anchor, :3] - RT @ X0[anchor, :3]
    out = np.empty_like(X0[rows])
    out[:, :3] = X0[rows, :3] @ RT.T + tT
    out[:, 3:] = (RT @ X0[rows, 3:].reshape(-1, 3, 3)).reshape(-1, 9)
    return out


def _prefix_graph(
    problem: GraphProblem, k: int, poses: FloatArray, landmarks: FloatArray
) -> tuple[GraphData, IntArray]:
    """The graph of the first ``k`` pose rows at ``poses``/``landmarks`` (file formats): every
    edge whose poses lie in the prefix, and landmarks once the prefix holds at least two rows
    of their readings (one ``se2_xy`` or ``range_bearing``, or two ranges/bearings), so
    that each one is determined. Returns the graph and the landmark rows it holds."""
    data = problem.data
    n_l = problem.landmark_ids.shape[0]
    rows_seen = np.zeros(n_l)
    for blk in problem.blocks:
        if blk.b is not None and blk.b_is_landmark:
            np.add.at(rows_seen, blk.b[blk.a < k], float(blk.m))
    lm_in = rows_seen >= 2
    edges: list[EdgeSet] = []
    for blk in problem.blocks:
        keep = blk.a < k
        if blk.b is not None:
            keep &= lm_in[blk.b] if blk.b_is_landmark else blk.b < k
        es = blk.edges
        edges.append(
            EdgeSet(
                es.kind,
                es.i[keep],
                es.j[keep],
                es.measurement[keep],
                es.information[keep],
                es.lines[keep],
            )
        )
    ids = problem.pose_ids[:k]
    eq = np.asarray(data.equivalences, dtype=np.int64).reshape(-1, 2)
    eq = eq[np.isin(eq, ids).all(axis=1)]
    lm_rows = np.flatnonzero(lm_in)
    sub = GraphData(
        dim=data.dim,
        pose_ids=ids.copy(),
        poses=poses[:k].copy(),
        landmark_ids=problem.landmark_ids[lm_rows].copy(),
        landmarks=landmarks[lm_rows].copy(),
        edges=tuple(edges),
        fixed_ids=ids[problem.fixed[:k]].copy(),
        equivalences=eq,
        family=data.family,
        source=data.source,
    )
    return sub, lm_rows


def grow_initialization(
    problem: GraphProblem, config: OptimizerConfig | None = None
) -> tuple[FloatArray, FloatArray]:
    """Starting ``(poses, landmarks)`` (file formats) from batch solves over growing prefixes.

    Poses are taken in time order (rows of ``pose_ids``: the file's vertex order, or sorted
    ids). Starting from the odometry spanning tree, the first ``grow.initial_poses`` poses
    and the edges among them are optimised with ``config`` (relative tolerance
    ``grow.relative_tolerance``); the remaining poses and unplaced landmarks are moved by the
    rigid correction of the last optimised pose; then the prefix doubles (adding at most
    ``grow.max_step`` poses) until it covers the graph. Each solve starts close to its
    optimum, as in an incremental smoother; the cost is a few batch solves of growing size
    (the Victoria Park count and time are in ``docs/estimators/optim.md``). A prefix that does
    not form a valid graph (ids out of time order, so it falls apart) is skipped.
    """
    cfg = config if config is not None else OptimizerConfig()
    p0, l0 = initial_values(problem, "odometry", cfg.linear_solver)
    n = problem.pose_ids.shape[0]
    X0 = problem.to_internal(p0)
    X, L = X0.copy(), l0.copy()
    placed = np.zeros(L.shape[0], dtype=bool)
    rtol = max(cfg.stopping.relative_tolerance, cfg.grow.relative_tolerance)
    stage = replace(
        cfg, initialization="vertices", stopping=replace(cfg.stopping, relative_tolerance=rtol)
    )
    k = min(cfg.grow.initial_poses, n)
    while k < n:
        sub, lm_rows = _prefix_graph(problem, k, problem.to_external(X), L)
        try:
            sub_problem = GraphProblem.from_data(sub, objective=cfg.objective, gauge="anchor_first")
        except SlamkitError:
            sub_problem = None
        if sub_problem is not None:
            res = optimize(sub, stage, problem=sub_problem)
            X[:k] = problem.to_internal(res.poses)
            L[lm_rows] = res.landmarks
            placed[lm_rows] = True
            X[k:] = _carry(X, X0, k - 1, slice(k, n), problem.dim)
            if (~placed).any():
                T = pose2.compose(X[k - 1], pose2.inverse(X0[k - 1]))
                L[~placed] = pose2.transform_points(T, l0[~placed])
        k = min(2 * k, k + cfg.grow.max_step, n)
    return problem.to_external(X[problem.alias]), L
