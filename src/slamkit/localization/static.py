"""Static (single-shot) localization: least squares, trilateration, triangulation.

Everything here is a pure function of arrays that returns a frozen result; nothing is
remembered between calls. The pieces, from the bottom up:

* :func:`weighted_least_squares` — the batch solution of the linear model ``y = H x + n``,
  ``n ~ N(0, W)``: ``x = (Hᵀ W⁻¹ H)⁻¹ Hᵀ W⁻¹ y`` with covariance ``(Hᵀ W⁻¹ H)⁻¹``.
* :func:`rls_init`, :func:`rls_update`, :func:`rls_from_first` — the same estimate built one
  measurement block at a time (recursive least squares) over a frozen
  :class:`RecursiveLeastSquares` state.
* :func:`trilaterate` (ranges → position), :func:`triangulate` (bearings, heading unknown →
  pose) and :func:`localize_range_bearing` (range-bearing → pose): an algebraic initial
  guess followed by Gauss–Newton on the non-linear measurement model.
* :func:`localize_from_readings` — dispatches on a :class:`LandmarkSensorSpec` (range-bearing,
  bearing, range, and robot-frame positions); this is what
  the filters use to start without a prior and what the ``least-squares`` estimator runs at
  every landmark event.

Gauss–Newton, used by all the non-linear solvers: with residual ``e(x) = z − h(x)``
(angular components wrapped to ``[-pi, pi)``), Jacobian ``J = ∂h/∂x`` and measurement
covariance ``R = L Lᵀ``, each step solves the linearised problem ``min ‖e − J Δ‖²_{R⁻¹}``
through the whitened normal equations ``(Jᵀ R⁻¹ J) Δ = Jᵀ R⁻¹ e`` (a linear solve) and sets
``x ← x + Δ`` (heading wrapped). **Stopping rule:** stop as soon as a step has Euclidean norm
``‖Δ‖₂ < 1e-10`` (metres and radians mixed; :data:`GN_STEP_TOL`), or after 50 steps
(:data:`GN_MAX_ITERATIONS`), whichever comes first; ``converged`` in the result says which,
``iterations`` counts the steps. The covariance of the fix is ``(Jᵀ R⁻¹ J)⁻¹`` at the solution,
obtained by solving with the normal matrix, never by an explicit inverse.

Degenerate geometry is refused with :class:`~slamkit.errors.GeometryError` rather than
answered with a meaningless number. At the solution the test is the condition number of the
Jacobi-scaled normal matrix ``D Jᵀ R⁻¹ J D`` (``D = diag(Jᵀ R⁻¹ J)^(-1/2)``, which makes it
independent of the units of the unknowns) against ``max_condition`` (default ``1e8``: the
weakest combination of unknowns is then determined 10⁴ times worse than the best, relative to
their scales). The algebraic initial guesses are checked before iterating: for trilateration
the spread of the landmarks ((nearly) collinear landmarks leave the side of the line
undetermined), for triangulation a second null direction of the linear system (robot and
landmarks on one circle or one line).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.datasets.stream import LandmarkSensorSpec
from slamkit.errors import CovarianceError, GeometryError, InputError, ShapeError
from slamkit.geometry import align_points_2d, wrap_angle
from slamkit.maps import LandmarkMap
from slamkit.models import BearingOnly, RangeBearing, RangeOnly

__all__ = [
    "GN_MAX_ITERATIONS",
    "GN_STEP_TOL",
    "MAX_CONDITION",
    "MIN_READINGS",
    "UNIFORM_HEADING_VARIANCE",
    "LeastSquaresResult",
    "PoseFix",
    "PositionFix",
    "RecursiveLeastSquares",
    "localize_from_readings",
    "localize_range_bearing",
    "rls_from_first",
    "rls_init",
    "rls_update",
    "triangulate",
    "trilaterate",
    "weighted_least_squares",
]

GN_STEP_TOL: Final = 1e-10
"""Gauss–Newton stops when the Euclidean norm of a step is below this (m and rad mixed)."""
GN_MAX_ITERATIONS: Final = 50
"""Gauss–Newton stops after this many steps even if the step is still larger."""
MAX_CONDITION: Final = 1e8
"""Default limit on the condition number of the Jacobi-scaled normal matrix."""
MIN_READINGS: Final[dict[str, int]] = {"range-bearing": 2, "position": 2, "range": 3, "bearing": 3}
"""Fewest readings (of distinct landmarks) each sensor kind needs for a fix."""
UNIFORM_HEADING_VARIANCE: Final = float(np.pi**2 / 3.0)
"""Variance of a heading uniform on ``[-pi, pi)``: ``(2 pi)² / 12``."""

# The solvers call the models' array kernels (``predict_unchecked``, ``jacobians_unchecked``)
# directly: the inputs are validated once at the entry point, and skipping the per-call checks
# inside the Gauss–Newton loop makes a fix several times faster (~10 iterations a snapshot).
_RANGE, _BEARING, _RANGE_BEARING = RangeOnly(), BearingOnly(), RangeBearing()


def _at_landmarks(pose: FloatArray, lm: FloatArray) -> FloatArray:
    """``pose (3,)`` broadcast against ``lm (K, 2)``, as the model kernels expect."""
    return np.broadcast_to(pose, (lm.shape[0], 3))


# ---------------------------------------------------------------------- results
@dataclass(frozen=True)
class LeastSquaresResult:
    """Solution ``x (n,)`` of a weighted linear least-squares problem, its covariance
    ``cov (n, n)`` and the residuals ``y − H x (m,)``."""

    x: FloatArray
    cov: FloatArray
    residuals: FloatArray


@dataclass(frozen=True)
class PositionFix:
    """A position ``(2,)`` with covariance ``(2, 2)`` from ranges alone.

    ``residuals (K,)`` are ``z − h(position)`` at the solution; ``iterations`` the number of
    Gauss–Newton steps taken; ``converged`` whether the last step was below the tolerance.
    """

    position: FloatArray
    cov: FloatArray
    residuals: FloatArray
    iterations: int
    converged: bool = True


@dataclass(frozen=True)
class PoseFix:
    """A pose ``(x, y, theta)`` with covariance ``(3, 3)`` from one set of readings.

    ``residuals`` are ``z − h(pose)`` at the solution, shaped like the readings that were
    used (angles wrapped); ``iterations`` and ``converged`` as in :class:`PositionFix`.
    """

    pose: FloatArray
    cov: FloatArray
    residuals: FloatArray
    iterations: int
    converged: bool = True


@dataclass(frozen=True)
class RecursiveLeastSquares:
    """The state of recursive least squares: estimate ``x (n,)``, its covariance
    ``cov (n, n)`` and the number of measurement rows absorbed so far (``count``)."""

    x: FloatArray
    cov: FloatArray
    count: int = 0


# ------------------------------------------------------------ linear least squares
def _whitened_solve(A: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``argmin ‖b − A x‖²`` and ``(AᵀA)⁻¹`` for a whitened system, through ``A = Q R``.

    ``x = R⁻¹ Qᵀ b`` by back substitution; ``(AᵀA)⁻¹ = (RᵀR)⁻¹`` by two triangular solves
    (``cho_solve`` with ``R`` as the Cholesky factor of the normal matrix), so the normal
    matrix is never formed nor inverted. Raises GeometryError naming the rank if ``A`` has
    dependent columns.
    """
    m, n = A.shape
    if m < n:
        raise GeometryError(
            f"least squares: {m} measurement(s) cannot determine {n} unknowns (rank <= {m} < {n})"
        )
    Q, R = np.linalg.qr(A)
    s = np.linalg.svd(R, compute_uv=False)  # the singular values of A
    tol = (s[0] if s.size else 0.0) * max(m, n) * np.finfo(float).eps
    rank = int(np.count_nonzero(s > tol)) if s.size and s[0] > 0 else 0
    if rank < n:
        raise GeometryError(
            f"least squares: the measurement matrix has rank {rank} < {n} unknowns; "
            "the measurements do not determine the state"
        )
    x = sla.solve_triangular(R, Q.T @ b, lower=False)
    cov = sla.cho_solve((R, False), np.eye(n))
    return x, 0.5 * (cov + cov.T)


def _chol_lower(W: FloatArray, name: str) -> FloatArray:
    try:
        return np.asarray(np.linalg.cholesky(W), dtype=np.float64)
    except np.linalg.LinAlgError as exc:  # pragma: no cover - as_covariance checked it
        raise CovarianceError(f"{name}: expected a positive definite matrix") from exc


def weighted_least_squares(H: ArrayLike, y: ArrayLike, W: ArrayLike) -> LeastSquaresResult:
    """Batch weighted least squares for ``y = H x + n``, ``n ~ N(0, W)``.

    ``H (m, n)``, ``y (m,)``, ``W (m, m)`` the (symmetric positive definite) covariance of the
    measurements. Returns ``x = (Hᵀ W⁻¹ H)⁻¹ Hᵀ W⁻¹ y``, ``cov = (Hᵀ W⁻¹ H)⁻¹`` and the
    residuals ``y − H x``.

    Computed without any inverse: with the Cholesky factor ``W = L Lᵀ`` the problem becomes
    the ordinary least squares ``min ‖L⁻¹ y − L⁻¹ H x‖²`` (triangular solves), which is
    solved through a QR factorisation; the covariance comes from the triangular factor.
    Raises :class:`~slamkit.errors.GeometryError` naming the rank when ``H`` has fewer than
    ``n`` independent rows.
    """
    Ha = as_array(H, "H", (None, None))
    m, n = Ha.shape
    if n == 0:
        raise ShapeError("H: expected at least one unknown (column), got shape (m, 0)")
    ya = as_array(y, "y", (m,))
    Wa = as_covariance(W, "W", m)
    L = _chol_lower(Wa, "W")
    A = sla.solve_triangular(L, Ha, lower=True)
    b = sla.solve_triangular(L, ya, lower=True)
    x, cov = _whitened_solve(A, b)
    return LeastSquaresResult(x, cov, ya - Ha @ x)


# --------------------------------------------------------- recursive least squares
def rls_init(x0: ArrayLike, C0: ArrayLike) -> RecursiveLeastSquares:
    """The starting state: prior estimate ``x0 (n,)`` with covariance ``C0 (n, n)``.

    A vague start (large ``C0``) forgets the prior only approximately; :func:`rls_from_first`
    starts exactly from the first measurements instead.
    """
    x = as_array(x0, "x0", (None,)).copy()
    C = as_covariance(C0, "C0", x.size)
    return RecursiveLeastSquares(x, C.copy(), 0)


def _measurement_block(
    state: RecursiveLeastSquares, H_k: ArrayLike, y_k: ArrayLike, W_k: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    n = state.x.size
    H = as_array(H_k, "H_k")
    if H.ndim == 1:  # one row given as a vector
        H = H[None, :]
    H = as_array(H, "H_k", (None, n))
    m = H.shape[0]
    y = as_array(y_k, "y_k").reshape(-1)
    if y.shape != (m,):
        raise ShapeError(f"y_k: expected {m} value(s), got shape {np.shape(y_k)}")
    W = as_array(W_k, "W_k")
    if W.ndim == 0:  # a scalar variance for a single row
        W = W.reshape(1, 1)
    W = as_covariance(W, "W_k", m)
    return H, y, W


def rls_update(
    state: RecursiveLeastSquares, H_k: ArrayLike, y_k: ArrayLike, W_k: ArrayLike
) -> RecursiveLeastSquares:
    """Absorb the measurement block ``y_k = H_k x + n_k``, ``n_k ~ N(0, W_k)``.

    ``H_k (m_k, n)`` (or one row ``(n,)``), ``y_k (m_k,)`` (or a scalar), ``W_k (m_k, m_k)``
    (or a scalar variance); the block must be uncorrelated with every earlier one. With the
    innovation covariance ``S = W_k + H_k C H_kᵀ``:

    * gain ``K = C H_kᵀ S⁻¹`` (from a Cholesky solve of ``S``, not an inverse);
    * ``x ← x + K (y_k − H_k x)``;
    * ``C ← (I − K H_k) C (I − K H_k)ᵀ + K W_k Kᵀ`` (Joseph form, symmetrised).
    """
    H, y, W = _measurement_block(state, H_k, y_k, W_k)
    C = state.cov
    S = W + H @ C @ H.T
    try:
        cho = sla.cho_factor(0.5 * (S + S.T), lower=True)
    except np.linalg.LinAlgError as exc:
        raise CovarianceError(
            "rls_update: the innovation covariance W_k + H_k C H_kᵀ is not positive definite"
        ) from exc
    # K = C Hᵀ S⁻¹  ⇔  Kᵀ = S⁻¹ H C  (S and C symmetric).
    K = sla.cho_solve(cho, H @ C).T
    x = state.x + K @ (y - H @ state.x)
    # Joseph form: it equals C − K H C only for the optimal gain, but it is a sum of two
    # symmetric PSD terms for *any* K, so the rounding errors of the gain cannot make the
    # covariance lose symmetry or positive definiteness (C − K H C subtracts nearly equal
    # numbers once the estimate is precise and can turn indefinite).
    A = np.eye(x.size) - K @ H
    C_new = A @ C @ A.T + K @ W @ K.T
    return RecursiveLeastSquares(x, 0.5 * (C_new + C_new.T), state.count + H.shape[0])


def rls_from_first(H: ArrayLike, y: ArrayLike, W: ArrayLike) -> RecursiveLeastSquares:
    """Recursive least squares over the rows of ``y = H x + n`` started from the data.

    The first ``k`` rows, with ``k`` the smallest number that determines ``x`` (``H[:k]`` of
    full column rank), are solved in batch by :func:`weighted_least_squares`; that estimate
    and its covariance start the recursion, and every later row is absorbed by
    :func:`rls_update`. In exact arithmetic the result equals the batch solution over all
    rows. ``W (m, m)`` may correlate the first ``k`` rows among themselves only: every later
    row must be uncorrelated with all others (diagonal there), otherwise the recursion would
    not be exact and :class:`~slamkit.errors.InputError` is raised.
    """
    Ha = as_array(H, "H", (None, None))
    m, n = Ha.shape
    ya = as_array(y, "y", (m,))
    Wa = as_covariance(W, "W", m)
    k = next((j for j in range(n, m + 1) if np.linalg.matrix_rank(Ha[:j]) == n), None)
    if k is None:
        rank = int(np.linalg.matrix_rank(Ha)) if m else 0
        raise GeometryError(
            f"rls_from_first: H has rank {rank} < {n} unknowns; the measurements do not "
            "determine the state"
        )
    off = Wa - np.diag(np.diag(Wa))
    if np.any(off[k:, :] != 0.0):
        raise InputError(
            f"rls_from_first: rows {k}..{m - 1} are absorbed one at a time, so they must be "
            "uncorrelated with all other rows (W diagonal there)"
        )
    first = weighted_least_squares(Ha[:k], ya[:k], Wa[:k, :k])
    state = RecursiveLeastSquares(first.x, first.cov, k)
    for i in range(k, m):
        state = rls_update(state, Ha[i], ya[i], Wa[i, i])
    return state


# ----------------------------------------------------------------- Gauss–Newton
ResidualFn = Callable[[FloatArray], tuple[FloatArray, FloatArray]]


@dataclass(frozen=True)
class _GNResult:
    x: FloatArray
    cov: FloatArray
    residuals: FloatArray
    iterations: int
    converged: bool


def _scaled_condition(A: FloatArray) -> float:
    """Condition number of the Jacobi-scaled normal matrix ``D AᵀA D`` of a whitened ``A``."""
    norms = np.linalg.norm(A, axis=0)
    if np.any(norms == 0.0):
        return float("inf")
    s = np.linalg.svd(A / norms, compute_uv=False)
    return float("inf") if s[-1] == 0.0 else float((s[0] / s[-1]) ** 2)


def _check_condition(A: FloatArray, max_condition: float, what: str) -> None:
    cond = _scaled_condition(A)
    if not cond <= max_condition:
        raise GeometryError(
            f"{what}: the normal matrix has condition number {cond:.3g} > {max_condition:.3g}; "
            "the geometry of the landmarks does not determine the answer"
        )


def _whitener(R: FloatArray) -> Callable[[FloatArray], FloatArray]:
    """``M ↦ L⁻¹ M`` for the Cholesky factor ``R = L Lᵀ`` (a division when ``R`` is diagonal)."""
    if np.count_nonzero(R - np.diag(np.diag(R))) == 0:
        inv_sigma = 1.0 / np.sqrt(np.diag(R))
        return lambda M: (M.T * inv_sigma).T
    L = _chol_lower(R, "measurement covariance")
    return lambda M: sla.solve_triangular(L, M, lower=True, check_finite=False)


def _normal_solve(A: FloatArray, b: FloatArray, what: str) -> FloatArray:
    """``(AᵀA)⁻¹ Aᵀ b`` by solving the normal equations; GeometryError naming the rank when
    ``AᵀA`` is singular."""
    try:
        return np.asarray(np.linalg.solve(A.T @ A, A.T @ b), dtype=np.float64)
    except np.linalg.LinAlgError:
        rank = int(np.linalg.matrix_rank(A))
        raise GeometryError(
            f"{what}: the linearised measurements have rank {rank} < {A.shape[1]} unknowns; "
            "the geometry does not determine the answer"
        ) from None


def _gauss_newton(
    x0: FloatArray,
    fn: ResidualFn,
    R: FloatArray,
    *,
    heading_index: int | None,
    max_condition: float,
    what: str,
) -> _GNResult:
    """Minimise ``e(x)ᵀ R⁻¹ e(x)`` from ``x0``; ``fn(x) -> (e (N,), J (N, n))`` with
    ``e = z − h(x)``, ``J = ∂h/∂x``. The stopping rule is in the module docstring.

    Each step solves the whitened normal equations ``(AᵀA) Δ = Aᵀ b`` (``A = L⁻¹ J``,
    ``b = L⁻¹ e``); squaring the condition number is harmless here because fixes whose
    normal matrix is worse conditioned than ``max_condition`` are refused anyway.
    """
    whiten = _whitener(R)
    x = x0.copy()
    iterations = 0
    converged = False
    while iterations < GN_MAX_ITERATIONS:
        e, J = fn(x)
        step = _normal_solve(whiten(J), whiten(e), what)
        x = x + step
        if heading_index is not None and not -math.pi <= x[heading_index] < math.pi:
            x[heading_index] = wrap_angle(x[heading_index])
        iterations += 1
        if math.sqrt(float(step @ step)) < GN_STEP_TOL:
            converged = True
            break
    # Residuals and covariance at the solution itself (one more linearisation).
    e, J = fn(x)
    A = whiten(J)
    _check_condition(A, max_condition, what)
    N = A.T @ A
    cov = np.linalg.solve(N, np.eye(N.shape[0]))  # (Jᵀ R⁻¹ J)⁻¹ by a solve
    return _GNResult(x, 0.5 * (cov + cov.T), e, iterations, converged)


# ----------------------------------------------------------------- input helpers
def _noise_cov(value: ArrayLike, k: int, name: str) -> FloatArray:
    """A ``(k, k)`` covariance from one sigma, ``k`` sigmas or a ``(k, k)`` covariance."""
    a = as_array(value, name)
    if a.ndim == 0 or a.ndim == 1:
        sig = np.broadcast_to(a, (k,)) if a.ndim == 0 else as_array(a, name, (k,))
        if np.any(sig <= 0):
            raise InputError(f"{name}: expected standard deviation(s) > 0, got {value!r}")
        return np.diag(np.asarray(sig, dtype=float) ** 2)
    if a.ndim == 2:
        return as_covariance(a, name, k)
    raise ShapeError(f"{name}: expected a sigma, {k} sigmas or a ({k}, {k}) covariance")


def _landmarks(landmarks: ArrayLike, need: int, what: str) -> FloatArray:
    lm = as_array(landmarks, "landmarks", (None, 2))
    if lm.shape[0] < need:
        raise GeometryError(
            f"{what} needs at least {need} landmarks, got {lm.shape[0]}: the pose is not determined"
        )
    return lm


# ----------------------------------------------------------------- trilateration
def _trilateration_guess(lm: FloatArray, r: FloatArray, max_condition: float) -> FloatArray:
    """Linear least squares after subtracting the first range equation.

    ``‖p − l_i‖² = r_i²`` minus ``‖p − l_0‖² = r_0²`` is linear in ``p``:
    ``2 (l_i − l_0)ᵀ p = r_0² − r_i² + ‖l_i‖² − ‖l_0‖²`` for ``i = 1 … K−1``. Coordinates are
    taken relative to the landmark centroid, which keeps the squares small.
    """
    c = lm.mean(axis=0)
    q = lm - c
    A = 2.0 * (q[1:] - q[0])
    b = r[0] ** 2 - r[1:] ** 2 + np.sum(q[1:] ** 2, axis=1) - np.sum(q[0] ** 2)
    # Both columns are in metres, so the plain (unscaled) condition number of AᵀA measures
    # the geometry: (largest / smallest spread of the landmarks)², rotation-invariant.
    sv = np.linalg.svd(A, compute_uv=False)
    cond = float("inf") if sv[-1] == 0.0 else float((sv[0] / sv[-1]) ** 2)
    if not cond <= max_condition:
        raise GeometryError(
            f"trilateration: the landmarks are (nearly) collinear (condition number {cond:.3g} "
            f"> {max_condition:.3g} of the linearised geometry); ranges to landmarks on one "
            "line cannot tell the two sides of the line apart"
        )
    p, _ = _whitened_solve(A, b)
    return np.asarray(p + c, dtype=float)


def trilaterate(
    landmarks: ArrayLike,
    ranges: ArrayLike,
    sigma_range: ArrayLike,
    *,
    max_condition: float = MAX_CONDITION,
) -> PositionFix:
    """The position ``(2,)`` at the given ranges from known landmarks.

    ``landmarks (K, 2)`` (m), ``ranges (K,)`` (m, ≥ 0), ``sigma_range``: one standard
    deviation for all ranges, ``(K,)`` standard deviations, or a ``(K, K)`` covariance.

    The algebraic guess subtracts the first range equation from the others (linear least
    squares, see :func:`_trilateration_guess`); Gauss–Newton then minimises the weighted
    squared range residuals (stopping rule in the module docstring). Raises
    :class:`~slamkit.errors.GeometryError` with fewer than 3 landmarks, with (nearly)
    collinear landmarks, or when the normal matrix at the solution is ill-conditioned
    (``max_condition``); :class:`~slamkit.errors.NonFiniteError` on NaN/inf.
    """
    lm = as_array(landmarks, "landmarks", (None, 2))
    r = as_array(ranges, "ranges", (lm.shape[0],))
    R = _noise_cov(sigma_range, lm.shape[0], "sigma_range")
    _landmarks(lm, 3, "trilateration")
    if np.any(r < 0):
        raise InputError("ranges: expected distances >= 0")
    p0 = _trilateration_guess(lm, r, max_condition)

    def fn(p: FloatArray) -> tuple[FloatArray, FloatArray]:
        pose = _at_landmarks(np.array([p[0], p[1], 0.0]), lm)
        e = r - _RANGE.predict_unchecked(pose, lm)[:, 0]
        Hp, _ = _RANGE.jacobians_unchecked(pose, lm)
        return e, Hp[:, 0, :2]

    out = _gauss_newton(
        p0, fn, R, heading_index=None, max_condition=max_condition, what="trilateration"
    )
    return PositionFix(out.x, out.cov, out.residuals, out.iterations, out.converged)


# ----------------------------------------------------------------- triangulation
def _triangulation_guess(lm: FloatArray, beta: FloatArray, max_condition: float) -> FloatArray:
    """Pose from bearings by a homogeneous linear system.

    The landmark ``l_i`` lies on the ray from ``p`` at world angle ``φ_i = β_i + θ``:
    ``(l_i − p) × (cos φ_i, sin φ_i) = 0``. With ``c = cos θ``, ``s = sin θ`` and the
    robot-frame coordinates of the world origin ``−(u, v)``, ``(u, v) = R(θ)ᵀ p``, this
    expands to an equation that is *linear* in ``w = (c, s, u, v)``:

        c (lx sβ − ly cβ) + s (lx cβ + ly sβ) − sβ u + cβ v = 0.

    ``w`` is the right singular vector of the smallest singular value (a one-dimensional
    null space for a determined pose), scaled to ``c² + s² = 1``. The sign of ``w`` (θ or
    θ + π: a line has two directions) is chosen so that the landmarks lie ahead along their
    rays. A second (near-)zero singular value means the bearings fit a whole family of poses:
    robot and landmarks on one circle, or on one line.
    """
    cen = lm.mean(axis=0)
    q = lm - cen  # centred coordinates keep the columns of similar size
    sb, cb = np.sin(beta), np.cos(beta)
    M = np.stack(
        [q[:, 0] * sb - q[:, 1] * cb, q[:, 0] * cb + q[:, 1] * sb, -sb, cb],
        axis=1,
    )
    if M.shape[0] < 4:  # pad to square so the SVD returns the whole null space
        M = np.vstack([M, np.zeros((4 - M.shape[0], 4))])
    # Jacobi scaling of the columns (metres vs. unitless) makes the rank test unit-free;
    # M w = 0  ⇔  (M D)(D⁻¹ w) = 0.
    d = np.linalg.norm(M, axis=0)
    d[d == 0.0] = 1.0
    _, s, Vt = np.linalg.svd(M / d)
    if not (s[0] > 0 and (s[0] / s[2]) ** 2 <= max_condition):
        ratio = np.inf if s[2] == 0 else (s[0] / s[2]) ** 2
        raise GeometryError(
            f"triangulation: the bearings fit a whole family of poses (condition number "
            f"{ratio:.3g} > {max_condition:.3g}); the robot and the landmarks lie (nearly) on "
            "one circle or one line"
        )
    w = Vt[-1] / d
    norm = float(np.hypot(w[0], w[1]))
    if norm == 0.0:
        raise GeometryError("triangulation: the bearings do not determine the heading")
    w = w / norm
    c, s_, u, v = w
    p = np.array([c * u - s_ * v, s_ * u + c * v])
    # Sign: landmarks ahead along the rays, Σ (l_i − p)·(cos φ_i, sin φ_i) > 0.
    phi = beta + np.arctan2(s_, c)
    ahead = float(np.sum((q[:, 0] - p[0]) * np.cos(phi) + (q[:, 1] - p[1]) * np.sin(phi)))
    if ahead < 0:  # −w has the same p = R(θ)(u, v) but the opposite heading
        c, s_ = -c, -s_
    return np.array([p[0] + cen[0], p[1] + cen[1], float(np.arctan2(s_, c))])


def triangulate(
    landmarks: ArrayLike,
    bearings: ArrayLike,
    sigma_bearing: ArrayLike,
    *,
    max_condition: float = MAX_CONDITION,
) -> PoseFix:
    """The pose ``(x, y, theta)`` from bearings to known landmarks, heading unknown.

    ``landmarks (K, 2)`` (m), ``bearings (K,)`` (rad, relative to the robot's heading,
    counter-clockwise), ``sigma_bearing``: one standard deviation, ``(K,)`` of them or a
    ``(K, K)`` covariance (rad).

    Bearings fix the position through the angles *between* landmarks, so at least three
    are needed. The algebraic guess solves a homogeneous linear system (derived in
    :func:`_triangulation_guess`); Gauss–Newton then refines ``(x, y, θ)`` with wrapped
    bearing residuals. Raises :class:`~slamkit.errors.GeometryError` with fewer than 3
    landmarks or when the pose is not determined — the robot on the circle through the
    landmarks (every point of the arc sees them under the same angles) or on their common
    line — detected through the condition numbers described in the module docstring.
    """
    lm = as_array(landmarks, "landmarks", (None, 2))
    beta = as_array(bearings, "bearings", (lm.shape[0],))
    R = _noise_cov(sigma_bearing, lm.shape[0], "sigma_bearing")
    _landmarks(lm, 3, "triangulation")
    x0 = _triangulation_guess(lm, beta, max_condition)

    def fn(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        pose = _at_landmarks(x, lm)
        e = wrap_angle(beta - _BEARING.predict_unchecked(pose, lm)[:, 0])
        Hp, _ = _BEARING.jacobians_unchecked(pose, lm)
        return e, Hp[:, 0, :]

    out = _gauss_newton(
        x0, fn, R, heading_index=2, max_condition=max_condition, what="triangulation"
    )
    return PoseFix(out.x, out.cov, out.residuals, out.iterations, out.converged)


# ------------------------------------------------------------ range and bearing
def localize_range_bearing(
    landmarks: ArrayLike,
    z: ArrayLike,
    cov: ArrayLike,
    *,
    max_condition: float = MAX_CONDITION,
) -> PoseFix:
    """The pose ``(x, y, theta)`` from range-bearing readings ``z (K, 2)`` of known
    ``landmarks (K, 2)``; ``cov (2, 2)`` is the noise of one ``(range, bearing)`` reading
    (readings independent of each other).

    Each reading places its landmark in the robot frame at ``r (cos β, sin β)``; the rigid
    alignment of those points onto the map (:func:`~slamkit.geometry.align_points_2d`) is the
    initial pose, from two readings on. Gauss–Newton then minimises the weighted squared
    residuals (range, wrapped bearing). Raises :class:`~slamkit.errors.GeometryError` with
    fewer than 2 readings, coincident landmarks, or an ill-conditioned normal matrix.
    """
    lm = as_array(landmarks, "landmarks", (None, 2))
    k = lm.shape[0]
    za = as_array(z, "z", (k, 2))
    Q = as_covariance(cov, "cov", 2)
    _landmarks(lm, 2, "range-bearing localization")
    if np.any(za[:, 0] < 0):
        raise InputError("z: expected ranges >= 0 in the first column")
    p_robot = za[:, :1] * np.stack([np.cos(za[:, 1]), np.sin(za[:, 1])], axis=1)
    x0 = align_points_2d(p_robot, lm).as_pose()

    def fn(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        pose = _at_landmarks(x, lm)
        e = za - _RANGE_BEARING.predict_unchecked(pose, lm)
        e[:, 1] = wrap_angle(e[:, 1])
        Hp, _ = _RANGE_BEARING.jacobians_unchecked(pose, lm)
        return e.reshape(-1), Hp.reshape(-1, 3)

    # Readings independent: block-diagonal (2K, 2K).
    R = np.asarray(np.kron(np.eye(k), Q), dtype=np.float64)
    out = _gauss_newton(
        np.asarray(x0, dtype=float),
        fn,
        R,
        heading_index=2,
        max_condition=max_condition,
        what="range-bearing localization",
    )
    return PoseFix(out.x, out.cov, out.residuals.reshape(k, 2), out.iterations, out.converged)


def _localize_relative_positions(
    sensor: LandmarkSensorSpec, lm: FloatArray, z: FloatArray, max_condition: float
) -> PoseFix:
    """Pose from landmark positions measured in the robot frame (sensor kind "position").

    The readings are points in the robot frame, so their rigid alignment onto the map is the
    pose itself (and the exact answer for isotropic noise); Gauss–Newton with the sensor's
    own model accounts for a general ``(2, 2)`` noise covariance.
    """
    model = sensor.model()
    x0 = np.asarray(align_points_2d(z, lm).as_pose(), dtype=float)

    def fn(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        e = model.residual(z, model.predict(x, lm))
        Hp, _ = model.jacobians(x, lm)
        return e.reshape(-1), Hp.reshape(-1, 3)

    R = np.asarray(np.kron(np.eye(lm.shape[0]), sensor.noise_cov), dtype=np.float64)
    out = _gauss_newton(
        x0, fn, R, heading_index=2, max_condition=max_condition, what="position localization"
    )
    return PoseFix(out.x, out.cov, out.residuals.reshape(z.shape), out.iterations, out.converged)


# ------------------------------------------------------------------- dispatch
def localize_from_readings(
    z: ArrayLike,
    ids: ArrayLike,
    sensor: LandmarkSensorSpec,
    landmarks: LandmarkMap,
    *,
    max_condition: float = MAX_CONDITION,
) -> PoseFix:
    """A single-shot pose fix from one set of landmark readings.

    ``z (K, m)`` readings of the sensor ``sensor`` (``m = sensor.dim``), ``ids (K,)`` their
    landmark identities in ``landmarks``; readings with ``id < 0`` (unknown identity) are
    ignored, a non-negative id missing from the map raises
    :class:`~slamkit.errors.InputError`. Each reading has the noise ``sensor.noise_cov``.
    Dispatches on ``sensor.kind``:

    * ``"range-bearing"`` → :func:`localize_range_bearing` (≥ 2 readings);
    * ``"position"`` (landmark ``(x, y)`` in the robot frame) → the rigid alignment of the
      readings onto the map, refined by Gauss–Newton with the sensor's model (≥ 2 readings);
    * ``"bearing"`` → :func:`triangulate` (≥ 3 readings);
    * ``"range"`` → :func:`trilaterate` (≥ 3 readings). Ranges say nothing about the
      heading, so the returned heading is ``0`` with variance ``pi²/3`` — the variance of a
      heading uniform on ``[-pi, pi)`` — and no correlation with the position. Treat it as
      "unknown", not as a Gaussian estimate.

    Raises :class:`~slamkit.errors.GeometryError` when the usable readings do not determine
    the pose (too few, degenerate geometry); :data:`MIN_READINGS` gives the minimum counts.
    """
    if sensor.kind not in MIN_READINGS:
        raise InputError(
            f"localize_from_readings: sensor kind {sensor.kind!r} is not supported; expected "
            f"one of {', '.join(MIN_READINGS)}"
        )
    m = sensor.dim
    za = as_array(z, "z", (None, m))
    ida = np.asarray(ids)
    if ida.shape != (za.shape[0],) or not (ida.size == 0 or np.issubdtype(ida.dtype, np.integer)):
        raise ShapeError(f"ids: expected {za.shape[0]} integers, got shape {ida.shape}")
    use = ida >= 0
    zu, idu = za[use], ida[use].astype(np.int64)
    need = MIN_READINGS[sensor.kind]
    if idu.size < need:
        raise GeometryError(
            f"{sensor.kind} localization needs at least {need} readings of known landmarks, "
            f"got {idu.size}"
        )
    unknown = np.setdiff1d(idu, landmarks.ids)
    if unknown.size:
        raise InputError(f"ids: landmark(s) {unknown[:10].tolist()} are not in the map")
    lm = landmarks.position_of(idu)
    cov = sensor.noise_cov
    if sensor.kind == "range-bearing":
        return localize_range_bearing(lm, zu, cov, max_condition=max_condition)
    if sensor.kind == "position":
        return _localize_relative_positions(sensor, lm, zu, max_condition)
    sigma = float(np.sqrt(cov[0, 0]))
    if sensor.kind == "bearing":
        fix = triangulate(lm, zu[:, 0], sigma, max_condition=max_condition)
        return PoseFix(fix.pose, fix.cov, fix.residuals[:, None], fix.iterations, fix.converged)
    pos = trilaterate(lm, zu[:, 0], sigma, max_condition=max_condition)
    pose_cov = np.zeros((3, 3))
    pose_cov[:2, :2] = pos.cov
    pose_cov[2, 2] = UNIFORM_HEADING_VARIANCE
    return PoseFix(
        np.array([pos.position[0], pos.position[1], 0.0]),
        pose_cov,
        pos.residuals[:, None],
        pos.iterations,
        pos.converged,
    )
