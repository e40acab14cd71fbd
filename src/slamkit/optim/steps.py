"""The step strategies of :func:`~slamkit.optim.loop.run_least_squares`: how each method
finds its step and whether it takes it.

With ``m(δ) = f + 2 gᵀδ + δᵀ H δ`` the model of the cost (no factor ½), the Gauss-Newton step
solves ``H δ = -g``.

* **GN** (:class:`GaussNewtonStep`) takes every step.
* **LM** (:class:`LevenbergMarquardtStep`) solves ``(H + λD) δ = -g`` with ``D = I``
  (``damping="levenberg"``, GTSAM's default) or ``D = diag(H)`` (``"marquardt"``); a step is
  accepted when it lowers ``f``, then ``λ ← λ / lambda_factor``, else
  ``λ ← λ · lambda_factor`` and the system is refactored.
* **Dogleg** (:class:`DoglegStep`) factors ``H`` once per linearisation; inside the trust
  region of radius ``Δ`` it takes the GN step ``δ_gn``, else the Cauchy step ``-α g``
  (``α = ‖g‖² / gᵀHg``) cut at ``Δ``, else the point of the dogleg path ``-αg → δ_gn`` at
  distance ``Δ``. The first region holds the first GN step (``Δ₀ ≥ ‖δ_gn‖``). With the
  gain ratio ``ϱ = (f - f_new) / (m(0) - m(δ))``: accept when ``ϱ > 0``;
  ``Δ ← max(Δ, 3‖δ‖)`` when ``ϱ > 0.75``, ``Δ ← Δ / 2`` when ``ϱ < 0.25``
  (Madsen, Nielsen & Tingleff, 2004).
* **GN with backtracking** (:class:`BacktrackingGaussNewtonStep`), the incremental
  optimiser's batch step: the GN step, halved up to five times while it raises ``f``; no
  decrease along it is a :class:`~slamkit.optim.loop.NoStep` (the caller falls back to LM).
"""

from __future__ import annotations

import numpy as np

from slamkit.errors import ConvergenceError, GeometryError
from slamkit.optim.loop import Estimate, NoStep, SolverContext, Step, indeterminate_error
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
    """Damped steps with an adaptive ``λ`` (kept across iterations)."""

    def __init__(self, config: LmConfig) -> None:
        self.config = config
        self.lam = config.lambda_initial

    def step(self, ctx: SolverContext, current: Estimate, iteration: int) -> Step | NoStep:
        """Raise ``λ`` until ``(H + λD) δ = -g`` lowers the cost; lower it after success."""
        cfg = self.config
        H, g = current.lin.H, current.lin.g
        assert H is not None and g is not None
        diag = H[ctx.pattern.diag]
        while True:
            shift = self.lam * (np.maximum(diag, 1e-12) if cfg.damping == "marquardt" else 1.0)
            shift_arr = np.broadcast_to(np.asarray(shift, dtype=np.float64), diag.shape)
            try:
                delta = ctx.solve(H, g, shift_arr)
                new = ctx.move(current, delta)
                ok = bool(np.isfinite(new.lin.cost) and new.lin.cost < current.lin.cost)
            except SingularSystem:
                ok = False
            if ok:
                break
            self.lam *= cfg.lambda_factor
            if self.lam > cfg.lambda_max:
                return NoStep("no decrease found (lambda > lambda_max)", False, self.lam)
        found = Step(new, _max_abs(delta), self.lam)
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


def make_step(config: OptimizerConfig) -> GaussNewtonStep | LevenbergMarquardtStep | DoglegStep:
    """The strategy of ``config.solver``, with its section's settings."""
    if config.solver == "gn":
        return GaussNewtonStep()
    if config.solver == "lm":
        return LevenbergMarquardtStep(config.lm)
    return DoglegStep(config.dogleg)
