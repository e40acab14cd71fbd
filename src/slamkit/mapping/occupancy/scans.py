"""The input of occupancy mapping: range readings checked, scans and their known poses taken
from a data set, and the box of world coordinates a set of scans reaches.

Known poses are the data set's true trajectory, interpolated at the scan times
(:func:`known_pose_at`), or its odometry readings (the latest at or before each scan): the
robot's poses, composed with the laser's mounting into the sensor's (:func:`sensor_poses`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.datasets.stream import Dataset, LaserScan, Odometry
from slamkit.errors import InputError, NonFiniteError, ShapeError
from slamkit.geometry.pose2 import compose
from slamkit.geometry.pose2 import interpolate_poses as known_pose_at
from slamkit.mapping.inverse_model import ResolvedModel, ray_extents
from slamkit.mapping.occupancy.config import OccupancyMappingConfig

__all__ = [
    "check_ranges",
    "data_bounds",
    "known_pose_at",
    "laser_scans",
    "scan_bounds",
    "scan_poses",
    "sensor_poses",
]


# --------------------------------------------------------------------------------------------
# input: range readings
# --------------------------------------------------------------------------------------------


def check_ranges(
    ranges: ArrayLike, *, first_scan: int = 0, times: ArrayLike | None = None
) -> FloatArray:
    """``ranges (B,)`` (one scan) or ``(S, B)`` as float64, every reading a finite number
    ``>= 0`` [m]; a reading ``>= max range`` is the "no return" mark. A NaN or infinite
    reading raises :class:`~slamkit.errors.NonFiniteError`, a negative one
    :class:`~slamkit.errors.InputError`, naming the scan (``first_scan`` + its row, and its
    time if ``times (S,)`` is given), the beam and the value. Two reductions over the array
    when all is well (NaN propagates through ``min``); the culprit is searched only on
    failure."""
    R = np.asarray(ranges, dtype=np.float64)
    if R.ndim not in (1, 2):
        raise ShapeError(f"ranges: expected (B,) or (S, B), got shape {R.shape}")
    if R.size == 0:
        return R
    low, high = float(R.min()), float(R.max())
    if low >= 0.0 and high < math.inf:
        return R
    rows = R.reshape(-1, R.shape[-1])
    non_finite = ~np.isfinite(rows)
    bad = non_finite | (rows < 0.0)
    k, j = divmod(int(np.argmax(bad)), rows.shape[1])
    where = f"scan {first_scan + k}"
    if times is not None:
        where += f" (t={float(np.asarray(times, dtype=np.float64).reshape(-1)[k]):.6f} s)"
    message = (
        f"{where}, beam {j}: expected a finite range >= 0 m (a reading at the max range "
        f"means no return), got {float(rows[k, j])}"
    )
    raise (NonFiniteError if non_finite[k, j] else InputError)(message)


def scan_bounds(
    poses: ArrayLike,
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    model: ResolvedModel,
) -> tuple[float, float, float, float]:
    """``(xmin, ymin, xmax, ymax)`` of every sensor position and every ray end actually used
    (``min(r_k + alpha/2, r_max)``) over scans ``ranges (S, B)`` from ``poses (S, 3)``, widened
    by the beam width's spread at the longest ray. Works through the scans in blocks, so
    memory stays small for long logs."""
    P = as_array(poses, "poses", (None, 3))
    R = as_array(ranges, "ranges", (P.shape[0], None), finite=False)
    check_ranges(R)
    beams = np.asarray(beam_angles, dtype=np.float64)
    lo = np.full(2, np.inf)
    hi = np.full(2, -np.inf)
    longest = 0.0
    for s0 in range(0, P.shape[0], 512):
        p = P[s0 : s0 + 512]
        _, d_end = ray_extents(R[s0 : s0 + 512], model)
        longest = max(longest, float(d_end.max(initial=0.0)))
        ang = p[:, 2:3] + beams[None, :]
        ex = p[:, 0:1] + d_end * np.cos(ang)
        ey = p[:, 1:2] + d_end * np.sin(ang)
        lo = np.minimum(lo, [min(ex.min(), p[:, 0].min()), min(ey.min(), p[:, 1].min())])
        hi = np.maximum(hi, [max(ex.max(), p[:, 0].max()), max(ey.max(), p[:, 1].max())])
    spread = longest * math.sin(min(model.beta, math.pi) / 2.0)
    return (
        float(lo[0] - spread),
        float(lo[1] - spread),
        float(hi[0] + spread),
        float(hi[1] + spread),
    )


# --------------------------------------------------------------------------------------------
# known poses
# --------------------------------------------------------------------------------------------


def laser_scans(dataset: Dataset) -> tuple[FloatArray, FloatArray]:
    """Scan times ``(S,)`` and ranges ``(S, B)`` of a data set."""
    scans = [ev for ev in dataset.events if isinstance(ev, LaserScan)]
    if not scans:
        raise InputError(f"data set {dataset.name!r} has no laser scans")
    times = np.array([ev.t for ev in scans], dtype=np.float64)
    return times, np.stack([ev.ranges for ev in scans])


def _odometry_at(dataset: Dataset, times: FloatArray) -> FloatArray:
    """The latest odometry pose at or before each scan time."""
    odo = [ev for ev in dataset.events if isinstance(ev, Odometry)]
    if not odo:
        raise InputError(f"pose_source 'odometry': data set {dataset.name!r} has no odometry")
    t_odo = np.array([ev.t for ev in odo])
    idx = np.searchsorted(t_odo, times, side="right") - 1
    if np.any(idx < 0):
        raise InputError("pose_source 'odometry': a scan comes before the first odometry reading")
    return np.stack([odo[i].pose for i in idx])


def scan_poses(dataset: Dataset, times: FloatArray, source: str) -> FloatArray:
    """Known sensor poses ``(S, 3)`` at the scan ``times``: the robot's poses from the true
    trajectory (mapping with known poses) or the odometry (see
    :class:`OccupancyMappingConfig.pose_source`), each composed with the laser's mounting
    (:attr:`~slamkit.datasets.LaserSpec.mounting`: laser = robot ⊕ mounting)."""
    if source == "odometry":
        robot = _odometry_at(dataset, times)
    else:
        truth = dataset.truth
        if truth.times is None or truth.poses is None:
            raise InputError(
                f"occupancy mapping with known poses needs the true trajectory, which data set "
                f"{dataset.name!r} does not have (use pose_source='odometry')"
            )
        robot = known_pose_at(truth.times, truth.poses, times)
    return sensor_poses(robot, dataset)


def sensor_poses(robot: FloatArray, dataset: Dataset) -> FloatArray:
    """The laser's poses ``(S, 3)`` for robot poses ``(S, 3)`` (or one ``(3,)``):
    ``robot ⊕ mounting``; the poses themselves when the laser sits at the robot's origin."""
    mounting = (0.0, 0.0, 0.0) if dataset.laser is None else dataset.laser.mounting
    if not any(mounting):
        return robot
    return np.asarray(compose(robot, np.asarray(mounting, dtype=np.float64)), dtype=np.float64)


def data_bounds(
    dataset: Dataset, config: OccupancyMappingConfig
) -> tuple[float, float, float, float]:
    """:func:`scan_bounds` of the scans ``config`` would use from ``dataset`` (scan and beam
    strides applied), at the poses of ``config.pose_source``."""
    if dataset.laser is None:
        raise InputError(f"occupancy mapping needs laser scans; {dataset.name!r} has none")
    times, ranges = laser_scans(dataset)
    used = slice(None, None, config.scan_stride)
    poses = scan_poses(dataset, times[used], config.pose_source)
    beams = dataset.laser.beam_angles[:: config.beam_stride]
    model = config.model.resolve(config.resolution, beams, dataset.laser.max_range)
    return scan_bounds(poses, ranges[used, :: config.beam_stride], beams, model)
