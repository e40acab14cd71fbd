"""Settings of UKF-SLAM (:class:`UkfSlamConfig`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from slamkit.localization.ukf import SigmaPointParams
from slamkit.slam.ekf_slam.config import EkfSlamConfig

__all__ = ["UkfSlamConfig"]


@dataclass(frozen=True)
class UkfSlamConfig(EkfSlamConfig):
    """Settings of :class:`~slamkit.slam.ukf_slam.UkfSlam`: those of EKF-SLAM (association,
    provisional list, removal, checks; the same meaning and defaults) plus the sigma
    points."""

    sigma_points: SigmaPointParams = field(default_factory=SigmaPointParams)
    """α, β, κ of the scaled sigma points (a ``[estimator.sigma_points]`` table in a file);
    the same set serves the prediction (pose and control noise), the update (pose and one
    landmark) and a new landmark (pose and reading)."""
