"""Multilevel relaxation (Frese, Larsson & Duckett, IEEE T-RO 21(2), 2005) and plain block
Gauss-Seidel: the Gauss-Newton step of a 2D pose graph found without a factorisation.

Each iteration of the least-squares loop (:mod:`slamkit.optim.loop`) linearises the graph as
the other solvers do (``H``, ``g`` in the fixed pattern) and solves ``H δ = -g``
approximately, then moves the poses by ``X ⊕ δ``. No factor is formed, so nothing fills in:
every level holds sparse matrices only (their total against the Cholesky factor's is
measured in ``docs/estimators/optim.md``).

**Block Gauss-Seidel** (the relaxation). Split ``H = D + L + U`` into its 3x3 diagonal
blocks (one per pose), strict block-lower and block-upper parts. A forward sweep solves each
pose's block with all others held, in order, i.e. ``(D + L) x' = b - U x``; written as
``(I + D⁻¹L) x' = D⁻¹(b - U x)`` the matrix is *unit* lower triangular (``D⁻¹L`` is strictly
block-lower, so strictly lower), one sparse triangular solve. The backward sweep is the same
with ``L`` and ``U`` swapped; a forward then backward pair is symmetric Gauss-Seidel.
Relaxation damps the error components that vary from pose to pose within a few sweeps but
barely moves the smooth ones (a whole loop bending): their residual is small compared with
their error, and information travels one edge per sweep.

**The hierarchy.** Level ``k + 1`` groups the nodes of level ``k`` in consecutive runs of
:data:`GROUP_SIZE` (the variable order, which is time order in the shared files), down to at
most :data:`COARSEST_NODES` nodes. Each node carries a frame ``(p, θ)``: a pose's own at
level 0, the mean position of its group and the heading of the group's first node above. A
coarse node's correction ``(u, ω)`` (``u`` in its frame) is a rigid motion of its whole group
about ``p_c``; a member ``i`` with frame ``(p_i, θ_i)`` then moves, in its own tangent
coordinates (the right update ``X ⊕ δ`` moves the position by ``R_i δ_t``), by::

    δ_i = T_i [u; ω],   T_i = [[R_iᵀ R_c,  R_iᵀ J (p_i - p_c)],    J = [[0, -1], [1, 0]]
                               [0,         1               ]]

For members with the group's heading and position ``T_i`` is the identity: the paper's
piecewise-constant interpolation; the lever arm ``J (p_i - p_c)`` adds what a rotated group
does to its members' positions, so bending modes are represented at every level. That
tentative ``T`` alone makes a weak V-cycle, because a piecewise-rigid correction has kinks
at the group borders that cost energy; so on every level the interpolation is smoothed by
one damped block-Jacobi step, ``P = (I - ω D⁻¹H) T`` with ``ω = 4 / (3 ρ(D⁻¹H))`` (smoothed
aggregation; ``ρ`` by a few power iterations), which cuts the error left by one cycle
several-fold (the measurements are in ``docs/estimators/optim.md``). The coarse system is
Galerkin's, ``H_c = Pᵀ H P`` with residual ``Pᵀ r``: the quadratic model restricted to the
interpolated corrections, whose minimiser is the best coarse correction.

**The V-cycle** (:meth:`Hierarchy.v_cycle`): ``sweeps`` forward sweeps, restrict the
residual, recurse (a dense Cholesky solve on the coarsest level), add the prolongated
correction ``e`` scaled by ``α = eᵀr / eᵀHe`` (the step along ``e`` that minimises the
model; it makes up for an inexact coarse solve), ``sweeps`` backward sweeps.

**Krylov acceleration.** The paper iterates V-cycles. Here each V-cycle preconditions a
conjugate-gradient step instead (:func:`multilevel_solve`; ``krylov=False`` gives the plain
iteration): near the minimum the gradient is made of the smoothest modes, which the plain
cycles reduce slowly and not monotonically in the residual (on Intel's g2o objective the
loop stalled), while CG combines the cycles' corrections optimally. The coarse scaling
``α`` depends on the input, so ``β`` is the flexible (Polak-Ribière) one. Per
linearisation MLR runs V-cycles, Gauss-Seidel sweeps alternately forward and backward, from
``δ = 0`` until ``‖H δ + g‖ ≤ linear_tolerance · ‖g‖`` or the budget is spent
(:class:`~slamkit.optim.settings.RelaxationConfig`).

**The step.** The relaxed ``δ`` is damped as Levenberg-Marquardt damps the Gauss-Newton
step with ``D = H`` (:mod:`slamkit.optim.steps`): the trial is ``δ / (1 + λ)``, taken when it
lowers the cost; ``λ`` grows by Nielsen's ``ν`` on a rise and shrinks by the gain ratio on a
decrease, and is kept across iterations. Halving the step afresh in each iteration instead
left MLR at a local minimum on a hard start where GN and LM converge (measured in
``docs/estimators/optim.md``). A step whose linear solve missed its tolerance is *bounded*
(:class:`~slamkit.optim.loop.Step`): its small cost change says the solve was short, not that
the minimum is reached, so the stopping rule does not end the loop on it. A first trial that
raises the cost by less than ``relative_tolerance · f`` is rounding noise at the minimum:
converged, as for the incremental optimiser's backtracking step.
The measurements (where MLR wins over GN/LM and where not) are in
``docs/estimators/optim.md``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from slamkit.errors import ConfigError, ConvergenceError
from slamkit.optim.data import FloatArray
from slamkit.optim.graph import GraphProblem
from slamkit.optim.loop import Estimate, NoStep, SolverContext, Step
from slamkit.optim.settings import RelaxationConfig

__all__ = [
    "COARSEST_NODES",
    "GROUP_SIZE",
    "LAMBDA_INITIAL",
    "LAMBDA_MAX",
    "POWER_ITERATIONS",
    "BlockGaussSeidel",
    "Hierarchy",
    "LinearSolve",
    "RelaxationStep",
    "build_hierarchy",
    "check_relaxation_problem",
    "free_pose_frames",
    "gauss_seidel_solve",
    "interpolation",
    "multilevel_solve",
    "spectral_radius",
    "tentative_interpolation",
]

COARSEST_NODES = 48
"""The coarsest level has at most this many nodes (144 unknowns), solved by dense Cholesky."""
GROUP_SIZE = 4
"""Nodes per coarse node. Smaller groups make the smoothed coarse matrices dense and the
Galerkin products dominate the time; larger ones weaken the cycle until Intel no longer
converges (measurements in ``docs/estimators/optim.md``)."""
POWER_ITERATIONS = 15
"""Power iterations for ``ρ(D⁻¹H)``, the damping of the interpolation's smoothing."""
LAMBDA_INITIAL = 1e-5
"""The first damping ``λ`` of the step ``δ / (1 + λ)`` (LM's default, ``D = H``)."""
LAMBDA_MAX = 1e10
"""No decrease with ``λ`` above this ends the loop (not converged), as for LM."""

BLOCK = 3  # tangent size of a 2D pose


def check_relaxation_problem(problem: GraphProblem, solver: str) -> None:
    """Raise :class:`ConfigError` unless ``problem`` is a 2D pose graph (3x3 blocks only):
    the relaxation solvers' interpolation is that of SE(2) poses."""
    if problem.dim != 2 or problem.landmark_ids.shape[0]:
        what = "a 3D graph" if problem.dim != 2 else "a graph with landmarks"
        raise ConfigError(f"solver {solver!r}: needs a 2D pose graph, got {what}")


def free_pose_frames(problem: GraphProblem, poses: FloatArray) -> FloatArray:
    """``(N, 3)`` poses ``(x, y, θ)`` of the free pose variables, in variable order."""
    var = problem.pose_var
    rows = np.flatnonzero(var >= 0)
    out = np.empty((problem.n_free_poses, BLOCK))
    out[var[rows][::-1]] = poses[rows][::-1]  # the first row of each variable wins
    return out


@dataclass(frozen=True)
class BlockGaussSeidel:
    """Block Gauss-Seidel sweeps on ``A`` (CSR, both triangles) with 3x3 diagonal blocks
    (module docstring): ``A = D + L + U``, kept as ``D⁻¹``, the strictly lower and upper
    parts, and the unit triangular ``I + D⁻¹L`` and ``I + D⁻¹U`` ready for triangular solves
    (SuperLU objects in the natural order: a triangular matrix is its own factor, nothing
    fills in)."""

    A: scipy.sparse.csr_matrix
    d_inv: scipy.sparse.csr_matrix
    lower: scipy.sparse.csr_matrix  # L
    upper: scipy.sparse.csr_matrix  # U
    unit_lower: Any  # SuperLU of I + D⁻¹L
    unit_upper: Any  # SuperLU of I + D⁻¹U

    @classmethod
    def of(cls, A: scipy.sparse.csr_matrix) -> BlockGaussSeidel:
        """Split ``A`` into its blocks; a singular diagonal block raises
        :class:`ConvergenceError` (a pose its own edges do not determine)."""
        coo = A.tocoo()
        r, c, v = coo.row, coo.col, coo.data
        br, bc = r // BLOCK, c // BLOCK
        n_nodes = A.shape[0] // BLOCK
        blocks = np.zeros((n_nodes, BLOCK, BLOCK))
        on = br == bc
        blocks[br[on], r[on] % BLOCK, c[on] % BLOCK] = v[on]
        try:
            inv = np.linalg.inv(blocks)
        except np.linalg.LinAlgError:
            raise ConvergenceError("a pose's diagonal block of H is singular", step=0) from None
        inv = 0.5 * (inv + np.swapaxes(inv, 1, 2))  # the inverse of a symmetric block
        d_inv = scipy.sparse.bsr_matrix(
            (inv, np.arange(n_nodes), np.arange(n_nodes + 1)), shape=A.shape
        ).tocsr()

        def part(mask: np.ndarray) -> scipy.sparse.csr_matrix:
            return scipy.sparse.csr_matrix((v[mask], (r[mask], c[mask])), shape=A.shape)

        def triangular(strict: scipy.sparse.csr_matrix) -> Any:
            unit = (scipy.sparse.identity(A.shape[0], format="csr") + d_inv @ strict).tocsc()
            return scipy.sparse.linalg.splu(unit, permc_spec="NATURAL", diag_pivot_thresh=0.0)

        lower, upper = part(br > bc), part(br < bc)
        return cls(A, d_inv, lower, upper, triangular(lower), triangular(upper))

    def forward(self, x: FloatArray, b: FloatArray) -> FloatArray:
        """One forward sweep: ``(D + L) x' = b - U x``."""
        return np.asarray(self.unit_lower.solve(self.d_inv @ (b - self.upper @ x)))

    def backward(self, x: FloatArray, b: FloatArray) -> FloatArray:
        """One backward sweep: ``(D + U) x' = b - L x``."""
        return np.asarray(self.unit_upper.solve(self.d_inv @ (b - self.lower @ x)))


def tentative_interpolation(frames: FloatArray) -> tuple[scipy.sparse.csr_matrix, FloatArray]:
    """The rigid interpolation ``T`` from consecutive runs of :data:`GROUP_SIZE` of ``frames``
    ``(N, 3)`` to their groups, and the groups' frames (mean position, first member's
    heading)."""
    k = GROUP_SIZE
    n = frames.shape[0]
    group = np.arange(n) // k
    n_c = (n + k - 1) // k
    size = np.bincount(group, minlength=n_c).astype(float)
    centre = np.stack(
        [np.bincount(group, frames[:, k], minlength=n_c) / size for k in (0, 1)], axis=1
    )
    coarse = np.column_stack([centre, frames[::k, 2]])
    th_i, th_c = frames[:, 2], coarse[group, 2]
    ci, si = np.cos(th_i), np.sin(th_i)
    lever = frames[:, :2] - centre[group]  # p_i - p_c
    jl = np.column_stack([-lever[:, 1], lever[:, 0]])  # J (p_i - p_c)
    blocks = np.zeros((n, BLOCK, BLOCK))
    dc, ds = np.cos(th_c - th_i), np.sin(th_c - th_i)
    blocks[:, 0, 0], blocks[:, 0, 1] = dc, -ds  # R_iᵀ R_c = R(θ_c - θ_i)
    blocks[:, 1, 0], blocks[:, 1, 1] = ds, dc
    blocks[:, 0, 2] = ci * jl[:, 0] + si * jl[:, 1]  # R_iᵀ J (p_i - p_c)
    blocks[:, 1, 2] = -si * jl[:, 0] + ci * jl[:, 1]
    blocks[:, 2, 2] = 1.0
    P = scipy.sparse.bsr_matrix(
        (blocks, group, np.arange(n + 1)), shape=(BLOCK * n, BLOCK * n_c)
    ).tocsr()
    P.eliminate_zeros()
    return P, coarse


def spectral_radius(smoother: BlockGaussSeidel) -> float:
    """``ρ(D⁻¹A)`` by :data:`POWER_ITERATIONS` power iterations from a fixed start vector
    (``D⁻¹A`` is similar to the symmetric ``D^-½ A D^-½``, so its eigenvalues are real and
    positive and the iteration converges to the largest)."""
    n = smoother.A.shape[0]
    v = np.cos(np.arange(n) * 2.399963)  # a fixed vector with every frequency in it
    lam = 1.0
    for _ in range(POWER_ITERATIONS):
        v = smoother.d_inv @ (smoother.A @ v)
        lam = float(np.linalg.norm(v)) or 1.0
        v /= lam
    return lam


def interpolation(
    smoother: BlockGaussSeidel, frames: FloatArray
) -> tuple[scipy.sparse.csr_matrix, FloatArray]:
    """The smoothed interpolation ``P = (I - ω D⁻¹A) T`` (module docstring) from the groups
    of ``frames`` to the level of ``smoother``, and the groups' frames."""
    T, coarse = tentative_interpolation(frames)
    omega = 4.0 / (3.0 * spectral_radius(smoother))
    P = (T - omega * (smoother.d_inv @ (smoother.A @ T))).tocsr()
    return P, coarse


@dataclass(frozen=True)
class Hierarchy:
    """The levels of one linearisation: each level's smoother and the interpolation from the
    next coarser level (``P[k]`` maps level ``k + 1`` to level ``k``), and the Cholesky
    factor of the coarsest matrix."""

    smoothers: tuple[BlockGaussSeidel, ...]
    interpolations: tuple[scipy.sparse.csr_matrix, ...]
    coarsest: tuple[FloatArray, bool]
    sweeps: int

    @property
    def sizes(self) -> tuple[int, ...]:
        """Unknowns per level, finest first."""
        sizes = [s.A.shape[0] for s in self.smoothers]
        return (*sizes, self.coarsest[0].shape[0])

    def v_cycle(self, b: FloatArray, x: FloatArray, level: int = 0) -> FloatArray:
        """One V-cycle for ``A_level x = b`` from ``x`` (module docstring)."""
        if level == len(self.smoothers):
            return np.asarray(scipy.linalg.cho_solve(self.coarsest, b))
        sm, P = self.smoothers[level], self.interpolations[level]
        for _ in range(self.sweeps):
            x = sm.forward(x, b)
        r = b - sm.A @ x
        e = P @ self.v_cycle(P.T @ r, np.zeros(P.shape[1]), level + 1)
        eAe = float(e @ (sm.A @ e))
        x = x + (float(e @ r) / eAe if eAe > 0 else 1.0) * e  # the model's best step along e
        for _ in range(self.sweeps):
            x = sm.backward(x, b)
        return x


def build_hierarchy(A: scipy.sparse.spmatrix, frames: FloatArray, sweeps: int) -> Hierarchy:
    """The multilevel hierarchy of ``A`` (``3N x 3N``, symmetric positive definite, both
    triangles) for poses ``frames`` ``(N, 3)`` in variable order; ``sweeps`` forward and
    backward sweeps per level in each V-cycle."""
    A = scipy.sparse.csr_matrix(A)
    smoothers: list[BlockGaussSeidel] = []
    interps: list[scipy.sparse.csr_matrix] = []
    while frames.shape[0] > COARSEST_NODES:
        smoother = BlockGaussSeidel.of(A)
        P, frames = interpolation(smoother, frames)
        smoothers.append(smoother)
        interps.append(P)
        A = (P.T @ A @ P).tocsr()  # Galerkin: the model restricted to group motions
    dense = A.toarray()
    try:
        factor = scipy.linalg.cho_factor(0.5 * (dense + dense.T), lower=True)
    except np.linalg.LinAlgError:
        raise ConvergenceError("the coarsest level's matrix is not positive definite", 0) from None
    return Hierarchy(tuple(smoothers), tuple(interps), factor, sweeps)


@dataclass(frozen=True)
class LinearSolve:
    """An approximate solution of ``A x = b``: ``x``, the V-cycles (MLR) or sweeps
    (Gauss-Seidel) it took, and ``‖b - A x‖ / ‖b‖`` after each (``residuals[0] = 1`` at
    ``x = 0``)."""

    x: FloatArray
    iterations: int
    residuals: tuple[float, ...]

    @property
    def relative_residual(self) -> float:
        """``‖b - A x‖ / ‖b‖`` at the returned ``x``."""
        return self.residuals[-1]


def multilevel_solve(
    hierarchy: Hierarchy,
    b: FloatArray,
    tolerance: float,
    max_cycles: int,
    *,
    krylov: bool = True,
) -> LinearSolve:
    """``A x = b`` from ``x = 0`` until ``‖b - A x‖ ≤ tolerance · ‖b‖`` or ``max_cycles``
    V-cycles: conjugate gradients preconditioned by one V-cycle each (``krylov``, module
    docstring), or the V-cycles alone (``krylov=False``, the paper's scheme)."""
    if not hierarchy.smoothers:  # the whole problem is the coarsest level: solved exactly
        x = hierarchy.v_cycle(b, np.zeros_like(b))
        return LinearSolve(x, 1, (1.0, 0.0))
    A = hierarchy.smoothers[0].A
    nb = float(np.linalg.norm(b)) or 1.0
    x = np.zeros_like(b)
    r = b.copy()
    res = [1.0]
    z_old = r_old = p = None
    rz_old = 1.0
    while res[-1] > tolerance and len(res) <= max_cycles:
        if not krylov:
            x = hierarchy.v_cycle(b, x)
            r = b - A @ x
            res.append(float(np.linalg.norm(r)) / nb)
            continue
        z = hierarchy.v_cycle(r, np.zeros_like(r))
        if p is None or r_old is None or z_old is None:
            p = z
        else:
            # Flexible (Polak-Ribière) β: the V-cycle's coarse scaling α depends on its
            # input, so the preconditioner varies from one iteration to the next.
            p = z + max(float(z @ (r - r_old)) / rz_old, 0.0) * p
        Ap = A @ p
        pAp = float(p @ Ap)
        if not pAp > 0:
            break
        step = float(p @ r) / pAp
        x = x + step * p
        r_old, z_old, rz_old = r, z, float(z @ r) or 1.0
        r = r - step * Ap
        res.append(float(np.linalg.norm(r)) / nb)
    return LinearSolve(x, len(res) - 1, tuple(res))


def gauss_seidel_solve(
    smoother: BlockGaussSeidel, b: FloatArray, tolerance: float, max_sweeps: int
) -> LinearSolve:
    """Symmetric block Gauss-Seidel (a forward then a backward sweep, each counted) from
    ``x = 0`` until ``‖b - A x‖ ≤ tolerance · ‖b‖`` or ``max_sweeps`` sweeps."""
    nb = float(np.linalg.norm(b)) or 1.0
    x = np.zeros_like(b)
    res = [1.0]
    while res[-1] > tolerance and len(res) <= max_sweeps:
        x = smoother.backward(x, b) if len(res) % 2 == 0 else smoother.forward(x, b)
        res.append(float(np.linalg.norm(b - smoother.A @ x)) / nb)
    return LinearSolve(x, len(res) - 1, tuple(res))


class RelaxationStep:
    """The step strategy of ``solver="mlr"`` (``multilevel=True``) and
    ``solver="gauss_seidel"``: the approximate Gauss-Newton step, damped as LM damps it
    with ``D = H`` (module docstring); ``relative_tolerance`` is the stopping rule's, below which
    a rise is rounding noise. The linear work joins ``ctx.factor_seconds`` and
    ``ctx.linear_iterations``; :attr:`solves` keeps every iteration's :class:`LinearSolve`."""

    def __init__(
        self, config: RelaxationConfig, multilevel: bool, relative_tolerance: float
    ) -> None:
        self.config = config
        self.multilevel = multilevel
        self.relative_tolerance = relative_tolerance
        self.lam = LAMBDA_INITIAL
        self.nu = 2.0
        self.solves: list[LinearSolve] = []

    def _solve(self, ctx: SolverContext, current: Estimate) -> LinearSolve:
        H, g = current.lin.H, current.lin.g
        assert H is not None and g is not None
        cfg = self.config
        A = ctx.pattern.full_matrix(H).tocsr()
        if self.multilevel:
            frames = free_pose_frames(ctx.problem, current.poses)
            hierarchy = build_hierarchy(A, frames, cfg.sweeps)
            return multilevel_solve(hierarchy, -g, cfg.linear_tolerance, cfg.max_cycles)
        smoother = BlockGaussSeidel.of(A)
        return gauss_seidel_solve(smoother, -g, cfg.linear_tolerance, cfg.max_sweeps)

    def step(self, ctx: SolverContext, current: Estimate, iteration: int) -> Step | NoStep:
        """``x ⊕ δ / (1 + λ)`` with ``δ`` the relaxed solution of ``H δ = -g``: ``λ`` grows
        until the cost falls, then shrinks by the gain ratio (module docstring)."""
        t0 = time.perf_counter()
        solve = self._solve(ctx, current)
        ctx.factor_seconds += time.perf_counter() - t0
        ctx.linear_iterations += solve.iterations
        self.solves.append(solve)
        H, g = current.lin.H, current.lin.g
        assert H is not None and g is not None
        delta = solve.x
        size = float(np.max(np.abs(delta))) if delta.shape[0] else 0.0
        short = solve.relative_residual > self.config.linear_tolerance
        f = current.lin.cost
        first = True
        while self.lam <= LAMBDA_MAX:
            trial = delta / (1.0 + self.lam)  # (H + λH) δ' = -g
            new = ctx.move(current, trial)
            if (
                first
                and np.isfinite(new.lin.cost)
                and 0 < new.lin.cost - f <= (self.relative_tolerance * abs(f))
            ):
                return NoStep("the cost rose by rounding noise at the minimum", True, self.lam)
            first = False
            if np.isfinite(new.lin.cost) and new.lin.cost <= f:
                # the model's reduction m(0) - m(δ') = -2gᵀδ' - δ'ᵀHδ'; Nielsen's update
                predicted = -2.0 * float(g @ trial) - float(trial @ ctx.pattern.matvec(H, trial))
                rho = (f - new.lin.cost) / predicted if predicted > 0 else 1.0
                used = self.lam
                self.lam = max(self.lam * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-20)
                self.nu = 2.0
                return Step(new, size / (1.0 + used), used, bounded=short)
            self.lam *= self.nu
            self.nu *= 2.0
        return NoStep("no decrease along the relaxed Gauss-Newton step", False, self.lam)
