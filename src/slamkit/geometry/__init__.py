"""Geometry: angles, SE(2) pose arrays, Lie groups, point-set alignment, smoothing."""

from slamkit.geometry import alignment, pose2, smoothing
from slamkit.geometry._lie import UNIT_NORM_TOL, LieGroup
from slamkit.geometry.alignment import Similarity, align_points, align_points_2d
from slamkit.geometry.angles import angle_diff, circular_mean, pose_mean, wrap_angle
from slamkit.geometry.se2 import SE2
from slamkit.geometry.se3 import SE3
from slamkit.geometry.smoothing import smooth_points, smooth_poses
from slamkit.geometry.so2 import SO2
from slamkit.geometry.so3 import SO3

__all__ = [
    "SE2",
    "SE3",
    "SO2",
    "SO3",
    "UNIT_NORM_TOL",
    "LieGroup",
    "Similarity",
    "align_points",
    "align_points_2d",
    "alignment",
    "angle_diff",
    "circular_mean",
    "pose2",
    "pose_mean",
    "smooth_points",
    "smooth_poses",
    "smoothing",
    "wrap_angle",
]
