"""Place recognition: loop candidates that do not depend on how far the estimate drifted.

The local loop search (:func:`~slamkit.slam.laser_graph.loops.loop_candidates`) looks for
old keyframes near the current estimate, within a radius grown with the path travelled. A
front end that drifted farther than that radius never finds its loop. So each keyframe also
gets a *signature* of what it saw, in its own frame: a polar occupancy of its own scan and
those of the keyframes before it
(:data:`~slamkit.slam.laser_graph.freespace.NEIGHBOURHOOD_KEYFRAMES`
in all), :data:`RINGS` rings of :data:`RING_WIDTH` by :data:`SECTORS` sectors, each cell
occupied when a point falls in it (Kim and Kim's Scan Context, here on a laser's plane).

* Its *ring key*, the share of occupied sectors in each ring, does not change when the robot
  turns on the spot: old keyframes whose ring keys are nearest the new one's (L1) are the
  places the robot may be at, wherever the estimate puts it.
* Their full signatures, compared over every turn of the sectors (the cells both occupy,
  over the geometric mean of their counts), give the likeliest one and the turn between
  the two: the correlative verification starts there, the translation window
  :data:`WINDOW_XY` around the old keyframe and the rotation :data:`WINDOW_DEG` around the
  turn.

What the signature cannot tell apart (identical rooms, a corridor from either end) is for
the verification, the free-space check and the back end: a candidate is only a hypothesis.
"""

from __future__ import annotations

import math

import numpy as np

from slamkit._validation import FloatArray

__all__ = [
    "RINGS",
    "RING_WIDTH",
    "SECTORS",
    "SHORTLIST",
    "WINDOW_DEG",
    "WINDOW_XY",
    "PlaceIndex",
    "signature",
]

RINGS = 20
"""Rings of the polar signature ..."""
RING_WIDTH = 0.5
"""... each this wide [m] (so it covers 10 m around the keyframe)."""
SECTORS = 90
"""Sectors of the polar signature (4° each)."""
SHORTLIST = 10
"""Old keyframes, nearest by ring key, whose whole signatures are compared."""
MIN_SIMILARITY = 0.5
"""A shortlisted keyframe is a candidate only when at least this share of the occupied
cells agree (the geometric mean of the two counts; 1: the same cells)."""
WINDOW_XY = 1.5
"""The verification's translation window around the old keyframe [m] (keyframes are 0.4 m
apart and a revisit passes within a corridor's width of the old path) ..."""
WINDOW_DEG = 12.0
"""... and its rotation window around the signatures' turn [deg] (three sectors)."""


def signature(points: FloatArray) -> np.ndarray:
    """The polar occupancy ``(RINGS, SECTORS)`` (bool) of ``points (N, 2)`` in a keyframe's
    frame (see the module docstring)."""
    r = np.hypot(points[:, 0], points[:, 1])
    ring = (r / RING_WIDTH).astype(np.int64)
    keep = ring < RINGS
    angle = np.arctan2(points[keep, 1], points[keep, 0])
    sector = ((angle + math.pi) / (2 * math.pi) * SECTORS).astype(np.int64) % SECTORS
    grid = np.zeros((RINGS, SECTORS), dtype=bool)
    grid[ring[keep], sector] = True
    return grid


class PlaceIndex:
    """The signatures of every keyframe so far, searched by ring key."""

    def __init__(self) -> None:
        self._grids: list[np.ndarray] = []
        self._keys = np.zeros((64, RINGS))  # ring keys, rows doubled when full
        self._spectra: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self._grids)

    def add(self, grid: np.ndarray) -> None:
        """The next keyframe's :func:`signature`."""
        n = len(self._grids)
        if n == self._keys.shape[0]:
            self._keys = np.vstack([self._keys, np.zeros_like(self._keys)])
        self._keys[n] = grid.mean(axis=1)
        self._grids.append(grid)
        self._spectra.append(np.fft.rfft(grid.astype(np.float64), axis=1))

    def candidates(self, k: int, eligible: np.ndarray, count: int) -> list[tuple[int, float]]:
        """Up to ``count`` old keyframes ``j`` (``eligible (K,)`` bool) whose signature is most
        like keyframe ``k``'s, best first, with the turn ``θ_k − θ_j`` [rad] that aligns
        them; only those sharing at least :data:`MIN_SIMILARITY` of their cells."""
        pool = np.flatnonzero(eligible[: len(self._grids)])
        if pool.size == 0 or not self._grids[k].any():
            return []
        d = np.abs(self._keys[pool] - self._keys[k]).sum(axis=1)
        short = pool[np.argsort(d, kind="stable")[:SHORTLIST]]
        n_k = self._grids[k].sum()
        found = []
        for j in short.tolist():
            n_j = self._grids[j].sum()
            if n_j == 0:
                continue
            # Cells both occupy for every turn s of k's sectors: Σ_r Σ_i k[r, i + s] j[r, i].
            overlap = np.fft.irfft(
                (self._spectra[k] * np.conj(self._spectra[j])).sum(axis=0), n=SECTORS
            )
            s = int(np.argmax(overlap))
            similarity = float(overlap[s]) / math.sqrt(float(n_k) * float(n_j))
            if similarity >= MIN_SIMILARITY:
                # k's sector i + s holds what j's sector i does: k is turned by -s sectors.
                turn = -2.0 * math.pi * s / SECTORS
                found.append((similarity, j, math.atan2(math.sin(turn), math.cos(turn))))
        found.sort(key=lambda f: -f[0])
        return [(j, turn) for _, j, turn in found[:count]]
