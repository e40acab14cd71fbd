"""The EKF-SLAM state in preallocated buffers, and the kernels that work on it in place.

The state ``x = (x_r, m_1, …, m_L)``, ``n = 3 + 2L``, and its covariance ``Σ (n × n)`` live
in the leading part of buffers whose capacity doubles when full (:class:`SlamState`), so
adding a landmark writes two rows and two columns, ``O(n)``, and removing one copies the
kept rows and columns down. The kernels take views of the active part and trust their
caller (validated at the public entry points of :mod:`slamkit.slam.ekf_slam.belief`).

Prediction (:func:`predict_inplace`): landmarks do not move, so with ``G = ∂g/∂x_r``,
``V = ∂g/∂u`` and the control noise ``Q``::

    x_r ← g(x_r, u, dt)
    Σ_rr ← G Σ_rr Gᵀ + V Q Vᵀ            (3 × 3)
    Σ_rm ← G Σ_rm,  Σ_mr = Σ_rmᵀ          (3 × 2L)

A new landmark (:func:`add_landmark_inplace`) from its first reading by the inverse model
``m = g⁻¹(x_r, z)`` with ``L_x = ∂m/∂x_r``, ``L_z = ∂m/∂z``: to first order
``δm = L_x δx_r + L_z δz``, so ``Σ_mm = L_x Σ_rr L_xᵀ + L_z R L_zᵀ`` and
``Σ_m,: = L_x Σ_r,:`` (cross with the WHOLE state).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError
from slamkit.models import MotionModel
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.models.motion import motion_kernels
from slamkit.slam.ekf_slam.update import SCRATCH_BYTES

__all__ = [
    "LandmarkWriter",
    "SlamState",
    "add_landmark_inplace",
    "diagonal_blocks",
    "predict_inplace",
]


def diagonal_blocks(cov: FloatArray, L: int) -> FloatArray:
    """The ``(L, 2, 2)`` landmark blocks on the diagonal of a SLAM covariance (copies)."""
    idx = 3 + 2 * np.arange(L)
    out = np.empty((L, 2, 2))
    out[:, 0, 0] = cov[idx, idx]
    out[:, 0, 1] = cov[idx, idx + 1]
    out[:, 1, 0] = cov[idx + 1, idx]
    out[:, 1, 1] = cov[idx + 1, idx + 1]
    return out


def predict_inplace(
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


def add_landmark_inplace(
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


LandmarkWriter = Callable[[FloatArray, FloatArray, int, FloatArray], None]
"""``write(mean_buf, cov_buf, n, z)``: put the landmark first read at ``z`` into rows and
columns ``n, n + 1`` of the buffers, with its cross-covariances with the first ``n`` entries."""

_PER_LANDMARK = ("ids", "provisional", "misses", "info")


class SlamState:
    """The mean and covariance buffers of EKF-SLAM and what it keeps per landmark, all in
    state order: ``ids``, ``provisional`` (still on the provisional list), ``misses``
    (consecutive scans that should have seen it and did not) and ``info``
    (``Σ H_jᵀ R⁻¹ H_j`` of its readings). Only the first :attr:`n_landmarks` rows (the first
    :attr:`n` entries of the mean) are in use; the estimator owns it and mutates it."""

    def __init__(self, capacity: int, pose: FloatArray | None, cov: FloatArray | None) -> None:
        self.mean_buf = np.zeros(3 + 2 * capacity)
        self.cov_buf = np.zeros((3 + 2 * capacity, 3 + 2 * capacity))
        self.ids = np.zeros(capacity, dtype=np.int64)
        self.provisional = np.zeros(capacity, dtype=bool)
        self.misses = np.zeros(capacity, dtype=np.int64)
        self.info = np.zeros((capacity, 2, 2))  # Σ H_jᵀ R⁻¹ H_j of each feature's readings
        self.n_landmarks = 0
        self.scratch = np.empty(SCRATCH_BYTES // 8)
        if pose is not None:
            self.mean_buf[:3] = pose
            if cov is not None:
                self.cov_buf[:3, :3] = cov
        self.slot_of: dict[int, int] = {}  # landmark id -> index in the state

    @property
    def n(self) -> int:
        """Entries of the state in use, ``3 + 2L``."""
        return 3 + 2 * self.n_landmarks

    @property
    def capacity(self) -> int:
        """Landmarks the buffers hold before the next doubling."""
        return int(self.ids.size)

    def views(self) -> tuple[FloatArray, FloatArray]:
        """Views of the active mean ``(n,)`` and covariance ``(n, n)`` (writable)."""
        n = self.n
        return self.mean_buf[:n], self.cov_buf[:n, :n]

    def ensure_capacity(self, extra: int) -> None:
        """Double the buffers until ``extra`` more landmarks fit (copying the active part)."""
        need = self.n_landmarks + extra
        cap = self.capacity
        if need <= cap:
            return
        while cap < need:
            cap *= 2
        n, N = self.n, 3 + 2 * cap
        mean_buf = np.zeros(N)
        cov_buf = np.zeros((N, N))
        mean_buf[:n] = self.mean_buf[:n]
        cov_buf[:n, :n] = self.cov_buf[:n, :n]
        self.mean_buf, self.cov_buf = mean_buf, cov_buf
        if self.scratch.size < N:
            self.scratch = np.empty(N)
        for name in _PER_LANDMARK:
            old = getattr(self, name)
            new = np.zeros((cap, *old.shape[1:]), dtype=old.dtype)
            new[: self.n_landmarks] = old[: self.n_landmarks]
            setattr(self, name, new)

    def add(
        self,
        z: FloatArray,
        landmark_id: int,
        write: LandmarkWriter,
        provisional: bool,
    ) -> int:
        """Append the landmark first read at ``z``, its mean and covariance written by
        ``write`` (:func:`add_landmark_inplace`'s signature without the model and noise);
        returns its index in the state."""
        self.ensure_capacity(1)
        write(self.mean_buf, self.cov_buf, self.n, z)
        j = self.n_landmarks
        self.ids[j] = landmark_id
        self.provisional[j] = provisional
        self.misses[j] = 0
        self.info[j] = 0.0
        self.slot_of[landmark_id] = j
        self.n_landmarks += 1
        return j

    def remove(self, rows: NDArray[np.int64]) -> None:
        """Marginalise the landmarks ``rows`` out: drop their rows and columns."""
        L = self.n_landmarks
        keep_lm = np.setdiff1d(np.arange(L), rows)
        keep = np.concatenate([np.arange(3), (3 + 2 * keep_lm[:, None] + np.arange(2)).ravel()])
        n = keep.size
        mean, cov = self.views()
        new_mean = mean[keep]
        new_cov = cov[np.ix_(keep, keep)]
        self.mean_buf[:n] = new_mean
        self.cov_buf[:n, :n] = new_cov
        for name in _PER_LANDMARK:
            arr = getattr(self, name)
            arr[: keep_lm.size] = arr[keep_lm]
        self.n_landmarks = int(keep_lm.size)
        self.slot_of = {int(i): j for j, i in enumerate(self.ids[: self.n_landmarks].tolist())}
