"""The one list of every estimator, by name.

To add an estimator: write a config dataclass and a class with the
:class:`~slamkit.estimation.contract.Estimator` methods whose constructor takes
``(dataset, config, rng)``, then add one :class:`EstimatorEntry` below. The runner and the
CLI (``slamkit run NAME``) find it here. Targets are imported on use, so listing is cheap.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from slamkit.config import config_from_mapping
from slamkit.datasets.stream import Dataset
from slamkit.errors import InputError, UnknownNameError
from slamkit.estimation.contract import Estimator, EstimatorFactory
from slamkit.pipeline.eta import Pace

__all__ = ["ESTIMATORS", "EstimatorEntry", "WorkUnit", "get_estimator_entry", "list_estimators"]

Requirement = Literal[
    "motion",
    "initial_pose",
    "landmark_sensor",
    "known_landmarks",
    "laser",
    "known_grid",
    "true_poses",
]
"""Parts of a Dataset an estimator may need; ``true_poses`` is for mapping with known poses."""

WorkUnit = Literal["scans", "readings", "events"]
"""The events an estimator spends its time on (:mod:`slamkit.pipeline.work`): laser scans,
landmark readings, or every event alike."""


def _has(dataset: Dataset, requirement: Requirement) -> bool:
    if requirement == "true_poses":
        return dataset.truth.poses is not None
    return getattr(dataset, requirement) is not None


@dataclass(frozen=True)
class EstimatorEntry:
    """A registered estimator: ``target`` and ``config`` are ``"module:Name"`` strings;
    ``requires`` lists the parts of a :class:`Dataset` it cannot run without."""

    name: str
    description: str
    target: str
    config: str
    requires: tuple[Requirement, ...] = ()
    known_poses: bool = False
    """The estimator maps with known poses: the runner gives it the data set's true poses
    through the stream (:func:`~slamkit.datasets.stream.with_known_poses`)."""
    work: WorkUnit = "events"
    """The events that cost the estimator its time, in which a run's progress is counted
    (:func:`~slamkit.pipeline.work.work_measure`; every event when the data set has none)."""
    pace: Pace = "steady"
    """How its time per unit of work behaves through a run (:mod:`slamkit.pipeline.eta`):
    ``"growing"`` when each unit costs more as the run goes (graph SLAM's closure search
    and solves over a growing graph), so the time left is not the recent rate times the
    work left."""

    @staticmethod
    def _resolve(spec: str) -> Any:
        module, _, attr = spec.partition(":")
        return getattr(importlib.import_module(module), attr)

    def config_type(self) -> type:
        cls: type = self._resolve(self.config)
        return cls

    def make_config(self, values: Mapping[str, Any] | Any | None = None) -> Any:
        """The config object from a mapping (unknown keys rejected), or the object itself."""
        cls = self.config_type()
        if isinstance(values, cls):
            return values
        return config_from_mapping(cls, values, f"estimator {self.name}")

    def check(self, dataset: Dataset) -> None:
        """Raise :class:`InputError` naming what the data set lacks for this estimator."""
        missing = [r for r in self.requires if not _has(dataset, r)]
        if missing:
            raise InputError(
                f"estimator {self.name!r} needs {', '.join(missing)}, which data set "
                f"{dataset.name!r} does not provide"
            )

    def create(self, dataset: Dataset, config: Any, rng: np.random.Generator) -> Estimator:
        self.check(dataset)
        factory: EstimatorFactory = self._resolve(self.target)
        return factory(dataset, config, rng)


ESTIMATORS: dict[str, EstimatorEntry] = {
    e.name: e
    for e in (
        EstimatorEntry(
            "dead-reckoning",
            "integrate controls/odometry, propagate the covariance; no measurements",
            "slamkit.localization.dead_reckoning:DeadReckoning",
            "slamkit.localization.dead_reckoning:DeadReckoningConfig",
            requires=("motion",),
        ),
        EstimatorEntry(
            "least-squares",
            "static single-shot least-squares fix at every landmark event (no filtering)",
            "slamkit.localization.least_squares:LeastSquaresLocalization",
            "slamkit.localization.least_squares:LeastSquaresConfig",
            requires=("landmark_sensor", "known_landmarks"),
            work="readings",
        ),
        EstimatorEntry(
            "ekf-localization",
            "EKF localization against a known landmark map (known ids or ML association)",
            "slamkit.localization.ekf:EkfLocalization",
            "slamkit.localization.ekf:EkfConfig",
            requires=("motion", "landmark_sensor", "known_landmarks"),
            work="readings",
        ),
        EstimatorEntry(
            "ukf-localization",
            "UKF localization (augmented sigma points, circular means) against a known map",
            "slamkit.localization.ukf:UkfLocalization",
            "slamkit.localization.ukf:UkfConfig",
            requires=("motion", "landmark_sensor", "known_landmarks"),
            work="readings",
        ),
        EstimatorEntry(
            "mcl",
            "Monte Carlo localization in a known map (landmarks or laser likelihood field); "
            "augmented MCL, KLD-sampling, global localization without a prior",
            "slamkit.localization.mcl:MonteCarloLocalization",
            "slamkit.localization.mcl:MclConfig",
            requires=("motion",),
            work="scans",
        ),
        EstimatorEntry(
            "laser-odometry",
            "laser odometry: wheel odometry as the prior, scan-to-keyframe point-to-line ICP; "
            "the map from the keyframes",
            "slamkit.localization.laser_odometry:LaserOdometry",
            "slamkit.localization.laser_odometry:LaserOdometryConfig",
            requires=("motion", "laser"),
            work="scans",
        ),
        EstimatorEntry(
            "graph-slam",
            "graph-based laser SLAM: scan-matched keyframes, correlative loop closures "
            "verified and refined, the pose graph optimised; the map from the optimised poses",
            "slamkit.slam.laser_graph:LaserGraphSlam",
            "slamkit.slam.laser_graph:LaserGraphConfig",
            requires=("laser",),  # without odometry: scan matching alone
            work="scans",
            pace="growing",
        ),
        EstimatorEntry(
            "occupancy-mapping",
            "occupancy grid with known (true) poses: log-odds, α/β inverse laser model, "
            "Bresenham rays",
            "slamkit.mapping.occupancy:OccupancyMapping",
            "slamkit.mapping.occupancy:OccupancyMappingConfig",
            requires=("laser",),
            work="scans",
            known_poses=True,
        ),
        EstimatorEntry(
            "ekf-mapping",
            "EKF landmark mapping with known (true) poses; nearest-neighbour association for "
            "unlabelled readings",
            "slamkit.mapping.ekf_mapping:EkfMapping",
            "slamkit.mapping.ekf_mapping:EkfMappingConfig",
            requires=("landmark_sensor", "true_poses"),
            work="readings",
            known_poses=True,
        ),
        EstimatorEntry(
            "ekf-slam",
            "EKF-SLAM: pose and point landmarks with the full covariance; known ids, nearest "
            "neighbour or JCBB association; provisional feature list",
            "slamkit.slam.ekf_slam:EkfSlam",
            "slamkit.slam.ekf_slam:EkfSlamConfig",
            requires=("motion", "landmark_sensor"),
            work="readings",
        ),
        EstimatorEntry(
            "ukf-slam",
            "UKF-SLAM: EKF-SLAM's state, association and feature list with unscented "
            "prediction, updates and landmark initialisation (sigma points over the pose and "
            "the few entries a step reads)",
            "slamkit.slam.ukf_slam:UkfSlam",
            "slamkit.slam.ukf_slam:UkfSlamConfig",
            requires=("motion", "landmark_sensor"),
            work="readings",
        ),
        EstimatorEntry(
            "fastslam1",
            "FastSLAM 1.0: particles over paths, a 2×2 EKF per landmark and particle, "
            "per-particle maximum-likelihood association",
            "slamkit.slam.fastslam:FastSlam1",
            "slamkit.slam.fastslam:FastSlamConfig",
            requires=("motion", "landmark_sensor"),
            work="readings",
        ),
        EstimatorEntry(
            "fastslam2",
            "FastSLAM 2.0: as fastslam1, poses drawn from the proposal that includes the "
            "measurement",
            "slamkit.slam.fastslam:FastSlam2",
            "slamkit.slam.fastslam:FastSlamConfig",
            requires=("motion", "landmark_sensor"),
            work="readings",
        ),
        EstimatorEntry(
            "grid-rbpf",
            "grid-based Rao-Blackwellized particle filter SLAM (Grisetti et al. 2007): "
            "per-particle occupancy grids with shared tiles, scan-matching proposal",
            "slamkit.slam.grid_rbpf:GridRbpf",
            "slamkit.slam.grid_rbpf:GridRbpfConfig",
            requires=("motion", "laser"),
            work="scans",
        ),
        EstimatorEntry(
            "seif",
            "sparse extended information filter SLAM: constant-time motion update, bounded "
            "active landmarks, sparsification, amortised mean recovery",
            "slamkit.slam.seif:Seif",
            "slamkit.slam.seif:SeifConfig",
            requires=("motion", "landmark_sensor"),
            work="readings",
        ),
        EstimatorEntry(
            "range-only-slam",
            "range-only SLAM: beacons at unknown positions started from the ranges along the "
            "path (mirror ambiguity kept until it resolves), one robust batch solve",
            "slamkit.slam.range_only:RangeOnlySlam",
            "slamkit.slam.range_only:RangeOnlySlamConfig",
            requires=("motion", "landmark_sensor"),
            work="readings",
        ),
    )
}


def list_estimators() -> list[EstimatorEntry]:
    return list(ESTIMATORS.values())


def get_estimator_entry(name: str) -> EstimatorEntry:
    try:
        return ESTIMATORS[name]
    except KeyError:
        raise UnknownNameError("estimator", name, sorted(ESTIMATORS)) from None
