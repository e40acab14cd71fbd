"""The Gaussian kernels of a pose + landmark-map filter, as one object the estimator holds.

:class:`~slamkit.slam.ekf_slam.EkfSlam` does its association, provisional list, removal and
bookkeeping the same way whatever approximates the non-linear models; only three steps
depend on it — the prediction, the update with one reading and the initialisation of a new
landmark. They are the methods of :class:`SlamKernels`: :class:`EkfKernels` linearises
with the analytic Jacobians, :class:`~slamkit.slam.ukf_slam.UnscentedKernels` uses sigma
points. The choice is made once, when the estimator is built, and passed down as this
object.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from slamkit._validation import FloatArray
from slamkit.models import LandmarkModel, MotionModel
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.slam.ekf_slam.state import add_landmark_inplace, predict_inplace
from slamkit.slam.ekf_slam.update import update_inplace

__all__ = ["EkfKernels", "SlamKernels"]


class SlamKernels(Protocol):
    """The three model-dependent steps of a pose + map Gaussian filter, in place on views
    of the active state (mean ``(n,)``, covariance ``(n, n)``, pose first)."""

    def predict(self, mean: FloatArray, cov: FloatArray, u: FloatArray, dt: float) -> None:
        """Move the pose with control ``u`` over ``dt`` seconds; the map does not move."""
        ...

    def update(
        self,
        mean: FloatArray,
        cov: FloatArray,
        slot: int,
        z: FloatArray,
        scratch: FloatArray,
        consider: bool,
    ) -> float:
        """Update with reading ``z`` of the landmark in rows ``slot, slot + 1``; returns the
        NIS. ``consider``: the Schmidt update of a provisional feature (only its rows move).
        A landmark on the sensor raises :class:`~slamkit.errors.GeometryError`."""
        ...

    def add(self, mean_buf: FloatArray, cov_buf: FloatArray, n: int, z: FloatArray) -> None:
        """Write the landmark first read at ``z`` into rows and columns ``n, n + 1`` of the
        buffers, with its cross-covariance with the first ``n`` entries."""
        ...


@dataclass(frozen=True)
class EkfKernels:
    """EKF-SLAM's kernels: the analytic Jacobians (:func:`~slamkit.slam.ekf_slam.state.
    predict_inplace`, :func:`~slamkit.slam.ekf_slam.update.update_inplace`,
    :func:`~slamkit.slam.ekf_slam.state.add_landmark_inplace`)."""

    motion: MotionModel
    Q: FloatArray
    """Control-noise covariance."""
    model: LandmarkModel
    inverse: InvertibleLandmarkModel
    """The same sensor model, seen through its inverse (a new landmark from one reading)."""
    R: FloatArray
    """Reading-noise covariance."""
    angular: tuple[int, ...]
    """Indices of the reading's angular components."""

    def predict(self, mean: FloatArray, cov: FloatArray, u: FloatArray, dt: float) -> None:
        predict_inplace(mean, cov, u, dt, self.motion, self.Q)

    def update(
        self,
        mean: FloatArray,
        cov: FloatArray,
        slot: int,
        z: FloatArray,
        scratch: FloatArray,
        consider: bool,
    ) -> float:
        nis, _, _ = update_inplace(
            mean, cov, slot, z, self.model, self.R, self.angular, scratch, consider=consider
        )
        return nis

    def add(self, mean_buf: FloatArray, cov_buf: FloatArray, n: int, z: FloatArray) -> None:
        add_landmark_inplace(mean_buf, cov_buf, n, z, self.inverse, self.R)
