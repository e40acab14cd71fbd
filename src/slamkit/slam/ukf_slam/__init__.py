"""UKF-SLAM: the robot pose and a map of point landmarks in one Gaussian, propagated by the
unscented transform instead of Jacobians.

The state, its buffers, data association (known ids, nearest neighbour, JCBB), the
provisional feature list and removal are EKF-SLAM's (:mod:`slamkit.slam.ekf_slam`); the
estimator is :class:`~slamkit.slam.ekf_slam.EkfSlam` holding other kernels
(:class:`~slamkit.slam.ekf_slam.kernels.SlamKernels`). The derivation of the three
unscented steps — sigma points over the pose and the noise for the prediction, over the
pose and the one landmark for an update, over the pose and the reading for a new landmark,
each carried to the whole map by the conditional Gaussian ``Cov(y, r) = Cov(y, s) Σ_ss⁺
Σ_sr`` — and their cost per step are in :mod:`slamkit.slam.ukf_slam.kernels`; the measured
comparison with EKF-SLAM in ``docs/estimators/ukf_slam.md``.

* :mod:`~slamkit.slam.ukf_slam.kernels` — :class:`UnscentedKernels`, :func:`regress`;
* :mod:`~slamkit.slam.ukf_slam.config` — :class:`UkfSlamConfig`;
* :mod:`~slamkit.slam.ukf_slam.estimator` — :class:`UkfSlam`.
"""

from slamkit.slam.ukf_slam.config import UkfSlamConfig
from slamkit.slam.ukf_slam.estimator import UkfSlam
from slamkit.slam.ukf_slam.kernels import UnscentedKernels, regress

__all__ = ["UkfSlam", "UkfSlamConfig", "UnscentedKernels", "regress"]
