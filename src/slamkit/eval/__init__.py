"""Evaluation: trajectory accuracy (ATE, RPE), filter consistency (NEES/NIS), landmark-map
accuracy and the relation metric of the Freiburg laser benchmark. Numerics only; plotting
lives in :mod:`slamkit.viz`."""

from slamkit.eval.association import AssociationScores, association_scores
from slamkit.eval.consistency import (
    ConsistencyReport,
    chi2_bounds,
    consistency_report,
    nees,
    nis,
)
from slamkit.eval.convergence import (
    ConvergenceReport,
    ErrorStats,
    convergence,
    convergence_against_truth,
)
from slamkit.eval.gps import GpsError, GpsOutliers, GpsScoreConfig, gps_error, gps_outliers
from slamkit.eval.innovations import NisSummary, nis_summary
from slamkit.eval.landmarks import (
    LandmarkError,
    LandmarkMatch,
    landmark_map_error,
    match_landmarks,
)
from slamkit.eval.monitor import (
    MONITOR_MARGIN,
    MONITOR_PROBABILITY,
    MONITOR_WINDOW,
    ConsistencyWarning,
    autocorrelation_time,
    nees_warning,
    nis_warning,
)
from slamkit.eval.relations import (
    RelationError,
    poses_at_stamps,
    relation_errors,
    select_relations,
)
from slamkit.eval.signals import SelfSignals, self_signals
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
    "MONITOR_MARGIN",
    "MONITOR_PROBABILITY",
    "MONITOR_WINDOW",
    "AlignMode",
    "AssociationScores",
    "ConsistencyReport",
    "ConsistencyWarning",
    "ConvergenceReport",
    "ErrorStats",
    "GpsError",
    "GpsOutliers",
    "GpsScoreConfig",
    "LandmarkError",
    "LandmarkMatch",
    "NisSummary",
    "RelationError",
    "RelativeError",
    "RpeUnit",
    "SelfSignals",
    "TrajectoryError",
    "absolute_trajectory_error",
    "associate",
    "association_scores",
    "autocorrelation_time",
    "chi2_bounds",
    "consistency_report",
    "convergence",
    "convergence_against_truth",
    "gps_error",
    "gps_outliers",
    "landmark_map_error",
    "match_landmarks",
    "nees",
    "nees_warning",
    "nis",
    "nis_summary",
    "nis_warning",
    "pose_errors",
    "poses_at_stamps",
    "relation_errors",
    "relative_pose_error",
    "select_relations",
    "self_signals",
]
