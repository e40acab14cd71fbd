"""Raw odometry at the scans' stamps: what the readers of raw laser logs share.

A raw log (a ROS bag, a CARMEN log whose laser lines carry no pose) holds laser scans and the
robot's wheel odometry as two streams at their own stamps. slamkit's stream wants one
:class:`~slamkit.datasets.Odometry` event per scan, at the scan's stamp and just before it, so
the odometry is interpolated on SE(2) to each scan stamp
(:func:`~slamkit.geometry.pose2.interpolate_poses`: the position linearly, the heading along
the shorter arc). The rules, the same for every format:

* a scan before the first or after the last odometry message has no odometry: it is dropped
  and counted (``before_odometry``, ``after_odometry``);
* a scan that falls inside a gap of the odometry longer than ``max_odom_gap`` (the two
  messages around it further apart than that) would get a pose guessed over the gap: that is
  an error, or (lenient) the scan is dropped and counted (``odometry_gap``). A message at
  the scan's own stamp leaves no gap;
* stamps must increase: a message whose stamp is not later than every one before it is out
  of order (an error, or lenient dropped and counted), except a repeat of the previous
  message (the same stamp and the same pose), which is dropped silently and counted.

The noise the :class:`~slamkit.datasets.MotionSpec` declares for raw odometry is nominal
(the logs do not say): by default 0.05 m and 2° per step of ``(rot1, trans, rot2)``, the
convention of the DP-SLAM reader (:class:`~slamkit.datasets.carmen.DpSlamOptions`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.assemble import assemble_events, odometry_events, scan_events
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.reading import ReadingSummary
from slamkit.datasets.relations import Relations
from slamkit.datasets.stream import Dataset, GroundTruth, LaserSpec, MotionSpec, Odometry
from slamkit.errors import ConfigError
from slamkit.geometry.pose2 import interpolate_poses
from slamkit.models import OdometryModel

__all__ = [
    "DEFAULT_MAX_ODOM_GAP",
    "RAW_INITIAL_COV",
    "RAW_ODOMETRY_SIGMA_ROT_DEG",
    "RAW_ODOMETRY_SIGMA_TRANS",
    "OdometryAtScans",
    "check_gap_option",
    "increasing_mask",
    "odometry_at_scans",
    "raw_laser_dataset",
    "raw_odometry_cov",
    "repeat_mask",
    "signed_by_speed",
]

DEFAULT_MAX_ODOM_GAP = 0.5
"""Longest gap of the odometry [s] a scan may fall into by default."""

RAW_ODOMETRY_SIGMA_TRANS = 0.02
"""Nominal per-step translation noise of raw odometry [m] (the MotionSpec's). Measured on
the raw Intel, ACES and Freiburg 079 logs: over their reference relations shorter than 2 s,
the wheels' error per step (one odometry reading per scan) is 0.008-0.016 m by the median
and 0.025-0.054 m by the RMS (``docs/estimators/laser_graph.md``, "Odometry noise"); 0.02 m
is that magnitude, as for the corrected CARMEN logs."""

RAW_ODOMETRY_SIGMA_ROT_DEG = 1.0
"""Nominal per-step rotation noise of raw odometry [deg] (each of the step's two rotations;
the MotionSpec's). Measured as above: 0.2-0.5° by the median, 0.5-1.1° by the RMS."""

RAW_INITIAL_COV: FloatArray = np.diag([1e-4, 1e-4, math.radians(0.5) ** 2])
"""The prior around the first odometry pose: the map frame is the odometry frame at the
first scan, known up to 1 cm and 0.5° (as for the other laser logs)."""

STAMP_TOLERANCE = 1e-9
"""An odometry message this close to a scan [s] is at the scan's stamp (no gap)."""


def check_gap_option(value: float) -> None:
    """``max_odom_gap`` must be a number > 0 (``inf``: no limit)."""
    if not (isinstance(value, int | float) and value > 0):
        raise ConfigError(f"max_odom_gap: expected a number > 0 [s] (inf: no limit), got {value!r}")


def raw_odometry_cov(sigma_trans: float, sigma_rot_deg: float) -> FloatArray:
    """Covariance of ``(rot1, trans, rot2)`` per step (rad², m², rad²)."""
    sr = math.radians(sigma_rot_deg)
    return np.diag([sr**2, sigma_trans**2, sr**2])


def increasing_mask(times: FloatArray) -> NDArray[np.bool_]:
    """``True`` where a stamp is later than every stamp before it (the others are out of
    order; the first is always in order)."""
    t = np.asarray(times, dtype=np.float64)
    if t.size == 0:
        return np.zeros(0, dtype=bool)
    earlier = np.maximum.accumulate(np.concatenate([[-np.inf], t[:-1]]))
    return np.asarray(t > earlier)


def repeat_mask(times: FloatArray, poses: FloatArray) -> NDArray[np.bool_]:
    """``True`` where a message repeats the one before it: the same stamp and the same pose."""
    t = np.asarray(times, dtype=np.float64)
    p = np.asarray(poses, dtype=np.float64)
    out = np.zeros(t.size, dtype=bool)
    if t.size > 1:
        out[1:] = (t[1:] == t[:-1]) & np.all(p[1:] == p[:-1], axis=1)
    return out


@dataclass(frozen=True, eq=False)
class OdometryAtScans:
    """The odometry interpolated to the scan stamps.

    ``keep (N,)`` marks the scans that have odometry; ``poses (K, 3)`` are their odometry
    poses (``K = keep.sum()``). ``gap (N,)`` is the span [s] of the two odometry messages
    around each scan (0 where one is at its stamp, ``inf`` outside the odometry);
    ``in_gap (N,)`` marks the scans inside a gap longer than the limit (not kept)."""

    keep: NDArray[np.bool_]
    poses: FloatArray
    gap: FloatArray
    in_gap: NDArray[np.bool_]
    before: int
    after: int

    @property
    def dropped(self) -> dict[str, int]:
        return {
            "before_odometry": self.before,
            "after_odometry": self.after,
            "odometry_gap": int(self.in_gap.sum()),
        }


def signed_by_speed(poses: FloatArray, speed: FloatArray) -> FloatArray:
    """Odometry poses ``(M, 3)`` whose steps go backward where the reported forward
    ``speed (M,)`` [m/s] says the robot reversed: for a log whose poses were integrated from
    the unsigned speed (they always advance) while its velocities keep the sign.

    Step ``i`` (messages ``i-1`` → ``i``) travels ``≈ (v_{i-1} + v_i) Δt / 2`` (trapezoid):
    where that is negative its translation is reversed, ``Δp_i → -Δp_i`` in the world frame
    (``-Δp`` in the frame of pose ``i-1``, the same thing); the headings are kept as they
    are (the wheels' turning is signed either way), and the first pose stays. Steps whose
    speeds sum to zero or more are kept."""
    step = np.diff(poses[:, :2], axis=0)
    backward = (speed[:-1] + speed[1:]) < 0.0
    step[backward] *= -1.0
    out: FloatArray = poses.copy()
    out[1:, :2] = poses[0, :2] + np.cumsum(step, axis=0)
    return out


def odometry_at_scans(
    scan_times: FloatArray, odom_times: FloatArray, odom_poses: FloatArray, max_gap: float
) -> OdometryAtScans:
    """Interpolate odometry ``(M, 3)`` at ``odom_times (M,)`` (strictly increasing) to
    ``scan_times (N,)`` under the rules of the module docstring. The caller decides whether a
    scan in a gap is an error (``in_gap``)."""
    st = np.asarray(scan_times, dtype=np.float64)
    ot = np.asarray(odom_times, dtype=np.float64)
    n = st.size
    if ot.size == 0:
        empty = np.zeros(n, dtype=bool)
        return OdometryAtScans(empty, np.zeros((0, 3)), np.full(n, np.inf), empty, n, 0)
    before = st < ot[0] - STAMP_TOLERANCE
    after = st > ot[-1] + STAMP_TOLERANCE
    inside = ~(before | after)
    hi = np.clip(np.searchsorted(ot, st, side="left"), 0, ot.size - 1)
    lo = np.clip(hi - 1, 0, ot.size - 1)
    at_stamp = (np.abs(ot[hi] - st) <= STAMP_TOLERANCE) | (np.abs(ot[lo] - st) <= STAMP_TOLERANCE)
    gap = np.where(at_stamp, 0.0, ot[hi] - ot[lo])
    gap = np.where(inside, gap, np.inf)
    in_gap = inside & (gap > max_gap)
    keep = inside & ~in_gap
    poses = interpolate_poses(ot, odom_poses, st[keep]) if keep.any() else np.zeros((0, 3))
    return OdometryAtScans(
        keep, poses, gap, in_gap, int(np.count_nonzero(before)), int(np.count_nonzero(after))
    )


def raw_laser_dataset(
    *,
    name: str,
    times: FloatArray,
    odometry: FloatArray | None,
    ranges: FloatArray,
    laser: LaserSpec,
    motion_cov: FloatArray,
    description: str,
    metadata: dict[str, Any],
    relations: Relations | None = None,
    reading: ReadingSummary | None = None,
    provenance: Provenance | None = None,
) -> Dataset:
    """The :class:`Dataset` of a raw log: per scan an :class:`Odometry` event (the robot's
    pose in the odometry frame) and a :class:`LaserScan` at the same stamp, in that order;
    an odometry :class:`MotionSpec` with the nominal ``motion_cov``; the prior around the
    first odometry pose (:data:`RAW_INITIAL_COV`); ``relations`` as the ground truth;
    ``reading``, what the reader did to the file; ``provenance``, the reader's record.
    ``odometry=None`` (a log without it): scans only, no motion model, the prior at the
    origin."""
    t_list = np.asarray(times, dtype=np.float64)
    moves: list[Odometry] = [] if odometry is None else odometry_events(t_list, odometry)
    start = np.zeros(3) if odometry is None else np.array(odometry[0], dtype=np.float64)
    return Dataset(
        name=name,
        events=assemble_events(moves, scan_events(t_list, ranges)),
        motion=None
        if odometry is None
        else MotionSpec(OdometryModel(), motion_cov, source="odometry"),
        laser=laser,
        initial_pose=start if t_list.size else None,
        initial_cov=RAW_INITIAL_COV.copy() if t_list.size else None,
        truth=GroundTruth(relations=relations),
        description=description,
        metadata=metadata,
        reading=reading,
        provenance=provenance or Provenance(),
    )
