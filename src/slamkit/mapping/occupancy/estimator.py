"""The pipeline estimator :class:`OccupancyMapping`: occupancy-grid mapping with known poses."""

from __future__ import annotations

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, Event, KnownPose, LaserScan, Odometry
from slamkit.errors import InputError
from slamkit.estimation.contract import EstimatorOutput, PoseEstimate
from slamkit.estimation.shell import EstimatorShell
from slamkit.geometry.pose2 import compose
from slamkit.mapping.occupancy.config import OccupancyMappingConfig
from slamkit.mapping.occupancy.mapper import OccupancyMapper

__all__ = ["OccupancyMapping"]


class OccupancyMapping(EstimatorShell):
    """Occupancy-grid mapping **with known poses**, as a pipeline estimator.

    The poses arrive through the stream: with ``pose_source="truth"`` (the default) as
    :class:`~slamkit.datasets.KnownPose` events, which :func:`slamkit.pipeline.run` adds
    from the data set's true trajectory at the head of every time stamp (interpolated where a
    scan falls between true poses); the estimator never reads ``truth``. Its
    :meth:`estimate` reports the known pose (its trajectory error is zero by construction);
    its product is the map, returned by :meth:`finish` as ``EstimatorOutput(grid=...)``.
    Each scan is laid from the laser's pose, the robot's composed with
    :attr:`~slamkit.datasets.LaserSpec.mounting`.
    With ``pose_source="odometry"`` it uses the odometry readings instead and reports those
    (a map that shows the odometry's drift).
    """

    name = "occupancy mapping"

    def __init__(
        self, dataset: Dataset, config: OccupancyMappingConfig, rng: np.random.Generator
    ) -> None:
        if dataset.laser is None:
            raise InputError(f"occupancy mapping needs laser scans; {dataset.name!r} has none")
        super().__init__()
        self._config = config
        self._source = config.pose_source
        if self._source == "truth" and dataset.truth.poses is None:
            raise InputError(
                f"occupancy mapping with known poses needs the true trajectory, which "
                f"data set {dataset.name!r} does not have (use pose_source='odometry')"
            )
        # Online: the grid grows with the scans (sizing it from every future scan, as the
        # batch builder may, would read the stream ahead and, for known poses, the truth).
        self._mapper = OccupancyMapper(dataset.laser, config, None)
        start = dataset.initial_pose if dataset.initial_pose is not None else np.zeros(3)
        self._odometry: FloatArray = np.asarray(start, dtype=np.float64)
        self._known: FloatArray | None = None
        mounting = dataset.laser.mounting
        self._mounting = np.asarray(mounting, dtype=np.float64) if any(mounting) else None

    def _laser_pose(self) -> FloatArray:
        """The laser's pose now: the robot's ⊕ the laser's mounting."""
        if self._mounting is None:
            return self._pose()
        return np.asarray(compose(self._pose(), self._mounting), dtype=np.float64)

    def _pose(self) -> FloatArray:
        if self._source == "truth" and self._known is not None:
            return self._known
        return self._odometry

    def handle(self, event: Event) -> None:
        if isinstance(event, Odometry):  # the pose itself, not the control between two
            self._odometry = np.asarray(event.pose, dtype=np.float64)
        super().handle(event)

    def on_known_pose(self, event: KnownPose) -> None:
        self._known = np.asarray(event.pose, dtype=np.float64)

    def on_scan(self, event: LaserScan) -> None:
        if self._source == "truth" and self._known is None:
            raise InputError(
                f"occupancy mapping with known poses: no KnownPose before the scan at "
                f"t={event.t} (run it through slamkit.pipeline.run on a data set with a true "
                "trajectory, or give KnownPose events)"
            )
        self._mapper.offer(self._laser_pose(), event.ranges)

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(self._pose())

    def finish(self) -> EstimatorOutput:
        grid = self._mapper.occupancy_grid()
        stats = self._mapper.stats.as_dict()
        stats["pose_source"] = self._source
        stats["grid_shape"] = list(grid.shape)
        return EstimatorOutput(grid=grid, diagnostics={"mapping": stats})
