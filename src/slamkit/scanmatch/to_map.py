"""Scan-to-map matching: register a scan to an occupancy grid through MCL's likelihood field.

The map enters as a :class:`~slamkit.localization.LikelihoodField` (built from a grid with
:meth:`LikelihoodField.from_grid` when a grid is given), so scan-to-map matching and MCL score
a scan with the same beam model. With ``d_p(ξ)`` the field's distance at the world point
``R(θ) q_p + t`` of beam end point ``q_p`` under pose ``ξ = (x, y, θ)``, bilinearly
interpolated between cell centres (:func:`~slamkit.maps.likelihood_field.
interpolate_distance`), the pose maximises the scan's log-likelihood

    log p(z | ξ, m) = sum_p log( z_hit N(d_p; 0, σ²) + z_rand / r_max ).

**Iteration** (Gauss-Newton on a reweighted least-squares surrogate, Levenberg-Marquardt
damped). At the current pose each point's responsibility ``w_p = z_hit N(d_p; 0, σ²) /
p(d_p)`` is the posterior probability that it is a hit (an EM step on the mixture; outliers
get ``w ≈ 0``). The surrogate ``sum_p w_p d_p² / (2σ²)`` is minimised by Gauss-Newton with
the Jacobian

    J_p = ∇d(p)ᵀ [ I₂ | (-(p_y - t_y), p_x - t_x)ᵀ ],      (∂p/∂θ = R'(θ) q_p)

giving ``H = sum_p w_p J_pᵀ J_p / σ²``, ``g = sum_p w_p d_p J_pᵀ / σ²`` and the damped step
``(H + λ diag H) δ = -g``. A step is kept only if the true negative log-likelihood decreases
(then ``λ`` shrinks tenfold, else it grows tenfold and the step is retried); the loop stops
when a kept step is below the tolerances, no damping gives a descent, or after
``max_iterations``. This is the Hector-SLAM / Cartographer idea of descending an
interpolated map field, on the distance field of the likelihood-field model.

**Covariance**: the inverse of ``H`` at the optimum (the Gauss-Newton Hessian of the negative
log-likelihood, beams taken as independent, so it is optimistic). An ``H`` that leaves a
direction nearly unconstrained (a corridor) gives a standard deviation above
``max_std_xy`` / ``max_std_theta`` and a :class:`~slamkit.errors.MatchError` ``"degenerate"``.

A far-off initial guess can start with a correlative search (pass ``coarse``, a
:class:`~slamkit.scanmatch.correlative.CorrelativeReference`, typically built once with
:meth:`CorrelativeReference.from_likelihood_field`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import ConfigError, InputError, MatchError
from slamkit.geometry.angles import wrap_angle_float
from slamkit.maps import OccupancyGrid
from slamkit.maps.likelihood_field import LikelihoodField, interpolate_distance
from slamkit.scanmatch.correlative import CorrelativeReference, correlative_match
from slamkit.scanmatch.result import MatchResult, require_points

__all__ = ["MapMatchConfig", "match_to_map"]

_MAX_DAMPING = 1e8  # beyond this the step is ~ -g / (λ diag H): no descent left to find


@dataclass(frozen=True)
class MapMatchConfig:
    """Settings of :func:`match_to_map` (metres and radians)."""

    sigma_hit: float = 0.05
    """``sigma_hit`` of the likelihood field built when a grid is given [m] (a given field
    keeps its own)."""
    max_iterations: int = 30
    """Most Gauss-Newton iterations (kept steps)."""
    step_tolerance_xy: float = 1e-5
    """Stop when a kept step moves less than this [m] ..."""
    step_tolerance_theta: float = 1e-6
    """... and turns less than this [rad]."""
    initial_damping: float = 1e-3
    """Initial Levenberg-Marquardt ``λ`` (relative to ``diag H``)."""
    inlier_sigmas: float = 3.0
    """A point within this many ``sigma_hit`` of an obstacle is an inlier."""
    min_points: int = 10
    """Fewest current points, and fewest that see the known map at the start and are
    inliers at the end, accepted (else ``MatchError``)."""
    max_std_xy: float | None = 0.1
    """Raise ``MatchError("degenerate")`` when the position standard deviation along some
    direction exceeds this [m]; ``None`` never raises."""
    max_std_theta: float | None = 0.05
    """The same for the heading [rad]."""

    def __post_init__(self) -> None:
        for name in ("sigma_hit", "inlier_sigmas", "initial_damping"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: expected a number > 0, got {v!r}")
        for name in ("step_tolerance_xy", "step_tolerance_theta"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: expected a number >= 0, got {v!r}")
        for name in ("max_iterations", "min_points"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")
        for name in ("max_std_xy", "max_std_theta"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: expected None or a number > 0, got {v!r}")


@dataclass(frozen=True)
class _State:
    """The field seen from one pose."""

    pose: FloatArray
    world: FloatArray  # (N, 2) end points in the map frame
    d: FloatArray  # (N,) interpolated distances
    grad: FloatArray  # (N, 2) their gradients
    nll: float  # -log p(z | pose, m)


def _state(field: LikelihoodField, points: FloatArray, pose: FloatArray) -> _State:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    world = np.empty_like(points)
    world[:, 0] = c * points[:, 0] - s * points[:, 1] + pose[0]
    world[:, 1] = s * points[:, 0] + c * points[:, 1] + pose[1]
    d, grad = interpolate_distance(field, world)
    return _State(pose, world, d, grad, -float(field.log_p(d).sum()))


def _normal_equations(field: LikelihoodField, st: _State) -> tuple[FloatArray, FloatArray]:
    """``H (3, 3)`` and ``g (3,)`` of the reweighted surrogate at ``st`` (module docstring)."""
    sigma = field.sigma_hit
    with np.errstate(divide="ignore"):
        log_hit = (
            np.log(field.z_hit)
            - 0.5 * (st.d / sigma) ** 2
            - math.log(sigma * math.sqrt(2 * math.pi))
        )
    w = np.exp(log_hit - field.log_p(st.d))  # responsibility of the hit component
    J = np.empty((st.d.size, 3))
    J[:, :2] = st.grad
    # ∂p/∂θ = (-(p_y - t_y), p_x - t_x): the end point's lever arm turned by 90°.
    J[:, 2] = -st.grad[:, 0] * (st.world[:, 1] - st.pose[1]) + st.grad[:, 1] * (
        st.world[:, 0] - st.pose[0]
    )
    Jw = J * (w / sigma**2)[:, None]
    return Jw.T @ J, Jw.T @ st.d


def _as_field(
    field_or_grid: LikelihoodField | OccupancyGrid, cfg: MapMatchConfig
) -> LikelihoodField:
    if isinstance(field_or_grid, LikelihoodField):
        return field_or_grid
    if isinstance(field_or_grid, OccupancyGrid):
        return LikelihoodField.from_grid(field_or_grid, cfg.sigma_hit)
    raise InputError(
        "field_or_grid: expected a LikelihoodField or an OccupancyGrid, got "
        f"{type(field_or_grid).__name__}"
    )


def match_to_map(
    field_or_grid: LikelihoodField | OccupancyGrid,
    current_points: ArrayLike,
    initial: ArrayLike,
    config: MapMatchConfig | None = None,
    *,
    coarse: CorrelativeReference | None = None,
) -> MatchResult:
    """Register ``current_points (N, 2)`` (sensor frame) to a map from ``initial =
    T_map_sensor (3,)`` by Gauss-Newton / Levenberg-Marquardt on the likelihood field (see
    the module docstring); with ``coarse``, a correlative search against it comes first.

    Returns the pose, ``H⁻¹`` as covariance, the mean per-point likelihood relative to a
    perfect hit as score, the inlier fraction (``d <= inlier_sigmas · sigma_hit``) and the
    number of kept steps. Raises :class:`MatchError` with reason ``"too_few_points"`` (an
    empty or tiny scan), ``"too_few_correspondences"`` (fewer than ``min_points`` points see
    the known map at the start, or are inliers at the end: e.g. a scan outside the map) or
    ``"degenerate"`` (a direction left unconstrained); a correlative start may raise its own.
    """
    cfg = MapMatchConfig() if config is None else config
    if not isinstance(cfg, MapMatchConfig):
        raise InputError(f"config: expected a MapMatchConfig, got {type(cfg).__name__}")
    field = _as_field(field_or_grid, cfg)
    pts = require_points(
        as_array(current_points, "current points", (None, 2)), cfg.min_points, "current"
    )
    pose = as_array(initial, "initial pose", (3,)).copy()
    method = "to_map"
    if coarse is not None:
        pose = correlative_match(coarse, pts, pose).pose.copy()
        method = "correlative+to_map"

    st = _state(field, pts, pose)
    seen = int(np.count_nonzero(st.d < field.outside_distance))
    if seen < cfg.min_points:
        raise MatchError(
            f"only {seen} of {pts.shape[0]} current points fall on the known map at the "
            f"initial pose; at least {cfg.min_points} are needed",
            "too_few_correspondences",
        )
    lam = cfg.initial_damping
    iterations = 0
    while iterations < cfg.max_iterations:
        H, g = _normal_equations(field, st)
        kept = False
        while lam < _MAX_DAMPING:
            A = H + lam * np.diag(np.diag(H)) + 1e-12 * np.eye(3)
            step = -np.linalg.solve(A, g)
            cand = st.pose + step
            cand[2] = wrap_angle_float(float(cand[2]))
            new = _state(field, pts, cand)
            if new.nll <= st.nll:
                st, kept = new, True
                lam = max(lam / 10.0, 1e-9)
                break
            lam *= 10.0
        if not kept:
            break
        iterations += 1
        if (
            math.hypot(step[0], step[1]) < cfg.step_tolerance_xy
            and abs(step[2]) < cfg.step_tolerance_theta
        ):
            break

    sigma = field.sigma_hit
    inlier = st.d <= cfg.inlier_sigmas * sigma
    n_in = int(np.count_nonzero(inlier))
    if n_in < cfg.min_points:
        raise MatchError(
            f"only {n_in} of {pts.shape[0]} points lie within {cfg.inlier_sigmas} sigma_hit "
            f"of an obstacle after refinement; at least {cfg.min_points} are needed",
            "too_few_correspondences",
        )
    H, _ = _normal_equations(field, st)
    evals, evecs = np.linalg.eigh(H)
    if evals[0] <= 1e-12 * max(evals[-1], 1e-300):
        raise MatchError(
            "scan-to-map Hessian is singular: the map does not constrain the pose", "degenerate"
        )
    cov = (evecs / evals) @ evecs.T  # H⁻¹ from its eigen decomposition (H is symmetric PD)
    cov = 0.5 * (cov + cov.T)
    std_xy = math.sqrt(float(np.linalg.eigvalsh(cov[:2, :2])[-1]))
    std_t = math.sqrt(float(cov[2, 2]))
    if cfg.max_std_xy is not None and std_xy > cfg.max_std_xy:
        raise MatchError(
            f"scan-to-map position std {std_xy:.3f} m along the weakest direction exceeds "
            f"max_std_xy {cfg.max_std_xy}",
            "degenerate",
        )
    if cfg.max_std_theta is not None and std_t > cfg.max_std_theta:
        raise MatchError(
            f"scan-to-map heading std {std_t:.4f} rad exceeds max_std_theta {cfg.max_std_theta}",
            "degenerate",
        )
    top = float(field.log_p(0.0))
    score = float(np.mean(np.exp(field.log_p(st.d) - top)))
    return MatchResult(
        pose=st.pose,
        cov=cov,
        score=min(max(score, 0.0), 1.0),
        inlier_fraction=n_in / pts.shape[0],
        iterations=iterations,
        method=method,
    )
