"""Gaussian-filter kernels shared by every Kalman-type estimator (EKF and UKF localization,
ML association, EKF mapping, EKF-SLAM, SEIF): the covariance checks, the closed-form small
innovation inverse, the gain with the Joseph-form covariance update, angle wrapping of
innovations, and the evaluation of motion and landmark models on already-validated arrays.

These are the estimators' fast path: they trust their arguments (finite float arrays of the
right shapes, validated once by the caller) and never return NaN — a result that is not a
covariance any more raises :class:`~slamkit.errors.ConvergenceError`, from
:func:`check_covariance`: the one definiteness test, with one tolerance
(:data:`DEFINITENESS_TOLERANCE`) and one message, that every Gaussian filter runs
(``docs/consistency.md`` lists where). The Joseph form
``P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ`` is a sum of two PSD terms, so it stays positive
semi-definite up to rounding where the short form ``(I − K H) P`` can cancel into an
indefinite matrix (see :mod:`slamkit.estimation.kalman`).

Models built on :class:`~slamkit.models.MotionModelBase` and
:class:`~slamkit.models.LandmarkModelBase` are evaluated through their unchecked kernels; any
other model that satisfies the public :class:`~slamkit.models.MotionModel` /
:class:`~slamkit.models.LandmarkModel` protocol goes through its public (validating) methods,
and a test checks that both routes give the same numbers.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import scipy.linalg

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError
from slamkit.geometry import wrap_angle
from slamkit.models import LandmarkModel, MotionModel
from slamkit.models.measurement import LandmarkModelBase
from slamkit.models.motion import motion_kernels

__all__ = [
    "DEFINITENESS_TOLERANCE",
    "angular_indices",
    "check_covariance",
    "check_covariance_entries",
    "check_finite_covariance",
    "check_state_covariance",
    "gain_update",
    "innovation_unchecked",
    "measure_unchecked",
    "motion_jacobians_unchecked",
    "move_unchecked",
    "predict_measurement_unchecked",
    "small_spd_inverse",
    "solve_innovation",
    "wrap_array",
    "wrap_components",
]

# --------------------------------------------------------------------------------------------
# kernels (no validation: callers pass finite float arrays of the right shapes)
# --------------------------------------------------------------------------------------------


DEFINITENESS_TOLERANCE = 1e-9
"""Relative tolerance of :func:`check_covariance`: a covariance whose smallest eigenvalue is
below ``−DEFINITENESS_TOLERANCE · max|λ|`` has lost positive (semi-)definiteness.

Rounding alone leaves far smaller negative eigenvalues: a Joseph-form update or a linearised
prediction of a PSD matrix is PSD up to a few ``n ε ‖P‖`` (ε = 2.2e-16), and ``eigvalsh``
itself errs by as much. EKF-SLAM on ``landmark-loop`` with σ = 1e-6 readings reaches
``λ_min = −9.8e-18`` (``−6.0e-17`` of the largest) — rounding, not a lost covariance; that
filter is *inconsistent* (NEES ~1e9), which the consistency monitor of
:mod:`slamkit.eval.monitor` reports. A filter whose update genuinely cancels into an
indefinite matrix (the short form ``P − K S Kᵀ`` with very precise readings) goes far beyond
the tolerance: ``−6.2e-14`` against a largest eigenvalue of ``4.0e-13`` (−15 %) in the UKF
on ``five-features`` at σ = 1e-6."""


def _sylvester_3x3(cov: FloatArray) -> bool:
    """Whether a symmetric ``3 × 3`` matrix is positive definite by Sylvester's criterion
    (leading minors > 0), on plain floats: a sixth of a LAPACK Cholesky call at this size.
    ``False`` also for NaN entries (every comparison with NaN is false)."""
    (a, b, c), (_, d, e), (_, _, f) = cov.tolist()
    minor2 = a * d - b * b
    det = a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c)
    return bool(a > 0.0 and minor2 > 0.0 and det > 0.0)


def check_covariance(cov: FloatArray, where: str, what: str = "covariance") -> None:
    """Raise :class:`ConvergenceError` unless ``cov`` is finite and positive semi-definite
    within :data:`DEFINITENESS_TOLERANCE`: the one definiteness check of every Gaussian filter
    (EKF, KF and UKF localization, dead reckoning, EKF-SLAM, EKF mapping, SEIF's information
    matrix with ``what="information matrix"``; FastSLAM's landmarks through
    :func:`check_covariance_entries`). ``cov`` is one ``(n, n)`` matrix or a stack ``(..., n, n)``
    (EKF mapping's per-landmark blocks), each judged against its own largest eigenvalue.

    The messages: ``"{where}: the {what} became non-finite"`` and ``"{where}: the {what} lost
    positive definiteness (smallest eigenvalue λ, largest |λ| Λ)"``.

    A positive definite matrix is proved so cheaply — Sylvester's criterion on floats for
    ``3 × 3`` (a pose block), a Cholesky factorisation otherwise; only when that fails are the
    eigenvalues computed, to tell a singular PSD matrix (a known pose, an unobserved
    direction, rounding at the tolerance's scale) from one that has lost definiteness.
    """
    if cov.shape == (3, 3) and _sylvester_3x3(cov):
        return
    if not np.isfinite(cov).all():
        raise ConvergenceError(f"{where}: the {what} became non-finite")
    if cov.size == 0:
        return
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(cov).reshape(-1, cov.shape[-1])  # ascending, per matrix
        scale = np.maximum(np.abs(eig).max(axis=1), 1e-300)
        bad = np.flatnonzero(eig[:, 0] < -DEFINITENESS_TOLERANCE * scale)
        if bad.size:
            i = int(bad[0])
            raise ConvergenceError(
                f"{where}: the {what} lost positive definiteness (smallest eigenvalue "
                f"{eig[i, 0]:.3g}, largest |eigenvalue| {scale[i]:.3g})"
            ) from None


def check_covariance_entries(
    c00: FloatArray, c01: FloatArray, c11: FloatArray, where: str, what: str = "covariance"
) -> None:
    """:func:`check_covariance` of the symmetric ``2 × 2`` matrices ``[[c00, c01], [c01,
    c11]]`` given by their entries (arrays of one shape: the struct-of-arrays landmarks of
    FastSLAM's particles), with the same tolerance and messages. Their eigenvalues are
    ``m ± r`` with ``m = (c00 + c11) / 2``, ``r = hypot((c00 − c11) / 2, c01)``, so the test
    is ``m − r ≥ −DEFINITENESS_TOLERANCE (|m| + r)``, run only when Sylvester's criterion
    (``c00 > 0``, ``c00 c11 − c01² > 0``: four elementwise operations) fails somewhere."""
    if bool(np.all((c00 > 0.0) & (c00 * c11 - c01 * c01 > 0.0))):
        return
    m = 0.5 * (c00 + c11)
    r = np.hypot(0.5 * (c00 - c11), c01)
    low = m - r
    scale = np.abs(m) + r  # max |eigenvalue|
    ok = low >= -DEFINITENESS_TOLERANCE * scale  # False for NaN, too
    if bool(np.all(ok)):
        return
    if not (np.isfinite(c00).all() and np.isfinite(c01).all() and np.isfinite(c11).all()):
        raise ConvergenceError(f"{where}: the {what} became non-finite")
    i = int(np.flatnonzero(~np.asarray(ok).ravel())[0])
    raise ConvergenceError(
        f"{where}: the {what} lost positive definiteness (smallest eigenvalue "
        f"{float(np.ravel(low)[i]):.3g}, largest |eigenvalue| {float(np.ravel(scale)[i]):.3g})"
    )


def check_state_covariance(
    cov: FloatArray, where: str, step: int, full_every: int | None, what: str = "covariance"
) -> None:
    """The per-step check of a filter whose state is a pose followed by a map:
    :func:`check_covariance` of the pose block ``cov[:3, :3]`` at every step, and of the whole
    matrix at the steps that are multiples of ``full_every`` (``None``: the pose block only;
    a ``3 × 3`` state is always checked whole). The pose block costs ~1 µs; the whole matrix
    is an ``O(n³)`` factorisation (measured in ``docs/estimators/ekf_slam.md``)."""
    n = cov.shape[0]
    if n == 3 or (full_every is not None and step % full_every == 0):
        check_covariance(cov, where, what)
    else:
        check_covariance(cov[:3, :3], where, what)


def check_finite_covariance(cov: FloatArray, where: str) -> None:
    """Raise :class:`ConvergenceError` if ``cov`` holds NaN or inf.

    Only finiteness: the filters run :func:`check_covariance`, which also catches a
    covariance that has lost definiteness (a Joseph-form update or a linearised prediction
    cannot lose it by more than rounding, but carries an indefinite input forward).
    (One sum is checked: it is finite exactly when every entry is, barring overflow near
    1e308, which the element-wise check then catches.)
    """
    if not math.isfinite(float(cov.sum())) and not np.isfinite(cov).all():
        raise ConvergenceError(f"{where}: the covariance became non-finite")


def small_spd_inverse(S: FloatArray, where: str) -> FloatArray | None:
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


def solve_innovation(S: FloatArray, rhs: FloatArray, where: str) -> FloatArray:
    """``S⁻¹ rhs`` for an innovation covariance ``S (m, m)``; ConvergenceError unless S is
    positive definite (a filter whose S is not has diverged). Closed form for ``m <= 2``
    (:func:`small_spd_inverse`), else a Cholesky factorisation and triangular solves."""
    inv = small_spd_inverse(S, where)
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


def gain_update(
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
    S_inv = small_spd_inverse(S, where)
    if S_inv is not None:  # one or two components: the closed form (see there)
        K = PHt @ S_inv  # K = P Hᵀ S⁻¹
        Sinv_nu = S_inv @ nu
    else:
        # Solve S X = [H P | ν] once instead of forming S⁻¹. As S and P are symmetric, the
        # first n columns of X are Kᵀ = S⁻¹ H P and the last one is S⁻¹ ν.
        X = solve_innovation(S, np.column_stack([PHt.T, nu]), where)
        K, Sinv_nu = X[:, :n].T, X[:, n]
    nis = float(nu @ Sinv_nu)  # νᵀ S⁻¹ ν
    new_mean = mean + K @ nu
    # Joseph form: P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ (PSD by construction, see the module
    # docstring), then symmetrised against round-off.
    A = _identity(n) - K @ H
    new_cov = A @ cov @ A.T + K @ R @ K.T
    new_cov = 0.5 * (new_cov + new_cov.T)
    # The Joseph form keeps a PSD matrix PSD, so this catches a covariance that had already
    # lost definiteness (or overflowed) before the update: the filters' one check.
    check_covariance(new_cov, where)
    return new_mean, new_cov, S, nis


# --------------------------------------------------------------------------------------------
# model evaluation on already-validated arrays (the filters' fast path)
# --------------------------------------------------------------------------------------------
# slamkit's own models validate and broadcast their arguments in the public methods and do the
# arithmetic in their ``*_unchecked`` kernels. The filters call the kernels directly on arrays
# they have validated once (their state, the data set's readings), which saves most of the
# cost of a small update; models from elsewhere go through their public methods.

_PI = float(np.pi)


def wrap_components(v: FloatArray, idx: tuple[int, ...]) -> FloatArray:
    """Wrap the components ``idx`` of the vector ``v`` in place with :func:`wrap_angle`.

    The call is skipped for angles already in ``[-π, π)``, which ``wrap_angle`` returns
    unchanged (bit for bit), so the result is always exactly ``wrap_angle``'s.
    """
    for i in idx:
        a = float(v[i])
        if not -_PI <= a < _PI:
            v[i] = float(wrap_angle(a))
    return v


def wrap_array(a: FloatArray) -> FloatArray:
    """``wrap_angle(a)``, without the call when every angle is already in ``[-π, π)``."""
    if bool(((a >= -_PI) & (a < _PI)).all()):
        return a
    return wrap_angle(a)


def angular_indices(model: LandmarkModel) -> tuple[int, ...]:
    return tuple(i for i, ang in enumerate(model.angular) if ang)


def measure_unchecked(
    model: LandmarkModel, pose: FloatArray, landmark: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``(h(pose, landmark), H_pose)``; batch axes as in the model (pose and landmark must
    already have the same batch shape)."""
    if isinstance(model, LandmarkModelBase):
        if pose.ndim == 1 and landmark.ndim == 1:
            return model.predict_with_pose_jacobian(pose, landmark)
        return model.predict_unchecked(pose, landmark), model.jacobians_unchecked(pose, landmark)[0]
    return model.predict(pose, landmark), model.jacobians(pose, landmark)[0]


def predict_measurement_unchecked(
    model: LandmarkModel, pose: FloatArray, landmark: FloatArray
) -> FloatArray:
    """``h(pose, landmark)``; the batch axes of the arguments broadcast (e.g. sigma points
    ``(N, 3)`` against one landmark ``(2,)``)."""
    if isinstance(model, LandmarkModelBase):
        return model.predict_unchecked(pose, landmark)
    return model.predict(pose, landmark)


def innovation_unchecked(
    model: LandmarkModel, z: FloatArray, z_hat: FloatArray, idx: tuple[int, ...]
) -> FloatArray:
    """``model.residual(z, z_hat)`` for one reading: ``z − z_hat`` with the angular components
    ``idx`` wrapped (slamkit's models define the residual exactly so)."""
    if isinstance(model, LandmarkModelBase):
        return wrap_components(z - z_hat, idx)
    return np.asarray(model.residual(z, z_hat), dtype=np.float64)


def move_unchecked(model: MotionModel, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
    """``g(x, u, dt)`` for poses ``(..., 3)`` and controls of the same batch shape."""
    return motion_kernels(model).apply_unchecked(x, u, dt)


def motion_jacobians_unchecked(
    model: MotionModel, x: FloatArray, u: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray]:
    return motion_kernels(model).jacobians_unchecked(x, u, dt)
