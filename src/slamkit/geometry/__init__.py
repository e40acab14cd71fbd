"""Geometry: angles, SE(2) pose arrays, Lie groups, point-set alignment, smoothing."""

from slamkit.geometry import alignment, pose2, smoothing
from slamkit.geometry.alignment import Similarity, align_points, align_points_2d
from slamkit.geometry.angles import angle_diff, circular_mean, pose_mean, wrap_angle
from slamkit.geometry.smoothing import smooth_points, smooth_poses

__all__ = [
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
