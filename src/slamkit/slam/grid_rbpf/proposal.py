"""The proposals of the grid RBPF: where a particle's new pose is drawn from, and the
factor its weight is multiplied by.

With ``x'`` the particle's previous pose, ``u`` the odometry since, ``m`` its map and ``z``
the new scan, the optimal proposal is ``p(x | m, x', z, u) ∝ p(z | x, m) p(x | x', u)``
and the weight factor its normaliser ``η = ∫ p(z | x, m) p(x | x', u) dx`` (Grisetti,
Stachniss & Burgard 2007, eqs. 9-11). The scan likelihood is the likelihood field of the
particle's map, tempered: ``log p(z | x, m) / T``, with ``T = likelihood_temperature`` in
the weights and ``T =`` :data:`PROPOSAL_TEMPERATURE` (1: untempered) in the Gaussian fitted
as the proposal. Three ways to draw:

* :func:`gaussian_proposal` (the paper's): around the scan-match mode ``x*`` evaluate
  ``f(x) = p(z | x, m) p(x | x', u)`` on a 3 × 3 × 3 stencil ``x_k = x* + B s_k``,
  ``s_k ∈ {-1, 0, 1}³``, whose basis ``B`` spans ± :data:`STENCIL_SIGMAS` standard deviations
  along the principal axes of the predicted proposal covariance ``(H/T + Σ_u⁻¹)⁻¹`` (``H``
  the match's information, ``Σ_u`` the motion covariance). With normalised weights
  ``w_k = f(x_k) / Σ f``, the proposal is ``N(μ, Σ)``, ``μ = Σ w_k x_k``,
  ``Σ = Σ w_k (x_k - μ)(x_k - μ)ᵀ`` (headings relative to ``x*``, wrapped), and
  ``η ≈ |det B| Σ_k f(x_k)`` — the quadrature of the integral on the stencil's cells, so that
  particles whose stencils differ in size are weighed alike (``η`` on a second stencil,
  sized with the weights' temperature).
* :func:`mode_proposal` (GMapping's released code): ``x* + ε``, ``ε ~ N(0, diag(σ²))``
  small, with ``η ≈ f(x*)``.
* :func:`motion_proposal` (the fallback when the match fails): ``x ~ p(x | x', u)``, weight
  factor ``p(z | x, m)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.pose2 import compose
from slamkit.maps.likelihood_field import LikelihoodField, log_likelihood
from slamkit.slam.grid_rbpf.config import GridRbpfConfig

__all__ = [
    "MODE_NOISE",
    "MOTION_FLOOR",
    "PROPOSAL_TEMPERATURE",
    "STENCIL",
    "STENCIL_SIGMAS",
    "Scan",
    "gaussian_proposal",
    "mode_proposal",
    "motion_covariance",
    "motion_log_density",
    "motion_proposal",
]

STENCIL = np.array(
    [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], dtype=np.float64
)
"""The 27 stencil offsets ``s_k`` of :func:`gaussian_proposal` (in units of the basis)."""

_COV_FLOOR = np.diag([1e-8, 1e-8, 1e-10])  # m², m², rad²: keeps a fitted Σ factorizable

STENCIL_SIGMAS = 1.5
"""The stencil of :func:`gaussian_proposal` spans ± this many standard deviations of the
predicted proposal along each of its principal axes."""

PROPOSAL_TEMPERATURE = 1.0
"""The temperature of the likelihood in the Gaussian fitted as the proposal: 1, the
likelihood as it is, so the draws stay as close to the match as the scan allows (with the
weights' temperature of 10 for both the simulated rooms scored 0.056 m instead of 0.037 m,
``docs/estimators/grid_rbpf.md``)."""

MODE_NOISE = np.array([0.01, 0.01, math.radians(0.3)])
"""The mode proposal's noise: standard deviations of x, y [m] and heading [rad] added to the
match (GMapping's released code adds noise of this size)."""

MOTION_FLOOR = np.array([0.01, math.radians(0.5)])
"""The least position [m] and heading [rad] standard deviations of one update's motion:
a robot that did not move still has a pose known only so well."""


@dataclass(frozen=True, eq=False)
class Scan:
    """One scan as the weights see it: ``ranges (B,)`` [m] at ``angles (B,)`` [rad] (every
    ``beam_stride``-th beam; readings to be skipped set to the field's max range, which the
    likelihood field ignores) and the laser's ``mounting (3,)`` in the robot frame."""

    ranges: FloatArray
    angles: FloatArray
    mounting: FloatArray

    def log_likelihood(
        self, field: LikelihoodField, poses: FloatArray, temperature: float
    ) -> FloatArray:
        """``log p(z | x_k, m) / T`` ``(K,)`` of robot poses ``(K, 3)``."""
        return log_likelihood(field, poses, self.ranges, self.angles, self.mounting) / temperature


def motion_covariance(
    delta: FloatArray, cfg: GridRbpfConfig, travelled: tuple[float, float] | None = None
) -> FloatArray:
    """``Σ_u (3, 3)`` of the odometry motion ``delta = (dx, dy, dθ)`` (in the frame of the
    previous pose): position and heading standard deviations grow linearly with the distance
    travelled and the angle turned, plus floors; isotropic in position, so the same in the
    world frame whatever the heading.

    ``travelled = (path length [m], turning [rad])``: what the odometry went through since
    the previous pose, summed step by step (``Σ |Δt_i|``, ``Σ |Δθ_i|``) — the wheels err per
    metre rolled and per radian turned, so a robot that backs up and drives on again errs
    over the whole way, not over the net ``delta``. None: the net motion of ``delta``."""
    if travelled is None:
        d = math.hypot(float(delta[0]), float(delta[1]))
        a = abs(float(wrap_angle(delta[2])))
    else:
        d, a = float(travelled[0]), float(travelled[1])
    s_xy = MOTION_FLOOR[0] + cfg.motion_trans_per_m * d + cfg.motion_trans_per_rad * a
    s_th = MOTION_FLOOR[1] + cfg.motion_rot_per_m * d + cfg.motion_rot_per_rad * a
    sd = np.array([s_xy, s_xy, s_th])
    with np.errstate(over="ignore"):  # an absurd motion gives inf: the caller checks
        return np.diag(sd * sd)


def motion_log_density(poses: FloatArray, mean: FloatArray, cov: FloatArray) -> FloatArray:
    """``log N(x_k; mean, cov)`` ``(K,)`` for poses ``(K, 3)`` (heading difference wrapped)."""
    r = poses - mean
    r[:, 2] = wrap_angle(r[:, 2])
    L = np.linalg.cholesky(cov)
    y = np.linalg.solve(L, r.T)
    log_det = 2.0 * float(np.log(np.diag(L)).sum())
    out: FloatArray = -0.5 * (np.sum(y * y, axis=0) + log_det + 3.0 * math.log(2.0 * math.pi))
    return out


def _log_f(
    field: LikelihoodField,
    scan: Scan,
    poses: FloatArray,
    predicted: FloatArray,
    motion_cov: FloatArray,
    temperature: float,
) -> FloatArray:
    """``log f(x_k) = log p(z | x_k, m) / T + log p(x_k | x', u)``."""
    return scan.log_likelihood(field, poses, temperature) + motion_log_density(
        poses, predicted, motion_cov
    )


def _stencil(
    mode: FloatArray,
    information: FloatArray,
    motion_cov: FloatArray,
    temperature: float,
    sigmas: float,
) -> tuple[FloatArray, float]:
    """The stencil poses ``(27, 3)`` around ``mode`` along the principal axes of
    ``(H/T + Σ_u⁻¹)⁻¹``, ``± sigmas`` standard deviations, and ``log |det B|``."""
    info = information / temperature + np.linalg.inv(motion_cov)
    evals, evecs = np.linalg.eigh(0.5 * (info + info.T))
    scale = sigmas / np.sqrt(evals)
    poses: FloatArray = mode + STENCIL @ (evecs * scale).T
    # B's columns are orthogonal: |det B| is the product of their lengths.
    return poses, float(np.log(scale).sum())


def gaussian_proposal(
    field: LikelihoodField,
    scan: Scan,
    predicted: FloatArray,
    mode: FloatArray,
    match_information: FloatArray,
    motion_cov: FloatArray,
    cfg: GridRbpfConfig,
    rng: np.random.Generator,
) -> tuple[FloatArray, float]:
    """The new pose drawn from the Gaussian fitted around the match ``mode``, and
    ``log η`` (module docstring). ``match_information`` is the match's ``H (3, 3)``.

    The Gaussian is fitted with the likelihood tempered by :data:`PROPOSAL_TEMPERATURE` and
    ``η`` integrated with ``likelihood_temperature``, each on its own stencil (the second
    is wider): the proposal follows the match as closely as the scan allows, the weights
    do not let one particle take all the weight."""
    t_p, t_w = PROPOSAL_TEMPERATURE, cfg.likelihood_temperature
    poses, log_det_p = _stencil(mode, match_information, motion_cov, t_p, STENCIL_SIGMAS)
    log_f = _log_f(field, scan, poses, predicted, motion_cov, t_p)
    top = float(log_f.max())
    if not math.isfinite(top):
        return mode.copy(), -math.inf
    w = np.exp(log_f - top)
    w /= w.sum()
    rel = poses - mode
    rel[:, 2] = wrap_angle(rel[:, 2])
    mu_rel = w @ rel
    centred = rel - mu_rel
    cov = (centred * w[:, None]).T @ centred + _COV_FLOOR
    draw = mode + mu_rel + np.linalg.cholesky(cov) @ rng.standard_normal(3)
    draw[2] = float(wrap_angle(draw[2]))
    if t_w == t_p:
        log_fw, log_det = log_f, log_det_p
    else:
        wide, log_det = _stencil(mode, match_information, motion_cov, t_w, STENCIL_SIGMAS)
        log_fw = _log_f(field, scan, wide, predicted, motion_cov, t_w)
    # η ≈ |det B| Σ_k f(x_k): the stencil as a quadrature rule of ∫ f.
    top_w = float(log_fw.max())
    log_eta = top_w + math.log(float(np.exp(log_fw - top_w).sum())) + log_det
    return draw, log_eta


def mode_proposal(
    field: LikelihoodField,
    scan: Scan,
    predicted: FloatArray,
    mode: FloatArray,
    motion_cov: FloatArray,
    cfg: GridRbpfConfig,
    rng: np.random.Generator,
) -> tuple[FloatArray, float]:
    """The match ``mode`` plus small noise, and ``log f(mode)`` as the weight factor."""
    t_w = cfg.likelihood_temperature
    log_f = float(_log_f(field, scan, mode[None, :], predicted, motion_cov, t_w)[0])
    draw = mode + MODE_NOISE * rng.standard_normal(3)
    draw[2] = float(wrap_angle(draw[2]))
    return draw, log_f


def motion_proposal(
    field: LikelihoodField | None,
    scan: Scan,
    previous: FloatArray,
    delta: FloatArray,
    motion_cov: FloatArray,
    cfg: GridRbpfConfig,
    rng: np.random.Generator,
) -> tuple[FloatArray, float]:
    """A draw from the motion model, ``previous ⊕ (delta + ε)``, ``ε ~ N(0, Σ_u)``, and
    ``log p(z | x, m) / T`` there (0 without a field: nothing to weigh against)."""
    eps = np.linalg.cholesky(motion_cov) @ rng.standard_normal(3)
    draw = compose(previous, delta + eps)
    if field is None:
        return draw, 0.0
    return draw, float(scan.log_likelihood(field, draw[None, :], cfg.likelihood_temperature)[0])
