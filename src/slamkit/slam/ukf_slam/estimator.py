"""The UKF-SLAM estimator of the pipeline (:class:`UkfSlam`): EKF-SLAM's shell with the
unscented kernels (:mod:`~slamkit.slam.ukf_slam.kernels`)."""

from __future__ import annotations

from slamkit.localization.ukf import SigmaPointParams
from slamkit.slam.ekf_slam.config import EkfSlamConfig
from slamkit.slam.ekf_slam.estimator import EkfSlam
from slamkit.slam.ekf_slam.kernels import EkfKernels, SlamKernels
from slamkit.slam.ukf_slam.config import UkfSlamConfig
from slamkit.slam.ukf_slam.kernels import UnscentedKernels

__all__ = ["UkfSlam"]


class UkfSlam(EkfSlam):
    """UKF-SLAM with point landmarks, as an estimator of the pipeline.

    Everything but the three model-dependent steps is :class:`~slamkit.slam.ekf_slam.
    EkfSlam`'s — events, known ids or association by nearest neighbour or JCBB (its
    Mahalanobis distances from the analytic Jacobians at the current mean), the provisional
    list, removal, the covariance checks, the output and its diagnostics — so the two are
    compared on their Gaussian approximation alone. The prediction, the update and a new
    landmark's initialisation are the unscented transforms of
    :class:`~slamkit.slam.ukf_slam.UnscentedKernels`, configured by :class:`UkfSlamConfig`.
    """

    name = "UKF-SLAM"
    key = "ukf-slam"

    def make_kernels(self, config: EkfSlamConfig, ekf: EkfKernels) -> SlamKernels:
        # an EkfSlamConfig (no sigma-point table) runs with the default sigma points
        p = config.sigma_points if isinstance(config, UkfSlamConfig) else SigmaPointParams()
        return UnscentedKernels(ekf.motion, ekf.Q, ekf.model, ekf.inverse, ekf.R, ekf.angular, p)
