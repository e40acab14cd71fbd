"""Odometry noise learned by maximum likelihood from the laser's relative motions.

The measurement of pair ``p`` (scans ``a < b``, :mod:`slamkit.calibration.pairs`) is the
residual ``r_p = between(T̂_La_Lb, T_La_Lb)`` of the laser's matched motion against the one
the calibrated odometry predicts. To first order it is Gaussian with covariance

    S_p = Σ_match,p + Σ_k θ_k B_k,p,

the matcher's covariance plus the odometry's, where the odometry noise of each step ``j``
is a covariance ``Q_j`` of ``(rot1, trans, rot2)`` linear in parameters ``θ_k >= 0``:
``Q_j = Σ_k θ_k f_k(j) E_k`` with ``E_k`` the diagonal selecting the rotations
(``diag(1, 0, 1)``) or the translation (``diag(0, 1, 0)``) and ``f_k(j)`` a feature of the
step. Two models are offered:

* ``per_step`` (the raw loaders' ``odometry_sigma_rot_deg`` and ``odometry_sigma_trans``,
  what a :class:`~slamkit.datasets.MotionSpec` of raw odometry holds): ``Q_j = diag(σ_r²,
  σ_t², σ_r²)`` whatever the step;
* ``per_distance`` (the random part of :class:`~slamkit.sim.OdometryErrorModel`): ``var(trans)
  = k_trans² d_j`` and each of the two rotations ``(k_rot² |a_j| + k_drift² d_j) / 2``, with
  ``d_j`` the step's distance and ``a_j`` its turn.

A step's noise reaches the end pose ``b`` through the chain of the steps after it. In world
coordinates (the odometry integrated from the origin, ``X_j`` the pose before step ``j``),
``∂X_{j+1}/∂u_j = V_j`` (:meth:`~slamkit.models.OdometryModel.jacobians`), and moving
``X_{j+1}`` moves ``X_b`` rigidly: ``∂X_b/∂X_{j+1} = [[1, 0, -(y_b - y_{j+1})],
[0, 1, x_b - x_{j+1}], [0, 0, 1]]``. A small error of the end pose written in its own frame
(what ``between`` of the pair measures) is the world error with its position rotated by
``R(θ_b)ᵀ``. So with ``A_j = R_bᵀ ∂X_b/∂X_{j+1} V_j``,

    B_k,p = Σ_{a <= j < b} f_k(j) A_j E_k A_jᵀ.

The negative log-likelihood ``½ Σ_p [log det S_p + r_pᵀ S_p⁻¹ r_p]`` is minimised over
``η = log θ`` (so ``θ > 0``) with its analytic gradient ``½ Σ_p [tr(S_p⁻¹ B_k,p) - r_pᵀ S_p⁻¹
B_k,p S_p⁻¹ r_p] θ_k``; the parameters' covariance is the inverse Fisher information
``I_kl = ½ Σ_p tr(S_p⁻¹ B_k,p S_p⁻¹ B_l,p)``. Pairs whose Mahalanobis distance ``r_pᵀ S_p⁻¹
r_p`` exceeds the χ²(3) 99.9 % bound are trimmed and the fit repeated (a scan match gone
wrong, a glitch of the wheels), at most :data:`TRIM_ROUNDS` times; the count is reported.
This is one M-step of Eliazar & Parr's EM with the scan-matched motions standing in for the
path; :func:`slamkit.calibration.calibrate` alternates it with the systematic fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError, InputError
from slamkit.geometry import wrap_angle
from slamkit.models import OdometryModel, integrate_odometry

__all__ = [
    "CHI2_3_999",
    "NOISE_MODELS",
    "TRIM_ROUNDS",
    "NoiseFit",
    "NoiseModelName",
    "fit_noise",
    "negative_log_likelihood",
    "odometry_cov_bases",
]

NoiseModelName = Literal["per_step", "per_distance"]

NOISE_MODELS: dict[str, tuple[str, ...]] = {
    "per_step": ("sigma_rot", "sigma_trans"),
    "per_distance": ("k_trans", "k_rot", "k_drift"),
}
"""Each model's parameters (standard deviations; ``θ`` are their squares): ``sigma_rot``
[rad per rotation per step], ``sigma_trans`` [m per step], ``k_trans`` [m/√m], ``k_rot``
[rad/√rad], ``k_drift`` [rad/√m]."""

CHI2_3_999 = 16.266
"""χ²(3) 99.9 % quantile: a pair's Mahalanobis distance beyond it is trimmed."""

TRIM_ROUNDS = 5
"""Fits repeated at most this often while trimming changes the pairs kept."""

_LOWER = -60.0  # log θ: a variance of 1e-26, i.e. none

_ROT = np.diag([1.0, 0.0, 1.0])
_TRANS = np.diag([0.0, 1.0, 0.0])


def _step_pairs(
    n_steps: int, first: NDArray[np.int64], last: NDArray[np.int64]
) -> NDArray[np.int64]:
    """For each step ``j`` the pair holding it (``first[p] <= j < last[p]``), or -1."""
    j = np.arange(n_steps)
    p = np.searchsorted(first, j, side="right") - 1
    inside = (p >= 0) & (j < last[np.clip(p, 0, None)]) if first.size else np.zeros(n_steps, bool)
    return np.where(inside, p, -1).astype(np.int64)


def odometry_cov_bases(
    steps: FloatArray,
    first: NDArray[np.int64],
    last: NDArray[np.int64],
    model: NoiseModelName,
) -> FloatArray:
    """``B (K, P, 3, 3)``: the odometry covariance of each pair's end pose in its own frame
    per unit of each parameter ``θ_k`` of ``model`` (the module docstring's ``B_k,p``), for
    steps ``(S, 3)`` (the odometry increments, corrected) and pairs ``first``/``last``."""
    if model not in NOISE_MODELS:
        raise InputError(f"noise model: expected one of {sorted(NOISE_MODELS)}, got {model!r}")
    X = integrate_odometry(np.zeros(3), steps)
    _, V = OdometryModel().jacobians(X[:-1], steps)  # ∂X_{j+1}/∂u_j, world coordinates
    pair = _step_pairs(steps.shape[0], first, last)
    used = pair >= 0
    j = np.nonzero(used)[0]
    end = X[last[pair[j]]]
    after = X[j + 1]
    A = V[j].copy()
    # Moving X_{j+1} carries X_b rigidly: the heading row's effect times the lever arm.
    A[:, 0, :] -= (end[:, 1] - after[:, 1])[:, None] * V[j, 2, :]
    A[:, 1, :] += (end[:, 0] - after[:, 0])[:, None] * V[j, 2, :]
    c, s = np.cos(end[:, 2]), np.sin(end[:, 2])
    x_row, y_row = A[:, 0, :].copy(), A[:, 1, :].copy()
    A[:, 0, :] = c[:, None] * x_row + s[:, None] * y_row  # R(θ_b)ᵀ on the position rows
    A[:, 1, :] = -s[:, None] * x_row + c[:, None] * y_row
    rot = np.einsum("nik,kl,njl->nij", A, _ROT, A)
    trans = np.einsum("nik,kl,njl->nij", A, _TRANS, A)
    d = np.abs(steps[j, 1])
    turn = np.abs(wrap_angle(steps[j, 0] + steps[j, 2]))
    if model == "per_step":
        per_step = [rot, trans]
    else:
        per_step = [trans * d[:, None, None], rot * (0.5 * turn)[:, None, None],
                    rot * (0.5 * d)[:, None, None]]  # fmt: skip
    out = np.zeros((len(per_step), first.size, 3, 3))
    for k, contrib in enumerate(per_step):
        np.add.at(out[k], pair[j], contrib)
    return out


@dataclass(frozen=True, eq=False)
class NoiseFit:
    """A fitted noise model: ``values`` (standard deviations, see :data:`NOISE_MODELS`),
    their ``stds`` (delta method from the inverse Fisher information; 0 for a value at 0,
    a noise the data show none of), the pairs
    ``used`` and ``trimmed``, and the fit's mean Mahalanobis distance per degree of freedom
    (1 when the model explains the residuals)."""

    model: NoiseModelName
    names: tuple[str, ...]
    values: tuple[float, ...]
    stds: tuple[float, ...]
    used: int
    trimmed: int
    chi2_per_dof: float
    kept: NDArray[np.bool_] | None = None
    """The pairs the fit kept (None: not fitted, a starting value)."""

    def theta(self) -> FloatArray:
        """``θ``: the parameters' squares (variances per unit feature)."""
        return np.square(np.asarray(self.values, dtype=np.float64))

    def as_dict(self) -> dict[str, object]:
        return {
            "model": self.model,
            "values": dict(zip(self.names, self.values, strict=True)),
            "stds": dict(zip(self.names, self.stds, strict=True)),
            "pairs_used": self.used,
            "pairs_trimmed": self.trimmed,
            "chi2_per_dof": self.chi2_per_dof,
        }


def _nll(
    eta: FloatArray, r: FloatArray, base: FloatArray, bases: FloatArray
) -> tuple[float, FloatArray]:
    theta = np.exp(eta)
    S = base + np.einsum("k,kpij->pij", theta, bases)
    sign, logdet = np.linalg.slogdet(S)
    if np.any(sign <= 0):
        return math.inf, np.zeros_like(eta)
    Si_r = np.linalg.solve(S, r[..., None])[..., 0]
    Si_B = np.linalg.solve(S[None], bases)  # S⁻¹ B_k for every k and pair
    value = 0.5 * float(np.sum(logdet) + np.einsum("pi,pi->", r, Si_r))
    tr = np.einsum("kpii->k", Si_B)
    quad = np.einsum("pi,kpij,pj->k", Si_r, bases, Si_r)
    return value, 0.5 * (tr - quad) * theta


def _mahalanobis(r: FloatArray, S: FloatArray) -> FloatArray:
    return np.einsum("pi,pi->p", r, np.linalg.solve(S, r[..., None])[..., 0])


def fit_noise(
    residuals: FloatArray,
    base_cov: FloatArray,
    bases: FloatArray,
    model: NoiseModelName,
    start: FloatArray | None = None,
) -> NoiseFit:
    """The maximum-likelihood ``θ`` of ``model`` for ``residuals (P, 3)`` with known
    covariance ``base_cov (P, 3, 3)`` (the matcher's) plus ``Σ_k θ_k bases[k]`` (from
    :func:`odometry_cov_bases`); see the module docstring. ``start (K,)`` is the first guess
    of ``θ`` (default: each basis's share of the residuals' mean square)."""
    names = NOISE_MODELS[model]
    if bases.shape[0] != len(names):
        raise InputError(
            f"noise model {model!r}: expected {len(names)} bases, got {bases.shape[0]}"
        )
    keep = np.ones(residuals.shape[0], dtype=bool)
    if start is None:
        scale = np.einsum("kpii->k", bases) / max(residuals.shape[0], 1)
        mean_sq = float(np.mean(residuals**2)) * 3.0
        start = np.full(len(names), mean_sq) / np.maximum(scale * len(names), 1e-300)
    eta = np.log(np.maximum(np.asarray(start, dtype=np.float64), 1e-16))
    for _ in range(TRIM_ROUNDS):
        if int(keep.sum()) <= len(names):
            raise ConvergenceError(
                f"noise fit: {int(keep.sum())} pairs left after trimming; too few for "
                f"{len(names)} parameters"
            )
        r, base, B = residuals[keep], base_cov[keep], bases[:, keep]
        res = minimize(_nll, eta, args=(r, base, B), jac=True, method="L-BFGS-B",
                       bounds=[(_LOWER, 10.0)] * len(names))  # fmt: skip
        eta = res.x
        S_all = base_cov + np.einsum("k,kpij->pij", np.exp(eta), bases)
        new_keep = _mahalanobis(residuals, S_all) <= CHI2_3_999
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    theta = np.exp(eta)
    r, base, B = residuals[keep], base_cov[keep], bases[:, keep]
    S = base + np.einsum("k,kpij->pij", theta, B)
    Si_B = np.linalg.solve(S[None], B)
    fisher = 0.5 * np.einsum("kpij,lpji->kl", Si_B, Si_B)
    # A parameter at its lower bound (the data show none of that noise) is reported as 0
    # with no spread; the others' covariance is the inverse Fisher information among them.
    free = eta > _LOWER + 1.0
    theta = np.where(free, theta, 0.0)
    theta_var = np.zeros(len(names))
    if np.any(free):
        theta_var[free] = np.diag(np.linalg.pinv(fisher[np.ix_(free, free)]))
    sig = np.sqrt(theta)
    # σ = √θ: dσ = dθ / (2σ)
    sig_std = np.where(
        free, np.sqrt(np.maximum(theta_var, 0.0)) / np.maximum(2.0 * sig, 1e-300), 0.0
    )
    chi2 = float(np.mean(_mahalanobis(r, S))) / 3.0
    return NoiseFit(
        model=model,
        names=names,
        values=tuple(float(v) for v in sig),
        stds=tuple(float(v) for v in sig_std),
        used=int(keep.sum()),
        trimmed=int((~keep).sum()),
        chi2_per_dof=chi2,
        kept=keep,
    )


def negative_log_likelihood(
    theta: FloatArray, residuals: FloatArray, base_cov: FloatArray, bases: FloatArray
) -> float:
    """``½ Σ_p [log det S_p + r_pᵀ S_p⁻¹ r_p]`` with ``S_p = base_cov_p + Σ_k θ_k bases[k, p]``
    (the module docstring): to compare noise models on the same pairs."""
    S = base_cov + np.einsum("k,kpij->pij", np.asarray(theta, dtype=np.float64), bases)
    _, logdet = np.linalg.slogdet(S)
    return 0.5 * float(np.sum(logdet) + np.sum(_mahalanobis(residuals, S)))
