"""The Riemannian staircase: from a solution the certificate refuses to SE-Sync's global
optimum (Rosen et al., "SE-Sync", IJRR 2019, Algorithms 1-3), 2D and 3D.

Notation of :mod:`slamkit.optim.certificate`: ``F(R) = tr(R Q Rᵀ)`` over ``R = [R_1 … R_n]``
(d x dn, ``R_i ∈ SO(d)``), ``Λ``, ``S = Q - Λ``.

**The lifted problem.** Replace each ``R_i`` by ``Y_i ∈ R^{r×d}`` with orthonormal columns
(``Y_iᵀ Y_i = I``, the Stiefel manifold ``St(d, r)``), ``r ≥ d``, and minimise
``F(Y) = tr(Y Q Yᵀ) = tr(Q YᵀY)``. ``Z = YᵀY`` is positive semidefinite with identity
diagonal blocks, so ``F(Y)`` is a value of SE-Sync's semidefinite relaxation: never above
``F*``; at ``r = d`` with ``det Y_i > 0`` it is the original problem.

**Gradient and Hessian.** With the metric ``⟨A, B⟩ = tr(AᵀB)`` the Euclidean gradient is
``2 Y Q`` and the tangent space at ``Y`` is ``{Ẏ : Y_iᵀ Ẏ_i skew}``; the orthogonal projection
onto it removes ``Y_i sym(Y_iᵀ Z_i)`` from each block. The blocks of ``sym(Y_iᵀ (Y Q)_i)`` are
the multipliers ``Λ_i``, so ``grad F = 2 Y S`` (``S = Q - Λ(Y)``): ``Y`` is critical iff
``S Yᵀ = 0``. The Riemannian Hessian of an embedded submanifold is the projected directional
derivative of the Euclidean gradient less the Weingarten term ``Ẏ sym(Y_iᵀ ∇F_i)`` per block,
i.e. ``Hess F[Ẏ] = P_Y(2 Ẏ Q - 2 Ẏ Λ) = 2 P_Y(Ẏ S)``.

**Optimiser.** A Riemannian trust region (Absil, Baker and Gallivan 2007): at each iterate the
model ``F + ⟨g, η⟩ + ½⟨η, H η⟩`` is minimised over the tangent space inside a trust region by
truncated conjugate gradients (Steihaug-Toint), preconditioned by ``η ↦ P_Y(η (Q + εI)⁻¹)``
(SPD on the tangent space; ``(Q + εI)⁻¹ x`` is the lower block of the solution of the sparse
``[[L_r, V_r], [V_rᵀ, B + εI]] [y; z] = [0; x]``, factored once), with the trust region
measured in the norm of that preconditioner's inverse. The step is retracted block by block
onto ``St(d, r)`` by the polar factor (``U Vᵀ`` of the block's SVD). The ratio of actual to
predicted decrease accepts the step (> 0.1) and shrinks (< ¼) or grows (> ¾ at the boundary)
the radius.

**Climbing.** At a critical point of rank ``r`` the certificate is checked with the same
``Λ``, ``S`` (:func:`~slamkit.optim.certificate.certify_blocks`: ``Z = YᵀY`` is as good a
witness as rotations). ``S ⪰ 0`` (to the certificate's tolerance) means ``Z`` is optimal for
the relaxation. Otherwise let ``v`` be the unit eigenvector of ``λ_min(S) < 0``. Append a
zero row to ``Y`` (rank ``r + 1``: still critical, same ``F``) and move along ``Ẏ`` = the new
row set to ``vᵀ``: ``Y_iᵀ Ẏ_i = 0`` (tangent), the gradient there is zero and
``⟨Ẏ, Hess F[Ẏ]⟩ = 2 vᵀ S v = 2 λ_min < 0``, so ``F(Y + αẎ) ≈ F + α² λ_min`` decreases: a
second-order descent direction out of the saddle. The step ``α`` starts at ``√n`` (order-one
turns into the new dimension) and halves until ``F`` falls by at least ``10⁻⁴ α² |λ_min|``.
The trust region then runs at rank ``r + 1``; repeat.

**Rounding.** Let ``Y = U Σ Vᵀ`` with ``Σ`` descending; ``R̂ = Σ_d V_dᵀ`` (the best rank-``d``
factor of ``Z``, exact when ``rank Z = d``). ``R̂`` and its reflection ``diag(1, …, -1) R̂``
give the same ``Z``; keep the one with more blocks of positive determinant, then replace
each block by its nearest rotation (SVD ``U diag(1, …, det(U Vᵀ)) Vᵀ``). The trust region
polishes that at rank ``d`` and the translations follow in closed form
(:meth:`~slamkit.optim.certificate.SchurQ.translations`). The rounded rotations are certified
like any solution: when ``Z`` had rank ``d`` they are the global optimum and
``F(R) = F(Y)``; otherwise the certificate says so and the gap bounds the loss.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse
from numpy.typing import ArrayLike

from slamkit._validation import as_array
from slamkit.errors import ConfigError, InputError
from slamkit.optim import factors3d
from slamkit.optim.certificate import (
    CERTIFY_RTOL,
    Certificate,
    SchurQ,
    certify_blocks,
    check_certifiable,
    rotation_blocks,
    sesync_matrices,
)
from slamkit.optim.data import FloatArray, GraphData
from slamkit.optim.graph import GraphProblem
from slamkit.optim.sparse import LinearSolverName, SingularSystem, factor_spd

__all__ = [
    "LiftedProblem",
    "RankStep",
    "StaircaseConfig",
    "StaircaseResult",
    "nearest_rotations",
    "riemannian_staircase",
    "round_lifted",
]

_PRECONDITIONER_SHIFT = 1e-6
"""``ε = 1e-6 ‖Q‖₂`` in the preconditioner ``(Q + εI)⁻¹``: ``Q`` is singular without noise
(global rotations), and the shift only changes the preconditioner, never the answer."""


@dataclass(frozen=True)
class StaircaseConfig:
    """Stopping rules of :func:`riemannian_staircase`."""

    max_rank: int = 10
    """The highest rank tried (SE-Sync's default); not certified there: the best rounded
    solution is returned with ``certified=False``."""
    gradient_rtol: float = 1e-9
    """The trust region stops at rank ``r`` once ``‖grad F‖_F ≤ gradient_rtol · ‖Q‖₂ · √(dn)``
    (``grad F = 2 Y S``: a relative distance from criticality far below the certificate's
    ``1e-6``)."""
    max_iterations: int = 500
    """Trust-region iterations per rank at most (each a truncated CG of at most 200 Hessian
    products)."""

    def __post_init__(self) -> None:
        if not (isinstance(self.max_rank, int) and self.max_rank >= 2):
            raise ConfigError(f"staircase.max_rank: expected an integer ≥ 2, got {self.max_rank!r}")
        if not (np.isfinite(self.gradient_rtol) and self.gradient_rtol > 0):
            raise ConfigError(
                f"staircase.gradient_rtol: expected a positive number, got {self.gradient_rtol!r}"
            )
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 1):
            raise ConfigError(
                f"staircase.max_iterations: expected an integer ≥ 1, got {self.max_iterations!r}"
            )


@dataclass(frozen=True)
class RankStep:
    """One rank of the staircase: the trust region's critical point and its certificate."""

    rank: int
    objective: float
    """``F(Y) = tr(Y Q Yᵀ)`` at the critical point (≤ ``F*`` once certified)."""
    lambda_min: float
    """``λ_min(S)`` there (certified iff ``> -tolerance``)."""
    certified: bool
    iterations: int
    """Trust-region iterations at this rank."""
    gradient_norm: float
    """``‖grad F‖_F`` where the trust region stopped."""

    def as_dict(self) -> dict[str, float | int | bool]:
        return {
            "rank": self.rank,
            "objective": self.objective,
            "lambda_min": self.lambda_min,
            "certified": self.certified,
            "iterations": self.iterations,
            "gradient_norm": self.gradient_norm,
        }


@dataclass(frozen=True)
class StaircaseResult:
    """The outcome of :func:`riemannian_staircase`."""

    poses: FloatArray
    """The rounded solution, rows in the order of ``GraphProblem.from_data(data).pose_ids``
    (2D ``(x, y, θ)``, 3D ``(x, y, z, qw, qx, qy, qz)``), moved rigidly so that pose 0 is where
    the start had it (``F`` does not see the move)."""
    certificate: Certificate
    """The certificate of ``poses`` (:func:`~slamkit.optim.certify`'s)."""
    steps: tuple[RankStep, ...]
    """Every rank tried, from ``d`` up."""
    relaxation_objective: float
    """``F(Y)`` at the last rank: SE-Sync's relaxation, ``≤ F*`` when that rank certified."""
    seconds: float

    @property
    def certified(self) -> bool:
        return self.certificate.certified

    @property
    def objective(self) -> float:
        """``F`` of the rounded ``poses`` (``F*`` when certified)."""
        return self.certificate.objective

    @property
    def ranks_climbed(self) -> int:
        """Ranks above ``d`` the staircase went (0: the start was already certified)."""
        return len(self.steps) - 1

    def as_dict(self) -> dict[str, object]:
        """For ``metrics.json``: the verdict, ``F*``, the ranks and the rounded certificate."""
        return {
            "certified": self.certified,
            "objective": self.objective,
            "relaxation_objective": self.relaxation_objective,
            "ranks_climbed": self.ranks_climbed,
            "final_rank": self.steps[-1].rank,
            "steps": [s.as_dict() for s in self.steps],
            "certificate": self.certificate.as_dict(),
            "seconds": self.seconds,
        }


class LiftedProblem:
    """``F(Y) = tr(Y Q Yᵀ)``, its Riemannian gradient and Hessian on ``St(d, r)^n``
    (module docstring). A point is ``(n, r, d)`` blocks ``Y_i``; tangent vectors have the
    same shape."""

    def __init__(self, q: SchurQ, q_norm: float):
        """``q``: the data matrix's products; ``q_norm``: ``‖Q‖₂`` (sets the preconditioner's
        shift ``ε = 1e-6 ‖Q‖₂``)."""
        mats = q.mats
        self.q = q
        self.n, self.d = mats.n, mats.dim
        self.m = mats.laplacian.shape[0]
        shift = np.r_[np.zeros(self.m), np.full(self.d * self.n, _PRECONDITIONER_SHIFT * q_norm)]
        k = scipy.sparse.bmat(
            [[mats.laplacian, mats.coupling], [mats.coupling.T, mats.rotation]], format="csc"
        ) + scipy.sparse.diags(shift, format="csc")
        try:  # Schur complement Q + εI ≻ 0 and L_r ≻ 0: only a broken graph fails here
            self.precond = factor_spd(k, q.solver)
        except SingularSystem as exc:
            raise InputError("staircase: the preconditioner's matrix does not factor") from exc

    def _right(self, y: FloatArray, op: Callable[[FloatArray], FloatArray]) -> FloatArray:
        """``(Y A)`` blockwise for a symmetric dn x dn operator ``A`` applied to ``Yᵀ``."""
        n, r, d = y.shape
        stacked = y.transpose(1, 0, 2).reshape(r, n * d)
        return op(stacked.T).reshape(n, d, r).transpose(0, 2, 1)

    def q_right(self, y: FloatArray) -> FloatArray:
        """``Y Q`` as blocks."""
        return self._right(y, self.q)

    def objective(self, y: FloatArray) -> float:
        """``F(Y) = tr(Y Q Yᵀ)``."""
        return float(np.sum(y * self.q_right(y)))

    def gradient(self, y: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``grad F = 2 Y S`` and the multipliers ``Λ_i = sym(Y_iᵀ (Y Q)_i)`` it used."""
        yq = self.q_right(y)
        yy = np.swapaxes(y, 1, 2) @ yq
        lam = 0.5 * (yy + np.swapaxes(yy, 1, 2))
        return 2.0 * (yq - y @ lam), lam  # 2 P_Y(Y Q) = 2 (Y Q - Y Λ), tangent already

    def hessian(self, y: FloatArray, lam: FloatArray, eta: FloatArray) -> FloatArray:
        """``Hess F[η] = 2 P_Y(η S) = 2 P_Y(η Q - η Λ)`` (``lam`` from :meth:`gradient`)."""
        return self.project(y, 2.0 * (self.q_right(eta) - eta @ lam))

    @staticmethod
    def project(y: FloatArray, z: FloatArray) -> FloatArray:
        """``P_Y(Z)_i = Z_i - Y_i sym(Y_iᵀ Z_i)``."""
        yz = np.swapaxes(y, 1, 2) @ z
        return z - y @ (0.5 * (yz + np.swapaxes(yz, 1, 2)))

    def preconditioner(self, y: FloatArray, eta: FloatArray) -> FloatArray:
        """``P_Y(η (Q + εI)⁻¹)``, ``(Q + εI)⁻¹ x`` from the factored sparse block matrix."""
        m = self.m

        def solve(x: FloatArray) -> FloatArray:
            rhs = np.vstack([np.zeros((m, x.shape[1])), x])
            return np.asarray(self.precond.solve(rhs)[m:])

        return self.project(y, self._right(eta, solve))

    @staticmethod
    def retract(y: FloatArray, eta: FloatArray) -> FloatArray:
        """Each block ``Y_i + η_i`` replaced by its polar factor ``U Vᵀ`` (a second-order
        retraction)."""
        u, _, vt = np.linalg.svd(y + eta, full_matrices=False)
        return np.asarray(u @ vt)


def _inner(a: FloatArray, b: FloatArray) -> float:
    return float(np.sum(a * b))


def _trust_region(
    f: LiftedProblem, y: FloatArray, grad_tol: float, max_iterations: int, radius0: float
) -> tuple[FloatArray, int, float]:
    """Riemannian trust region with preconditioned truncated CG from ``y``: the point, the
    iterations and the final gradient norm (module docstring)."""
    fy = f.objective(y)
    radius, radius_max = radius0, 1e3 * radius0
    it = 0
    gnorm = np.inf
    while it < max_iterations:
        grad, lam = f.gradient(y)
        gnorm = np.sqrt(_inner(grad, grad))
        if gnorm <= grad_tol:
            break
        it += 1

        def hess(eta: FloatArray, y: FloatArray = y, lam: FloatArray = lam) -> FloatArray:
            return f.hessian(y, lam, eta)

        eta, h_eta, boundary = _truncated_cg(f, y, grad, hess, radius)
        predicted = -(_inner(grad, eta) + 0.5 * _inner(eta, h_eta))
        y_new = f.retract(y, eta)
        f_new = f.objective(y_new)
        # ρ = actual / predicted decrease; rounding makes both ~1e-16 F near the optimum.
        actual = fy - f_new
        rho = actual / predicted if predicted > 0 else -1.0
        if predicted <= 1e-15 * max(abs(fy), 1.0) and actual >= -1e-15 * max(abs(fy), 1.0):
            rho = 1.0  # at rounding level: take the step, the gradient test decides
        if rho < 0.25:
            radius *= 0.25
        elif rho > 0.75 and boundary:
            radius = min(2.0 * radius, radius_max)
        if rho > 0.1:
            y, fy = y_new, f_new
        if radius < 1e-14 * radius0:
            break  # no model step helps any more: stalled at rounding level
    return y, it, float(gnorm)


def _truncated_cg(
    f: LiftedProblem,
    y: FloatArray,
    grad: FloatArray,
    hess: Callable[[FloatArray], FloatArray],
    radius: float,
) -> tuple[FloatArray, FloatArray, bool]:
    """Steihaug-Toint CG on the model, trust region in the preconditioner's inverse norm.

    Stops on negative curvature or the boundary (then steps to it), or once the residual
    fell to ``‖r₀‖ min(‖r₀‖^θ, κ)`` (θ = 1, κ = 0.1: superlinear near the optimum), or after
    200 products. Returns ``η``, ``H η`` and whether it ended on the boundary. The norms
    ``⟨η, P⁻¹η⟩``, ``⟨η, P⁻¹δ⟩``, ``⟨δ, P⁻¹δ⟩`` follow by recurrences from CG's conjugacy."""
    eta = np.zeros_like(grad)
    h_eta = np.zeros_like(grad)
    r = grad.copy()
    r0 = np.sqrt(_inner(r, r))
    z = f.preconditioner(y, r)
    z_r = _inner(z, r)
    delta = -z
    e_pe, e_pd, d_pd = 0.0, 0.0, z_r
    stop = r0 * min(r0, 0.1)
    for _ in range(200):
        h_delta = hess(delta)
        d_hd = _inner(delta, h_delta)
        alpha = z_r / d_hd if d_hd > 0 else np.inf
        e_pe_new = e_pe + 2.0 * alpha * e_pd + alpha**2 * d_pd
        if d_hd <= 0 or e_pe_new >= radius**2:
            # τ ≥ 0 with ‖η + τδ‖² = Δ² in the P⁻¹ norm.
            tau = (-e_pd + np.sqrt(e_pd**2 + d_pd * (radius**2 - e_pe))) / d_pd
            return eta + tau * delta, h_eta + tau * h_delta, True
        e_pe = e_pe_new
        eta = eta + alpha * delta
        h_eta = h_eta + alpha * h_delta
        r = f.project(y, r + alpha * h_delta)  # projected: no drift off the tangent space
        if np.sqrt(_inner(r, r)) <= stop:
            break
        z = f.preconditioner(y, r)
        z_r_old, z_r = z_r, _inner(z, r)
        beta = z_r / z_r_old
        delta = -z + beta * delta
        e_pd = beta * (e_pd + alpha * d_pd)
        d_pd = z_r + beta**2 * d_pd
    return eta, h_eta, False


def _escape(f: LiftedProblem, y: FloatArray, vector: FloatArray, lam: float) -> FloatArray:
    """Rank ``r`` → ``r + 1`` along the eigenvector ``v`` of ``λ_min(S) < 0``: ``[Y; 0]`` moved
    along the new row ``vᵀ`` by the first ``α = √n / 2^k`` that lowers ``F`` by
    ``10⁻⁴ α² |λ|``."""
    n, r, d = y.shape
    lifted = np.concatenate([y, np.zeros((n, 1, d))], axis=1)
    direction = np.zeros_like(lifted)
    direction[:, r, :] = vector.reshape(n, d)
    f0 = f.objective(lifted)
    alpha = np.sqrt(n)
    while alpha > 1e-10:
        trial = f.retract(lifted, alpha * direction)
        if f.objective(trial) <= f0 - 1e-4 * alpha**2 * abs(lam):
            return trial
        alpha *= 0.5
    return f.retract(lifted, 1e-10 * direction)  # rounding-level λ: a nudge out of the saddle


def round_lifted(y: FloatArray) -> FloatArray:
    """``(n, r, d)`` lifted blocks ``Y_i`` → ``(n, d, d)`` rotations: the rank-``d`` factor
    of ``YᵀY``, its sign with more positive determinants, each block's nearest rotation
    (module docstring, *Rounding*)."""
    n, r, d = y.shape
    stacked = y.transpose(1, 0, 2).reshape(r, n * d)
    _, s, vt = np.linalg.svd(stacked, full_matrices=False)
    rhat = (s[:d, None] * vt[:d]).reshape(d, n, d).transpose(1, 0, 2)  # (n, d, d) blocks
    if np.count_nonzero(np.linalg.det(rhat) > 0) < n / 2:
        rhat[:, -1, :] *= -1.0  # the reflection diag(1, …, -1) from the left
    return nearest_rotations(rhat)


def nearest_rotations(blocks: FloatArray) -> FloatArray:
    """The rotation nearest each ``(n, d, d)`` block in the Frobenius norm:
    ``U diag(1, …, det(U Vᵀ)) Vᵀ`` from the block's SVD ``U Σ Vᵀ``."""
    u, _, vt = np.linalg.svd(blocks)
    sign = np.sign(np.linalg.det(u @ vt))
    u[:, :, -1] *= sign[:, None]
    return np.asarray(u @ vt)


def _poses(rots: FloatArray, q: SchurQ, start_rots: FloatArray, start_t0: FloatArray) -> FloatArray:
    """Rotations → file-format pose rows with their optimal translations, moved rigidly so
    that pose 0 has the start's pose 0 (``G = R_0^start R_0ᵀ``; ``R_i ← G R_i``,
    ``t_i ← G t_i + t_0^start``: ``F`` is invariant)."""
    n, d, _ = rots.shape
    g = start_rots[0] @ rots[0].T
    rots = g[None] @ rots
    t = q.translations(rots.transpose(1, 0, 2).reshape(d, n * d)) + start_t0[None]
    if d == 2:
        return np.column_stack([t, np.arctan2(rots[:, 1, 0], rots[:, 0, 0])])
    return factors3d.poses_to_external(np.concatenate([t, rots.reshape(n, 9)], axis=1))


def riemannian_staircase(
    data: GraphData,
    poses: ArrayLike,
    config: StaircaseConfig | None = None,
    *,
    linear_solver: LinearSolverName = "auto",
    rtol: float = CERTIFY_RTOL,
    callback: Callable[[RankStep], None] | None = None,
) -> StaircaseResult:
    """SE-Sync's global optimum of the relative-pose edges of ``data`` by the Riemannian
    staircase from the rotations of ``poses`` (rows in the order of
    ``GraphProblem.from_data(data).pose_ids``; 2D ``(x, y, θ)``, 3D
    ``(x, y, z, qw, qx, qy, qz)``), certified (module docstring).

    The trust region first runs at rank ``d`` from ``poses``: a start already at the optimum
    is certified there and returned with ``ranks_climbed = 0``. ``callback`` gets each rank's
    :class:`RankStep` as it finishes."""
    t0 = time.perf_counter()
    cfg = StaircaseConfig() if config is None else config
    check_certifiable(data)
    problem = GraphProblem.from_data(data, objective="sesync")
    d = int(data.dim)
    n = problem.pose_ids.shape[0]
    p = as_array(poses, "poses", (n, 3 if d == 2 else 7))
    if cfg.max_rank < d:
        raise InputError(f"staircase: max_rank {cfg.max_rank} is below the dimension {d}")
    mats = sesync_matrices(data, problem.pose_ids)
    q = SchurQ(mats, linear_solver)
    q_norm = q.norm()
    f = LiftedProblem(q, q_norm)
    grad_tol = cfg.gradient_rtol * q_norm * np.sqrt(d * n)
    radius0 = 0.1 * np.sqrt(q_norm * d * n)  # a turn of ~0.1 rad at every pose, in the P⁻¹ norm
    start_rots = rotation_blocks(p, d)
    y = start_rots.copy()
    steps: list[RankStep] = []
    while True:
        y, iters, gnorm = _trust_region(f, y, grad_tol, cfg.max_iterations, radius0)
        lifted = certify_blocks(q, y, rtol=rtol, q_norm=q_norm)
        cert = lifted.certificate
        step = RankStep(y.shape[1], cert.objective, cert.lambda_min, cert.certified, iters, gnorm)
        steps.append(step)
        if callback is not None:
            callback(step)
        if cert.certified or y.shape[1] >= cfg.max_rank:
            break
        y = _escape(f, y, lifted.eigenvector, cert.lambda_min)
    relaxation = steps[-1].objective
    rots = round_lifted(y) if y.shape[1] > d else y
    rots, _, _ = _trust_region(f, rots, grad_tol, cfg.max_iterations, radius0)  # polish at d
    rots = nearest_rotations(rots)  # the polish stays in SO(d); this only re-orthonormalises
    final = certify_blocks(q, rots, rtol=rtol, q_norm=q_norm).certificate
    out = _poses(rots, q, start_rots, p[:, :d][0])
    return StaircaseResult(out, final, tuple(steps), relaxation, time.perf_counter() - t0)
