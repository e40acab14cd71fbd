"""The linear Kalman filter: pure predict/update functions over frozen Gaussians, and a thin
stateful :class:`KalmanFilter` around them.

Model (column-vector notation; arrays are plain ``(n,)`` vectors and ``(n, n)`` matrices)::

    x_t = A x_{t-1} + B u_t + w,    w ~ N(0, Q_process)      (prediction)
    z_t = H x_t + v,                v ~ N(0, R)              (update)

Prediction: ``μ ← A μ + B u``, ``P ← A P Aᵀ + Q_process``.
Update with the innovation ``ν = z − H μ`` and its covariance ``S = H P Hᵀ + R``:
``K = P Hᵀ S⁻¹``, ``μ ← μ + K ν`` and the Joseph form
``P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ``.

The Joseph form is a sum of two PSD terms, so the updated covariance stays symmetric positive
semi-definite up to rounding; the short form ``(I − K H) P`` relies on ``K`` being exactly
optimal and, with very precise readings, cancels into an indefinite matrix (see the tests).
``S⁻¹`` is never formed: one linear solve of ``S X = [H P, ν]`` gives both ``Kᵀ`` and
``S⁻¹ ν`` — cheaper than an inverse and accurate to the conditioning of ``S``.

The kernels (the gain with the Joseph update, the covariance checks, the model evaluation on
validated arrays) live in :mod:`slamkit.estimation.gaussian`, shared by every Kalman-type
estimator. Public functions here validate their arguments; the kernels trust them. A result
that is not a covariance any more raises :class:`~slamkit.errors.ConvergenceError` instead of
returning NaN.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import ShapeError
from slamkit.estimation.belief import GaussianBelief
from slamkit.estimation.gaussian import check_covariance, gain_update
from slamkit.geometry import wrap_angle

__all__ = ["Gaussian", "KalmanFilter", "UpdateInfo", "kf_predict", "kf_update"]


@dataclass(frozen=True)
class Gaussian:
    """``N(mean, cov)`` over a plain vector state ``(n,)`` with no angular component (a
    constant-velocity target, a 1-D position). Use :class:`GaussianBelief` for poses, whose
    heading is kept wrapped."""

    mean: FloatArray
    cov: FloatArray

    def __post_init__(self) -> None:
        mean = as_array(self.mean, "mean", (None,)).copy()
        cov = as_covariance(self.cov, "cov", mean.size, semidefinite=True).copy()
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)


BeliefT = TypeVar("BeliefT", Gaussian, GaussianBelief)


@dataclass(frozen=True)
class UpdateInfo:
    """What one measurement update saw: the innovation ``ν (m,)`` (angles wrapped), its
    covariance ``S (m, m)`` and the normalised innovation squared ``νᵀ S⁻¹ ν`` (χ²(m) for a
    consistent filter)."""

    innovation: FloatArray
    S: FloatArray
    nis: float


def _kf_predict_arrays(
    mean: FloatArray,
    cov: FloatArray,
    A: FloatArray,
    Bu: FloatArray | None,
    Q: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """``(A μ + B u, A P Aᵀ + Q)``, symmetrised; ``Bu`` is the precomputed ``B u`` or None."""
    new_mean = A @ mean if Bu is None else A @ mean + Bu
    new_cov = A @ cov @ A.T + Q
    new_cov = 0.5 * (new_cov + new_cov.T)
    check_covariance(new_cov, "predict")
    return new_mean, new_cov


# --------------------------------------------------------------------------------------------
# validation of the public arguments
# --------------------------------------------------------------------------------------------


def _transition(
    n: int, A: ArrayLike, B: ArrayLike | None, u: ArrayLike | None
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    Aa = as_array(A, "A", (n, n))
    if (B is None) != (u is None):
        raise ShapeError("B and u: give both (a controlled system) or neither")
    if B is None or u is None:
        return Aa, None, None
    Ba = as_array(B, "B", (n, None))
    ua = as_array(u, "u", (Ba.shape[1],))
    return Aa, Ba, ua


def _observation(n: int, z: ArrayLike, H: ArrayLike, R: ArrayLike) -> tuple[FloatArray, ...]:
    za = as_array(z, "z", (None,))
    Ha = as_array(H, "H", (za.size, n))
    Ra = as_covariance(R, "R", za.size)
    return za, Ha, Ra


# --------------------------------------------------------------------------------------------
# public functional core
# --------------------------------------------------------------------------------------------


def kf_predict(
    belief: BeliefT,
    A: ArrayLike,
    B: ArrayLike | None,
    u: ArrayLike | None,
    Q_process: ArrayLike,
) -> BeliefT:
    """The linear prediction ``μ ← A μ + B u``, ``P ← A P Aᵀ + Q_process``.

    ``A (n, n)``; ``B (n, k)`` and ``u (k,)`` together, or both None for an uncontrolled
    system; ``Q_process (n, n)`` is the covariance of the additive process noise (positive
    semi-definite: a constant-velocity model's white-acceleration noise has rank one).
    Returns a new belief of the same type; the input is not modified.
    """
    n = belief.mean.size
    Aa, Ba, ua = _transition(n, A, B, u)
    Q = as_covariance(Q_process, "Q_process", n, semidefinite=True)
    Bu = None if Ba is None or ua is None else Ba @ ua
    mean, cov = _kf_predict_arrays(belief.mean, belief.cov, Aa, Bu, Q)
    return type(belief)(mean, cov)


def kf_update(
    belief: BeliefT, z: ArrayLike, H: ArrayLike, R: ArrayLike
) -> tuple[BeliefT, UpdateInfo]:
    """The linear measurement update with ``z (m,)``, ``H (m, n)`` and noise ``R (m, m)``.

    ``ν = z − H μ`` (not wrapped: a linear model has no angles; use
    :func:`slamkit.localization.ekf.ekf_update` for bearings), ``S = H P Hᵀ + R``,
    ``K = P Hᵀ S⁻¹``, ``μ ← μ + K ν`` and the Joseph form of the covariance (see the module
    docstring). Raises :class:`~slamkit.errors.NonFiniteError` for NaN readings,
    :class:`~slamkit.errors.CovarianceError` if ``R`` is not positive definite and
    :class:`~slamkit.errors.ConvergenceError` if the result is not a valid covariance.
    """
    za, Ha, Ra = _observation(belief.mean.size, z, H, R)
    nu = za - Ha @ belief.mean
    mean, cov, S, nis = gain_update(belief.mean, belief.cov, nu, Ha, Ra, "kf_update")
    return type(belief)(mean, cov), UpdateInfo(nu, S, nis)


class KalmanFilter:
    """A stateful linear Kalman filter for a fixed model ``(A, B, Q_process, H, R)``.

    A thin shell over :func:`kf_predict` and :func:`kf_update`: the matrices are validated
    once here, and every step runs the same kernels as the functions (the two agree to
    rounding, see the tests). ``belief`` is the current :class:`Gaussian` or
    :class:`GaussianBelief` (same type as the one given).
    """

    def __init__(
        self,
        belief: Gaussian | GaussianBelief,
        A: ArrayLike,
        Q_process: ArrayLike,
        H: ArrayLike,
        R: ArrayLike,
        B: ArrayLike | None = None,
    ) -> None:
        n = belief.mean.size
        self._type = type(belief)
        self._A = as_array(A, "A", (n, n))
        self._B = None if B is None else as_array(B, "B", (n, None))
        self._Q = as_covariance(Q_process, "Q_process", n, semidefinite=True)
        self._H = as_array(H, "H", (None, n))
        self._R = as_covariance(R, "R", self._H.shape[0])
        self._mean = belief.mean.copy()
        self._cov = belief.cov.copy()

    @property
    def belief(self) -> Gaussian | GaussianBelief:
        """The current belief as a new frozen value."""
        return self._type(self._mean, self._cov)

    @property
    def mean(self) -> FloatArray:
        return self._mean.copy()

    @property
    def cov(self) -> FloatArray:
        return self._cov.copy()

    def predict(self, u: ArrayLike | None = None) -> None:
        """One prediction with control ``u (k,)`` (required exactly when ``B`` was given)."""
        if (u is None) != (self._B is None):
            raise ShapeError("u: expected a control exactly when the filter has a B matrix")
        Bu = None
        if self._B is not None and u is not None:
            Bu = np.asarray(self._B @ as_array(u, "u", (self._B.shape[1],)), dtype=np.float64)
        self._mean, self._cov = _kf_predict_arrays(self._mean, self._cov, self._A, Bu, self._Q)
        self._normalise()

    def update(self, z: ArrayLike) -> UpdateInfo:
        """One update with the reading ``z (m,)``; returns the innovation statistics."""
        za = as_array(z, "z", (self._H.shape[0],))
        nu = za - self._H @ self._mean
        self._mean, self._cov, S, nis = gain_update(
            self._mean, self._cov, nu, self._H, self._R, "KalmanFilter.update"
        )
        self._normalise()
        return UpdateInfo(nu, S, nis)

    def _normalise(self) -> None:
        # What the belief type's constructor would do: a pose belief keeps its heading wrapped.
        if self._type is GaussianBelief:
            self._mean[2] = wrap_angle(self._mean[2])
