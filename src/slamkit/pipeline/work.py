"""The work a run does, counted in the events that cost the estimator its time.

A progress bar that counts every event lies about the time left when the events differ in
cost: a laser SLAM spends its time on the scans (matching, closures), not on the odometry
readings between them, so on a log with several odometry readings per scan an events-based
bar races ahead and its estimate of the time left is far too short. :func:`work_measure`
counts, for the estimator of an :class:`~slamkit.pipeline.EstimatorEntry`, the events of
the kind it spends its time on (:attr:`EstimatorEntry.work`): laser scans or landmark
readings, or every event when the data set has none of that kind. The runner reports its
progress in these units, and a front end says what it counts (``scans 1,234/13,630``).
Counting the right events is half of an honest time left; the other half is the time per
unit, which grows through a graph-SLAM run (:attr:`WorkMeasure.pace`,
:mod:`slamkit.pipeline.eta`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slamkit.datasets.stream import Dataset, LandmarkReadings, LaserScan
from slamkit.pipeline.eta import Pace
from slamkit.pipeline.registry import EstimatorEntry, WorkUnit

__all__ = ["WorkMeasure", "work_measure"]

_KINDS: dict[WorkUnit, type] = {"scans": LaserScan, "readings": LandmarkReadings}


@dataclass(frozen=True)
class WorkMeasure:
    """What a run's progress counts: ``unit`` (``"scans"``, ``"readings"`` or
    ``"events"``) and ``weights (N,)``, one per event of the data set: 1 for an event of
    that unit, else 0."""

    unit: WorkUnit
    weights: NDArray[np.int64]
    pace: Pace = "steady"
    """How the time per unit behaves (:attr:`EstimatorEntry.pace`): what the time left is
    estimated from (:class:`~slamkit.pipeline.eta.TimeLeft`)."""

    @property
    def total(self) -> int:
        """The units of work in the whole run."""
        return int(self.weights.sum())


def work_measure(entry: EstimatorEntry, dataset: Dataset) -> WorkMeasure:
    """The units ``entry``'s estimator works in over ``dataset``: the events of kind
    :attr:`EstimatorEntry.work`, or every event when the data set has none of them."""
    kind = _KINDS.get(entry.work)
    if kind is not None:
        weights = np.fromiter(
            (isinstance(ev, kind) for ev in dataset.events), dtype=np.int64, count=len(dataset)
        )
        if weights.any():
            return WorkMeasure(entry.work, weights, entry.pace)
    return WorkMeasure("events", np.ones(len(dataset), dtype=np.int64), entry.pace)
