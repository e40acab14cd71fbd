"""Motion, landmark-measurement and laser models with analytic Jacobians."""

from slamkit.models.ackermann import Ackermann
from slamkit.models.laser import LaserScanner, cast_rays_grid, cast_rays_segments
from slamkit.models.measurement import (
    MIN_RANGE,
    BearingOnly,
    InvertibleLandmarkModel,
    LandmarkModel,
    LandmarkModelBase,
    RangeBearing,
    RangeOnly,
    RelativePosition,
    landmark_initial_covariance,
)
from slamkit.models.motion import (
    DifferentialDrive,
    MotionModel,
    MotionModelBase,
    OdometryModel,
    UnicycleArc,
    UnicycleEuler,
    integrate_odometry,
    motion_kernels,
    odometry_control,
    odometry_noise_cov,
    propagate_gaussian,
    propagate_gaussian_unchecked,
    signed_odometry_steps,
)

__all__ = [
    "MIN_RANGE",
    "Ackermann",
    "BearingOnly",
    "DifferentialDrive",
    "InvertibleLandmarkModel",
    "LandmarkModel",
    "LandmarkModelBase",
    "LaserScanner",
    "MotionModel",
    "MotionModelBase",
    "OdometryModel",
    "RangeBearing",
    "RangeOnly",
    "RelativePosition",
    "UnicycleArc",
    "UnicycleEuler",
    "cast_rays_grid",
    "cast_rays_segments",
    "integrate_odometry",
    "landmark_initial_covariance",
    "motion_kernels",
    "odometry_control",
    "odometry_noise_cov",
    "propagate_gaussian",
    "propagate_gaussian_unchecked",
    "signed_odometry_steps",
]
