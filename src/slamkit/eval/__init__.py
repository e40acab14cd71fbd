"""Evaluation: trajectory accuracy (ATE, RPE), filter consistency (NEES/NIS) and landmark-map
accuracy. Numerics only; plotting lives in :mod:`slamkit.viz`."""

from slamkit.eval.consistency import (
    ConsistencyReport,
    chi2_bounds,
    consistency_report,
    nees,
    nis,
)
from slamkit.eval.gps import GpsError, GpsOutliers, GpsScoreConfig, gps_error, gps_outliers
from slamkit.eval.innovations import NisSummary, nis_summary
from slamkit.eval.landmarks import LandmarkError, landmark_map_error
from slamkit.eval.trajectory import (
    AlignMode,
    RelativeError,
    RpeUnit,
    TrajectoryError,
    absolute_trajectory_error,
    associate,
    pose_errors,
    relative_pose_error,
)

__all__ = [
    "AlignMode",
    "ConsistencyReport",
    "GpsError",
    "GpsOutliers",
    "GpsScoreConfig",
    "LandmarkError",
    "NisSummary",
    "RelativeError",
    "RpeUnit",
    "TrajectoryError",
    "absolute_trajectory_error",
    "associate",
    "chi2_bounds",
    "consistency_report",
    "gps_error",
    "gps_outliers",
    "landmark_map_error",
    "nees",
    "nis",
    "nis_summary",
    "pose_errors",
    "relative_pose_error",
]
