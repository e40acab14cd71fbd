"""The step strategies of :func:`~slamkit.optim.loop.run_least_squares`: how each method
finds its step and whether it takes it.

With ``m(δ) = f + 2 gᵀδ + δᵀ H δ`` the model of the cost (no factor ½), the Gauss-Newton step
solves ``H δ = -g``.

* **GN** (:class:`GaussNewtonStep`) takes every step.
* **LM** (:class:`LevenbergMarquardtStep`) solves ``(H + λD) δ = -g`` and accepts the step
  when it lowers ``f``; otherwise ``λ`` grows and the step is recomputed. The damping matrix:

  - ``D = H`` (``damping="hessian"``, the default): ``(1 + λ) H δ = -g``, so
    ``δ = δ_gn / (1 + λ)``, the Gauss-Newton step shortened; ``H`` is factored once per
    linearisation and a rejected trial costs one cost evaluation, no factorisation.
    Every mode of the Gauss-Newton step keeps its proportion. With ``D = I``
    (``"levenberg"``, GTSAM's default) the eigen-component of ``δ`` along an eigenvector of
    ``H`` with eigenvalue ``σ`` is the GN one times ``σ / (σ + λ)``: the soft modes (whole
    loops bending, ``σ`` far below the diagonal of ``H``) are cut most, and those are what a
    start far from the optimum must move. On ``carlone/input_INTEL_g2o.g2o`` from odometry
    ``D = I`` is still at χ² 66,010 after 100 iterations, ``D = H`` converges (215.8) in 38
    (``docs/estimators/optim.md``). A singular ``H`` (a variable its edges do not
    determine) falls back to ``D = I`` for that iteration.
  - ``D = diag(H)`` (``"marquardt"``).

  **The gain-ratio schedule** (``schedule="gain_ratio"``, Nielsen 1999). The model's
  predicted reduction of a step is ``m(0) - m(δ) = -2gᵀδ - δᵀHδ``; for the damped step
  ``g = -(H + λD) δ`` so this is ``δᵀHδ + 2λ δᵀDδ > 0``. The gain ratio is
  ``ϱ = (f - f(x ⊕ δ)) / (m(0) - m(δ))``. A step is accepted when ``ϱ > 0``; then
  ``λ ← λ · max(1/3, 1 - (2ϱ - 1)³)`` and ``ν ← 2``. The factor is a smooth version of the
  trust-region rule (grow the region when the model is good, shrink it when bad): it is 1
  at ``ϱ = ½``, falls to ``1/3`` (at most) as ``ϱ → 1`` (the model is trusted: less damping)
  and rises to 2 as ``ϱ → 0`` (the model overestimates the decrease: more damping), with no
  jump between the cases, so ``λ`` does not oscillate as the fixed ×/÷ factor does. A
  rejected step sets ``λ ← λ · ν`` and ``ν ← 2ν``: repeated rejections raise ``λ``
  geometrically faster (2, 8, 64, ... in all), so a bad region is left in a few
  factorisations, and the next acceptance resets ``ν``. ``schedule="fixed"`` is the old
  rule: ``λ ← λ / lambda_factor`` on accept, ``λ ← λ · lambda_factor`` on reject.
* **Dogleg** (:class:`DoglegStep`) factors ``H`` once per linearisation; inside the trust
  region of radius ``Δ`` it takes the GN step ``δ_gn``, else the Cauchy step ``-α g``
  (``α = ‖g‖² / gᵀHg``) cut at ``Δ``, else the point of the dogleg path ``-αg → δ_gn`` at
  distance ``Δ``. The first region holds the first GN step (``Δ₀ ≥ ‖δ_gn‖``). With the
  gain ratio ``ϱ = (f - f_new) / (m(0) - m(δ))``: accept when ``ϱ > 0``;
  ``Δ ← max(Δ, 3‖δ‖)`` when ``ϱ > 0.75``, ``Δ ← Δ / 2`` when ``ϱ < 0.25``
  (Madsen, Nielsen & Tingleff, 2004).
* **MLR and Gauss-Seidel** (:class:`~slamkit.optim.mlr.RelaxationStep`): the Gauss-Newton
  step found approximately by multigrid-preconditioned CG or block Gauss-Seidel sweeps, no
  factorisation (:mod:`slamkit.optim.mlr`).
* **GN with backtracking** (:class:`BacktrackingGaussNewtonStep`), the incremental
  optimiser's batch step: the GN step, halved up to five times while it raises ``f``; no
  decrease along it is a :class:`~slamkit.optim.loop.NoStep` (the caller falls back to LM).
"""

from __future__ import annotations

import numpy as np

from slamkit.errors import ConvergenceError, GeometryError
from slamkit.optim.loop import Estimate, NoStep, SolverContext, Step, indeterminate_error
from slamkit.optim.mlr import RelaxationStep
from slamkit.optim.settings import DoglegConfig, LmConfig, OptimizerConfig
from slamkit.optim.sparse import SingularSystem

__all__ = [
    "BacktrackingGaussNewtonStep",
    "DoglegStep",
    "GaussNewtonStep",
    "LevenbergMarquardtStep",
    "make_step",
]


def _max_abs(delta: np.ndarray) -> float:
    return float(np.max(np.abs(delta))) if delta.shape[0] else 0.0


def _gauss_newton_direction(ctx: SolverContext, current: Estimate) -> np.ndarray:
    """``δ_gn = -H⁻¹ g``; a singular ``H`` raises the error naming the undetermined variable."""
    H, g = current.lin.H, current.lin.g
    assert H is not None and g is not None
    try:
        return ctx.solve(H, g, None)
    except SingularSystem as exc:
        raise indeterminate_error(ctx.problem, exc, H) from None


class GaussNewtonStep:
    """The full Gauss-Newton step, always taken."""

    def step(self, ctx: SolverContext, current: Estimate, iteration: int) -> Step | NoStep:
        """``x ⊕ δ_gn``; a non-finite cost there raises :class:`ConvergenceError`."""
        delta = _gauss_newton_direction(ctx, current)
        new = ctx.move(current, delta)
        if not np.isfinite(new.lin.cost):
            raise ConvergenceError("Gauss-Newton produced a non-finite cost", step=iteration)
        return Step(new, _max_abs(delta), 0.0)


class LevenbergMarquardtStep:
    """Damped steps with an adaptive ``λ`` (and, for the gain-ratio schedule, ``ν``) kept
    across iterations; the damping matrix is ``config.damping``, the schedule
    ``config.schedule`` (module docstring)."""

    def __init__(self, config: LmConfig) -> None:
        self.config = config
        self.lam = config.lambda_initial
        self.nu = 2.0

    def _trial(
        self, ctx: SolverContext, current: Estimate, gn: np.ndarray | None
    ) -> tuple[np.ndarray, Estimate, float] | None:
        """The step at the current ``λ``, the estimate there and its gain ratio ``ϱ``
        (``-1`` when the cost does not decrease); ``None`` when the damped system is
        singular. ``gn``: the Gauss-Newton step, for ``damping="hessian"``."""
        cfg = self.config
        H, g = current.lin.H, current.lin.g
        assert H is not None and g is not None
        if gn is not None:
            delta = gn / (1.0 + self.lam)  # (H + λH) δ = -g
        else:
            diag = H[ctx.pattern.diag]
            scale = np.maximum(diag, 1e-12) if cfg.damping == "marquardt" else 1.0
            shift = np.broadcast_to(np.asarray(self.lam * scale, dtype=np.float64), diag.shape)
            try:
                delta = ctx.solve(H, g, shift)
            except SingularSystem:
                return None
        new = ctx.move(current, delta)
        actual = current.lin.cost - new.lin.cost
        # The model's reduction m(0) - m(δ) = -2gᵀδ - δᵀHδ (> 0 for every damped step).
        predicted = -2.0 * float(g @ delta) - float(delta @ ctx.pattern.matvec(H, delta))
        rho = -1.0
        if np.isfinite(new.lin.cost) and actual > 0:
            rho = actual / predicted if predicted > 0 else 1.0
        return delta, new, rho

    def step(self, ctx: SolverContext, current: Estimate, iteration: int) -> Step | NoStep:
        """Raise ``λ`` until the damped step lowers the cost (``ϱ > 0``); then lower ``λ``
        by the schedule."""
        cfg = self.config
        H, g = current.lin.H, current.lin.g
        assert H is not None and g is not None
        gn = None
        if cfg.damping == "hessian":
            try:  # one factorisation per linearisation: every trial scales the GN step
                gn = ctx.solve(H, g, None)
            except SingularSystem:
                gn = None  # H is singular: Levenberg's D = I for this iteration
        gain_ratio = cfg.schedule == "gain_ratio"
        while True:
            trial = self._trial(ctx, current, gn)
            if trial is not None and trial[2] > 0:
                break
            if gain_ratio:  # Nielsen: λ ← λ·ν, ν ← 2ν
                self.lam *= self.nu
                self.nu *= 2.0
            else:
                self.lam *= cfg.lambda_factor
            if self.lam > cfg.lambda_max:
                return NoStep("no decrease found (lambda > lambda_max)", False, self.lam)
        delta, new, rho = trial
        found = Step(new, _max_abs(delta), self.lam)
        if gain_ratio:  # Nielsen: λ ← λ·max(1/3, 1 - (2ϱ - 1)³), ν ← 2
            self.lam = max(self.lam * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-20)
            self.nu = 2.0
        else:
            self.lam = max(self.lam / cfg.lambda_factor, 1e-20)
        return found


class DoglegStep:
    """Powell's dogleg in a trust region whose radius ``Δ`` is kept across iterations."""

    def __init__(self, config: DoglegConfig) -> None:
        self.config = config
        self.radius = config.trust_radius_initial
        self.first = True

    def step(self, ctx: SolverContext, current: Estimate, iteration: int) -> Step | NoStep:
        """Shrink ``Δ`` until the dogleg point lowers the cost (gain ratio ``ϱ > 0``)."""
        H, g = current.lin.H, current.lin.g
        assert H is not None and g is not None
        h_gn = _gauss_newton_direction(ctx, current)
        Hg = ctx.pattern.matvec(H, g)
        gg = float(g @ g)
        gHg = float(g @ Hg)
        alpha = gg / gHg if gHg > 0 else 0.0
        h_sd = -alpha * g  # the Cauchy point (minimiser of the model along -g)
        n_gn = float(np.linalg.norm(h_gn))
        n_sd = float(np.linalg.norm(h_sd))
        if self.first:
            # The first region holds the GN step: it shrinks only on evidence that the model
            # fails. From a small Δ₀ the early steps follow the gradient instead, into
            # another basin (MIT: χ² 1,940 from Δ₀ = 1, GN's 770.7 from Δ₀ = ‖δ_gn‖).
            self.radius = max(self.radius, n_gn)
            self.first = False
        while True:
            radius = self.radius
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
            predicted = -2.0 * float(g @ h) - float(h @ ctx.pattern.matvec(H, h))
            new = ctx.move(current, h)
            gain = (current.lin.cost - new.lin.cost) / predicted if predicted > 0 else -1.0
            if not np.isfinite(new.lin.cost):
                gain = -1.0
            h_norm = float(np.linalg.norm(h))
            if gain > 0.75:
                self.radius = max(radius, 3.0 * h_norm)
            elif gain < 0.25:
                self.radius = radius / 2.0
            if gain > 0:
                return Step(new, _max_abs(h), self.radius, bounded=n_gn > radius)
            if self.radius < self.config.trust_radius_min:
                return NoStep(
                    "no decrease found (trust radius < trust_radius_min)", False, self.radius
                )


class BacktrackingGaussNewtonStep:
    """The incremental batch step's policy: the Gauss-Newton step from a warm start, halved
    while it raises the cost.

    A rise within ``relative_tolerance · f`` is rounding noise at the minimum: converged, the
    lower point kept. Otherwise ``α`` halves from 1 while ``f`` rises and ``α > 0.05`` (at
    most five halvings); no decrease even then is a :class:`NoStep` that is not converged
    (the incremental optimiser continues with LM). The step size for the step tolerance is
    the full GN step's ``max |δ|``. ``update`` is the incremental update number named by a
    non-finite cost's :class:`ConvergenceError`.
    """

    def __init__(self, relative_tolerance: float, update: int) -> None:
        self.relative_tolerance = relative_tolerance
        self.update = update

    def step(self, ctx: SolverContext, current: Estimate, iteration: int) -> Step | NoStep:
        """The GN step, backtracked (class docstring)."""
        lin, problem = current.lin, ctx.problem
        assert lin.H is not None and lin.g is not None
        try:
            delta = ctx.solve(lin.H, lin.g, None)
        except SingularSystem as exc:
            which = (
                f"{problem.variable_of_column(exc.column)} is not determined"
                if exc.column is not None
                else "the back-end does not say which variable is not determined"
            )
            raise GeometryError(
                f"the normal equations of the graph so far are singular ({exc}); {which}"
            ) from None
        new = ctx.move(current, delta)
        if not np.isfinite(new.lin.cost):
            raise ConvergenceError("a batch step produced a non-finite cost", self.update)
        if (
            new.lin.cost > lin.cost
            and new.lin.cost - lin.cost <= self.relative_tolerance * lin.cost
        ):
            return NoStep("the cost rose by rounding noise at the minimum", True, 0.0)
        alpha = 1.0
        while new.lin.cost > lin.cost and alpha > 0.05:
            # Gauss-Newton overshot (a strongly nonlinear correction): backtrack.
            alpha *= 0.5
            new = ctx.move(current, alpha * delta)
        if not new.lin.cost <= lin.cost:
            return NoStep("no decrease along the Gauss-Newton direction", False, 0.0)
        return Step(new, float(np.abs(delta).max()), 0.0)


def make_step(
    config: OptimizerConfig,
) -> GaussNewtonStep | LevenbergMarquardtStep | DoglegStep | RelaxationStep:
    """The strategy of ``config.solver``, with its section's settings."""
    if config.solver in ("mlr", "gauss_seidel"):
        return RelaxationStep(
            config.relaxation,
            multilevel=config.solver == "mlr",
            relative_tolerance=config.stopping.relative_tolerance,
        )
    if config.solver == "gn":
        return GaussNewtonStep()
    if config.solver == "lm":
        return LevenbergMarquardtStep(config.lm)
    return DoglegStep(config.dogleg)
