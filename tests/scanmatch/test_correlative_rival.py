"""The runner-up of a correlative search (:func:`correlative_rival`): found where a
reference repeats itself, absent where it does not, and the same from every search order."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from slamkit.backend import SEAM, Backend
from slamkit.geometry.pose2 import between
from slamkit.models.laser import LaserScanner
from slamkit.scanmatch import (
    CorrelativeConfig,
    CorrelativeReference,
    correlative_match,
    scan_points,
)
from slamkit.scanmatch.correlative import correlative_rival
from slamkit.sim.worlds import rooms_world

SPOT = np.array([5.0, 6.0, 0.3])  # in rooms_world's corridor
CFG = CorrelativeConfig(window_xy=3.0, window_theta=math.radians(10), levels=5)


def _scan(pose: np.ndarray, rng: np.random.Generator, beams: int) -> np.ndarray:
    laser = LaserScanner.from_fov(2 * np.pi, beams, 12.0, 0.01)
    return scan_points(laser.simulate(pose, rooms_world(), rng), laser.beam_angles, 12.0)


def _case(seed: int, copy: tuple[float, float] | None):
    """A reference scan (with a copy of itself shifted by ``copy`` in its frame, when given),
    a current scan from a pose nearby and the true ``T_ref_cur``."""
    rng = np.random.default_rng(seed)
    moved = SPOT + np.array([*rng.uniform(-0.3, 0.3, 2), rng.uniform(-0.1, 0.1)])
    ref = _scan(SPOT, rng, 360)
    if copy is not None:
        ref = np.vstack([ref, ref + np.asarray(copy)])
    return ref, _scan(moved, rng, 180), between(SPOT, moved)


@pytest.mark.parametrize("seed", range(3))
def test_a_reference_that_repeats_itself_has_a_rival_one_copy_away(seed: int) -> None:
    ref, cur, truth = _case(seed, (2.0, 0.0))
    reference = CorrelativeReference.from_points(ref, CFG)
    best = correlative_match(reference, cur, np.zeros(3), CFG)
    rival = correlative_rival(reference, cur, np.zeros(3), best, 0.3, 0.9, CFG)
    assert rival is not None and rival >= 0.9 * best.score
    # Left out with everything within 2.1 m of the optimum, the copy cannot be found.
    assert correlative_rival(reference, cur, np.zeros(3), best, 2.1, 0.9, CFG) is None
    # The optimum is one of the two places: the truth, or the truth moved by the copy.
    off = best.pose[:2] - truth[:2]
    assert min(np.hypot(*off), np.hypot(*(off - [2.0, 0.0]))) < 0.1


@pytest.mark.parametrize("seed", range(3))
def test_a_reference_seen_once_has_no_rival(seed: int) -> None:
    ref, cur, truth = _case(seed, None)
    reference = CorrelativeReference.from_points(ref, CFG)
    best = correlative_match(reference, cur, np.zeros(3), CFG)
    assert np.abs(best.pose[:2] - truth[:2]).max() < 0.1
    assert correlative_rival(reference, cur, np.zeros(3), best, 0.3, 0.9, CFG) is None


@pytest.mark.parametrize("seed", range(2))
def test_the_rival_is_the_same_from_every_search(seed: int) -> None:
    # A reference repeated 1.2 m along x, so that a rival exists: it scores the same in the
    # exhaustive search, the NumPy rounds and the compiled depth-first search, and an
    # optimum's own flank (the best pose just outside the left-out square) is never it.
    ref, cur, _ = _case(seed, (1.2, 0.0))
    small = CorrelativeConfig(window_xy=1.5, window_theta=0.1, angular_step=0.02, levels=4)
    reference = CorrelativeReference.from_points(ref, small)
    best = correlative_match(reference, cur, np.zeros(3), small)
    args = (reference, cur, np.zeros(3), best, 0.2, 0.8)
    fast = correlative_rival(*args, small)
    with SEAM.use(Backend.NUMPY):
        slow = correlative_rival(*args, small)
    exhaustive = correlative_rival(*args, replace(small, search="exhaustive"))
    assert fast is not None and fast == slow == exhaustive
    assert 0.8 * best.score <= fast <= best.score
