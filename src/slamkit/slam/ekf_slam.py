"""EKF-SLAM: the robot pose and a map of point landmarks in one Gaussian.

The state is ``x = (x_r, m_1, …, m_L)`` with the pose ``x_r = (x, y, θ)`` followed by the
landmark positions ``m_j = (x_j, y_j)``, ``n = 3 + 2L`` numbers, with the full covariance
``Σ (n × n)``; landmark ``j`` sits in rows ``s_j = 3 + 2j`` and ``s_j + 1``. Every formula
below is derived here (the course notes have typos, see ``notes/README.md``).

Prediction (:func:`slam_predict`)
---------------------------------
Landmarks do not move, so ``g`` changes the pose only: with ``G = ∂g/∂x_r`` (3 × 3),
``V = ∂g/∂u`` and the control noise ``Q``::

    x_r ← g(x_r, u, dt)
    Σ_rr ← G Σ_rr Gᵀ + V Q Vᵀ            (3 × 3)
    Σ_rm ← G Σ_rm,  Σ_mr = Σ_rmᵀ          (3 × 2L)

i.e. ``F Σ Fᵀ + F_x V Q Vᵀ F_xᵀ`` with ``F = diag(G, I)``, in ``O(L)`` instead of ``O(n³)``
(:func:`dense_slam_predict` is the full-matrix form; a test checks they agree to 1e-12).

Update with one reading ``z`` of landmark ``j`` (:func:`slam_update`)
--------------------------------------------------------------------
``h(x_r, m_j)`` depends on five state entries, so its ``m × n`` Jacobian ``H`` is zero
outside the columns ``0, 1, 2, s_j, s_j + 1``, where it holds ``H_r = ∂h/∂x_r`` and
``H_j = ∂h/∂m_j``. Because ``Σ`` is symmetric, ``H Σ`` (``m × n``) needs five ROWS of ``Σ``
(contiguous in memory)::

    H Σ = H_r Σ[0:3, :] + H_j Σ[s_j:s_j+2, :]          (= (Σ Hᵀ)ᵀ)
    S   = (H Σ)[:, 0:3] H_rᵀ + (H Σ)[:, s_j:s_j+2] H_jᵀ + R
    Kᵀ  = S⁻¹ (H Σ)                                      (K = Σ Hᵀ S⁻¹, n × m)
    x   ← x + K ν,   ν = z ⊖ h(x_r, m_j)                 (bearing wrapped, heading wrapped)

and the Joseph form ``Σ ← (I − K H) Σ (I − K H)ᵀ + K R Kᵀ``, multiplied out:
``Σ − K (H Σ) − (H Σ)ᵀ Kᵀ + K S Kᵀ``. With ``D = K S / 2 − (H Σ)ᵀ`` this is exactly

    Σ ← Σ + D Kᵀ + K Dᵀ                                  (one rank-2m product)

— the Joseph form, not the short ``Σ − K S Kᵀ``: it is the covariance of the estimator that
used THIS gain, rounding and all, hence symmetric positive semi-definite for any ``K``; the
short form is only right for the exactly optimal gain and loses definiteness when very
precise readings make ``K H`` nearly the identity in some direction. In exact arithmetic
``D = −(H Σ)ᵀ / 2`` and both agree (:func:`dense_slam_update` is the textbook
``(I − K H) Σ (I − K H)ᵀ + K R Kᵀ`` with the dense ``H``; a test checks they agree to
1e-10). The product is applied block-row by block-row through a small scratch buffer, so one
update reads and writes the ``n × n`` matrix once and allocates nothing of size ``n²``.

A new landmark (:func:`slam_add_landmark`)
------------------------------------------
From its first reading by the inverse model ``m = g⁻¹(x_r, z)`` with ``L_x = ∂m/∂x_r``
and ``L_z = ∂m/∂z``, to first order ``δm = L_x δx_r + L_z δz``, so::

    Σ_mm = L_x Σ_rr L_xᵀ + L_z R L_zᵀ,   Σ_m,: = L_x Σ_r,:    (cross with the WHOLE state)

The state lives in preallocated buffers whose capacity doubles when full; adding a landmark
writes two rows and two columns, ``O(n)``.

Data association, provisional features, removal: see :class:`EkfSlam` and :func:`jcbb`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Literal

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.datasets.stream import Control, Dataset, Event, LandmarkReadings, Odometry
from slamkit.errors import (
    ConfigError,
    ConvergenceError,
    GeometryError,
    InputError,
    NonFiniteError,
    ShapeError,
)
from slamkit.estimation.contract import (
    EstimatorOutput,
    InnovationLog,
    LandmarkEstimate,
    PoseEstimate,
    StepClock,
)
from slamkit.estimation.gaussian import (
    angular_indices,
    check_covariance,
    measure_unchecked,
    small_spd_inverse,
    wrap_components,
)
from slamkit.estimation.readings import ReadingStatus
from slamkit.geometry import wrap_angle
from slamkit.geometry.angles import wrap_angle_float
from slamkit.localization.kalman import UpdateInfo
from slamkit.mapping.ekf_mapping import (
    DISCARDED,
    INITIALISED,
    NEW,
    REJECTED,
    TOO_CLOSE,
    UPDATED,
    association_probabilities,
)
from slamkit.mapping.ekf_mapping import associate_nearest_unchecked as _greedy_nearest_neighbour
from slamkit.maps import LandmarkMap
from slamkit.models import MIN_RANGE, LandmarkModel, MotionModel, odometry_control
from slamkit.models.measurement import InvertibleLandmarkModel, LandmarkModelBase
from slamkit.models.motion import motion_kernels
from slamkit.prob import chi2_gate

__all__ = [
    "DISCARDED",
    "INITIALISED",
    "OWN_ID_BASE",
    "TOO_CLOSE",
    "TRACKED",
    "UPDATED",
    "EkfSlam",
    "EkfSlamConfig",
    "JcbbResult",
    "SlamBelief",
    "dense_slam_predict",
    "dense_slam_update",
    "jcbb",
    "slam_add_landmark",
    "slam_predict",
    "slam_update",
]

TRACKED = ReadingStatus.TRACKED
"""Reading status: the reading updated a provisional feature (the feature only; see
:class:`EkfSlam`); every code is a :class:`~slamkit.estimation.readings.ReadingStatus`."""

OWN_ID_BASE = 1_000_000
"""Ids the estimator gives the features it names itself (readings without ids) start here,
so that they never alias a data set's landmark ids: evaluation matches maps by id, and a
feature numbered 3 by the filter is not the data set's landmark 3."""

_SCRATCH_BYTES = 1 << 20
"""Size of the block of rows the rank-2m covariance product is formed in: small enough to
stay in cache, so the ``n × n`` matrix is streamed through memory once per update. Measured
(``benchmarks/bench_ekf_slam.py`` machine, n = 4003): 32 KiB 6.6 GB/s, 256 KiB 13.9 GB/s,
1 MiB 18.7 GB/s, 4 MiB 19.2 GB/s, one n × n temporary 5.1 GB/s."""


# --------------------------------------------------------------------------------------------
# the belief (public functional API)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SlamBelief:
    """The EKF-SLAM belief: ``mean (3 + 2L,)`` = pose then landmark positions, the full
    covariance ``cov (n, n)`` and the landmark ids ``(L,)`` in state order. Treated as
    immutable: the functions of this module return new beliefs."""

    mean: FloatArray
    cov: FloatArray
    ids: NDArray[np.int64]

    def __post_init__(self) -> None:
        mean = as_array(self.mean, "SLAM mean", (None,))
        if mean.size < 3 or (mean.size - 3) % 2:
            raise ShapeError(
                f"SLAM mean: expected 3 + 2L entries (pose, then landmarks), got {mean.size}"
            )
        cov = as_covariance(self.cov, "SLAM covariance", mean.size, semidefinite=True)
        ids = np.asarray(self.ids)
        if ids.shape != ((mean.size - 3) // 2,) or (
            ids.size and not np.issubdtype(ids.dtype, np.integer)
        ):
            raise ShapeError(
                f"SLAM ids: expected {(mean.size - 3) // 2} integers, got {ids.shape} {ids.dtype}"
            )
        if np.unique(ids).size != ids.size:
            raise InputError("SLAM ids: expected unique ids, got duplicates")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)
        object.__setattr__(self, "ids", ids.astype(np.int64))

    @classmethod
    def from_pose(cls, pose: ArrayLike, cov: ArrayLike) -> SlamBelief:
        """A belief with no landmarks yet (``cov`` may be zero: the map frame is the start)."""
        return cls(np.asarray(pose, dtype=float), np.asarray(cov, dtype=float), np.zeros(0, int))

    def __len__(self) -> int:
        return int(self.ids.size)

    @property
    def pose(self) -> FloatArray:
        return self.mean[:3]

    @property
    def pose_cov(self) -> FloatArray:
        return self.cov[:3, :3]

    @property
    def landmark_means(self) -> FloatArray:
        """``(L, 2)`` landmark positions."""
        return self.mean[3:].reshape(-1, 2)

    @property
    def landmark_covs(self) -> FloatArray:
        """``(L, 2, 2)`` marginal covariances of the landmarks."""
        return _diagonal_blocks(self.cov, len(self))


def _diagonal_blocks(cov: FloatArray, L: int) -> FloatArray:
    """The ``(L, 2, 2)`` landmark blocks on the diagonal of a SLAM covariance (copies)."""
    idx = 3 + 2 * np.arange(L)
    out = np.empty((L, 2, 2))
    out[:, 0, 0] = cov[idx, idx]
    out[:, 0, 1] = cov[idx, idx + 1]
    out[:, 1, 0] = cov[idx + 1, idx]
    out[:, 1, 1] = cov[idx + 1, idx + 1]
    return out


# --------------------------------------------------------------------------------------------
# kernels: in place on the active part of the state buffers (callers validated everything)
# --------------------------------------------------------------------------------------------


def _predict_inplace(
    mean: FloatArray,
    cov: FloatArray,
    u: FloatArray,
    dt: float,
    model: MotionModel,
    Q: FloatArray,
) -> None:
    """The prediction on ``mean (n,)`` and ``cov (n, n)`` (views of the active state)."""
    x = mean[:3]
    moved, G, V = motion_kernels(model).step_single(x, u, dt)  # the fused one-pose kernel
    mean[:3] = moved
    P = G @ cov[:3, :3] @ G.T + V @ Q @ V.T  # Σ_rr ← G Σ_rr Gᵀ + V Q Vᵀ
    cov[:3, :3] = 0.5 * (P + P.T)
    if cov.shape[0] > 3:
        cross = G @ cov[:3, 3:]  # Σ_rm ← G Σ_rm
        cov[:3, 3:] = cross
        cov[3:, :3] = cross.T
    if not (math.isfinite(float(P.sum())) and math.isfinite(float(mean[0] + mean[1]))):
        raise ConvergenceError("ekf-slam predict: the pose or its covariance became non-finite")


def reading_jacobians(
    model: LandmarkModel, pose: FloatArray, landmark: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(h (m,), H_r (m, 3), H_j (m, 2))`` for one pose and one landmark.

    slamkit's point-landmark models depend on the landmark only through ``m − t`` (world
    frame) and ``θ`` — moving pose and landmark by the same offset changes no reading — so
    ``∂h/∂m = −∂h/∂t``: the landmark Jacobian is minus the first two columns of the pose
    Jacobian, which the fused single-reading kernel already gives. (Checked against
    ``model.jacobians`` in the tests.) Other models are asked for both."""
    if isinstance(model, LandmarkModelBase):
        h, Hr = measure_unchecked(model, pose, landmark)
        return h, Hr, -Hr[:, :2]
    h = np.asarray(model.predict(pose, landmark), dtype=np.float64)
    Hr, Hj = model.jacobians(pose, landmark)
    return h, np.asarray(Hr, dtype=np.float64), np.asarray(Hj, dtype=np.float64)


def _rank_update(cov: FloatArray, A: FloatArray, B: FloatArray, scratch: FloatArray) -> None:
    """``cov += Aᵀ B`` for ``A, B (k, n)`` in blocks of rows formed in ``scratch`` (no
    ``n × n`` temporary: one read and one write of ``cov``)."""
    n = cov.shape[0]
    rows = max(1, min(n, scratch.size // max(n, 1)))  # the caller gives scratch.size >= n
    for a in range(0, n, rows):
        b = min(a + rows, n)
        t = scratch[: (b - a) * n].reshape(b - a, n)
        np.matmul(A[:, a:b].T, B, out=t)
        cov[a:b] += t


def _update_inplace(
    mean: FloatArray,
    cov: FloatArray,
    slot: int,
    z: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
    angular: tuple[int, ...],
    scratch: FloatArray,
    *,
    consider: bool = False,
) -> tuple[float, FloatArray, FloatArray]:
    """The 5-column EKF update with reading ``z`` of the landmark in state rows ``slot``,
    ``slot + 1``; returns ``(nis, ν, S)``.

    ``consider=True`` is the Schmidt ("consider") update of a provisional feature: the gain
    is zero outside the feature's two rows, so the pose and the rest of the map keep their
    mean and covariance, and only the feature's rows and columns change — by the Joseph
    form, which is the exact covariance of the filter for ANY gain, this one included::

        K_f = (Σ Hᵀ)_f S⁻¹,  Σ_f,: ← Σ_f,: − K_f (H Σ),
        Σ_ff ← Σ_ff − K_f (H Σ)_:,f − (H Σ)_:,fᵀ K_fᵀ + K_f S K_fᵀ
    """
    s = slot
    h, Hr, Hj = reading_jacobians(model, mean[:3], mean[s : s + 2])
    nu = wrap_components(z - h, angular)  # ν = z ⊖ h: bearing wrapped
    HS = Hr @ cov[:3, :] + Hj @ cov[s : s + 2, :]  # H Σ from five rows (m × n)
    S = HS[:, :3] @ Hr.T + HS[:, s : s + 2] @ Hj.T + R
    S = 0.5 * (S + S.T)
    S_inv = small_spd_inverse(S, "ekf-slam update")
    if S_inv is None:  # readings of more than two components
        S_inv = _spd_inverse(S)
    Sinv_nu = S_inv @ nu
    nis = float(nu @ Sinv_nu)
    if consider:
        Kf = HS[:, s : s + 2].T @ S_inv  # (2, m): the feature's rows of the gain
        mean[s : s + 2] += Kf @ nu
        HSf = HS[:, s : s + 2]  # (m, 2)
        block = cov[s : s + 2, s : s + 2] - Kf @ HSf - HSf.T @ Kf.T + Kf @ S @ Kf.T
        row = cov[s : s + 2, :] - Kf @ HS
        cov[s : s + 2, :] = row
        cov[:, s : s + 2] = row.T
        cov[s : s + 2, s : s + 2] = 0.5 * (block + block.T)
        if not math.isfinite(float(block.sum() + mean[s] + mean[s + 1])):
            raise ConvergenceError("ekf-slam update: the covariance became non-finite")
        return nis, nu, S
    Kt = S_inv @ HS  # Kᵀ = S⁻¹ H Σ (m × n)
    if not math.isfinite(float(Kt.sum() + nis)):
        raise ConvergenceError("ekf-slam update: the gain became non-finite")
    mean += HS.T @ Sinv_nu  # x + K ν with K ν = Σ Hᵀ S⁻¹ ν
    wrap_components(mean, (2,))
    # Joseph form multiplied out: Σ + D Kᵀ + K Dᵀ with D = K S / 2 − Σ Hᵀ (module docstring).
    Dt = 0.5 * (S @ Kt) - HS  # Dᵀ (m × n)
    _rank_update(cov, np.concatenate((Dt, Kt)), np.concatenate((Kt, Dt)), scratch)
    # Exact symmetry where the next steps read and the checks look.
    cov[:3, :3] = 0.5 * (cov[:3, :3] + cov[:3, :3].T)
    blk = cov[s : s + 2, s : s + 2]
    cov[s : s + 2, s : s + 2] = 0.5 * (blk + blk.T)
    return nis, nu, S


def _spd_inverse(S: FloatArray) -> FloatArray:
    try:
        factor = scipy.linalg.cho_factor(S)
    except np.linalg.LinAlgError:
        raise ConvergenceError(
            "ekf-slam update: the innovation covariance S is not positive definite"
        ) from None
    return np.asarray(scipy.linalg.cho_solve(factor, np.eye(S.shape[0])), dtype=np.float64)


def _add_landmark_inplace(
    mean_buf: FloatArray,
    cov_buf: FloatArray,
    n: int,
    z: FloatArray,
    model: InvertibleLandmarkModel,
    R: FloatArray,
) -> None:
    """Write a landmark seen at ``z`` into rows/columns ``n, n + 1`` of the buffers (which
    must have room): mean ``g⁻¹(x_r, z)``, covariance through both Jacobians and the cross
    covariance ``L_x Σ_r,:`` with the whole state."""
    x = mean_buf[:3]
    mean_buf[n : n + 2] = model.inverse(x, z)
    Lx, Lz = model.inverse_jacobians(x, z)
    cross = Lx @ cov_buf[:3, :n]  # (2, n): Σ_m,: = L_x Σ_r,:
    P = Lx @ cov_buf[:3, :3] @ Lx.T + Lz @ R @ Lz.T  # L_x Σ_rr L_xᵀ + L_z R L_zᵀ
    cov_buf[n : n + 2, :n] = cross
    cov_buf[:n, n : n + 2] = cross.T
    cov_buf[n : n + 2, n : n + 2] = 0.5 * (P + P.T)


# --------------------------------------------------------------------------------------------
# public functional core (validated; each call copies the belief)
# --------------------------------------------------------------------------------------------


def _landmark_model(model: object) -> InvertibleLandmarkModel:
    if not isinstance(model, InvertibleLandmarkModel):
        raise InputError(
            f"EKF-SLAM needs a measurement model with an inverse (one reading fixes a "
            f"landmark), got {type(model).__name__}: range-only and bearing-only readings "
            "cannot initialise a landmark from a single reading"
        )
    return model


def slam_predict(
    belief: SlamBelief, u: ArrayLike, dt: float, model: MotionModel, control_cov: ArrayLike
) -> SlamBelief:
    """The EKF-SLAM prediction (module docstring): the pose moves, ``Σ_rr`` and ``Σ_rm``
    change, the map block does not. ``control_cov (k, k)`` is the control noise ``Q``."""
    if not isinstance(model, MotionModel):
        raise InputError(f"model: expected a MotionModel, got {type(model).__name__}")
    ua = as_array(u, "u", (model.control_dim,))
    Q = as_covariance(control_cov, "control_cov", model.control_dim, semidefinite=True)
    if not (math.isfinite(dt) and dt >= 0):
        raise InputError(f"dt: expected a number >= 0, got {dt!r}")
    mean, cov = belief.mean.copy(), belief.cov.copy()
    _predict_inplace(mean, cov, ua, float(dt), model, Q)
    return SlamBelief(mean, cov, belief.ids.copy())


def _check_reading(z: ArrayLike, model: object, R: ArrayLike) -> tuple[FloatArray, FloatArray]:
    if not isinstance(model, LandmarkModel):
        raise InputError(f"model: expected a LandmarkModel, got {type(model).__name__}")
    za = as_array(z, "z", (model.dim,))
    Ra = as_covariance(R, "R", model.dim)
    return za, Ra


def slam_update(
    belief: SlamBelief,
    index: int,
    z: ArrayLike,
    model: LandmarkModel,
    R: ArrayLike,
    *,
    consider: bool = False,
) -> tuple[SlamBelief, UpdateInfo]:
    """One EKF-SLAM update with the reading ``z (m,)`` of the landmark in row ``index`` of
    the map (5-column Jacobian, Joseph form; module docstring). Returns the new belief and
    ``(ν, S, νᵀ S⁻¹ ν)``. ``consider=True``: the Schmidt update of a provisional feature,
    which changes only that landmark's mean and its rows and columns of the covariance
    (the robot and the rest of the map are untouched; see :class:`EkfSlamConfig`).

    Raises :class:`~slamkit.errors.NonFiniteError` for a NaN reading,
    :class:`~slamkit.errors.CovarianceError` if ``R`` is not positive definite,
    :class:`~slamkit.errors.GeometryError` if the landmark sits on the sensor and
    :class:`~slamkit.errors.ConvergenceError` if the innovation covariance is not one."""
    za, Ra = _check_reading(z, model, R)
    if not (isinstance(index, int | np.integer) and 0 <= index < len(belief)):
        raise InputError(f"index: expected a landmark row in [0, {len(belief)}), got {index!r}")
    mean, cov = belief.mean.copy(), belief.cov.copy()
    scratch = np.empty(max(_SCRATCH_BYTES // 8, mean.size))
    nis, nu, S = _update_inplace(
        mean, cov, 3 + 2 * int(index), za, model, Ra, angular_indices(model), scratch,
        consider=consider,
    )  # fmt: skip
    return SlamBelief(mean, cov, belief.ids.copy()), UpdateInfo(nu, S, nis)


def slam_add_landmark(
    belief: SlamBelief, z: ArrayLike, landmark_id: int, model: LandmarkModel, R: ArrayLike
) -> SlamBelief:
    """Append the landmark first seen at ``z (m,)`` from the belief's pose (module
    docstring): ``m = g⁻¹(x_r, z)``, ``Σ_mm = L_x Σ_rr L_xᵀ + L_z R L_zᵀ``,
    ``Σ_m,: = L_x Σ_r,:``."""
    za, Ra = _check_reading(z, model, R)
    inv = _landmark_model(model)
    if int(landmark_id) in set(belief.ids.tolist()):
        raise InputError(f"slam_add_landmark: id {landmark_id} is already mapped")
    n = belief.mean.size
    mean = np.zeros(n + 2)
    cov = np.zeros((n + 2, n + 2))
    mean[:n], cov[:n, :n] = belief.mean, belief.cov
    _add_landmark_inplace(mean, cov, n, za, inv, Ra)
    return SlamBelief(mean, cov, np.append(belief.ids, np.int64(landmark_id)))


def dense_slam_predict(
    belief: SlamBelief, u: ArrayLike, dt: float, model: MotionModel, control_cov: ArrayLike
) -> SlamBelief:
    """The textbook full-matrix prediction ``F Σ Fᵀ + F_x V Q Vᵀ F_xᵀ`` with
    ``F = diag(G, I)`` and ``F_x = [I_3 0]ᵀ`` — the reference :func:`slam_predict` is tested
    against (``O(n³)``)."""
    ua = as_array(u, "u", (model.control_dim,))
    Q = as_covariance(control_cov, "control_cov", model.control_dim, semidefinite=True)
    x = belief.mean[:3]
    G, V = model.jacobians(x, ua, dt)
    n = belief.mean.size
    F = np.eye(n)
    F[:3, :3] = G
    Fx = np.zeros((n, 3))
    Fx[:3, :3] = np.eye(3)
    mean = belief.mean.copy()
    mean[:3] = model.apply(x, ua, dt)
    cov = F @ belief.cov @ F.T + Fx @ V @ Q @ V.T @ Fx.T
    return SlamBelief(mean, 0.5 * (cov + cov.T), belief.ids.copy())


def dense_slam_update(
    belief: SlamBelief, index: int, z: ArrayLike, model: LandmarkModel, R: ArrayLike
) -> tuple[SlamBelief, UpdateInfo]:
    """The textbook full-matrix update: the dense ``m × n`` Jacobian ``H``,
    ``K = Σ Hᵀ S⁻¹`` and ``(I − K H) Σ (I − K H)ᵀ + K R Kᵀ`` (``O(n³)``): the reference
    :func:`slam_update` is tested against."""
    za, Ra = _check_reading(z, model, R)
    s = 3 + 2 * int(index)
    pose, lm = belief.mean[:3], belief.mean[s : s + 2]
    z_hat = model.predict(pose, lm)
    Hr, Hj = model.jacobians(pose, lm)
    n = belief.mean.size
    H = np.zeros((model.dim, n))
    H[:, :3], H[:, s : s + 2] = Hr, Hj
    nu = np.asarray(model.residual(za, z_hat), dtype=np.float64)
    P = belief.cov
    S = H @ P @ H.T + Ra
    K = P @ H.T @ np.linalg.inv(S)
    A = np.eye(n) - K @ H
    cov = A @ P @ A.T + K @ Ra @ K.T
    mean = belief.mean + K @ nu
    mean[2] = wrap_angle_float(float(mean[2]))
    nis = float(nu @ np.linalg.solve(S, nu))
    return SlamBelief(mean, 0.5 * (cov + cov.T), belief.ids.copy()), UpdateInfo(nu, S, nis)


# --------------------------------------------------------------------------------------------
# joint compatibility branch and bound
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class JcbbResult:
    """The JCBB hypothesis: for each of ``K`` readings the landmark column it is paired with
    (``-1``: none), the joint ``D² = ν_Hᵀ S_H⁻¹ ν_H`` of the pairs, the number of search
    nodes visited and whether the search finished inside its node budget (``False``: the
    best hypothesis found before the budget ran out)."""

    assignment: NDArray[np.int64]
    d2: float
    nodes: int
    complete: bool

    @property
    def pairings(self) -> int:
        return int(np.count_nonzero(self.assignment >= 0))


def jcbb(
    nu: ArrayLike,
    M: ArrayLike,
    R: ArrayLike,
    gate_probability: float = 0.999,
    max_nodes: int = 20_000,
) -> JcbbResult:
    """Joint compatibility branch and bound (Neira & Tardós, IEEE T-RA 17(6), 2001).

    ``nu (K, U, m)``: the innovation of each of ``K`` readings against each of ``U``
    candidate landmarks (angles wrapped). ``M (U·m, U·m)``: the joint covariance of the
    ``U`` predicted readings ``H Σ Hᵀ`` — off-diagonal blocks nonzero, since every
    prediction shares the robot pose — WITHOUT the noise; ``R (m, m)`` is the noise of one
    reading. A hypothesis pairs readings with distinct landmarks; it is *jointly
    compatible* when the stacked innovation ``ν_H`` and ``S_H = M_H + I ⊗ R`` give
    ``D² = ν_Hᵀ S_H⁻¹ ν_H ≤ χ²_{m·p}(gate_probability)`` (``p`` pairs). The search returns
    the jointly compatible hypothesis with the most pairs, the smallest ``D²`` among those.
    Each pair must also be individually compatible (the same test with ``p = 1``).

    ``D²`` grows incrementally: adding a pair with innovation ``ν_p``, noise-free block
    ``c`` against the pairs so far and own block ``s`` extends the Cholesky factor ``L`` of
    ``S_H`` by ``B = L⁻¹ c``, ``L_pp = chol(s + R − Bᵀ B)``, and
    ``D² += ‖L_pp⁻¹ (ν_p − Bᵀ y)‖²`` with ``y = L⁻¹ ν_H`` — ``O(p²)`` per node instead of a
    new factorisation. Readings are searched in order of increasing candidate count; the
    bound prunes a branch that cannot reach the best number of pairs (or, at equal count,
    has already a larger ``D²``). After ``max_nodes`` nodes the best hypothesis found so far
    is returned with ``complete=False``.
    """
    v = as_array(nu, "nu", (None, None, None))
    _, U, m = v.shape
    Ma = as_array(M, "M", (U * m, U * m))
    Ra = as_covariance(R, "R", m)
    if not 0 < gate_probability < 1:
        raise InputError(f"gate_probability: expected a number in (0, 1), got {gate_probability}")
    if not (isinstance(max_nodes, int) and max_nodes >= 1):
        raise InputError(f"max_nodes: expected an integer >= 1, got {max_nodes!r}")
    return _jcbb(v, Ma, Ra, gate_probability, max_nodes)


@lru_cache(maxsize=256)
def _chi2(dof: int, probability: float) -> float:
    return chi2_gate(dof, probability)


def _individual_d2(nu: FloatArray, M: FloatArray, R: FloatArray) -> FloatArray:
    """``d² (K, U)`` of every reading against every candidate with ``S_u = M_uu + R``."""
    _, U, m = nu.shape
    blocks = M.reshape(U, m, U, m)[np.arange(U), :, np.arange(U), :] + R  # (U, m, m)
    try:
        Sinv = np.linalg.inv(0.5 * (blocks + np.swapaxes(blocks, -1, -2)))
    except np.linalg.LinAlgError:
        raise ConvergenceError("jcbb: an innovation covariance is singular") from None
    return np.einsum("kui,uij,kuj->ku", nu, Sinv, nu)


def _lower_cholesky_inverse(C: FloatArray) -> FloatArray | None:
    """``L⁻¹`` of the lower Cholesky factor of a small SPD ``C``; ``None`` if ``C`` is not
    positive definite. Closed form for 2 × 2 (the usual reading), LAPACK otherwise."""
    if C.shape[0] == 2:
        a, b, d = float(C[0, 0]), 0.5 * float(C[0, 1] + C[1, 0]), float(C[1, 1])
        if not a > 0.0:
            return None
        l11 = math.sqrt(a)
        l21 = b / l11
        q = d - l21 * l21
        if not q > 0.0:
            return None
        l22 = math.sqrt(q)
        return np.array([[1.0 / l11, 0.0], [-l21 / (l11 * l22), 1.0 / l22]])
    try:
        L = np.linalg.cholesky(0.5 * (C + C.T))
    except np.linalg.LinAlgError:
        return None
    return np.asarray(scipy.linalg.solve_triangular(L, np.eye(C.shape[0]), lower=True))


def _jcbb(
    nu: FloatArray,
    M: FloatArray,
    R: FloatArray,
    probability: float,
    max_nodes: int,
    d2_ind: FloatArray | None = None,
) -> JcbbResult:
    K, U, m = nu.shape
    if K == 0 or U == 0:
        return JcbbResult(np.full(K, -1, dtype=np.int64), 0.0, 0, True)
    if d2_ind is None:
        d2_ind = _individual_d2(nu, M, R)
    gates = [0.0] + [_chi2(m * p, probability) for p in range(1, min(K, U) + 1)]
    cands = [[int(u) for u in np.argsort(d2_ind[k]) if d2_ind[k, u] <= gates[1]] for k in range(K)]
    order = sorted(range(K), key=lambda k: (len(cands[k]), k))
    # remaining[i]: readings from position i on that have a candidate (the bound).
    remaining = [0] * (K + 1)
    for i in range(K - 1, -1, -1):
        remaining[i] = remaining[i + 1] + (1 if cands[order[i]] else 0)

    M4 = M.reshape(U, m, U, m)
    cap = m * min(K, U)
    # Inverse of the Cholesky factor of S_H, grown and shrunk with the hypothesis: with
    # S_H = L Lᵀ and a new pair, L' = [[L, 0], [Bᵀ, L_pp]] has the inverse
    # [[L⁻¹, 0], [−L_pp⁻¹ Bᵀ L⁻¹, L_pp⁻¹]] — matrix products only, no triangular solves.
    Linv = np.zeros((cap, cap))
    y = np.zeros(cap)  # L⁻¹ ν_H
    landmarks: list[int] = []  # landmark of each pair, in hypothesis order
    assign = [-1] * K
    used = [False] * U
    best: dict[str, Any] = {"pairs": 0, "d2": math.inf, "assign": [-1] * K}
    state = {"nodes": 0}

    def extend(k: int, u: int, d2: float) -> float | None:
        """D² with the pair (k, u) added, writing the factor's new rows; None if the pair
        is not jointly compatible."""
        p = len(landmarks)
        r0 = p * m
        C = M4[u, :, u, :] + R  # the new pair's own block of S_H
        rhs = nu[k, u]
        if p:
            c = M4[landmarks, :, u, :].reshape(r0, m)  # cross-covariance, no noise
            Li = Linv[:r0, :r0]
            B = Li @ c  # L⁻¹ c
            C = C - B.T @ B  # Schur complement: L_pp L_ppᵀ = s − Bᵀ B
            rhs = rhs - B.T @ y[:r0]
        Lpp_inv = _lower_cholesky_inverse(C)
        if Lpp_inv is None:
            return None
        y_p = Lpp_inv @ rhs
        d2_new = d2 + float(y_p @ y_p)  # D² grows by ‖L_pp⁻¹ (ν_p − Bᵀ y)‖²
        if d2_new > gates[p + 1]:
            return None
        if p:
            Linv[r0 : r0 + m, :r0] = -Lpp_inv @ B.T @ Li
        Linv[r0 : r0 + m, r0 : r0 + m] = Lpp_inv
        y[r0 : r0 + m] = y_p
        return d2_new

    def search(i: int, d2: float) -> None:
        state["nodes"] += 1
        pairs = len(landmarks)
        if i == K:
            if pairs > best["pairs"] or (pairs == best["pairs"] and d2 < best["d2"]):
                best.update(pairs=pairs, d2=d2, assign=list(assign))
            return
        if state["nodes"] >= max_nodes:
            return
        k = order[i]
        # Pair reading k with each free, individually compatible landmark (nearest first)
        # if the result can still beat the best (more pairs, or as many with less D²).
        for u in cands[k]:
            bound = pairs + remaining[i]
            if bound < best["pairs"] or (bound == best["pairs"] and d2 >= best["d2"]):
                break
            if used[u]:
                continue
            d2_new = extend(k, u, d2)
            if d2_new is None:
                continue
            landmarks.append(u)
            used[u] = True
            assign[k] = u
            search(i + 1, d2_new)
            assign[k] = -1
            used[u] = False
            landmarks.pop()
        # Leave reading k unpaired if the others alone can still beat the best.
        bound = pairs + remaining[i + 1]
        if bound > best["pairs"] or (bound == best["pairs"] and d2 < best["d2"]):
            search(i + 1, d2)

    search(0, 0.0)
    complete = state["nodes"] < max_nodes
    assignment = np.asarray(best["assign"], dtype=np.int64)
    return JcbbResult(assignment, float(best["d2"]), state["nodes"], complete)


# --------------------------------------------------------------------------------------------
# the estimator
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EkfSlamConfig:
    """Settings of :class:`EkfSlam`. Units: metres, radians, m² for covariance traces."""

    motion_noise_scale: float = 1.0
    """Multiplies the data set's nominal control-noise covariance ``Q`` (>= 0)."""
    measurement_noise_scale: float = 1.0
    """Multiplies the landmark sensor's noise covariance ``R`` (> 0)."""
    use_ids: bool = True
    """Use the landmark ids the readings carry when the sensor provides them
    (``LandmarkSensorSpec.identities``); ``-1`` readings are then associated with the
    existing landmarks but never start one, so that an id chosen here cannot collide with a
    later labelled one. ``False`` (or a sensor without identities) ignores every id and
    associates all readings."""
    association: Literal["nn", "jcbb"] = "nn"
    """Data association of unlabelled readings. ``"nn"``: greedy global nearest neighbour
    in Mahalanobis distance (pairs taken by increasing ``d²`` inside the gate, one reading
    per landmark and scan). ``"jcbb"``: joint compatibility branch and bound over the scan
    (:func:`jcbb`), which respects that every prediction shares the robot's error."""
    gate_probability: float = 0.999
    """The individual (and, for JCBB, joint) χ² gate: ``d² ≤ χ²_m(p)`` (13.8 for ``m = 2``;
    JCBB's ``p`` pairs: ``χ²_{mp}(p)``)."""
    new_landmark_probability: float = 0.99999
    """An unmatched reading starts a feature only if its ``d²`` to EVERY landmark exceeds
    ``χ²_m(new_landmark_probability)`` (23.0 for ``m = 2``); between the two thresholds it
    is rejected rather than allowed to duplicate a landmark it just missed."""
    provisional_trace: float | None = 0.05
    """Provisional feature list [m²]: a new feature is in the state (predicted, tracked and
    associated like any landmark) but its readings update only the feature itself — the
    Schmidt (consider) update, so the robot and the map are untouched — until it is known
    well enough: the trace of its *measurement-only* covariance ``(Σₖ H_kᵀ R⁻¹ H_k)⁻¹``
    (``H_k = ∂h/∂m`` of each of its readings; the covariance it would have if the robot's
    poses at its sightings were known) falls below this; then it joins the map. One reading
    at range ``r`` gives ``L_z R L_zᵀ``, trace ``σ_r² + r² σ_b²`` (0.041 m² at 5 m,
    0.054 m² at 6 m with σ_r = 0.1 m, σ_b = 2°), so the default confirms a feature at its
    second sighting, or first within 5 m — a single reading is never enough, as the test
    runs after an update. Not the marginal ``Σ_ff``, which can never fall below the robot's
    own position variance: after some drift no feature would be confirmed and the map would
    stop growing. Not ``Σ_ff`` conditioned on the current pose either: that includes the
    motion noise since the last sighting, and with 0.5 s control steps (``landmark-loop``,
    ``dt=0.5``, seed 2) 15 of 40 features stayed provisional to the end. ``None``: features join
    the map at their first reading."""
    max_misses: int | None = 3
    """A provisional feature predicted inside the sensor's field of view and range (with a
    3σ margin) but not matched in this many consecutive scans is removed from the state
    (clutter, a spurious reading). ``None``: never."""
    max_misses_confirmed: int | None = None
    """The same for confirmed landmarks (``None``, the default: a confirmed landmark is
    kept — real landmarks are occluded, and removing one throws away its correlations)."""
    min_range: float = 0.0
    """Readings that place their landmark closer than this to the sensor [m] are skipped
    (a range-bearing EKF linearisation is wrong within a few σ_range of the sensor)."""
    jcbb_max_nodes: int = 20_000
    """Node budget of one JCBB search; when exhausted the best hypothesis so far is used and
    ``jcbb_incomplete`` counts it."""
    initial_capacity: int = 32
    """Landmarks the state buffers hold before their first doubling."""
    check_every: int | None = None
    """Every this many time steps a full Cholesky test of the whole covariance (``O(n³)``).
    The cheap checks (positive innovation covariance, finite gain, non-negative diagonal)
    run on every update regardless. ``None``: only the cheap checks."""
    record_innovations: bool = True
    """Keep the NIS of every map update in the output's :class:`InnovationLog`."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.motion_noise_scale) and self.motion_noise_scale >= 0):
            raise ConfigError(
                f"motion_noise_scale: expected a number >= 0, got {self.motion_noise_scale}"
            )
        if not (math.isfinite(self.measurement_noise_scale) and self.measurement_noise_scale > 0):
            raise ConfigError(
                f"measurement_noise_scale: expected a number > 0, got "
                f"{self.measurement_noise_scale}"
            )
        if self.association not in ("nn", "jcbb"):
            raise ConfigError(f"association: expected 'nn' or 'jcbb', got {self.association!r}")
        association_probabilities(self.gate_probability, self.new_landmark_probability)
        t = self.provisional_trace
        if t is not None and not (math.isfinite(t) and t > 0):
            raise ConfigError(f"provisional_trace: expected a number > 0 or None, got {t}")
        for name in ("max_misses", "max_misses_confirmed", "check_every"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1 or None, got {v!r}")
        if not (math.isfinite(self.min_range) and self.min_range >= 0):
            raise ConfigError(f"min_range: expected a number >= 0, got {self.min_range}")
        for name in ("jcbb_max_nodes", "initial_capacity"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")


def scan_readings(
    event: LandmarkReadings, m: int, use_ids: bool
) -> tuple[FloatArray, NDArray[np.int64]]:
    """A scan's readings ``(K, m)``, checked (shape, finite), and the ids to use: the
    event's, or all ``-1`` when ids are not used."""
    z = np.asarray(event.z, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] != m:
        raise ShapeError(f"readings at t={event.t}: expected shape (K, {m}), got {z.shape}")
    if not np.isfinite(z).all():
        raise NonFiniteError(f"readings at t={event.t}: NaN or inf values")
    if not use_ids:
        return z, np.full(z.shape[0], -1, dtype=np.int64)
    return z, np.asarray(event.ids, dtype=np.int64)


_COUNTS = (
    "predictions",
    "readings",
    "updates",
    "provisional_updates",
    "new_features",
    "promoted",
    "removed_provisional",
    "removed_confirmed",
    "rejected",
    "too_close",
    "degenerate",
    "jcbb_searches",
    "jcbb_nodes",
    "jcbb_incomplete",
)


class EkfSlam:
    """EKF-SLAM with point landmarks, as an estimator of the pipeline.

    Controls (or consecutive odometry poses) drive :func:`slam_predict`; each
    :class:`~slamkit.datasets.LandmarkReadings` event is one scan, handled in this order:

    1. **Association** at the state before the scan. Readings with an id (and
       ``use_ids``) go to that landmark, or start it. The others are compared with every
       landmark (confirmed and provisional) by ``d² = νᵀ S⁻¹ ν`` and paired by nearest
       neighbour or JCBB (``association``); an unpaired reading starts a feature if
       ``d² > χ²_m(new_landmark_probability)`` for every landmark, else it is rejected.
       Innovations are wrapped, so a landmark read at bearing ``+π − ε`` and ``−π + ε``
       (straight behind) is one landmark, not two.
    2. **Updates**, one reading at a time, each linearised at the state the previous one
       left: a confirmed landmark's reading updates the whole state (5-column Joseph
       update), a provisional feature's only the feature (Schmidt update, see
       :attr:`EkfSlamConfig.provisional_trace`), after which the feature is promoted if its
       measurement-only covariance is small enough.
    3. **New features** from their first reading (:func:`slam_add_landmark` on the buffers),
       provisional unless ``provisional_trace`` is ``None``. Readings with an id keep it;
       without ids the filter numbers its features from :data:`OWN_ID_BASE`.
    4. **Removal**: a feature predicted well inside the field of view and range (3σ margin,
       at the state before the scan) but not matched counts a miss; after
       ``max_misses`` consecutive misses a provisional feature is removed
       (``max_misses_confirmed`` for confirmed ones). Removing marginalises the feature out
       of the Gaussian: its rows and columns are dropped.

    The prior is the data set's (``initial_pose``, ``initial_cov``); without one the map
    frame is the start pose, known exactly. :meth:`finish` returns the confirmed
    landmarks with their marginal covariances and the diagnostics: counts (see
    ``_COUNTS``), ``n_landmarks``, ``n_provisional``, NIS statistics of the map updates
    (``mean_nis``, ``mean_nis_per_dof``, ``nis_above_95``: fraction above
    ``χ²_m(0.95)``, about 0.05 for a consistent filter) and of the provisional ones.

    Divergence — a non-finite state, an innovation covariance that is not positive
    definite, a negative variance, or (every ``check_every`` steps) a covariance that fails
    a Cholesky test — raises :class:`~slamkit.errors.ConvergenceError` with the step (the
    runner's numbering: one step per distinct time stamp).
    """

    name = "EKF-SLAM"

    def __init__(self, dataset: Dataset, config: EkfSlamConfig, rng: np.random.Generator) -> None:
        if dataset.motion is None or dataset.landmark_sensor is None:
            missing = [
                what
                for what, value in (
                    ("a motion model", dataset.motion),
                    ("a landmark sensor", dataset.landmark_sensor),
                )
                if value is None
            ]
            raise InputError(f"ekf-slam needs {' and '.join(missing)}; {dataset.name} has none")
        sensor = dataset.landmark_sensor
        meas = sensor.model()
        if not isinstance(meas, InvertibleLandmarkModel):
            raise InputError(
                f"ekf-slam cannot use the {sensor.kind!r} sensor of {dataset.name}: one reading "
                "does not locate a landmark (use range-bearing or position readings)"
            )
        self._config = config
        self._motion = dataset.motion.model
        self._Q = config.motion_noise_scale * dataset.motion.noise_cov
        self._meas: InvertibleLandmarkModel = meas
        self._model: LandmarkModel = sensor.model()
        self._R = as_covariance(config.measurement_noise_scale * sensor.noise_cov, "R", None)
        self._m = int(self._R.shape[0])
        self._angular = angular_indices(self._model)
        self._sensor = sensor
        self._gate = chi2_gate(self._m, config.gate_probability)
        self._new_gate = chi2_gate(self._m, config.new_landmark_probability)
        self._use_ids = config.use_ids and sensor.identities

        cap = config.initial_capacity
        self._mean_buf = np.zeros(3 + 2 * cap)
        self._cov_buf = np.zeros((3 + 2 * cap, 3 + 2 * cap))
        self._ids = np.zeros(cap, dtype=np.int64)
        self._provisional = np.zeros(cap, dtype=bool)
        self._misses = np.zeros(cap, dtype=np.int64)
        self._info = np.zeros((cap, 2, 2))  # Σ H_jᵀ R⁻¹ H_j of each feature's readings
        self._R_inv = np.linalg.inv(self._R)
        self._L = 0
        self._scratch = np.empty(_SCRATCH_BYTES // 8)
        if dataset.initial_pose is not None:
            self._mean_buf[:3] = dataset.initial_pose
            if dataset.initial_cov is not None:
                self._cov_buf[:3, :3] = dataset.initial_cov
        self._slot_of: dict[int, int] = {}  # landmark id -> index in the state
        self._next_id = OWN_ID_BASE
        self._last_odometry: FloatArray | None = None
        self._clock = StepClock()
        self._counts = dict.fromkeys(_COUNTS, 0)
        self._log_t: list[float] = []
        self._log_id: list[int] = []
        self._log_status: list[int] = []
        self._nis_t: list[float] = []
        self._nis: list[float] = []
        self._nis_id: list[int] = []
        self._nis_provisional: list[float] = []

    # -- views of the state ---------------------------------------------------------------

    @property
    def _n(self) -> int:
        return 3 + 2 * self._L

    def _views(self) -> tuple[FloatArray, FloatArray]:
        n = self._n
        return self._mean_buf[:n], self._cov_buf[:n, :n]

    @property
    def mean(self) -> FloatArray:
        """A copy of the state mean ``(3 + 2L,)`` (pose, then landmarks in state order)."""
        return self._mean_buf[: self._n].copy()

    @property
    def cov(self) -> FloatArray:
        """A copy of the full covariance ``(n, n)``."""
        n = self._n
        return self._cov_buf[:n, :n].copy()

    @property
    def landmark_ids(self) -> NDArray[np.int64]:
        """Ids of the landmarks in state order (confirmed and provisional)."""
        return self._ids[: self._L].copy()

    @property
    def provisional(self) -> NDArray[np.bool_]:
        """Which landmarks (state order) are still provisional."""
        return self._provisional[: self._L].copy()

    @property
    def capacity(self) -> int:
        """Landmarks the buffers hold before the next doubling."""
        return int(self._ids.size)

    def belief(self) -> SlamBelief:
        """The current belief (all landmarks, provisional ones included) as a value."""
        return SlamBelief(self.mean, self.cov, self.landmark_ids)

    # -- Estimator protocol ---------------------------------------------------------------

    def handle(self, event: Event) -> None:
        step = self._clock.tick(event.t)
        with self._clock.numbering("ekf-slam", event.t):
            if isinstance(event, Control):
                self._predict(event.u, event.dt)
            elif isinstance(event, Odometry):
                if self._last_odometry is not None:
                    self._predict(odometry_control(self._last_odometry, event.pose), 0.0)
                self._last_odometry = event.pose
            elif isinstance(event, LandmarkReadings):
                self._scan(event)
            if self._config.check_every is not None and step % self._config.check_every == 0:
                check_covariance(self._views()[1], "ekf-slam")

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(self._mean_buf[:3].copy(), self._cov_buf[:3, :3].copy())

    def reading_log(self) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """Every reading handled so far: ``(times, landmark ids, status)``; the id of the
        landmark the reading updated or started (``-1`` if none), status codes
        :data:`UPDATED`, :data:`TRACKED`, :data:`INITIALISED`, :data:`DISCARDED`,
        :data:`TOO_CLOSE`."""
        return (
            np.asarray(self._log_t, dtype=np.float64),
            np.asarray(self._log_id, dtype=np.int64),
            np.asarray(self._log_status, dtype=np.int64),
        )

    def landmark_estimate(self) -> LandmarkEstimate:
        """The confirmed landmarks now, with their marginal covariances ``(M, 2, 2)``."""
        L = self._L
        mean, cov = self._views()
        keep = np.flatnonzero(~self._provisional[:L])
        covs = _diagonal_blocks(cov, L)[keep]
        covs = 0.5 * (covs + np.swapaxes(covs, -1, -2))
        return LandmarkEstimate(
            LandmarkMap(mean[3:].reshape(-1, 2)[keep].copy(), self._ids[:L][keep].copy()), covs
        )

    def finish(self) -> EstimatorOutput:
        L = self._L
        landmarks = self.landmark_estimate()
        keep = np.flatnonzero(~self._provisional[:L])
        nis = np.asarray(self._nis, dtype=float)
        nis_p = np.asarray(self._nis_provisional, dtype=float)
        q95 = chi2_gate(self._m, 0.95)
        diagnostics: dict[str, Any] = dict(self._counts)
        diagnostics.update(
            association="known ids" if self._use_ids else self._config.association,
            n_landmarks=int(keep.size),
            n_provisional=int(L - keep.size),
            state_dim=self._n,
            capacity=self.capacity,
            mean_nis=float(nis.mean()) if nis.size else None,
            mean_nis_per_dof=float(nis.mean()) / self._m if nis.size else None,
            nis_above_95=float(np.mean(nis > q95)) if nis.size else None,
            mean_nis_provisional=float(nis_p.mean()) if nis_p.size else None,
        )
        log = None
        if self._config.record_innovations:
            log = InnovationLog(
                times=np.asarray(self._nis_t, dtype=float),
                nis=nis,
                dof=np.full(nis.size, self._m, dtype=np.int64),
                landmark_ids=np.asarray(self._nis_id, dtype=np.int64),
            )
        return EstimatorOutput(
            landmarks=landmarks,
            diagnostics=diagnostics,
            innovations=log,
            reading_landmarks=np.asarray(self._log_id, dtype=np.int64),
        )

    # -- internals ------------------------------------------------------------------------

    def _predict(self, u: FloatArray, dt: float) -> None:
        mean, cov = self._views()
        _predict_inplace(mean, cov, u, dt, self._motion, self._Q)
        self._counts["predictions"] += 1

    def _ensure_capacity(self, extra: int) -> None:
        """Double the buffers until ``extra`` more landmarks fit (copying the active part)."""
        need = self._L + extra
        cap = self.capacity
        if need <= cap:
            return
        while cap < need:
            cap *= 2
        n, N = self._n, 3 + 2 * cap
        mean_buf = np.zeros(N)
        cov_buf = np.zeros((N, N))
        mean_buf[:n] = self._mean_buf[:n]
        cov_buf[:n, :n] = self._cov_buf[:n, :n]
        self._mean_buf, self._cov_buf = mean_buf, cov_buf
        if self._scratch.size < N:
            self._scratch = np.empty(N)
        for name in ("_ids", "_provisional", "_misses", "_info"):
            old = getattr(self, name)
            new = np.zeros((cap, *old.shape[1:]), dtype=old.dtype)
            new[: self._L] = old[: self._L]
            setattr(self, name, new)

    def _add(self, z: FloatArray, landmark_id: int) -> None:
        self._ensure_capacity(1)
        _add_landmark_inplace(self._mean_buf, self._cov_buf, self._n, z, self._meas, self._R)
        j = self._L
        self._ids[j] = landmark_id
        self._provisional[j] = self._config.provisional_trace is not None
        self._misses[j] = 0
        self._info[j] = 0.0
        self._slot_of[landmark_id] = j
        self._L += 1
        if self._provisional[j]:
            self._add_information(j)
        self._next_id = max(self._next_id, landmark_id + 1)
        self._counts["new_features"] += 1

    def _remove(self, rows: NDArray[np.int64]) -> None:
        """Marginalise the landmarks ``rows`` out: drop their rows and columns."""
        L = self._L
        keep_lm = np.setdiff1d(np.arange(L), rows)
        keep = np.concatenate([np.arange(3), (3 + 2 * keep_lm[:, None] + np.arange(2)).ravel()])
        n = keep.size
        mean, cov = self._views()
        new_mean = mean[keep]
        new_cov = cov[np.ix_(keep, keep)]
        self._mean_buf[:n] = new_mean
        self._cov_buf[:n, :n] = new_cov
        for name in ("_ids", "_provisional", "_misses", "_info"):
            arr = getattr(self, name)
            arr[: keep_lm.size] = arr[keep_lm]
        self._L = int(keep_lm.size)
        self._slot_of = {int(i): j for j, i in enumerate(self._ids[: self._L].tolist())}

    def _log(self, t: float, landmark_id: int, status: int) -> None:
        self._log_t.append(t)
        self._log_id.append(landmark_id)
        self._log_status.append(status)

    def _predictions(
        self, sel: NDArray[np.int64]
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """For the landmarks ``sel`` (state indices) at the current state: ``z_hat (U, m)``,
        the Jacobians ``H_r (U, m, 3)``, ``H_j (U, m, 2)`` and ``S (U, m, m)`` with the
        noise. The landmarks must be off the sensor."""
        U = sel.size
        mean, cov = self._views()
        lm = mean[3:].reshape(-1, 2)[sel]
        pose = np.broadcast_to(mean[:3], (U, 3))
        model = self._model
        if isinstance(model, LandmarkModelBase):
            z_hat, (Hr, Hj) = model.predict_unchecked(pose, lm), model.jacobians_unchecked(pose, lm)
        else:
            z_hat, (Hr, Hj) = model.predict(pose, lm), model.jacobians(pose, lm)
        C = cov[:3, 3:].reshape(3, -1, 2)[:, sel, :].transpose(1, 0, 2)  # Σ_r,j (U, 3, 2)
        B = _diagonal_blocks(cov, self._L)[sel]
        HrT, HjT = np.swapaxes(Hr, -1, -2), np.swapaxes(Hj, -1, -2)
        HC = Hr @ C @ HjT
        S = Hr @ cov[:3, :3] @ HrT + HC + np.swapaxes(HC, -1, -2) + Hj @ B @ HjT + self._R
        return z_hat, Hr, Hj, 0.5 * (S + np.swapaxes(S, -1, -2))

    def _distances(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(d² (K, L), ν (K, L, m))`` of readings against every landmark (``d² = inf``
        for a landmark on the sensor, whose reading and Jacobian are undefined)."""
        K, L = z.shape[0], self._L
        d2 = np.full((K, L), np.inf)
        nu = np.zeros((K, L, self._m))
        if L == 0 or K == 0:
            return d2, nu
        mean = self._mean_buf[: self._n]
        lm = mean[3:].reshape(L, 2)
        sel = np.flatnonzero(np.hypot(lm[:, 0] - mean[0], lm[:, 1] - mean[1]) >= MIN_RANGE)
        if sel.size == 0:
            return d2, nu
        z_hat, _, _, S = self._predictions(sel)
        v = z[:, None, :] - z_hat[None, :, :]  # ν = z ⊖ ẑ, angles wrapped
        for i in self._angular:
            v[..., i] = wrap_angle(v[..., i])
        nu[:, sel, :] = v
        d2[:, sel] = np.einsum("kli,lij,klj->kl", v, np.linalg.inv(S), v)
        return d2, nu

    def _in_view(self, sel: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Which of the landmarks ``sel`` have a predicted range and bearing inside the
        sensor's limits by three standard deviations of the prediction (state uncertainty
        only, no sensor noise): those a scan should have seen."""
        U = sel.size
        mean, cov = self._views()
        lm = mean[3:].reshape(-1, 2)[sel]
        dx, dy = lm[:, 0] - mean[0], lm[:, 1] - mean[1]
        r = np.hypot(dx, dy)
        ok = r >= MIN_RANGE
        rs = np.where(ok, r, 1.0)
        q = rs * rs
        b = wrap_angle(np.arctan2(dy, dx) - mean[2])
        # range-bearing Jacobians of the prediction: landmark, and pose (= −landmark | −e₂)
        Hj = np.empty((U, 2, 2))
        Hj[:, 0, 0], Hj[:, 0, 1] = dx / rs, dy / rs
        Hj[:, 1, 0], Hj[:, 1, 1] = -dy / q, dx / q
        Hr = np.zeros((U, 2, 3))
        Hr[:, :, :2] = -Hj
        Hr[:, 1, 2] = -1.0
        C = cov[:3, 3:].reshape(3, -1, 2)[:, sel, :].transpose(1, 0, 2)  # Σ_r,j (U, 3, 2)
        HC = Hr @ C @ np.swapaxes(Hj, -1, -2)
        B = _diagonal_blocks(cov, self._L)[sel]
        P = (
            Hr @ cov[:3, :3] @ np.swapaxes(Hr, -1, -2)
            + HC
            + np.swapaxes(HC, -1, -2)
            + Hj @ B @ np.swapaxes(Hj, -1, -2)
        )
        sr = 3.0 * np.sqrt(np.clip(P[:, 0, 0], 0.0, None))
        sb = 3.0 * np.sqrt(np.clip(P[:, 1, 1], 0.0, None))
        sensor = self._sensor
        inside = ok & (r + sr <= sensor.max_range) & (r - sr >= sensor.min_range)
        if sensor.fov < 2.0 * np.pi:
            inside &= np.abs(b) + sb <= sensor.fov / 2.0
        return np.asarray(inside)

    def _associate_scan(self, z: FloatArray) -> NDArray[np.int64]:
        """Landmark index per reading, or NEW / REJECTED (codes of ekf_mapping)."""
        K = z.shape[0]
        d2, nu = self._distances(z)
        if self._config.association == "nn" or self._L == 0:
            return _greedy_nearest_neighbour(d2, self._gate, self._new_gate)
        # JCBB over the landmarks individually compatible with some reading.
        cand = np.flatnonzero((d2 <= self._gate).any(axis=0))
        out = np.full(K, REJECTED, dtype=np.int64)
        if cand.size:
            M = self._joint_prediction_cov(cand)
            res = _jcbb(nu[:, cand, :], M, self._R, self._config.gate_probability,
                        self._config.jcbb_max_nodes, d2[:, cand])  # fmt: skip
            self._counts["jcbb_searches"] += 1
            self._counts["jcbb_nodes"] += res.nodes
            self._counts["jcbb_incomplete"] += int(not res.complete)
            hit = res.assignment >= 0
            out[hit] = cand[res.assignment[hit]]
        else:
            hit = np.zeros(K, dtype=bool)
        out[~hit & (d2.min(axis=1, initial=np.inf) > self._new_gate)] = NEW
        return out

    def _joint_prediction_cov(self, cand: NDArray[np.int64]) -> FloatArray:
        """``H Σ Hᵀ (U m × U m)`` of the predicted readings of the landmarks ``cand``."""
        mean, cov = self._views()
        U, m = cand.size, self._m
        idx = np.concatenate([np.arange(3), (3 + 2 * cand[:, None] + np.arange(2)).ravel()])
        sub = cov[np.ix_(idx, idx)]
        J = np.zeros((U * m, idx.size))
        for a, j in enumerate(cand.tolist()):
            _, Hr, Hj = reading_jacobians(self._model, mean[:3], mean[3 + 2 * j : 5 + 2 * j])
            J[a * m : (a + 1) * m, :3] = Hr
            J[a * m : (a + 1) * m, 3 + 2 * a : 5 + 2 * a] = Hj
        M = J @ sub @ J.T
        return 0.5 * (M + M.T)

    def _scan(self, event: LandmarkReadings) -> None:
        z, ids = scan_readings(event, self._m, self._use_ids)
        t = float(event.t)
        K = z.shape[0]
        self._counts["readings"] += K
        usable = np.ones(K, dtype=bool)
        if self._config.min_range > 0 and K:
            x = self._mean_buf[:3]
            d = np.hypot(*(self._meas.inverse(x, z) - x[:2]).T)
            usable = d >= self._config.min_range

        # Landmarks that may be removed (provisional ones, and confirmed ones if configured)
        # and that this scan should see: a miss for each one left unmatched.
        n_before = self._L
        removable = np.zeros(n_before, dtype=bool)
        if self._config.max_misses is not None:
            removable |= self._provisional[:n_before]
        if self._config.max_misses_confirmed is not None:
            removable |= ~self._provisional[:n_before]
        watch = np.flatnonzero(removable)
        in_view = np.zeros(n_before, dtype=bool)
        if watch.size:
            in_view[watch] = self._in_view(watch)
        matched = np.zeros(n_before, dtype=bool)

        # 1. association at the state before the scan
        target = np.full(K, REJECTED, dtype=np.int64)  # landmark index, NEW or REJECTED
        labelled = usable & (ids >= 0)
        for k in np.flatnonzero(labelled).tolist():
            target[k] = self._slot_of.get(int(ids[k]), NEW)
        free = np.flatnonzero(usable & (ids < 0))
        if free.size:
            match = self._associate_scan(z[free])
            if self._use_ids:  # unlabelled readings never start a landmark there
                match = np.where(match == NEW, REJECTED, match)
            target[free] = match

        # 2. updates in reading order; 3. new features
        for k in range(K):
            if not usable[k]:
                self._counts["too_close"] += 1
                self._log(t, -1, TOO_CLOSE)
                continue
            j = int(target[k])
            if j == REJECTED:
                self._counts["rejected"] += 1
                self._log(t, -1, DISCARDED)
                continue
            if j == NEW:
                lid = int(ids[k]) if labelled[k] else self._next_id
                if lid in self._slot_of:  # a repeated new id in one scan: update it instead
                    j = self._slot_of[lid]
                else:
                    self._add(z[k], lid)
                    self._log(t, lid, INITIALISED)
                    continue
            self._update(t, k, j, z[k])
            if j < n_before:
                matched[j] = True

        # 4. features expected but not seen
        if watch.size:
            self._count_misses(in_view, matched, n_before)

    def _update(self, t: float, k: int, j: int, z: FloatArray) -> None:
        mean, cov = self._views()
        lid = int(self._ids[j])
        provisional = bool(self._provisional[j])
        try:
            nis, _, _ = _update_inplace(
                mean, cov, 3 + 2 * j, z, self._model, self._R, self._angular, self._scratch,
                consider=provisional,
            )  # fmt: skip
        except GeometryError:
            self._counts["degenerate"] += 1
            self._log(t, -1, DISCARDED)
            return
        self._misses[j] = 0
        if provisional:
            self._add_information(j)
            self._counts["provisional_updates"] += 1
            self._nis_provisional.append(nis)
            self._log(t, lid, TRACKED)
            self._maybe_promote(j)
            return
        self._check_diagonal(cov)
        self._counts["updates"] += 1
        self._log(t, lid, UPDATED)
        if self._config.record_innovations:
            self._nis_t.append(t)
            self._nis.append(nis)
            self._nis_id.append(lid)

    def _check_diagonal(self, cov: FloatArray) -> None:
        d = np.diagonal(cov)
        low = float(d.min())
        if low < -1e-9 * max(float(d.max()), 1e-300):
            i = int(np.argmin(d))
            raise ConvergenceError(
                f"the covariance lost positive definiteness (variance {low:.3g} at state index {i})"
            )

    def _add_information(self, j: int) -> None:
        """Add one reading's information about feature ``j``, ``H_jᵀ R⁻¹ H_j`` (``H_j`` the
        reading's Jacobian with respect to the landmark, at the current estimate)."""
        mean = self._mean_buf
        s = 3 + 2 * j
        try:
            _, _, Hj = reading_jacobians(self._model, mean[:3], mean[s : s + 2])
        except GeometryError:
            return
        self._info[j] += Hj.T @ self._R_inv @ Hj

    def _maybe_promote(self, j: int) -> None:
        """Confirm feature ``j`` once the trace of its measurement-only covariance
        ``(Σ H_jᵀ R⁻¹ H_j)⁻¹`` is below the threshold (see
        :attr:`EkfSlamConfig.provisional_trace`)."""
        threshold = self._config.provisional_trace
        assert threshold is not None
        (a, b), (c, d) = self._info[j].tolist()
        det = a * d - b * c
        if det > 0.0 and (a + d) / det < threshold:  # trace of the 2 × 2 inverse
            self._provisional[j] = False
            self._counts["promoted"] += 1

    def _count_misses(
        self, in_view: NDArray[np.bool_], matched: NDArray[np.bool_], n_before: int
    ) -> None:
        L = self._L
        seen_or_away = matched | ~in_view
        missed = np.flatnonzero(~seen_or_away)
        self._misses[missed] += 1
        limit_p = self._config.max_misses
        limit_c = self._config.max_misses_confirmed
        prov = self._provisional[:n_before]
        drop = np.zeros(L, dtype=bool)
        if limit_p is not None:
            drop[:n_before] |= prov & (self._misses[:n_before] >= limit_p)
        if limit_c is not None:
            drop[:n_before] |= ~prov & (self._misses[:n_before] >= limit_c)
        rows = np.flatnonzero(drop)
        if rows.size:
            n_prov = int(np.count_nonzero(self._provisional[rows]))
            self._counts["removed_provisional"] += n_prov
            self._counts["removed_confirmed"] += int(rows.size) - n_prov
            self._remove(rows)
