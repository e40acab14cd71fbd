"""The pipeline estimator :class:`OccupancyMapping`: occupancy-grid mapping with known poses."""

from __future__ import annotations

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, Event, LaserScan, Odometry
from slamkit.errors import InputError
from slamkit.estimation.contract import EstimatorOutput, PoseEstimate
from slamkit.mapping.occupancy.config import OccupancyMappingConfig
from slamkit.mapping.occupancy.mapper import OccupancyMapper
from slamkit.mapping.occupancy.scans import data_bounds, known_pose_at

__all__ = ["OccupancyMapping"]


class OccupancyMapping:
    """Occupancy-grid mapping **with known poses**, as a pipeline estimator.

    This estimator deliberately reads the data set's *true trajectory*
    (``dataset.truth.times/poses``) in its constructor — mapping with known poses is defined
    as being given the poses — and uses the pose at each scan's time stamp to integrate the
    scan (interpolated between true poses if a scan falls between them). Its
    :meth:`estimate` therefore reports the known pose (its trajectory error is zero by
    construction); its product is the map, returned by :meth:`finish` as
    ``EstimatorOutput(grid=...)``. With ``pose_source="odometry"`` it uses the odometry
    readings instead and reports those (a map that shows the odometry's drift).
    """

    def __init__(
        self, dataset: Dataset, config: OccupancyMappingConfig, rng: np.random.Generator
    ) -> None:
        if dataset.laser is None:
            raise InputError(f"occupancy mapping needs laser scans; {dataset.name!r} has none")
        self._config = config
        self._source = config.pose_source
        truth = dataset.truth
        self._times: FloatArray | None = None
        self._poses: FloatArray | None = None
        if self._source == "truth":
            if truth.times is None or truth.poses is None or truth.times.size == 0:
                raise InputError(
                    f"occupancy mapping with known poses needs the true trajectory, which "
                    f"data set {dataset.name!r} does not have (use pose_source='odometry')"
                )
            self._times = truth.times.copy()
            self._poses = truth.poses.copy()
        bounds = data_bounds(dataset, config) if config.bounds == "data" else None
        self._mapper = OccupancyMapper(dataset.laser, config, bounds)
        self._t = dataset.start_time
        start = dataset.initial_pose if dataset.initial_pose is not None else np.zeros(3)
        self._odometry: FloatArray = np.asarray(start, dtype=np.float64)

    def _pose(self, t: float) -> FloatArray:
        if self._times is not None and self._poses is not None:
            t_clamped = min(max(t, float(self._times[0])), float(self._times[-1]))
            return known_pose_at(self._times, self._poses, t_clamped)
        return self._odometry

    def handle(self, event: Event) -> None:
        self._t = event.t
        if isinstance(event, Odometry):
            self._odometry = np.asarray(event.pose, dtype=np.float64)
        elif isinstance(event, LaserScan):
            if self._times is not None and self._poses is not None:
                pose = known_pose_at(self._times, self._poses, event.t)
            else:
                pose = self._odometry
            self._mapper.offer(pose, event.ranges)

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(self._pose(self._t))

    def finish(self) -> EstimatorOutput:
        grid = self._mapper.occupancy_grid()
        stats = self._mapper.stats.as_dict()
        stats["pose_source"] = self._source
        stats["grid_shape"] = list(grid.shape)
        return EstimatorOutput(grid=grid, diagnostics={"mapping": stats})
