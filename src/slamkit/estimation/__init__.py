"""The estimation core under every estimator of ``localization``, ``mapping`` and ``slam``.

* :mod:`~slamkit.estimation.contract` — what the runner needs of an estimator (``handle``,
  ``estimate``, ``finish``), the values it returns (:class:`PoseEstimate`,
  :class:`EstimatorOutput`, ...) and the optional views an estimator may offer
  (:class:`LandmarkView`, :class:`ParticleView`) for animation frames.
* :mod:`~slamkit.estimation.readings` — the status of each landmark reading and the codes
  of data association, as ``IntEnum``.
* :mod:`~slamkit.estimation.gaussian` — the Gaussian-filter kernels shared by every
  Kalman-type estimator: covariance checks, the gain with the Joseph update, angle wrapping of
  innovations, model evaluation on validated arrays (the fast path).
* :mod:`~slamkit.estimation.health` — the run warnings of every laser tracker that weighs
  the laser against the wheels (odometry glitches overridden, scans lost, unmatched
  stretches), shared by laser odometry and graph SLAM's front end.

Layers: this package imports ``models``, ``maps``, ``datasets``, ``prob`` and ``geometry``;
``localization``, ``mapping``, ``slam`` and ``pipeline`` import it.
"""

from slamkit.estimation.contract import (
    Estimator,
    EstimatorFactory,
    EstimatorOutput,
    Frame,
    InnovationLog,
    LandmarkEstimate,
    LandmarkIds,
    LandmarkView,
    ParticleSnapshot,
    ParticleView,
    PoseEstimate,
    SmoothedTrajectory,
    SnapshotSchedule,
    SpreadSnapshots,
    StepClock,
)
from slamkit.estimation.readings import AssociationCode, ReadingStatus

__all__ = [
    "AssociationCode",
    "Estimator",
    "EstimatorFactory",
    "EstimatorOutput",
    "Frame",
    "InnovationLog",
    "LandmarkEstimate",
    "LandmarkIds",
    "LandmarkView",
    "ParticleSnapshot",
    "ParticleView",
    "PoseEstimate",
    "ReadingStatus",
    "SmoothedTrajectory",
    "SnapshotSchedule",
    "SpreadSnapshots",
    "StepClock",
]
