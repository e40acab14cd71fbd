"""Simultaneous localization and mapping: estimators of the robot's path and a map at once.

* :mod:`slamkit.slam.ekf_slam` — EKF-SLAM over the pose and point landmarks (full
  covariance, 5-column updates, nearest-neighbour or JCBB association, provisional features).
* :mod:`slamkit.slam.ukf_slam` — UKF-SLAM: EKF-SLAM's state and association with unscented
  prediction, updates and landmark initialisation.
* :mod:`slamkit.slam.fastslam` — FastSLAM 1.0 and 2.0: particles over paths, a 2×2 EKF per
  landmark and particle, per-particle association, vectorised over particles.
* :mod:`slamkit.slam.seif` — SEIF SLAM: information form, bounded active landmarks,
  sparsification, amortised mean recovery (known correspondences).
"""

from slamkit.slam.ekf_slam import (
    EkfSlam,
    EkfSlamConfig,
    JcbbResult,
    SlamBelief,
    dense_slam_predict,
    dense_slam_update,
    jcbb,
    slam_add_landmark,
    slam_predict,
    slam_update,
)
from slamkit.slam.fastslam import (
    FastSlam1,
    FastSlam2,
    FastSlamConfig,
    FastSlamParticles,
    fastslam1_update,
    fastslam2_update,
    fastslam_predict,
    fastslam_resample,
)
from slamkit.slam.seif import Seif, SeifConfig
from slamkit.slam.ukf_slam import UkfSlam, UkfSlamConfig

__all__ = [
    "EkfSlam",
    "EkfSlamConfig",
    "FastSlam1",
    "FastSlam2",
    "FastSlamConfig",
    "FastSlamParticles",
    "JcbbResult",
    "Seif",
    "SeifConfig",
    "SlamBelief",
    "UkfSlam",
    "UkfSlamConfig",
    "dense_slam_predict",
    "dense_slam_update",
    "fastslam1_update",
    "fastslam2_update",
    "fastslam_predict",
    "fastslam_resample",
    "jcbb",
    "slam_add_landmark",
    "slam_predict",
    "slam_update",
]
