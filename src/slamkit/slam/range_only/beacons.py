"""Locating a beacon from ranges read along a path, with its mirror ambiguity kept.

**The problem.** Ranges ``r_k`` to an unknown beacon ``l`` are read from positions ``p_k``
(the dead-reckoned path so far). Each range puts ``l`` on a circle about ``p_k``; the beacon
is where the circles meet. Least squares: minimise ``Σ ρ(((‖l - p_k‖ - r_k) / σ)²)`` over
``l`` (``ρ`` a robust kernel of :mod:`slamkit.optim.robust`).

**Seeds.** Write the positions in their principal frame (centre ``c``, major axis ``e₁``,
minor axis ``e₂``): ``p_k = c + a_k e₁ + b_k e₂`` and ``l = c + x e₁ + y e₂``. On a straight
path (``b_k = 0``) ``r_k² = (x - a_k)² + y²``, i.e. ``r_k² - a_k² = w - 2 a_k x`` with
``w = x² + y²``: linear in ``(x, w)``. Its least-squares solution gives ``x`` and
``|y| = √(w - x²)``, the two seeds ``(x, ±|y|)``. Each is refined by Gauss-Newton with IRLS
weights (``∂‖l - p_k‖/∂l = uₖᵀ``, the unit vector from ``p_k`` to ``l``).

**The mirror.** On a straight path the cost is symmetric in ``y``: both seeds are minima of
equal cost and nothing in the data can choose between them. When the path leaves the line
by ``b_k``, ``(y - b_k)² - (y + b_k)² = -4 y b_k`` separates the two predicted ranges by
``δ_k ≈ 2 y b_k / r_k``. For fixed points, with whitened noise ``n_k``, the cost gap is
``ΔS = S_wrong - S_true = Σ (n_k + δ_k/σ)² - n_k² = λ + 2 Σ n_k δ_k / σ`` with
``λ = Σ δ_k² / σ²``: mean ``λ``, variance ``4λ``. We decide for the lower-cost hypothesis
once ``|ΔS| ≥ τ``. The wrong one is chosen only if ``ΔS ≤ -τ``, with probability
``Φ(-(τ + λ) / (2√λ))``; over ``λ`` this is largest at ``λ = τ``, so
``P(wrong) ≤ Φ(-√τ)``: with ``τ = 25`` (:data:`MIRROR_GAP`), ``Φ(-5) ≈ 3e-7`` per decision.
When the two refined points coincide (within :data:`SAME_POINT_M`) the path has already
turned enough for a single minimum and no test is needed. Until one of these happens both
hypotheses are kept (:class:`BeaconFix` with ``resolved=False``).

**Precision.** A fix is only taken when the chosen point's standard deviation (from
``(Jᵀ W J / σ²)⁻¹``) is at most ``max_sigma`` in every direction: a short stretch of path can
be unambiguous yet still leave the beacon poorly placed along the circles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import InputError
from slamkit.optim.robust import RobustKernel, robust_rho_and_weight

__all__ = [
    "MIRROR_GAP",
    "SAME_POINT_M",
    "BeaconFix",
    "BeaconHypothesis",
    "locate_beacon",
    "mirror_seeds",
    "refine_beacon",
]

MIRROR_GAP = 25.0
"""``τ``: the robust χ² gap between the two mirror hypotheses at which the lower one is taken
(``P(wrong) ≤ Φ(-√τ) ≈ 3e-7``; derivation in the module docstring)."""

SAME_POINT_M = 0.5
"""Two refined hypotheses closer than this [m] are one point: the path has turned enough."""

_GN_ITERATIONS = 30


@dataclass(frozen=True)
class BeaconHypothesis:
    """One local minimum of the beacon's range cost: ``position (2,)``, its robust cost
    ``cost`` (``Σ ρ(e²/σ²)``) and covariance ``cov (2, 2)``."""

    position: FloatArray
    cost: float
    cov: FloatArray


@dataclass(frozen=True)
class BeaconFix:
    """The outcome of :func:`locate_beacon`: the hypotheses (lowest cost first; one when the
    minima coincide) and whether the first is taken (``resolved``) and why (``reason``)."""

    hypotheses: tuple[BeaconHypothesis, ...]
    resolved: bool
    reason: str

    @property
    def best(self) -> BeaconHypothesis:
        return self.hypotheses[0]


def _check(positions: FloatArray, ranges: FloatArray) -> tuple[FloatArray, FloatArray]:
    p = np.asarray(positions, dtype=np.float64)
    r = np.asarray(ranges, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or r.shape != (p.shape[0],):
        raise InputError(
            f"locate_beacon: expected positions (K, 2) and ranges (K,), got {p.shape} and {r.shape}"
        )
    if not (np.isfinite(p).all() and np.isfinite(r).all()):
        raise InputError("locate_beacon: positions and ranges must be finite")
    return p, r


def mirror_seeds(positions: FloatArray, ranges: FloatArray) -> FloatArray:
    """The two seeds ``(2, 2)``: the straight-path solution and its mirror image across the
    positions' major axis (module docstring). Needs two distinct positions."""
    p, r = _check(positions, ranges)
    c = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - c, full_matrices=False)
    if s[0] <= 0.0:
        raise InputError("mirror_seeds: the positions do not move")
    e1, e2 = vt[0], np.array([-vt[0, 1], vt[0, 0]])
    a = (p - c) @ e1
    # r² - a² = w - 2 a x, least squares in (x, w)
    A = np.column_stack([-2.0 * a, np.ones_like(a)])
    (x, w), *_ = np.linalg.lstsq(A, r * r - a * a, rcond=None)
    y = np.sqrt(max(w - x * x, 0.0))
    return np.stack([c + x * e1 + y * e2, c + x * e1 - y * e2])


def refine_beacon(
    positions: FloatArray,
    ranges: FloatArray,
    seed: FloatArray,
    sigma: float,
    kernel: RobustKernel,
) -> BeaconHypothesis:
    """Gauss-Newton with IRLS weights from ``seed`` on ``Σ ρ(((‖l - p_k‖ - r_k)/σ)²)``."""
    p, r = _check(positions, ranges)
    lm = np.asarray(seed, dtype=np.float64).copy()
    H = np.eye(2)
    for _ in range(_GN_ITERATIONS):
        d = lm - p
        dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        e = (dist - r) / sigma
        _, w = robust_rho_and_weight(kernel, e * e)
        J = d / dist[:, None] / sigma  # ∂e/∂l = uᵀ / σ
        H = (J * w[:, None]).T @ J
        g = (J * w[:, None]).T @ e
        try:
            step = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            break
        lm = lm + step
        if np.hypot(*step) < 1e-6:
            break
    d = lm - p
    e = (np.hypot(d[:, 0], d[:, 1]) - r) / sigma
    rho, _ = robust_rho_and_weight(kernel, e * e)
    try:
        cov = np.asarray(np.linalg.inv(H), dtype=np.float64)
    except np.linalg.LinAlgError:
        cov = np.full((2, 2), np.inf)
    return BeaconHypothesis(lm, float(rho.sum()), cov)


def locate_beacon(
    positions: FloatArray,
    ranges: FloatArray,
    sigma: float,
    kernel: RobustKernel,
    max_sigma: float,
) -> BeaconFix:
    """Both mirror hypotheses of a beacon read from ``positions (K, 2)`` at ``ranges (K,)``
    [m], refined, and the decision between them (module docstring). ``sigma``: the range
    noise [m]; ``max_sigma``: the largest standard deviation [m] of a fix that is taken."""
    seeds = mirror_seeds(positions, ranges)
    hyps = sorted(
        (refine_beacon(positions, ranges, s, sigma, kernel) for s in seeds),
        key=lambda h: h.cost,
    )
    best, other = hyps
    sd = (
        float(np.sqrt(np.max(np.linalg.eigvalsh(best.cov))))
        if np.isfinite(best.cov).all()
        else np.inf
    )
    if not sd <= max_sigma:
        return BeaconFix((best, other), False, f"imprecise: standard deviation {sd:.3g} m")
    if np.hypot(*(best.position - other.position)) < SAME_POINT_M:
        return BeaconFix((best,), True, "one minimum")
    gap = other.cost - best.cost
    if gap >= MIRROR_GAP:
        return BeaconFix((best, other), True, f"mirror rejected: cost gap {gap:.3g}")
    return BeaconFix((best, other), False, f"ambiguous: cost gap {gap:.3g}")
