"""The FastSLAM particle set: poses, per-particle landmark Gaussians and log-weights (a
validated value type), and the checks that build one from trusted arrays."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError, ShapeError
from slamkit.estimation.contract import (
    LandmarkEstimate,
)
from slamkit.geometry.angles import wrap_angle
from slamkit.maps import LandmarkMap

IntArray = NDArray[np.int64]

LOG_2PI = math.log(2.0 * math.pi)
NEGLIGIBLE_LOG_WEIGHT = -700.0


# --------------------------------------------------------------------------------------------
# The particle set
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FastSlamParticles:
    """``P`` particles, each a pose and a map of up to ``C`` (the capacity) 2-D landmarks.

    ``poses (P, 3)``; ``log_weights (P,)`` normalised (``logsumexp = 0``); ``means (P, C, 2)``
    and ``covs (P, C, 2, 2)`` the landmark EKFs in world metres; ``counters (P, C)`` the
    existence counters; ``ids (P, C)`` the landmark ids; ``counts (P,)`` how many slots of
    each particle are used (slots ``>= counts[p]`` hold nothing). ``next_id`` is the id the
    next landmark started by an unlabelled reading gets.

    Values are treated as immutable: every function returns a new set, and none shares a
    buffer with its input.
    """

    poses: FloatArray
    log_weights: FloatArray
    means: FloatArray
    covs: FloatArray
    counters: IntArray
    ids: IntArray
    counts: IntArray
    next_id: int = 0

    def __post_init__(self) -> None:
        poses = as_array(self.poses, "particle poses", (None, 3))
        n = poses.shape[0]
        if n == 0:
            raise InputError("particle poses: expected at least one particle, got none")
        logw = as_array(self.log_weights, "log_weights", (n,), finite=False)
        if np.any(np.isnan(logw)) or np.any(logw == np.inf):
            raise InputError("log_weights: expected finite values or -inf, got NaN or +inf")
        means = as_array(self.means, "landmark means", (n, None, 2))
        cap = means.shape[1]
        covs = as_array(self.covs, "landmark covariances", (n, cap, 2, 2))
        counters = int_array(self.counters, "counters", (n, cap))
        ids = int_array(self.ids, "ids", (n, cap))
        counts = int_array(self.counts, "counts", (n,))
        if np.any((counts < 0) | (counts > cap)):
            raise InputError(f"counts: expected values in [0, {cap}], got {counts.tolist()}")
        for name, value in (
            ("poses", poses),
            ("log_weights", logw),
            ("means", means),
            ("covs", covs),
            ("counters", counters),
            ("ids", ids),
            ("counts", counts),
        ):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "next_id", int(self.next_id))

    @classmethod
    def start(cls, poses: ArrayLike, capacity: int = 8, next_id: int = 0) -> FastSlamParticles:
        """Particles at ``poses (P, 3)`` (copied, headings wrapped), equal weights, no
        landmarks, room for ``capacity`` landmarks each before the arrays grow."""
        p = as_array(poses, "particle poses", (None, 3)).copy()
        p[:, 2] = wrap_angle(p[:, 2])
        n = p.shape[0]
        if n == 0:
            raise InputError("particle poses: expected at least one particle, got none")
        cap = int(capacity)
        if cap < 1:
            raise InputError(f"capacity: expected an integer >= 1, got {capacity}")
        return cls(
            p,
            np.full(n, -math.log(n)),
            np.zeros((n, cap, 2)),
            np.zeros((n, cap, 2, 2)),
            np.zeros((n, cap), dtype=np.int64),
            np.full((n, cap), -1, dtype=np.int64),
            np.zeros(n, dtype=np.int64),
            next_id,
        )

    def __len__(self) -> int:
        return int(self.poses.shape[0])

    @property
    def capacity(self) -> int:
        return int(self.means.shape[1])

    @property
    def weights(self) -> FloatArray:
        """Normalised weights ``(P,)``. Log-weights below ``-700`` give exactly 0 (as
        :attr:`ParticleSet.weights`: below any effect on a sum, and subnormal otherwise)."""
        lw = self.log_weights
        w: FloatArray = np.zeros(lw.shape)
        np.exp(lw, out=w, where=lw > NEGLIGIBLE_LOG_WEIGHT)
        return w / w.sum()

    @property
    def best(self) -> int:
        """Index of the particle with the largest weight (the first of equals)."""
        return int(np.argmax(self.log_weights))

    def select(self, indices: ArrayLike) -> FastSlamParticles:
        """The particles ``indices`` with equal weights: a copy by fancy indexing, so a
        selected particle's map shares no memory with this set or another selected one."""
        idx = np.asarray(indices, dtype=np.intp)
        if idx.ndim != 1 or idx.size == 0:
            raise ShapeError(f"indices: expected a non-empty (n,) array, got {idx.shape}")
        if np.any((idx < 0) | (idx >= len(self))):
            raise InputError(f"indices: expected values in [0, {len(self)})")
        return trusted_particles(
            self.poses[idx],
            np.full(idx.size, -math.log(idx.size)),
            self.means[idx],
            self.covs[idx],
            self.counters[idx],
            self.ids[idx],
            self.counts[idx],
            self.next_id,
        )

    def landmarks_of(self, particle: int) -> LandmarkEstimate:
        """The map of one particle, landmarks ordered by id, with their 2×2 covariances.

        The covariances are conditional on the particle's path: they leave out the pose
        uncertainty, which lives in the spread of the particles."""
        i = int(particle)
        if not 0 <= i < len(self):
            raise InputError(f"particle: expected an index in [0, {len(self)}), got {particle}")
        n = int(self.counts[i])
        ids = self.ids[i, :n]
        order = np.argsort(ids, kind="stable")
        return LandmarkEstimate(
            LandmarkMap(self.means[i, :n][order].copy(), ids[order].copy()),
            self.covs[i, :n][order].copy(),
        )


def int_array(value: ArrayLike, name: str, shape: tuple[int, ...]) -> IntArray:
    arr = np.asarray(value)
    if arr.shape != shape:
        raise ShapeError(f"{name}: expected shape {shape}, got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise InputError(f"{name}: expected integers, got {arr.dtype}")
    return arr.astype(np.int64)


def trusted_particles(
    poses: FloatArray,
    log_weights: FloatArray,
    means: FloatArray,
    covs: FloatArray,
    counters: IntArray,
    ids: IntArray,
    counts: IntArray,
    next_id: int,
) -> FastSlamParticles:
    """A particle set from arrays the kernels built themselves (no re-validation)."""
    ps = object.__new__(FastSlamParticles)
    for name, value in (
        ("poses", poses),
        ("log_weights", log_weights),
        ("means", means),
        ("covs", covs),
        ("counters", counters),
        ("ids", ids),
        ("counts", counts),
        ("next_id", int(next_id)),
    ):
        object.__setattr__(ps, name, value)
    return ps
