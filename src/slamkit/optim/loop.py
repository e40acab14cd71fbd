"""The nonlinear least-squares loop that every solver runs: linearise → solve the step →
accept or reject → stopping rule, with one :class:`IterationInfo` per iteration.

The model of the cost around ``x`` is ``m(δ) = f + 2 gᵀδ + δᵀ H δ`` (``f`` has no ½), with
``H = Jᵀ W J`` and ``g = Jᵀ W r`` from :meth:`GraphProblem.linearize`. What differs between
Gauss-Newton, Levenberg-Marquardt and dogleg is only how a step is found and whether it is
taken; that is a :class:`StepStrategy` (:mod:`slamkit.optim.steps`). The loop owns the rest:

1. before iteration ``k``: stop (converged) when ``max |g| ≤ gradient_tolerance``;
2. ``strategy.step`` returns an accepted :class:`Step` (the new estimate, already linearised)
   or a :class:`NoStep` (no acceptable step: the loop records the iteration and stops;
   converged when the step says so or the cost is within ``absolute_tolerance`` of zero);
3. after an accepted step: record it, call the callback (``True`` stops), then stop
   (converged) on the first of the :class:`~slamkit.optim.settings.StoppingConfig` rules;
4. after ``max_iterations`` iterations: stop, not converged.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from slamkit.errors import GeometryError
from slamkit.optim.data import FloatArray
from slamkit.optim.graph import GraphProblem
from slamkit.optim.linearization import Linearization
from slamkit.optim.robust import RobustKernel
from slamkit.optim.settings import StoppingConfig
from slamkit.optim.sparse import Factorizer, SingularSystem

__all__ = [
    "Callback",
    "Estimate",
    "IterationInfo",
    "LoopOutcome",
    "NoStep",
    "SolverContext",
    "Step",
    "StepStrategy",
    "indeterminate_error",
    "run_least_squares",
]


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


Callback = Callable[[IterationInfo], bool | None]


@dataclass(frozen=True)
class Estimate:
    """Poses (internal format), landmarks and the linearisation at them."""

    poses: FloatArray
    landmarks: FloatArray
    lin: Linearization


@dataclass(frozen=True)
class Step:
    """An accepted step: the new estimate, the step's size ``max |δ|`` (read by the step
    tolerance and recorded) and the damping (LM ``λ``, dogleg ``Δ``, 0) it was found with.

    ``bounded``: the step was cut to a trust region instead of being the model's minimiser.
    A small cost change or step then says that the region is small, not that the cost is at
    a minimum, so the small-change rules do not end the loop on it (dogleg once stopped
    "converged" at a χ² of 1,940 on MIT, where GN and LM reach 770.7)."""

    estimate: Estimate
    size: float
    damping: float
    bounded: bool = False


@dataclass(frozen=True)
class NoStep:
    """No acceptable step: why, whether that counts as converged, and the last damping."""

    reason: str
    converged: bool
    damping: float


@dataclass(frozen=True)
class LoopOutcome:
    """Where the loop stopped. ``stalled``: the last iteration found no step (a
    :class:`NoStep`)."""

    estimate: Estimate
    iterations: int
    converged: bool
    reason: str
    stalled: bool = False


class SolverContext:
    """What the strategies share: the problem, the kernel, the factoriser (symbolic analysis
    done once), and counters and clocks of linearisations and factorisations (the relaxation
    solvers count their V-cycles or sweeps in ``linear_iterations`` and their linear solves'
    time in ``factor_seconds``)."""

    def __init__(self, problem: GraphProblem, kernel: RobustKernel, factorizer: Factorizer) -> None:
        self.problem = problem
        self.kernel = kernel
        self.pattern = problem.pattern
        self.factorizer = factorizer
        self.factorizations = 0
        self.linearizations = 0
        self.factor_seconds = 0.0
        self.assembly_seconds = 0.0
        self.linear_iterations = 0  # V-cycles or sweeps of the relaxation solvers

    def linearize(self, poses: FloatArray, landmarks: FloatArray) -> Estimate:
        """The estimate at ``(poses, landmarks)`` with its cost; ``H`` and ``g`` are formed
        when a strategy first reads them (a rejected trial and the last estimate of a solve
        need only the cost), and the time that takes joins :attr:`assembly_seconds` then."""
        lin = self.problem.linearize(poses, landmarks, self.kernel, deferred=True)
        self.linearizations += 1
        self.assembly_seconds += lin.seconds
        lin.on_formed = self._count_assembly
        return Estimate(poses, landmarks, lin)

    def _count_assembly(self, seconds: float) -> None:
        self.assembly_seconds += seconds

    def move(self, at: Estimate, delta: FloatArray) -> Estimate:
        """``at ⊕ δ``, linearised."""
        poses, landmarks = self.problem.retract(at.poses, at.landmarks, delta)
        return self.linearize(poses, landmarks)

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

    def clocks(self) -> tuple[float, float]:
        """The assembly and factor clocks now (an iteration's record subtracts them)."""
        return self.assembly_seconds, self.factor_seconds

    def info(
        self,
        iteration: int,
        lin: Linearization,
        step: float,
        accepted: bool,
        damping: float,
        since: tuple[float, float],
    ) -> IterationInfo:
        """The callback's record of an iteration that began when the clocks read ``since``."""
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


class StepStrategy(Protocol):
    """How one iteration finds its step from ``current`` (linearised, ``H`` and ``g`` set).
    A strategy may keep state across iterations (LM's ``λ``, dogleg's ``Δ``)."""

    def step(self, ctx: SolverContext, current: Estimate, iteration: int) -> Step | NoStep:
        """The accepted step, or why there is none."""
        ...


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


def _small_change(rule: StoppingConfig, f_old: float, f_new: float, step: float) -> str | None:
    change = abs(f_old - f_new)
    if change <= rule.absolute_tolerance:
        return f"cost change {change:.3g} <= absolute_tolerance"
    if change <= rule.relative_tolerance * abs(f_old):
        return f"relative cost change {change / max(abs(f_old), 1e-300):.3g} <= relative_tolerance"
    if step <= rule.step_tolerance:
        return f"step {step:.3g} <= step_tolerance"
    return None


def _gradient_small(rule: StoppingConfig, lin: Linearization) -> str | None:
    assert lin.g is not None
    gmax = float(np.max(np.abs(lin.g))) if lin.g.shape[0] else 0.0
    if gmax <= rule.gradient_tolerance:
        return f"gradient {gmax:.3g} <= gradient_tolerance"
    return None


def run_least_squares(
    ctx: SolverContext,
    start: Estimate,
    strategy: StepStrategy,
    rule: StoppingConfig,
    history: list[IterationInfo],
    callback: Callback | None = None,
    *,
    check_gradient: bool = True,
) -> LoopOutcome:
    """Iterate ``strategy`` from ``start`` until ``rule`` stops it (module docstring).
    Each iteration's record is appended to ``history`` and passed to ``callback``.
    ``check_gradient=False`` skips the gradient test (the incremental batch step, whose rule
    is on the cost change and the step only)."""
    current = start
    for it in range(1, rule.max_iterations + 1):
        if check_gradient:
            why = _gradient_small(rule, current.lin)
            if why:
                return LoopOutcome(current, it - 1, True, why)
        since = ctx.clocks()
        found = strategy.step(ctx, current, it)
        if isinstance(found, NoStep):
            history.append(ctx.info(it, current.lin, 0.0, False, found.damping, since))
            if callback is not None:
                callback(history[-1])
            # A cost within absolute_tolerance of zero, its least value, is a minimum: no
            # step can lower it by more than the tolerance (a chain without closures).
            if not found.converged and current.lin.cost <= rule.absolute_tolerance:
                why = f"cost {current.lin.cost:.3g} <= absolute_tolerance, no decrease possible"
                return LoopOutcome(current, it, True, why, stalled=True)
            return LoopOutcome(current, it, found.converged, found.reason, stalled=True)
        why = None
        if not found.bounded:
            why = _small_change(rule, current.lin.cost, found.estimate.lin.cost, found.size)
        current = found.estimate
        history.append(ctx.info(it, current.lin, found.size, True, found.damping, since))
        if callback is not None and callback(history[-1]):
            return LoopOutcome(current, it, False, "stopped by the callback")
        if why:
            return LoopOutcome(current, it, True, why)
    return LoopOutcome(current, rule.max_iterations, False, "max_iterations reached")
