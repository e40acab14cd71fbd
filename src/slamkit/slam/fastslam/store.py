"""The working store of a FastSLAM run: per-particle landmark means and covariances in planar
struct-of-arrays (``Work``), grown as landmarks are added."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.slam.fastslam.particles import FastSlamParticles, IntArray, trusted_particles

# --------------------------------------------------------------------------------------------
# Kernels (trusted inputs)
# --------------------------------------------------------------------------------------------


# Rows of the planar landmark store ``Work.lm (5, C, P)``: mean x, y; covariance Σ00, Σ01, Σ11.
MX, MY, _S00, _S01, _S11 = range(5)
TWO_PI = 2.0 * math.pi


# The association of a set that has seen no scan yet (shared, read-only).
_NO_IDS: IntArray = np.zeros(0, dtype=np.int64)
_NO_STATUS: NDArray[np.int8] = np.zeros(0, dtype=np.int8)
_NO_IDS.setflags(write=False)
_NO_STATUS.setflags(write=False)


class Work:
    """The mutable maps of a particle set, planar and slot-major: ``lm (5, C, P)`` holds the
    mean ``(x, y)`` and the covariance entries ``(Σ00, Σ01, Σ11)`` of slot ``j`` of every
    particle as contiguous rows ``lm[:, j]``; ``counters``, ``ids`` ``(C, P)``, ``counts``
    ``(P,)``. At 100 particles × a few readings NumPy's per-call overhead, not the
    arithmetic, is the cost: a scan's landmarks are gathered in one fancy-indexing
    operation, and with the particles on the last axis every operation (poses ``(P,)``
    broadcast against ``(K, P)`` blocks) runs one long inner loop — with particles first,
    a ``(P, 1)`` by ``(P, K)`` product costs ~6x a flat one. ``seen``/``updated`` ``(C, P)``
    mark the slots a scan matched or started (:meth:`begin_scan` clears them); ``removed``
    counts the landmarks the scan pruned."""

    seen: NDArray[np.bool_]
    updated: NDArray[np.bool_]

    def __init__(
        self,
        lm: FloatArray,
        counters: IntArray,
        ids: IntArray,
        counts: IntArray,
        next_id: int,
        scratch_of: Work | None = None,
    ) -> None:
        self.lm = lm
        self.counters = counters
        self.ids = ids
        self.counts = counts
        self.next_id = next_id
        self.removed = 0
        # The last scan's association: landmark id and status code of each reading, (K,)
        # when every particle agrees, else (K, P).
        self.assoc: IntArray = _NO_IDS
        self.assoc_status: NDArray[np.int8] = _NO_STATUS
        self.seen: NDArray[np.bool_]
        self.updated: NDArray[np.bool_]
        if scratch_of is not None and scratch_of.seen.shape == ids.shape:
            self.seen, self.updated = scratch_of.seen, scratch_of.updated
        else:
            self.seen = np.zeros(ids.shape, dtype=bool)
            self.updated = np.zeros(ids.shape, dtype=bool)
        self.all_ok = True  # the last update found every landmark off the sensor
        # False only while no landmark can have been started by an unlabelled reading.
        self.maybe_prunable = True
        # Whether every particle holds the same ids in the same slots (None: not known),
        # and then the slot of each id (None: not built yet).
        self._common: bool | None = None
        self.slot_of: dict[int, int] | None = None

    @property
    def common(self) -> bool | None:
        return self._common

    @common.setter
    def common(self, value: bool | None) -> None:
        self._common = value
        self.slot_of = None

    @classmethod
    def of(cls, ps: FastSlamParticles) -> Work:
        """A working copy of the maps of ``ps`` (shares no memory with it)."""
        n, cap = ps.ids.shape
        lm = np.empty((5, cap, n))
        lm[MX], lm[MY] = ps.means[..., 0].T, ps.means[..., 1].T
        lm[_S00], lm[_S01] = ps.covs[..., 0, 0].T, ps.covs[..., 0, 1].T
        lm[_S11] = ps.covs[..., 1, 1].T
        return cls(lm, ps.counters.T.copy(), ps.ids.T.copy(), ps.counts.copy(), ps.next_id)

    def particles(self, poses: FloatArray, log_weights: FloatArray) -> FastSlamParticles:
        """The maps as a particle set (new arrays) with ``poses`` and ``log_weights``."""
        means, covs = self.gaussians((slice(None), slice(None)))
        return trusted_particles(poses, log_weights, np.swapaxes(means, 0, 1).copy(),
                        np.swapaxes(covs, 0, 1).copy(), self.counters.T.copy(),
                        self.ids.T.copy(), self.counts.copy(), self.next_id)  # fmt: skip

    def gaussians(self, index: tuple[Any, Any]) -> tuple[FloatArray, FloatArray]:
        """Means ``(..., 2)`` and covariances ``(..., 2, 2)`` of the slots ``index``
        (``(slots, particles)``, any NumPy index), as new arrays."""
        g = self.lm[(slice(None), *index)]
        means = np.stack((g[MX], g[MY]), axis=-1)
        covs = np.empty((*g.shape[1:], 2, 2))
        covs[..., 0, 0], covs[..., 1, 1] = g[_S00], g[_S11]
        covs[..., 0, 1] = covs[..., 1, 0] = g[_S01]
        return means, covs

    def select(self, indices: NDArray[np.intp]) -> Work:
        """The maps of the particles ``indices`` (resampling), replacing this object (which
        is not used afterwards): copies by fancy indexing, so two selected particles never
        share a landmark buffer. When every particle holds the same labelled landmarks in
        the same slots (``common``, nothing prunable), the ids, counters and counts are the
        same in every column and are passed on as they are; so are the per-scan scratch
        marks (cleared by :meth:`begin_scan`)."""
        same_layout = bool(self.common) and not self.maybe_prunable
        if same_layout:
            counters, ids, counts = self.counters, self.ids, self.counts
        else:
            counters, ids, counts = (self.counters[:, indices], self.ids[:, indices],
                                     self.counts[indices])  # fmt: skip
        w = Work(self.lm[:, :, indices], counters, ids, counts, self.next_id, self)
        w.common = True if self.common else None
        w.maybe_prunable = self.maybe_prunable
        w.slot_of = self.slot_of  # the same slots: resampling keeps a common layout common
        return w

    def move(self, angles: FloatArray, shifts: FloatArray) -> None:
        """Move every particle's map rigidly into another frame, particle ``p`` by
        ``m ← R(angles[p]) m + shifts[p]`` (``(P,)``, ``(P, 2)``), ``Σ ← R Σ Rᵀ`` (in place;
        unused slots are moved too, harmlessly). With ``Σ = [[a, b], [b, d]]``::

            a' = c²a − 2cs b + s²d,  b' = cs (a − d) + (c² − s²) b,  d' = s²a + 2cs b + c²d
        """
        c, s = np.cos(angles), np.sin(angles)
        lm = self.lm
        x, y = lm[MX].copy(), lm[MY]
        lm[MX] = c * x - s * y + shifts[:, 0]
        lm[MY] = s * x + c * y + shifts[:, 1]
        a, b, d = lm[_S00].copy(), lm[_S01].copy(), lm[_S11].copy()
        cc, ss, cs = c * c, s * s, c * s
        lm[_S00] = cc * a - 2.0 * cs * b + ss * d
        lm[_S11] = ss * a + 2.0 * cs * b + cc * d
        lm[_S01] = cs * (a - d) + (cc - ss) * b

    def begin_scan(self) -> None:
        self.seen.fill(False)
        self.updated.fill(False)
        self.removed = 0

    @property
    def capacity(self) -> int:
        return int(self.ids.shape[0])

    def valid(self, cmax: int | None = None) -> NDArray[np.bool_]:
        """``(cmax, P)``: which of the first ``cmax`` slots (default: all) are in use."""
        c = self.capacity if cmax is None else cmax
        return np.arange(c)[:, None] < self.counts

    def is_common(self, cmax: int) -> bool:
        if self.common is None:
            c = self.counts
            ids = self.ids[:cmax]
            self.common = bool((c == c[0]).all() and (ids == ids[:, :1]).all())
        return self.common

    def grow(self, needed: int) -> None:
        """Double the capacity until ``needed`` slots fit (copying every array)."""
        cap = self.capacity
        if needed <= cap:
            return
        new = cap
        while new < needed:
            new *= 2
        n = self.counts.size
        lm = np.zeros((5, new, n))
        lm[:, :cap] = self.lm
        self.lm = lm

        def widen(a: NDArray[Any], fill: Any) -> NDArray[Any]:
            out = np.full((new, n), fill, dtype=a.dtype)
            out[:cap] = a
            return out

        self.counters = widen(self.counters, 0)
        self.ids = widen(self.ids, -1)
        self.seen = widen(self.seen, False)
        self.updated = widen(self.updated, False)


# What `landmark_terms` returns for `ok` when every landmark is off the sensor (broadcasts).
ALL_OK = np.ones((), dtype=bool)

# Rows of the stacked innovation terms of :func:`landmark_terms`.
ZH0, ZH1, H00, H01, H10, H11, T00, T01, T10, T11, I00, I01, I11, LOGDET = range(14)
