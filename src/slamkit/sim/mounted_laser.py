"""A simulated laser mounted off the robot's origin, for calibration studies.

The simulated scenarios cast their scans from the robot's pose (the laser at the origin,
facing ahead). :func:`remount_laser` casts every scan of a data set again from
``robot ⊕ mounting`` — the laser where a real robot might carry it — against the data set's
true walls, and states a ``nominal`` mounting in its :class:`~slamkit.datasets.LaserSpec`
(by default none: the laser believed at the origin), so a calibration has a known offset to
recover.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from slamkit.datasets.stream import Dataset, LaserScan, LaserSpec
from slamkit.errors import InputError
from slamkit.geometry.pose2 import compose, interpolate_poses
from slamkit.sim.sensors import simulate_scan

__all__ = ["remount_laser"]


def remount_laser(
    dataset: Dataset,
    mounting: tuple[float, float, float],
    rng: np.random.Generator,
    nominal: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Dataset:
    """``dataset`` with every scan cast again from the true pose ``⊕ mounting`` (``(x, y,
    yaw)`` [m, m, rad] in the robot frame) against ``dataset.truth.walls``, and its
    laser's stated mounting ``nominal``. Every other event is kept."""
    truth = dataset.truth
    if dataset.laser is None or truth.walls is None or truth.times is None or truth.poses is None:
        raise InputError(
            f"remount_laser: data set {dataset.name!r} needs a laser, true walls and a true path"
        )
    laser = dataset.laser
    M = np.asarray(mounting, dtype=np.float64)
    stamps = np.asarray([ev.t for ev in dataset.events if isinstance(ev, LaserScan)])
    poses = compose(interpolate_poses(truth.times, truth.poses, stamps), M)
    scans = iter(poses)
    events = tuple(
        LaserScan(ev.t, simulate_scan(next(scans), truth.walls, laser, rng))
        if isinstance(ev, LaserScan)
        else ev
        for ev in dataset.events
    )
    spec = LaserSpec(laser.beam_angles, laser.max_range, laser.range_sigma, nominal)
    return replace(dataset, events=events, laser=spec)
