"""UKF localization: the unscented transform instead of Jacobians.

**Sigma points** (Van der Merwe's scaled set, parameters in :class:`SigmaPointParams`): for a
Gaussian ``N(μ, P)`` of dimension ``n``, with ``c = α² (n + κ)`` (``= n + λ``, ``λ = c − n``)
and ``L`` a square root of ``P`` (``L Lᵀ = P``, Cholesky), the ``2n + 1`` points are ``μ`` and
``μ ± √c Lᵢ`` (columns ``Lᵢ``), with weights ``Wm₀ = λ / c``, ``Wc₀ = Wm₀ + 1 − α² + β`` and
``Wmᵢ = Wcᵢ = 1 / (2c)``.

**Prediction** (:func:`ukf_predict`). The control noise enters the motion model
non-additively (``g(x, u + ε, dt)``), so it is handled by *augmenting* the state with it: the
sigma points are drawn from ``N([μ, 0], blockdiag(P, Q))`` (dimension ``n + k``), each is moved
with its own perturbed control, and the new mean and covariance are the weighted moments of the
moved poses. (Sampling sigma points of the control alone would ignore the coupling of heading
uncertainty and control noise that the augmented set keeps.)

**Update** (:func:`ukf_update`). Fresh sigma points of the current belief are passed through
``h``; ``ẑ`` is their weighted mean, ``S = Σ Wcᵢ (Zᵢ − ẑ)(Zᵢ − ẑ)ᵀ + R`` and
``P_xz = Σ Wcᵢ (χᵢ − μ)(Zᵢ − ẑ)ᵀ``; then ``K = P_xz S⁻¹``, ``μ ← μ + K ν``,
``P ← P − K S Kᵀ``.

**Angles.** The mean of headings (state) and bearings (readings) is the weighted *circular*
mean (:func:`slamkit.geometry.circular_mean`), taken relative to the central sigma point so the
sums do not cancel; every residual ``χᵢ − μ`` and ``Zᵢ − ẑ`` has its angular components wrapped
before it enters a covariance, and so has the innovation ``ν``. In the update the state
residuals are the sigma offsets ``±√c Lᵢ`` themselves (no angles are subtracted there).

A covariance that stops being positive semi-definite (possible with a negative ``Wc₀`` and a
strongly non-linear model) raises :class:`~slamkit.errors.ConvergenceError`.

:class:`UkfLocalization` runs the steps :func:`choose_ukf_steps` picks once from its models:
the same equations on floats (:mod:`slamkit.localization.closed_form`) for a range-bearing
sensor, else :class:`GeneralUkfSteps`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.datasets.stream import Dataset
from slamkit.errors import ConfigError, ConvergenceError, InputError
from slamkit.estimation.belief import GaussianBelief
from slamkit.estimation.gaussian import (
    angular_indices,
    check_covariance,
    innovation_unchecked,
    move_unchecked,
    predict_measurement_unchecked,
    solve_innovation,
    wrap_array,
    wrap_components,
)
from slamkit.estimation.kalman import UpdateInfo
from slamkit.geometry import circular_mean, wrap_angle
from slamkit.localization.closed_form import FilterSteps, UkfClosedForm, closed_form_supports
from slamkit.localization.ekf import GaussianFilterConfig, GaussianLocalization, check_reading
from slamkit.models import LandmarkModel, MotionModel

__all__ = [
    "GeneralUkfSteps",
    "SigmaPointParams",
    "UkfConfig",
    "UkfLocalization",
    "choose_ukf_steps",
    "circular_mean_about",
    "psd_sqrt",
    "sigma_point_weights",
    "ukf_predict",
    "ukf_update",
    "unscented_motion_unchecked",
]


@dataclass(frozen=True)
class SigmaPointParams:
    """Van der Merwe's scaled sigma points (see the module docstring).

    The defaults ``α = 1, β = 2, κ = 0`` put the points at ``±√n`` standard deviations with
    non-negative mean weights (``Wm₀ = 0``), which keeps the circular means well conditioned;
    a small ``α`` (e.g. 1e-3) shrinks the spread towards the EKF's local linearisation at the
    price of a large negative ``Wm₀``.
    """

    alpha: float = 1.0
    """Spread of the points around the mean (> 0)."""
    beta: float = 2.0
    """Prior knowledge of the distribution: 2 is optimal for a Gaussian (>= 0)."""
    kappa: float = 0.0
    """Secondary scaling; ``n + κ`` must stay > 0 for every dimension ``n`` it is used at."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.alpha) and self.alpha > 0):
            raise ConfigError(f"alpha: expected a number > 0, got {self.alpha}")
        if not (math.isfinite(self.beta) and self.beta >= 0):
            raise ConfigError(f"beta: expected a number >= 0, got {self.beta}")
        if not math.isfinite(self.kappa):
            raise ConfigError(f"kappa: expected a finite number, got {self.kappa}")


@lru_cache(maxsize=64)
def sigma_point_weights(params: SigmaPointParams, n: int) -> tuple[FloatArray, FloatArray, float]:
    """``(Wm (2n+1,), Wc (2n+1,), c)`` with ``c = α² (n + κ)`` (read-only arrays)."""
    c = params.alpha**2 * (n + params.kappa)
    if not c > 0:
        raise InputError(
            f"sigma points: alpha² (n + kappa) must be > 0, got {c:.3g} for n = {n} "
            f"(alpha = {params.alpha}, kappa = {params.kappa})"
        )
    lam = c - n
    Wm = np.full(2 * n + 1, 0.5 / c)
    Wc = Wm.copy()
    Wm[0] = lam / c
    Wc[0] = lam / c + 1.0 - params.alpha**2 + params.beta
    Wm.setflags(write=False)
    Wc.setflags(write=False)
    return Wm, Wc, c


def psd_sqrt(P: FloatArray, where: str) -> FloatArray:
    """A square root ``L`` with ``L Lᵀ = P``: the Cholesky factor when ``P`` is positive
    definite, else (a singular PSD ``P``, e.g. a known start) a symmetric root from ``eigh``."""
    try:
        return np.asarray(np.linalg.cholesky(P), dtype=np.float64)
    except np.linalg.LinAlgError:
        check_covariance(P, where)  # the shared test: PSD within its rounding tolerance
        w, V = np.linalg.eigh(P)
        return np.asarray(V * np.sqrt(np.clip(w, 0.0, None)), dtype=np.float64)


def circular_mean_about(angles: FloatArray, weights: FloatArray, ref: float) -> float:
    """Weighted circular mean of ``angles`` computed about the reference angle ``ref``: the
    offsets ``angles − ref`` are small, so the weighted sums of sines and cosines keep full
    precision even with a large negative central weight. Wrapped to ``[-π, π)``."""
    a = ref + float(circular_mean(angles - ref, weights))
    return a if -math.pi <= a < math.pi else float(wrap_angle(a))


def unscented_motion_unchecked(
    mean: FloatArray,
    cov: FloatArray,
    u: FloatArray,
    dt: float,
    model: MotionModel,
    Q: FloatArray,
    params: SigmaPointParams,
    sqrt_Q: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The augmented unscented prediction on validated arrays (module docstring):
    ``(mean', cov', C)`` with ``C = Σ Wcᵢ (Yᵢ − ȳ)(χᵢ − μ)ᵀ (n × n)``, the covariance of the
    moved state with the state before the move (what a caller needs to carry correlations
    with quantities that do not move, e.g. a SLAM map: ``Σ_ym = C Σ_xx⁻¹ Σ_xm``).
    ``sqrt_Q`` may carry a precomputed root of ``Q``."""
    n, k = mean.size, u.size
    N = n + k
    Wm, Wc, c = sigma_point_weights(params, N)
    s = math.sqrt(c)
    Lx = psd_sqrt(cov, "ukf_predict")
    Lq = psd_sqrt(Q, "ukf_predict control noise") if sqrt_Q is None else sqrt_Q
    # Augmented sigma points [x, ε]: the centre, then +√c and −√c times the columns of
    # blockdiag(Lx, Lq). Rows 1..n and N+1..N+n move the state, the others the control noise.
    X = np.tile(mean, (2 * N + 1, 1))
    E = np.zeros((2 * N + 1, k))
    X[1 : n + 1] += s * Lx.T
    X[N + 1 : N + n + 1] -= s * Lx.T
    E[n + 1 : N + 1] = s * Lq.T
    E[N + n + 1 :] = -s * Lq.T
    Y = X  # moved in place: the pose part through g, the rest (if any) unchanged
    Y[:, :3] = move_unchecked(model, X[:, :3], u + E, dt)
    if not math.isfinite(float(Y[:, :3].sum())):
        raise ConvergenceError("ukf_predict: the motion moved a sigma point to a non-finite pose")
    new_mean = Wm @ Y
    new_mean[2] = circular_mean_about(Y[:, 2], Wm, float(Y[0, 2]))
    D = Y - new_mean
    D[:, 2] = wrap_array(D[:, 2])  # heading residuals wrapped before the outer products
    new_cov = (D.T * Wc) @ D
    new_cov = 0.5 * (new_cov + new_cov.T)
    check_covariance(new_cov, "ukf_predict")
    # Only the rows 1..n and N+1..N+n have a state offset (±√c Lx columns), with Wc = 1/(2c).
    cross = (D[1 : n + 1] - D[N + 1 : N + n + 1]).T @ Lx.T * (0.5 / s)
    return new_mean, new_cov, cross


def _ukf_predict_arrays(
    mean: FloatArray,
    cov: FloatArray,
    u: FloatArray,
    dt: float,
    model: MotionModel,
    Q: FloatArray,
    params: SigmaPointParams,
    sqrt_Q: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """:func:`ukf_predict` on validated arrays; ``sqrt_Q`` may carry a precomputed root of Q."""
    new_mean, new_cov, _ = unscented_motion_unchecked(mean, cov, u, dt, model, Q, params, sqrt_Q)
    return new_mean, new_cov


def _ukf_update_arrays(
    mean: FloatArray,
    cov: FloatArray,
    z: FloatArray,
    landmark: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
    params: SigmaPointParams,
    angular: tuple[int, ...],
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, float]:
    """:func:`ukf_update` on validated arrays: ``(mean, cov, ν, S, nis)``."""
    n = mean.size
    Wm, Wc, c = sigma_point_weights(params, n)
    L = math.sqrt(c) * psd_sqrt(cov, "ukf_update")
    dX = np.zeros((2 * n + 1, n))  # χᵢ − μ: the sigma offsets
    dX[1 : n + 1] = L.T
    dX[n + 1 :] = -L.T
    X = mean + dX
    Z = predict_measurement_unchecked(model, X[:, :3], landmark)  # (2n+1, m)
    z_hat = Wm @ Z
    for i in angular:
        z_hat[i] = circular_mean_about(Z[:, i], Wm, float(Z[0, i]))
    dZ = Z - z_hat
    for i in angular:
        dZ[:, i] = wrap_array(dZ[:, i])  # bearing residuals wrapped before the outer products
    WdZ = dZ.T * Wc  # (m, 2n+1)
    S = WdZ @ dZ + R
    S = 0.5 * (S + S.T)
    Pxz = (WdZ @ dX).T  # Σ Wcᵢ (χᵢ − μ)(Zᵢ − ẑ)ᵀ, (n, m)
    nu = innovation_unchecked(model, z, z_hat, angular)
    # One solve S X = [P_xzᵀ | ν] (no S⁻¹): X[:, :n] = Kᵀ (S symmetric), X[:, n] = S⁻¹ ν.
    sol = solve_innovation(S, np.column_stack((Pxz.T, nu)), "ukf_update")
    K = sol[:, :n].T
    nis = float(nu @ sol[:, n])
    new_mean = mean + K @ nu
    wrap_components(new_mean, (2,))
    new_cov = cov - K @ S @ K.T
    new_cov = 0.5 * (new_cov + new_cov.T)
    check_covariance(new_cov, "ukf_update")
    return new_mean, new_cov, nu, S, nis


# --------------------------------------------------------------------------------------------
# public functional core
# --------------------------------------------------------------------------------------------


def ukf_predict(
    belief: GaussianBelief,
    u: ArrayLike,
    dt: float,
    motion_model: MotionModel,
    Q: ArrayLike,
    params: SigmaPointParams | None = None,
) -> GaussianBelief:
    """The UKF prediction with control ``u (k,)`` over ``dt`` seconds and control-noise
    covariance ``Q (k, k)`` (positive semi-definite), by the augmented unscented transform
    (module docstring). ``params`` defaults to :class:`SigmaPointParams()`. Only the pose
    (the first three entries) moves; the rest of a longer state is carried along."""
    if not isinstance(motion_model, MotionModel):
        raise InputError(f"motion_model: expected a MotionModel, got {type(motion_model)}")
    k = motion_model.control_dim
    ua = as_array(u, "control u", (k,))
    dta = float(dt)
    if not (math.isfinite(dta) and dta >= 0):
        raise InputError(f"dt: expected a number >= 0, got {dt!r}")
    Qa = as_covariance(Q, "Q", k, semidefinite=True)
    p = SigmaPointParams() if params is None else params
    mean, cov = _ukf_predict_arrays(belief.mean, belief.cov, ua, dta, motion_model, Qa, p)
    return GaussianBelief(mean, cov)


def ukf_update(
    belief: GaussianBelief,
    z: ArrayLike,
    landmark: ArrayLike,
    model: LandmarkModel,
    R: ArrayLike,
    params: SigmaPointParams | None = None,
) -> tuple[GaussianBelief, UpdateInfo]:
    """One UKF update with the reading ``z (m,)`` of the landmark at ``landmark (2,)``,
    measurement model ``model`` and noise ``R (m, m)`` (module docstring). Returns the new
    belief and the innovation statistics. Errors as :func:`slamkit.localization.ekf.ekf_update`.
    """
    za, la, Ra = check_reading(z, landmark, model, R)
    p = SigmaPointParams() if params is None else params
    idx = angular_indices(model)
    mean, cov, nu, S, nis = _ukf_update_arrays(belief.mean, belief.cov, za, la, model, Ra, p, idx)
    return GaussianBelief(mean, cov), UpdateInfo(nu, S, nis)


class GeneralUkfSteps:
    """The UKF's steps for any models (:func:`ukf_predict` and :func:`ukf_update` on
    validated arrays): a :class:`~slamkit.localization.closed_form.FilterSteps`. ``sqrt_Q``
    is a root of ``Q`` (``L Lᵀ = Q``)."""

    def __init__(
        self,
        motion: MotionModel,
        measurement: LandmarkModel,
        Q: FloatArray,
        sqrt_Q: FloatArray,
        R: FloatArray,
        params: SigmaPointParams,
    ) -> None:
        self._motion, self._meas, self._params = motion, measurement, params
        self._Q, self._sqrt_Q, self._R = Q, sqrt_Q, R
        self._angular = angular_indices(measurement)

    def predict(
        self, mean: FloatArray, cov: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        return _ukf_predict_arrays(
            mean, cov, u, dt, self._motion, self._Q, self._params, self._sqrt_Q
        )

    def update(
        self, mean: FloatArray, cov: FloatArray, z: FloatArray, landmark: FloatArray
    ) -> tuple[FloatArray, FloatArray, float]:
        new_mean, new_cov, _, _, nis = _ukf_update_arrays(
            mean, cov, z, landmark, self._meas, self._R, self._params, self._angular
        )
        return new_mean, new_cov, nis


def _weights(params: SigmaPointParams, n: int) -> tuple[float, float, float, float]:
    """``(Wm₀, Wc₀, Wᵢ, √c)`` of the sigma points of dimension ``n``."""
    Wm, Wc, c = sigma_point_weights(params, n)
    return float(Wm[0]), float(Wc[0]), float(Wm[1]), math.sqrt(c)


def choose_ukf_steps(
    motion: MotionModel,
    measurement: LandmarkModel,
    Q: FloatArray,
    sqrt_Q: FloatArray,
    R: FloatArray,
    params: SigmaPointParams,
) -> FilterSteps:
    """The UKF steps for a pose-only filter with these models, chosen once: the closed form
    of :class:`~slamkit.localization.closed_form.UkfClosedForm` for a range-bearing sensor
    (its prediction for the ``UnicycleEuler`` motion, the general one for the others), else
    :class:`GeneralUkfSteps`. Both give the same numbers to rounding."""
    general = GeneralUkfSteps(motion, measurement, Q, sqrt_Q, R, params)
    if not closed_form_supports(motion, measurement)[1]:
        return general
    euler = closed_form_supports(motion, measurement)[2]
    k = Q.shape[0]
    return UkfClosedForm(general, euler, _weights(params, 3), _weights(params, 3 + k), sqrt_Q, R)


# --------------------------------------------------------------------------------------------
# estimator
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class UkfConfig(GaussianFilterConfig):
    """Settings of :class:`UkfLocalization`: those of the EKF plus the sigma points."""

    sigma_points: SigmaPointParams = field(default_factory=SigmaPointParams)
    """α, β, κ of the scaled sigma points (a ``[estimator.sigma_points]`` table in a file)."""


class UkfLocalization(GaussianLocalization):
    """UKF localization with point landmarks of a known map; the same events, association
    and diagnostics as :class:`~slamkit.localization.ekf.EkfLocalization`, configured by
    :class:`UkfConfig`."""

    name = "UKF localization"

    def __init__(self, dataset: Dataset, config: UkfConfig, rng: np.random.Generator) -> None:
        super().__init__(dataset, config, rng)
        self._params = config.sigma_points
        self._sqrt_Q = psd_sqrt(self._Q, "control noise")
        # Fail at construction, not at the first step, if the sigma points are degenerate.
        sigma_point_weights(self._params, 3)
        sigma_point_weights(self._params, 3 + self._Q.shape[0])
        # The closed form or the general steps, decided here once (the state is the pose).
        self._steps = choose_ukf_steps(
            self._motion, self._meas, self._Q, self._sqrt_Q, self._R, self._params
        )

    def _predict(self, u: FloatArray, dt: float) -> None:
        assert self._mean is not None and self._cov is not None
        self._mean, self._cov = self._steps.predict(self._mean, self._cov, u, dt)

    def _update(self, z: FloatArray, landmark: FloatArray, gate: float) -> tuple[float, bool]:
        assert self._mean is not None and self._cov is not None
        mean, cov, nis = self._steps.update(self._mean, self._cov, z, landmark)
        if nis > gate:
            return nis, False
        self._mean, self._cov = mean, cov
        return nis, True
