"""Gauss-Newton, Levenberg-Marquardt and Powell's dogleg on the sparse normal equations.

The problem (drawn for a four-pose loop)::

      X0 ──Z01──▶ X1          cost f(x) = Σ_k ρ(‖U_k e_k(x)‖²)
      ▲            │          e_k: g2o error of Z⁻¹ X_i⁻¹ X_j, or SE-Sync's chordal residual
     Z30          Z12         U_k: upper Cholesky factor of the information Ω_k
      │            ▼          X0 fixed (gauge) unless the file fixes a pose or has a prior
      X3 ◀──Z23── X2

Each iteration linearises all edges at once (:meth:`GraphProblem.linearize`): ``H = Jᵀ W J``
and ``g = Jᵀ W r`` (``W`` the IRLS weights of the robust kernel) in a sparsity pattern fixed at
the start, factors ``H`` (or ``H + λD``) with a sparse Cholesky whose symbolic analysis is
done once, and moves the poses on the manifold by ``X ⊕ δ`` (SE(2) or SE(3)). The model of
the cost around ``x`` is ``m(δ) = f + 2 gᵀδ + δᵀ H δ`` (``f`` has no ½), so the Gauss-Newton
step solves ``H δ = -g``.

* **GN** takes every step.
* **LM** solves ``(H + λD) δ = -g`` with ``D = I`` (``damping="levenberg"``, GTSAM's default)
  or ``D = diag(H)`` (``"marquardt"``); a step is accepted when it lowers ``f``, then
  ``λ ← λ / lambda_factor``, else ``λ ← λ · lambda_factor`` and the system is refactored.
* **Dogleg** factors ``H`` once per linearisation; inside the trust region of radius ``Δ`` it
  takes the GN step ``δ_gn``, else the Cauchy step ``-α g`` (``α = ‖g‖² / gᵀHg``) cut at
  ``Δ``, else the point of the dogleg path ``-αg → δ_gn`` at distance ``Δ``. With the gain
  ratio ``ϱ = (f - f_new) / (m(0) - m(δ))``: accept when ``ϱ > 0``; ``Δ ← max(Δ, 3‖δ‖)`` when
  ``ϱ > 0.75``, ``Δ ← Δ / 2`` when ``ϱ < 0.25`` (Madsen, Nielsen & Tingleff, 2004).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from slamkit.errors import ConfigError, ConvergenceError, GeometryError, SlamkitError
from slamkit.geometry import pose2
from slamkit.optim.data import EdgeSet, FloatArray, GraphData, IntArray
from slamkit.optim.graph import GaugeMode, GraphProblem, Linearization, ObjectiveName
from slamkit.optim.init import initial_values
from slamkit.optim.robust import DEFAULT_WIDTHS, KernelName, RobustKernel
from slamkit.optim.sparse import Factorizer, LinearSolverName, SingularSystem, make_factorizer

__all__ = [
    "IterationInfo",
    "OptimizeResult",
    "OptimizerConfig",
    "grow_initialization",
    "optimize",
    "resolve_initialization",
]

MethodName = Literal["lm", "gn", "dogleg"]
InitName = Literal["auto", "vertices", "odometry", "chordal", "grow"]


@dataclass(frozen=True)
class OptimizerConfig:
    """Settings of :func:`optimize`. ``f`` is the cost ``Σ ρ(‖U e‖²)`` (χ² without robust
    kernel, no factor ½). An *iteration* is one linearisation; LM may factor several damped
    systems and dogleg try several radii inside one iteration."""

    method: MethodName = "lm"
    """``"lm"`` (Levenberg-Marquardt), ``"gn"`` (Gauss-Newton) or ``"dogleg"`` (Powell)."""
    objective: ObjectiveName = "g2o"
    """``"g2o"``: ``Σ eᵀ Ω e`` with g2o's SE(2) error; ``"sesync"``: SE-Sync's ``F`` for the
    relative-pose edges (other edge kinds keep their g2o error)."""
    initialization: InitName = "auto"
    """``"vertices"``, ``"odometry"`` (spanning tree), ``"chordal"``, ``"grow"`` (batch solves
    over growing time-ordered prefixes, see :func:`grow_initialization`), or ``"auto"``:
    vertices when the file has them, else ``"grow"`` when the graph has landmark readings,
    else odometry. Ignored when initial values are passed."""
    grow_initial_poses: int = 250
    """``"grow"``: poses (rows in ``pose_ids`` order, i.e. time order) in the first prefix."""
    grow_max_step: int = 1500
    """``"grow"``: each prefix doubles, adding at most this many poses."""
    grow_relative_tolerance: float = 1e-3
    """``"grow"``: the ``relative_tolerance`` of the prefix solves (the last, full solve uses
    ``relative_tolerance``); they only need to land in the right basin."""
    gauge: GaugeMode = "anchor_first"
    """``"anchor_first"``: with no fixed pose and no prior, hold the first pose fixed;
    ``"none"``: raise :class:`~slamkit.errors.GeometryError` in that case."""
    linear_solver: LinearSolverName = "auto"
    """Sparse Cholesky back-end: ``"cholmod"`` (needs cvxopt), ``"superlu"``, ``"dense"``;
    ``"auto"`` is CHOLMOD when available, else SuperLU."""
    max_iterations: int = 100
    """Stop after this many linearisations (``converged = False``)."""
    relative_tolerance: float = 1e-6
    """Stop (converged) after a step when ``|f_old - f_new| ≤ relative_tolerance · f_old``."""
    absolute_tolerance: float = 1e-9
    """Stop (converged) after a step when ``|f_old - f_new| ≤ absolute_tolerance``."""
    gradient_tolerance: float = 0.0
    """Stop (converged) before solving when ``max |g| ≤ gradient_tolerance`` (``g = JᵀWr``)."""
    step_tolerance: float = 1e-12
    """Stop (converged) after a step when ``max |δ| ≤ step_tolerance`` (tangent units)."""
    lambda_initial: float = 1e-5
    """LM: the first damping ``λ``."""
    lambda_factor: float = 10.0
    """LM: ``λ`` is divided by this after an accepted step and multiplied after a rejected one."""
    lambda_max: float = 1e10
    """LM: stop (``converged = False``) when ``λ`` exceeds this without finding a decrease."""
    damping: Literal["levenberg", "marquardt"] = "levenberg"
    """LM: ``D = I`` (``"levenberg"``) or ``D = diag(H)`` (``"marquardt"``)."""
    trust_radius_initial: float = 1.0
    """Dogleg: the first trust-region radius ``Δ`` (max-norm-free Euclidean, tangent units)."""
    trust_radius_min: float = 1e-12
    """Dogleg: stop (``converged = False``) when ``Δ`` shrinks below this."""
    robust_kernel: KernelName = "none"
    """``"none"``, ``"huber"``, ``"cauchy"``, ``"geman_mcclure"`` or ``"dcs"`` (all edges)."""
    robust_width: float | None = None
    """Kernel width (δ, c or φ; see :mod:`slamkit.optim.robust`); ``None``: the kernel's
    default, :data:`~slamkit.optim.robust.DEFAULT_WIDTHS` (read :attr:`kernel`)."""

    def __post_init__(self) -> None:
        if self.method not in ("lm", "gn", "dogleg"):
            raise ConfigError(f"method: expected 'lm', 'gn' or 'dogleg', got {self.method!r}")
        if self.max_iterations < 0:
            raise ConfigError(f"max_iterations: expected >= 0, got {self.max_iterations}")
        for name in (
            "relative_tolerance",
            "absolute_tolerance",
            "gradient_tolerance",
            "step_tolerance",
            "trust_radius_min",
        ):
            v = getattr(self, name)
            if not (v >= 0 and np.isfinite(v)):
                raise ConfigError(f"{name}: expected a finite number >= 0, got {v}")
        for name in ("grow_initial_poses", "grow_max_step"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name}: expected >= 1, got {getattr(self, name)}")
        for name in (
            "lambda_initial",
            "lambda_max",
            "trust_radius_initial",
            "grow_relative_tolerance",
        ):
            v = getattr(self, name)
            if not (v > 0 and np.isfinite(v)):
                raise ConfigError(f"{name}: expected a finite number > 0, got {v}")
        if not self.lambda_factor > 1:
            raise ConfigError(f"lambda_factor: expected > 1, got {self.lambda_factor}")
        _ = self.kernel  # validates the name and the width

    @property
    def kernel(self) -> RobustKernel:
        """The robust kernel with its width resolved (``robust_width`` or the default)."""
        width = self.robust_width
        if width is None:
            width = DEFAULT_WIDTHS.get(self.robust_kernel, 1.0)
        return RobustKernel(self.robust_kernel, width)


@dataclass(frozen=True)
class IterationInfo:
    """What the callback sees after each iteration."""

    iteration: int
    cost: float  # f after the iteration
    chi2: float  # Σ ‖U e‖² (equals cost without robust kernel)
    step_norm: float  # max |δ| of the accepted step (0 when none was accepted)
    accepted: bool
    damping: float  # LM λ or dogleg Δ used for the accepted (or last) attempt
    factorizations: int  # cumulative
    assembly_seconds: float  # this iteration: residuals, Jacobians, H and g
    factor_seconds: float  # this iteration: numeric factorisations and solves


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
    g2o_chi2: float = float("nan")
    """g2o's χ² of the solution over every edge (:func:`slamkit.optim.g2o_chi2`), whatever
    the objective minimised (set by :func:`optimize`)."""
    sesync_objective: float = float("nan")
    """SE-Sync's ``F`` of the solution over the relative-pose edges
    (:func:`slamkit.optim.sesync_objective`; set by :func:`optimize`)."""

    def as_graph(self, data: GraphData) -> GraphData:
        """``data`` with its vertices replaced by the optimised values (for a writer)."""
        return replace(
            data,
            pose_ids=self.pose_ids.copy(),
            poses=self.poses.copy(),
            landmark_ids=self.landmark_ids.copy(),
            landmarks=self.landmarks.copy(),
        )


Callback = Callable[[IterationInfo], bool | None]


class _Solver:
    """State shared by the three methods: the problem, the factoriser, timings, counters."""

    def __init__(self, problem: GraphProblem, config: OptimizerConfig) -> None:
        self.problem = problem
        self.config = config
        self.kernel = config.kernel
        self.pattern = problem.pattern
        self.factorizer: Factorizer = make_factorizer(config.linear_solver, self.pattern)
        self.factorizations = 0
        self.factor_seconds = 0.0
        self.assembly_seconds = 0.0

    def linearize(self, poses: FloatArray, landmarks: FloatArray) -> Linearization:
        lin = self.problem.linearize(poses, landmarks, self.kernel)
        self.assembly_seconds += lin.seconds
        return lin

    def info(
        self,
        iteration: int,
        lin: Linearization,
        step: float,
        accepted: bool,
        damping: float,
        since: tuple[float, float],
    ) -> IterationInfo:
        """The callback's record of an iteration that began when the assembly and factor
        clocks read ``since``."""
        return IterationInfo(
            iteration,
            lin.cost,
            lin.chi2,
            step,
            accepted,
            damping,
            self.factorizations,
            self.assembly_seconds - since[0],
            self.factor_seconds - since[1],
        )

    def solve(self, H: FloatArray, g: FloatArray, shift: FloatArray | None) -> FloatArray:
        """``δ = -(H + shift)⁻¹ g`` (``shift`` added to the diagonal)."""
        t0 = time.perf_counter()
        data = H
        if shift is not None:
            data = H.copy()
            data[self.pattern.diag] += shift
        try:
            self.factorizations += 1
            self.factorizer.factor(data)
            delta = -self.factorizer.solve(g)
        finally:
            self.factor_seconds += time.perf_counter() - t0
        return delta


def indeterminate_error(problem: GraphProblem, exc: SingularSystem, H: FloatArray) -> GeometryError:
    """The error for a singular ``H``, naming the variable of the failed pivot and every
    variable whose own diagonal block is singular."""
    parts = []
    if exc.column is not None and 0 <= exc.column < problem.n:
        parts.append(f"the factorisation failed at {problem.variable_of_column(exc.column)}")
    alone = problem.singular_blocks(H)
    if alone:
        more = f" and {len(alone) - 8} more" if len(alone) > 8 else ""
        parts.append(
            f"{', '.join(alone[:8])}{more} "
            + ("is not determined by its" if len(alone) == 1 else "are not determined by their")
            + " own edges (too few readings)"
        )
    detail = "; ".join(parts) if parts else f"{exc}"
    return GeometryError(
        f"the normal equations are singular ({problem.n} unknowns), so some variable is not "
        f"determined by its edges: {detail}"
    )


def optimize(
    data: GraphData,
    config: OptimizerConfig | None = None,
    *,
    initial_poses: FloatArray | None = None,
    initial_landmarks: FloatArray | None = None,
    callback: Callback | None = None,
    problem: GraphProblem | None = None,
) -> OptimizeResult:
    """Minimise the graph's cost from the configured (or given) starting values.

    ``initial_poses`` ``(N, 3)`` (3D: ``(N, 7)``, ``(x, y, z, qw, qx, qy, qz)``) and
    ``initial_landmarks`` ``(L, 2)`` follow the problem's
    ``pose_ids`` / ``landmark_ids`` (the file's vertex order; sorted ids when the file has no
    vertices). ``callback(info)`` runs after every iteration; returning ``True`` stops.
    ``problem`` may pass a prebuilt :class:`GraphProblem` of ``data`` (built with the same
    objective and gauge) to skip validation.
    """
    cfg = config if config is not None else OptimizerConfig()
    t_start = time.perf_counter()
    if problem is None:
        problem = GraphProblem.from_data(data, objective=cfg.objective, gauge=cfg.gauge)
    init_used = "given"
    if initial_poses is None or (initial_landmarks is None and problem.landmark_ids.shape[0]):
        init_used = resolve_initialization(problem, cfg.initialization)
        if init_used == "grow":
            p0, l0 = grow_initialization(problem, cfg)
        else:
            p0, l0 = initial_values(problem, init_used, cfg.linear_solver)
        if initial_poses is not None:
            init_used = "given"
        poses = p0 if initial_poses is None else np.array(initial_poses, dtype=np.float64)
        landmarks = l0 if initial_landmarks is None else np.array(initial_landmarks, float)
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
    solver = _Solver(problem, cfg)
    setup = time.perf_counter() - t_start
    lin = solver.linearize(poses, landmarks)
    if not np.isfinite(lin.cost):
        raise ConvergenceError("the cost at the initial values is not finite", step=0)
    initial_cost = lin.cost
    history: list[IterationInfo] = []
    method = {"gn": _gauss_newton, "lm": _levenberg_marquardt, "dogleg": _dogleg}[cfg.method]
    poses, landmarks, lin, iterations, converged, reason = method(
        solver, poses, landmarks, lin, history, callback
    )
    total = time.perf_counter() - t_start
    g2o_value, sesync_value = problem.objective_values(poses, landmarks)
    return OptimizeResult(
        pose_ids=problem.pose_ids.copy(),
        poses=problem.to_external(poses),
        landmark_ids=problem.landmark_ids.copy(),
        landmarks=landmarks,
        cost=lin.cost,
        initial_cost=initial_cost,
        chi2=lin.chi2,
        iterations=iterations,
        factorizations=solver.factorizations,
        converged=converged,
        reason=reason,
        method=cfg.method,
        objective=cfg.objective,
        linear_solver=solver.factorizer.name,
        anchored_first=problem.anchored_first,
        setup_seconds=setup,
        assembly_seconds=solver.assembly_seconds,
        factor_seconds=solver.factor_seconds,
        total_seconds=total,
        history=tuple(history),
        initialization=init_used,
        g2o_chi2=g2o_value,
        sesync_objective=sesync_value,
    )


def resolve_initialization(problem: GraphProblem, name: str) -> str:
    """The initialisation ``"auto"`` stands for: the file's vertices when it has them, else
    ``"grow"`` for graphs with landmark readings (the odometry start of a long trajectory
    whose landmarks close loops lies in a bad basin: on Victoria Park LM from it stops at
    χ² ≈ 5e5, from the grown start at 6184), else the odometry spanning tree."""
    if name != "auto":
        return name
    if problem.data.poses.shape[0]:
        return "vertices"
    if any(blk.b_is_landmark for blk in problem.blocks):
        return "grow"
    return "odometry"


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
    ids). Starting from the odometry spanning tree, the first ``grow_initial_poses`` poses
    and the edges among them are optimised with ``config`` (tolerance
    ``grow_relative_tolerance``); the remaining poses and unplaced landmarks are moved by the
    rigid correction of the last optimised pose; then the prefix doubles (adding at most
    ``grow_max_step`` poses) until it covers the graph. Each solve starts close to its
    optimum, as in an incremental smoother; the cost is a few batch solves of growing size
    (on Victoria Park seven prefixes before the full solve, 1.3 s in all). A prefix that does
    not form a valid graph (ids out of time order, so it falls apart) is skipped.
    """
    cfg = config if config is not None else OptimizerConfig()
    p0, l0 = initial_values(problem, "odometry", cfg.linear_solver)
    n = problem.pose_ids.shape[0]
    X0 = problem.to_internal(p0)
    X, L = X0.copy(), l0.copy()
    placed = np.zeros(L.shape[0], dtype=bool)
    stage = replace(
        cfg,
        initialization="vertices",
        relative_tolerance=max(cfg.relative_tolerance, cfg.grow_relative_tolerance),
    )
    k = min(cfg.grow_initial_poses, n)
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
        k = min(2 * k, k + cfg.grow_max_step, n)
    return problem.to_external(X[problem.alias]), L


_Outcome = tuple[FloatArray, FloatArray, Linearization, int, bool, str]


def _small_change(cfg: OptimizerConfig, f_old: float, f_new: float, step: float) -> str | None:
    change = abs(f_old - f_new)
    if change <= cfg.absolute_tolerance:
        return f"cost change {change:.3g} <= absolute_tolerance"
    if change <= cfg.relative_tolerance * abs(f_old):
        return f"relative cost change {change / max(abs(f_old), 1e-300):.3g} <= relative_tolerance"
    if step <= cfg.step_tolerance:
        return f"step {step:.3g} <= step_tolerance"
    return None


def _gradient_small(cfg: OptimizerConfig, lin: Linearization) -> str | None:
    assert lin.g is not None
    gmax = float(np.max(np.abs(lin.g))) if lin.g.shape[0] else 0.0
    if gmax <= cfg.gradient_tolerance:
        return f"gradient {gmax:.3g} <= gradient_tolerance"
    return None


def _notify(history: list[IterationInfo], callback: Callback | None, info: IterationInfo) -> bool:
    history.append(info)
    return bool(callback(info)) if callback is not None else False


def _gauss_newton(
    s: _Solver,
    poses: FloatArray,
    landmarks: FloatArray,
    lin: Linearization,
    history: list[IterationInfo],
    callback: Callback | None,
) -> _Outcome:
    cfg = s.config
    for it in range(1, cfg.max_iterations + 1):
        why = _gradient_small(cfg, lin)
        if why:
            return poses, landmarks, lin, it - 1, True, why
        a0, f0 = s.assembly_seconds, s.factor_seconds
        assert lin.H is not None and lin.g is not None
        try:
            delta = s.solve(lin.H, lin.g, None)
        except SingularSystem as exc:
            raise indeterminate_error(s.problem, exc, lin.H) from None
        poses, landmarks = s.problem.retract(poses, landmarks, delta)
        new = s.linearize(poses, landmarks)
        if not np.isfinite(new.cost):
            raise ConvergenceError("Gauss-Newton produced a non-finite cost", step=it)
        step = float(np.max(np.abs(delta))) if delta.shape[0] else 0.0
        why = _small_change(cfg, lin.cost, new.cost, step)
        lin = new
        info = s.info(it, lin, step, True, 0.0, (a0, f0))
        if _notify(history, callback, info):
            return poses, landmarks, lin, it, False, "stopped by the callback"
        if why:
            return poses, landmarks, lin, it, True, why
    return poses, landmarks, lin, cfg.max_iterations, False, "max_iterations reached"


def _levenberg_marquardt(
    s: _Solver,
    poses: FloatArray,
    landmarks: FloatArray,
    lin: Linearization,
    history: list[IterationInfo],
    callback: Callback | None,
) -> _Outcome:
    cfg = s.config
    lam = cfg.lambda_initial
    for it in range(1, cfg.max_iterations + 1):
        why = _gradient_small(cfg, lin)
        if why:
            return poses, landmarks, lin, it - 1, True, why
        a0, f0 = s.assembly_seconds, s.factor_seconds
        assert lin.H is not None and lin.g is not None
        diag = lin.H[s.pattern.diag]
        while True:
            shift = lam * (np.maximum(diag, 1e-12) if cfg.damping == "marquardt" else 1.0)
            shift_arr = np.broadcast_to(np.asarray(shift, dtype=np.float64), diag.shape)
            try:
                delta = s.solve(lin.H, lin.g, shift_arr)
                p_new, l_new = s.problem.retract(poses, landmarks, delta)
                new = s.linearize(p_new, l_new)
                ok = bool(np.isfinite(new.cost) and new.cost < lin.cost)
            except SingularSystem:
                ok = False
            if ok:
                break
            lam *= cfg.lambda_factor
            if lam > cfg.lambda_max:
                info = s.info(it, lin, 0.0, False, lam, (a0, f0))
                _notify(history, callback, info)
                return (
                    poses,
                    landmarks,
                    lin,
                    it,
                    False,
                    "no decrease found (lambda > lambda_max)",
                )
        step = float(np.max(np.abs(delta))) if delta.shape[0] else 0.0
        why = _small_change(cfg, lin.cost, new.cost, step)
        info = s.info(it, new, step, True, lam, (a0, f0))
        poses, landmarks, lin = p_new, l_new, new
        lam = max(lam / cfg.lambda_factor, 1e-20)
        if _notify(history, callback, info):
            return poses, landmarks, lin, it, False, "stopped by the callback"
        if why:
            return poses, landmarks, lin, it, True, why
    return poses, landmarks, lin, cfg.max_iterations, False, "max_iterations reached"


def _dogleg(
    s: _Solver,
    poses: FloatArray,
    landmarks: FloatArray,
    lin: Linearization,
    history: list[IterationInfo],
    callback: Callback | None,
) -> _Outcome:
    cfg = s.config
    radius = cfg.trust_radius_initial
    for it in range(1, cfg.max_iterations + 1):
        why = _gradient_small(cfg, lin)
        if why:
            return poses, landmarks, lin, it - 1, True, why
        a0, f0 = s.assembly_seconds, s.factor_seconds
        H, g = lin.H, lin.g
        assert H is not None and g is not None
        try:
            h_gn = s.solve(H, g, None)
        except SingularSystem as exc:
            raise indeterminate_error(s.problem, exc, H) from None
        Hg = s.pattern.matvec(H, g)
        gg = float(g @ g)
        gHg = float(g @ Hg)
        alpha = gg / gHg if gHg > 0 else 0.0
        h_sd = -alpha * g  # the Cauchy point (minimiser of the model along -g)
        n_gn = float(np.linalg.norm(h_gn))
        n_sd = float(np.linalg.norm(h_sd))
        while True:
            if n_gn <= radius:
                h = h_gn
            elif n_sd >= radius:
                h = h_sd * (radius / n_sd)
            else:
                # ‖h_sd + β (h_gn - h_sd)‖ = Δ, β in [0, 1]: the positive root of a quadratic.
                d = h_gn - h_sd
                a2, b2, c2 = float(d @ d), float(2 * h_sd @ d), n_sd**2 - radius**2
                beta = (-b2 + np.sqrt(b2 * b2 - 4 * a2 * c2)) / (2 * a2)
                h = h_sd + beta * d
            predicted = -2.0 * float(g @ h) - float(h @ s.pattern.matvec(H, h))
            p_new, l_new = s.problem.retract(poses, landmarks, h)
            new = s.linearize(p_new, l_new)
            gain = (lin.cost - new.cost) / predicted if predicted > 0 else -1.0
            if not np.isfinite(new.cost):
                gain = -1.0
            h_norm = float(np.linalg.norm(h))
            if gain > 0.75:
                radius = max(radius, 3.0 * h_norm)
            elif gain < 0.25:
                radius = radius / 2.0
            if gain > 0:
                break
            if radius < cfg.trust_radius_min:
                info = s.info(it, lin, 0.0, False, radius, (a0, f0))
                _notify(history, callback, info)
                return (
                    poses,
                    landmarks,
                    lin,
                    it,
                    False,
                    "no decrease found (trust radius < trust_radius_min)",
                )
        step = float(np.max(np.abs(h))) if h.shape[0] else 0.0
        why = _small_change(cfg, lin.cost, new.cost, step)
        info = s.info(it, new, step, True, radius, (a0, f0))
        poses, landmarks, lin = p_new, l_new, new
        if _notify(history, callback, info):
            return poses, landmarks, lin, it, False, "stopped by the callback"
        if why:
            return poses, landmarks, lin, it, True, why
    return poses, landmarks, lin, cfg.max_iterations, False, "max_iterations reached"
