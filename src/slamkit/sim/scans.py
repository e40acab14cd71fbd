"""Simulated pairs of laser scans with a known relative motion, for testing scan matchers.

A pair is two scans of the same wall world taken from two sensor poses. The points of each
scan are in its own sensor frame and in scan (beam) order, beams without a return removed;
``T_ref_cur = between(pose_ref, pose_cur)`` is what a matcher should recover (the frame
convention of :mod:`slamkit.scanmatch.result`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.errors import InputError
from slamkit.geometry.pose2 import between, compose
from slamkit.maps import SegmentMap
from slamkit.models.laser import LaserScanner, scan_points

__all__ = [
    "ROOMS_FREE_POSES",
    "ScanPair",
    "corridor_world",
    "random_scan_pairs",
    "simulated_scan_pair",
]

ROOMS_FREE_POSES = np.array(
    [
        [5.0, 2.5],
        [7.0, 1.5],
        [14.0, 2.0],
        [18.0, 1.5],
        [12.5, 3.5],
        [6.0, 9.5],
        [9.0, 9.0],
        [4.0, 8.5],
        [15.5, 9.5],
        [17.5, 8.5],
    ]
)
"""Positions ``(n, 2)`` [m] inside the four rooms of :func:`slamkit.sim.rooms_world`, each at
least 1.2 m from every wall and pillar: safe centres for sensor poses jittered by up to
0.3 m and moved by up to 0.5 m."""


@dataclass(frozen=True, eq=False)
class ScanPair:
    """Two simulated scans and the motion between them.

    * ``reference (M, 2)``, ``current (K, 2)``: beam end points [m] in each scan's own sensor
      frame, in beam order, no-return beams removed;
    * ``T_ref_cur (3,)``: the true pose of the current sensor in the reference sensor frame;
    * ``pose_ref (3,)``, ``pose_cur (3,)``: the two sensor poses in the world frame.
    """

    reference: FloatArray
    current: FloatArray
    T_ref_cur: FloatArray
    pose_ref: FloatArray
    pose_cur: FloatArray


def simulated_scan_pair(
    world: SegmentMap,
    pose_ref: ArrayLike,
    pose_cur: ArrayLike,
    beam_angles: ArrayLike,
    max_range: float,
    range_sigma: float,
    rng: np.random.Generator,
) -> ScanPair:
    """Scan ``world`` from ``pose_ref`` and from ``pose_cur`` (sensor poses ``(3,)``) with
    beams at ``beam_angles (B,)`` [rad], ``max_range`` [m] (no return at or beyond it) and
    Gaussian range noise of ``range_sigma`` [m]; both scans draw their noise from ``rng``."""
    p_ref = as_array(pose_ref, "pose_ref", (3,))
    p_cur = as_array(pose_cur, "pose_cur", (3,))
    scanner = LaserScanner(as_array(beam_angles, "beam_angles", (None,)), max_range, range_sigma)
    ranges = scanner.simulate(np.stack([p_ref, p_cur]), world, rng)
    ref = scan_points(ranges[0], scanner.beam_angles, scanner.max_range)
    cur = scan_points(ranges[1], scanner.beam_angles, scanner.max_range)
    return ScanPair(ref, cur, between(p_ref, p_cur), p_ref.copy(), p_cur.copy())


def random_scan_pairs(
    world: SegmentMap,
    n: int,
    rng: np.random.Generator,
    *,
    beam_angles: ArrayLike,
    max_range: float,
    range_sigma: float,
    motion: tuple[float, float] = (0.3, np.deg2rad(10.0)),
    centres: ArrayLike = ROOMS_FREE_POSES,
    jitter: float = 0.3,
) -> list[ScanPair]:
    """``n`` scan pairs: the reference pose at a random one of ``centres (C, 2)`` jittered
    uniformly by up to ``jitter`` [m] per axis, with a uniform random heading; the motion to
    the current pose has a translation of length ``motion[0]`` [m] in a uniform random
    direction and a rotation of ``±motion[1]`` [rad] (random sign). The defaults suit
    :func:`slamkit.sim.rooms_world`."""
    if int(n) != n or n < 0:
        raise InputError(f"n: expected a non-negative integer, got {n!r}")
    c = as_array(centres, "centres", (None, 2))
    if c.shape[0] == 0:
        raise InputError("centres: expected at least one position, got none")
    step = as_positive(motion[0], "motion translation", allow_zero=True)
    turn = float(motion[1])
    jit = as_positive(jitter, "jitter", allow_zero=True)
    pairs = []
    for _ in range(int(n)):
        xy = c[rng.integers(c.shape[0])] + rng.uniform(-jit, jit, 2)
        pose_ref = np.array([xy[0], xy[1], rng.uniform(-np.pi, np.pi)])
        direction = rng.uniform(-np.pi, np.pi)
        sign = 1.0 if rng.random() < 0.5 else -1.0
        delta = np.array([step * np.cos(direction), step * np.sin(direction), sign * turn])
        pose_cur = compose(pose_ref, delta)
        pairs.append(
            simulated_scan_pair(world, pose_ref, pose_cur, beam_angles, max_range, range_sigma, rng)
        )
    return pairs


def corridor_world(length: float = 200.0, width: float = 2.0) -> SegmentMap:
    """Two parallel walls ``length`` [m] long along x, at ``y = ±width / 2``: a featureless
    corridor in which a laser cannot tell its position along x (centred on the origin)."""
    half_l = as_positive(length, "length") / 2.0
    half_w = as_positive(width, "width") / 2.0
    return SegmentMap(
        np.array(
            [
                [[-half_l, -half_w], [half_l, -half_w]],
                [[-half_l, half_w], [half_l, half_w]],
            ]
        )
    )
