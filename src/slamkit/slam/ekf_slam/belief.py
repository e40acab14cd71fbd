"""The EKF-SLAM belief as a value, and the validated functional core over it.

Each function checks its arguments, copies the belief and runs the in-place kernel of
:mod:`~slamkit.slam.ekf_slam.state` or :mod:`~slamkit.slam.ekf_slam.update` on the copy;
:func:`dense_slam_predict` and :func:`dense_slam_update` are the textbook full-matrix forms
the kernels are tested against. The maths is in :mod:`slamkit.slam.ekf_slam`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import InputError, ShapeError
from slamkit.estimation.gaussian import angular_indices
from slamkit.estimation.kalman import UpdateInfo
from slamkit.geometry.angles import wrap_angle_float
from slamkit.models import LandmarkModel, MotionModel
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.slam.ekf_slam.state import add_landmark_inplace, diagonal_blocks, predict_inplace
from slamkit.slam.ekf_slam.update import SCRATCH_BYTES, update_inplace

__all__ = [
    "SlamBelief",
    "dense_slam_predict",
    "dense_slam_update",
    "slam_add_landmark",
    "slam_predict",
    "slam_update",
]


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
        return diagonal_blocks(self.cov, len(self))


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
    predict_inplace(mean, cov, ua, float(dt), model, Q)
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
    scratch = np.empty(max(SCRATCH_BYTES // 8, mean.size))
    nis, nu, S = update_inplace(
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
    add_landmark_inplace(mean, cov, n, za, inv, Ra)
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
