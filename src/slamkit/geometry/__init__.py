"""Geometry: angles, SE(2) pose arrays, Lie groups, point-set alignment, smoothing."""

from slamkit.geometry import pose2
from slamkit.geometry.angles import angle_diff, circular_mean, pose_mean, wrap_angle

__all__ = ["angle_diff", "circular_mean", "pose2", "pose_mean", "wrap_angle"]
