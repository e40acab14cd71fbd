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

The kernels here (``_gain_update``, ``_solve_innovation``, the covariance checks and the model
evaluation helpers) are shared by the EKF, the UKF and the data association of this package.
Public functions validate their arguments; the kernels trust them (they are the estimators'
fast path, run on arrays validated once). A result that is not a covariance any more raises
:class:`~slamkit.errors.ConvergenceError` instead of returning NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import TypeVar

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import ConvergenceError, ShapeError
from slamkit.geometry import wrap_angle
from slamkit.localization.belief import GaussianBelief
from slamkit.models import LandmarkModel, MotionModel
from slamkit.models.measurement import _LandmarkBase
from slamkit.models.motion import _MotionBase

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


# --------------------------------------------------------------------------------------------
# kernels (no validation: callers pass finite float arrays of the right shapes)
# --------------------------------------------------------------------------------------------


def _check_covariance(cov: FloatArray, where: str) -> None:
    """Raise :class:`ConvergenceError` unless ``cov`` is finite and positive semi-definite.

    A Cholesky factorisation (cheap) proves definiteness in the usual case; only when it
    fails are the eigenvalues computed, to tell a singular PSD matrix (a known pose, an
    unobserved direction) from one that has lost definiteness.
    """
    if not np.isfinite(cov).all():
        raise ConvergenceError(f"{where}: the covariance became non-finite")
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(cov)
        scale = max(float(np.abs(eig).max()), 1e-300)
        if eig[0] < -1e-9 * scale:
            raise ConvergenceError(
                f"{where}: the covariance lost positive definiteness (smallest eigenvalue "
                f"{eig[0]:.3g})"
            ) from None


def _check_finite(cov: FloatArray, where: str) -> None:
    """Raise :class:`ConvergenceError` if ``cov`` holds NaN or inf.

    Enough after a Joseph-form update or a linearised prediction: both are sums of terms
    ``A P Aᵀ`` with ``P`` PSD, so they can lose definiteness by rounding only, never by more.
    (One sum is checked: it is finite exactly when every entry is, barring overflow near
    1e308, which the element-wise check then catches.)
    """
    if not math.isfinite(float(cov.sum())) and not np.isfinite(cov).all():
        raise ConvergenceError(f"{where}: the covariance became non-finite")


def _small_spd_inverse(S: FloatArray, where: str) -> FloatArray | None:
    """``S⁻¹`` of a 1x1 or 2x2 innovation covariance by its closed form, after proving it
    positive definite (Sylvester: ``S₀₀ > 0`` and ``det S > 0``); ``None`` for larger ``S``.

    Readings have one or two components, where a LAPACK call costs ten times the arithmetic;
    for a positive definite 2x2 matrix the adjugate formula is as accurate as a solve (both
    lose what the conditioning of ``S`` dictates, nothing more).
    """
    m = S.shape[0]
    if m == 1:
        s = float(S[0, 0])
        if not s > 0.0:
            raise ConvergenceError(f"{where}: the innovation variance S = {s:.3g} is not > 0")
        return np.array([[1.0 / s]])
    if m == 2:
        a, b, c, d = float(S[0, 0]), float(S[0, 1]), float(S[1, 0]), float(S[1, 1])
        det = a * d - b * c
        if not (a > 0.0 and det > 0.0):
            raise ConvergenceError(f"{where}: the innovation covariance S is not positive definite")
        return np.array([[d / det, -b / det], [-c / det, a / det]])
    return None


def _solve_innovation(S: FloatArray, rhs: FloatArray, where: str) -> FloatArray:
    """``S⁻¹ rhs`` for an innovation covariance ``S (m, m)``; ConvergenceError unless S is
    positive definite (a filter whose S is not has diverged). Closed form for ``m <= 2``
    (:func:`_small_spd_inverse`), else a Cholesky factorisation and triangular solves."""
    inv = _small_spd_inverse(S, where)
    if inv is not None:
        return inv @ rhs
    try:
        factor = scipy.linalg.cho_factor(S)
    except np.linalg.LinAlgError:
        raise ConvergenceError(
            f"{where}: the innovation covariance S is not positive definite"
        ) from None
    return np.asarray(scipy.linalg.cho_solve(factor, rhs), dtype=np.float64)


@lru_cache(maxsize=16)
def _identity(n: int) -> FloatArray:
    eye = np.eye(n)
    eye.setflags(write=False)
    return eye


def _gain_update(
    mean: FloatArray,
    cov: FloatArray,
    nu: FloatArray,
    H: FloatArray,
    R: FloatArray,
    where: str = "update",
) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """One Kalman update from the innovation ``nu (m,)`` with ``H (m, n)``, ``R (m, m)``.

    Returns ``(mean, cov, S, nis)``; the covariance in Joseph form, symmetrised. Angles in
    ``mean`` are not wrapped here (the callers own the state's conventions).
    """
    n = mean.size
    PHt = cov @ H.T  # (n, m)
    S = H @ PHt + R  # symmetric to rounding (P is)
    S_inv = _small_spd_inverse(S, where)
    if S_inv is not None:  # one or two components: the closed form (see there)
        K = PHt @ S_inv  # K = P Hᵀ S⁻¹
        Sinv_nu = S_inv @ nu
    else:
        # Solve S X = [H P | ν] once instead of forming S⁻¹. As S and P are symmetric, the
        # first n columns of X are Kᵀ = S⁻¹ H P and the last one is S⁻¹ ν.
        X = _solve_innovation(S, np.column_stack([PHt.T, nu]), where)
        K, Sinv_nu = X[:, :n].T, X[:, n]
    nis = float(nu @ Sinv_nu)  # νᵀ S⁻¹ ν
    new_mean = mean + K @ nu
    # Joseph form: P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ (PSD by construction, see the module
    # docstring), then symmetrised against round-off.
    A = _identity(n) - K @ H
    new_cov = A @ cov @ A.T + K @ R @ K.T
    new_cov = 0.5 * (new_cov + new_cov.T)
    _check_finite(new_cov, where)
    return new_mean, new_cov, S, nis


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
    _check_finite(new_cov, "predict")
    return new_mean, new_cov


# --------------------------------------------------------------------------------------------
# model evaluation on already-validated arrays (the filters' fast path)
# --------------------------------------------------------------------------------------------
# slamkit's own models validate and broadcast their arguments in the public methods and do the
# arithmetic in ``_h``/``_jac``/``_g``. The filters call the arithmetic directly on arrays they
# have validated once (their state, the data set's readings), which saves most of the cost of
# a small update; models from elsewhere go through their public methods.

_PI = float(np.pi)


def _wrap_components(v: FloatArray, idx: tuple[int, ...]) -> FloatArray:
    """Wrap the components ``idx`` of the vector ``v`` in place with :func:`wrap_angle`.

    The call is skipped for angles already in ``[-π, π)``, which ``wrap_angle`` returns
    unchanged (bit for bit), so the result is always exactly ``wrap_angle``'s.
    """
    for i in idx:
        a = float(v[i])
        if not -_PI <= a < _PI:
            v[i] = float(wrap_angle(a))
    return v


def _wrap_array(a: FloatArray) -> FloatArray:
    """``wrap_angle(a)``, without the call when every angle is already in ``[-π, π)``."""
    if bool(((a >= -_PI) & (a < _PI)).all()):
        return a
    return wrap_angle(a)


def _angular_indices(model: LandmarkModel) -> tuple[int, ...]:
    return tuple(i for i, ang in enumerate(model.angular) if ang)


def _measure(
    model: LandmarkModel, pose: FloatArray, landmark: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``(h(pose, landmark), H_pose)``; batch axes as in the model (pose and landmark must
    already have the same batch shape)."""
    if isinstance(model, _LandmarkBase):
        if pose.ndim == 1 and landmark.ndim == 1:
            return model._h_and_pose_jacobian(pose, landmark)
        return model._h(pose, landmark), model._jac(pose, landmark)[0]
    return model.predict(pose, landmark), model.jacobians(pose, landmark)[0]


def _predict_measurement(
    model: LandmarkModel, pose: FloatArray, landmark: FloatArray
) -> FloatArray:
    """``h(pose, landmark)``; the batch axes of the arguments broadcast (e.g. sigma points
    ``(N, 3)`` against one landmark ``(2,)``)."""
    if isinstance(model, _LandmarkBase):
        return model._h(pose, landmark)
    return model.predict(pose, landmark)


def _innovation(
    model: LandmarkModel, z: FloatArray, z_hat: FloatArray, idx: tuple[int, ...]
) -> FloatArray:
    """``model.residual(z, z_hat)`` for one reading: ``z − z_hat`` with the angular components
    ``idx`` wrapped (slamkit's models define the residual exactly so)."""
    if isinstance(model, _LandmarkBase):
        return _wrap_components(z - z_hat, idx)
    return np.asarray(model.residual(z, z_hat), dtype=np.float64)


def _move(model: MotionModel, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
    """``g(x, u, dt)`` for poses ``(..., 3)`` and controls of the same batch shape."""
    if isinstance(model, _MotionBase):
        return model._g(x, u, dt)
    return model.apply(x, u, dt)


def _motion_jacobians(
    model: MotionModel, x: FloatArray, u: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray]:
    if isinstance(model, _MotionBase):
        return model._jac(x, u, dt)
    return model.jacobians(x, u, dt)


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
    mean, cov, S, nis = _gain_update(belief.mean, belief.cov, nu, Ha, Ra, "kf_update")
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
        self._mean, self._cov, S, nis = _gain_update(
            self._mean, self._cov, nu, self._H, self._R, "KalmanFilter.update"
        )
        self._normalise()
        return UpdateInfo(nu, S, nis)

    def _normalise(self) -> None:
        # What the belief type's constructor would do: a pose belief keeps its heading wrapped.
        if self._type is GaussianBelief:
            self._mean[2] = wrap_angle(self._mean[2])
