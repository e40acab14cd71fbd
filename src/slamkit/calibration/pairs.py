"""The data of a calibration: the wheels' increments between scans and the laser's own
relative motions between keyframe scans.

A data set with wheel odometry and laser scans is reduced to

* ``steps (S - 1, 3)``: the odometry increment ``(rot1, trans, rot2)``
  (:func:`~slamkit.models.odometry_control`) from the odometry pose at scan ``i`` to the one
  at scan ``i + 1`` — the odometry pose at a scan is that of the last
  :class:`~slamkit.datasets.Odometry` event at or before it (the readers put one at each
  scan's stamp);
* keyframe scans chosen along the odometry (a new keyframe once the wheels report
  ``min_distance`` of travel or ``min_turn`` of turning since the last one), and for each
  pair of consecutive keyframes ``(a, b)`` the laser's relative motion ``T_La_Lb`` measured
  by point-to-line ICP (:func:`~slamkit.scanmatch.plicp`) of scan ``b`` against scan ``a``,
  started from the odometry's guess seen through the nominal mounting
  ``M⁻¹ ⊕ between(odo_a, odo_b) ⊕ M``, with the matcher's covariance.

A pair whose match fails, or keeps less than ``min_inlier_fraction`` of its points, is left
out and counted by reason. These pairs are the measurements every fit of this package reads
(:mod:`slamkit.calibration.systematic`, :mod:`slamkit.calibration.noise`).
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, LaserScan, Odometry
from slamkit.errors import InputError, MatchError
from slamkit.geometry import wrap_angle
from slamkit.geometry.pose2 import between, compose, inverse
from slamkit.models import odometry_control
from slamkit.scanmatch import PlIcpConfig, plicp, prepare_scan, scan_points

__all__ = ["ScanPairs", "odometry_at_scans", "scan_pairs"]


@dataclass(frozen=True, eq=False)
class ScanPairs:
    """The measurements of a calibration (see the module docstring).

    * ``steps (S - 1, 3)``: odometry increments ``(rot1, trans, rot2)`` between scans;
    * ``first (P,)``, ``last (P,)``: the scan indices ``a < b`` of each matched pair; step
      ``j`` (from scan ``j`` to ``j + 1``) lies in pair ``p`` when ``first[p] <= j < last[p]``;
    * ``T_laser (P, 3)``: the laser's measured motion ``T_La_Lb``; ``cov (P, 3, 3)`` its
      covariance (the matcher's), for its error written in the frame ``Lb`` (the
      residuals' frame, :func:`~slamkit.calibration.systematic.pair_residuals`);
    * ``nominal_mounting (3,)``: the data set's laser mounting (the matches' start);
    * ``dropped``: pairs left out, by reason; ``keyframes``: keyframe scans chosen.
    """

    steps: FloatArray
    first: NDArray[np.int64]
    last: NDArray[np.int64]
    T_laser: FloatArray
    cov: FloatArray
    nominal_mounting: FloatArray
    dropped: dict[str, int]
    keyframes: int

    @property
    def n_pairs(self) -> int:
        return int(self.first.size)


def odometry_at_scans(dataset: Dataset) -> tuple[FloatArray, FloatArray, list[FloatArray]]:
    """``(times (S,), odometry poses (S, 3), ranges per scan)`` of the scans that come after
    the first odometry reading; the pose is the last odometry reading at or before each scan.
    Raises :class:`~slamkit.errors.InputError` when the data set has no laser or no wheel
    odometry (a calibration compares the two)."""
    if dataset.laser is None:
        raise InputError(f"calibration: data set {dataset.name!r} has no laser scans")
    if dataset.motion is None or dataset.motion.source != "odometry":
        raise InputError(
            f"calibration: data set {dataset.name!r} has no wheel odometry (its motion comes "
            "from controls or is absent); a calibration compares the wheels with the laser"
        )
    times: list[float] = []
    poses: list[FloatArray] = []
    ranges: list[FloatArray] = []
    current: FloatArray | None = None
    for ev in dataset.events:
        if isinstance(ev, Odometry):
            current = ev.pose
        elif isinstance(ev, LaserScan) and current is not None:
            times.append(ev.t)
            poses.append(current)
            ranges.append(ev.ranges)
    if len(times) < 2:
        raise InputError(
            f"calibration: data set {dataset.name!r} has {len(times)} scans with odometry; "
            "at least 2 are needed"
        )
    return np.asarray(times), np.asarray(poses, dtype=np.float64), ranges


def _in_own_frame(pose: FloatArray, cov: FloatArray) -> FloatArray:
    """A match's covariance, given for ``(x, y, θ)`` in the reference frame, for the same
    error written in the matched (current) frame: the position block turned by ``R(θ)ᵀ``."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    R = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.asarray(R @ cov @ R.T)


def _keyframes(odom: FloatArray, min_distance: float, min_turn: float) -> list[int]:
    """Scan indices where the wheels' distance or turn since the last keyframe reaches the
    thresholds (path length and summed absolute turn, so a back-and-forth still counts)."""
    u = odometry_control(odom[:-1], odom[1:])
    dist = np.abs(u[:, 1])
    turn = np.abs(wrap_angle(u[:, 0] + u[:, 2]))
    keys = [0]
    d = a = 0.0
    for j in range(u.shape[0]):
        d += float(dist[j])
        a += float(turn[j])
        if d >= min_distance or a >= min_turn:
            keys.append(j + 1)
            d = a = 0.0
    return keys


def scan_pairs(
    dataset: Dataset,
    *,
    min_distance: float = 0.5,
    min_turn: float = 0.35,
    min_inlier_fraction: float = 0.5,
    config: PlIcpConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ScanPairs:
    """The calibration measurements of ``dataset`` (see the module docstring): keyframes
    every ``min_distance`` [m] or ``min_turn`` [rad] of odometry, consecutive keyframes
    matched by PLICP. ``progress(done, total)`` is called after each match."""
    _, odom, ranges = odometry_at_scans(dataset)
    laser = dataset.laser
    assert laser is not None  # odometry_at_scans checked it
    steps = odometry_control(odom[:-1], odom[1:])
    keys = _keyframes(odom, min_distance, min_turn)
    mount = np.asarray(laser.mounting, dtype=np.float64)
    mount_inv = inverse(mount)
    dropped: Counter[str] = Counter()
    first: list[int] = []
    last: list[int] = []
    measured: list[FloatArray] = []
    covs: list[FloatArray] = []
    total = len(keys) - 1
    prepared = None
    for p, (a, b) in enumerate(itertools.pairwise(keys)):
        try:
            if prepared is None or prepared[0] != a:
                pts_a = scan_points(ranges[a], laser.beam_angles, laser.max_range)
                prepared = (a, prepare_scan(pts_a))
            pts_b = scan_points(ranges[b], laser.beam_angles, laser.max_range)
            # The laser's motion guessed from the wheels: T_La_Lb = M⁻¹ ⊕ T_Ra_Rb ⊕ M.
            guess = compose(compose(mount_inv, between(odom[a], odom[b])), mount)
            match = plicp(prepared[1], pts_b, guess, config)
        except MatchError as exc:
            dropped[exc.reason] += 1
            prepared = None
        else:
            if match.inlier_fraction < min_inlier_fraction:
                dropped["low_overlap"] += 1
            else:
                first.append(a)
                last.append(b)
                measured.append(match.pose)
                covs.append(_in_own_frame(match.pose, match.cov))
        if progress is not None:
            progress(p + 1, total)
    return ScanPairs(
        steps=steps,
        first=np.asarray(first, dtype=np.int64),
        last=np.asarray(last, dtype=np.int64),
        T_laser=np.asarray(measured, dtype=np.float64).reshape(-1, 3),
        cov=np.asarray(covs, dtype=np.float64).reshape(-1, 3, 3),
        nominal_mounting=mount,
        dropped=dict(dropped),
        keyframes=len(keys),
    )
