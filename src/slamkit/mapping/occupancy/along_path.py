"""Mapping along a given path: the known poses of occupancy mapping taken from any trajectory
(a run's ``trajectory.tum``, another tool's output) instead of the data set's own reference.

:func:`dataset_on_path` returns the data set with the path as its reference trajectory, which
is where mapping with known poses reads its poses (interpolated on SE(2) to the scan stamps:
:func:`~slamkit.geometry.pose2.interpolate_poses`), and with the scans outside the path's time
span dropped — a pose there would be the path's end held, not a pose of the robot. The drop is
counted in :class:`PathCoverage`; a path that leaves most of the scans outside its span is
refused, since it is most likely the path of another log or on another clock.

The path is the robot's: each scan is laid from the path's pose composed with the laser's
mounting (:func:`~slamkit.mapping.occupancy.scans.sensor_poses`), as the data set's own
reference is.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import as_array
from slamkit.datasets.stream import Dataset, Event, LaserScan
from slamkit.errors import InputError

__all__ = ["MAX_OUTSIDE_SHARE", "STAMP_TOLERANCE", "PathCoverage", "dataset_on_path"]

MAX_OUTSIDE_SHARE = 0.5
"""A path is refused when more than this share of the scans lies outside its time span."""
STAMP_TOLERANCE = 1e-6
"""[s] A scan this close outside the path's span is kept (at the path's end pose): a TUM file
keeps 16 significant digits, so a Unix stamp comes back up to 5e-7 s off, and a stamp such as
``0.2 · 519 = 103.80000000000001`` comes back as ``103.8``."""


@dataclass(frozen=True)
class PathCoverage:
    """How a path covered a data set's scans: ``scans`` in all, ``before`` and ``after`` the
    path's time span ``[start, end]`` (dropped), and the number of poses in the path."""

    scans: int
    before: int
    after: int
    start: float
    end: float
    poses: int

    @property
    def used(self) -> int:
        return self.scans - self.before - self.after

    @property
    def dropped(self) -> int:
        return self.before + self.after

    def as_dict(self) -> dict[str, Any]:
        return {
            "scans": self.scans,
            "used": self.used,
            "dropped_before": self.before,
            "dropped_after": self.after,
            "path_start": self.start,
            "path_end": self.end,
            "path_poses": self.poses,
        }

    def line(self) -> str:
        """One line for a person."""
        text = (
            f"path: {self.poses} poses over {self.start:.3f}-{self.end:.3f} s cover "
            f"{self.used} of {self.scans} scans"
        )
        if self.dropped:
            text += f"; dropped {self.before} before and {self.after} after its span"
        return text


def dataset_on_path(
    dataset: Dataset, times: ArrayLike, poses: ArrayLike, *, source: str = "the path"
) -> tuple[Dataset, PathCoverage]:
    """``dataset`` with ``poses (N, 3)`` at ``times (N,)`` (strictly increasing, the data set's
    clock) as its reference trajectory, and without the laser scans outside
    ``[times[0], times[-1]]``; and the :class:`PathCoverage`. ``source`` names the path in
    errors (a file name). Raises :class:`~slamkit.errors.InputError` when the path has fewer
    than two poses, when the data set has no scans, and when more than
    :data:`MAX_OUTSIDE_SHARE` of the scans lie outside the path's span."""
    t = as_array(times, "path times", (None,))
    p = as_array(poses, "path poses", (t.size, 3))
    if t.size < 2:
        raise InputError(f"{source}: expected at least two poses, got {t.size}")
    if np.any(np.diff(t) <= 0):
        raise InputError(f"{source}: expected strictly increasing times")
    start, end = float(t[0]), float(t[-1])
    scan_t = np.array([e.t for e in dataset.events if isinstance(e, LaserScan)])
    if scan_t.size == 0:
        raise InputError(f"data set {dataset.name!r} has no laser scans to map")
    start, end = start - STAMP_TOLERANCE, end + STAMP_TOLERANCE
    before = int(np.count_nonzero(scan_t < start))
    after = int(np.count_nonzero(scan_t > end))
    coverage = PathCoverage(int(scan_t.size), before, after, float(t[0]), float(t[-1]), t.size)
    if coverage.dropped > MAX_OUTSIDE_SHARE * coverage.scans or coverage.used == 0:
        raise InputError(
            f"{source}: its poses span {t[0]:.3f}-{t[-1]:.3f} s, and {coverage.dropped} of "
            f"{coverage.scans} scans of {dataset.name!r} (stamps {scan_t[0]:.3f}-"
            f"{scan_t[-1]:.3f} s) lie outside it: is it a path of this log, on its clock?"
        )
    events: tuple[Event, ...] = dataset.events
    if coverage.dropped:
        events = tuple(
            e for e in events if not (isinstance(e, LaserScan) and not start <= e.t <= end)
        )
    truth = dataclasses.replace(dataset.truth, times=t, poses=p)
    return dataclasses.replace(dataset, events=events, truth=truth), coverage
