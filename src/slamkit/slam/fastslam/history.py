"""What a FastSLAM run reports: its association history (every scan's association per
particle and every resampling's parent indices, from which the association of any final
particle is traced back through its ancestors) and the summary of its particles."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.estimation.particles import particle_estimate_unchecked
from slamkit.mapping.ekf_mapping import TOO_CLOSE
from slamkit.slam.fastslam.particles import FastSlamParticles, IntArray

__all__ = ["AssociationHistory", "mixture_estimate", "particle_diagnostics"]


class AssociationHistory:
    """Per scan ``(time, ids (K,) or (K, P), status codes)`` and per resampling the parent
    indices ``(P,)``, in order."""

    def __init__(self) -> None:
        self._entries: list[tuple[float, IntArray, NDArray[np.int8]] | NDArray[np.intp]] = []

    def log_scan(
        self,
        t: float,
        assoc: IntArray,
        status: NDArray[np.int8],
        use: NDArray[np.bool_] | None,
    ) -> None:
        """Keep the association of a scan; ``use`` marks the readings that were not skipped
        (None: all), the others are logged ``TOO_CLOSE``."""
        if use is not None:
            a = np.full((use.size, *assoc.shape[1:]), -1, dtype=np.int64)
            s = np.full((use.size, *status.shape[1:]), TOO_CLOSE, dtype=np.int8)
            if assoc.size:
                a[use], s[use] = assoc, status
            assoc, status = a, s
        self._entries.append((float(t), assoc, status))

    def log_resampling(self, parents: NDArray[np.intp]) -> None:
        """The parent of every new particle, at a resampling."""
        self._entries.append(parents)

    def trace(self, particle: int) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """Every reading as ``particle`` (now) saw it, its own association and those of its
        ancestors: ``(times, landmark ids, status)``."""
        p = particle
        times, ids, status = [], [], []
        for entry in reversed(self._entries):
            if isinstance(entry, np.ndarray):
                p = int(entry[p])  # the parent of particle p before that resampling
                continue
            t, a, s = entry
            times.append(np.full(a.shape[0], t))
            ids.append(a[:, p] if a.ndim == 2 else a)
            status.append(s[:, p] if s.ndim == 2 else s)

        def cat(parts: list[NDArray[Any]], dtype: type) -> NDArray[Any]:
            return np.concatenate(parts[::-1]).astype(dtype) if parts else np.zeros(0, dtype)

        return cat(times, np.float64), cat(ids, np.int64), cat(status, np.int64)


def particle_diagnostics(particles: FastSlamParticles, ess: FloatArray) -> dict[str, Any]:
    """The run's summary of a particle set and of its effective sample sizes ``ess`` after
    every measurement update: particles, landmarks in the heaviest particle and over all,
    storage capacity, ESS statistics, the heaviest particle's weight."""
    best, counts = particles.best, particles.counts
    return {
        "n_particles": len(particles),
        "landmarks": int(counts[best]),
        "landmarks_mean": float(counts.mean()),
        "landmarks_min": int(counts.min()),
        "landmarks_max": int(counts.max()),
        "capacity": particles.capacity,
        "ess_min": float(ess.min()) if ess.size else None,
        "ess_mean": float(ess.mean()) if ess.size else None,
        "ess_median": float(np.median(ess)) if ess.size else None,
        "ess_final": float(ess[-1]) if ess.size else None,
        "best_particle_weight": float(particles.weights[best]),
    }


def mixture_estimate(
    poses: FloatArray, weights: FloatArray, covs: FloatArray | None, best: int | None
) -> tuple[FloatArray, FloatArray]:
    """The estimate of a weighted particle set (normalised ``weights``): mean and spread of
    ``poses``, plus the weighted mean of each particle's own covariance ``covs (P, 3, 3)``
    when they are Gaussians; the pose of particle ``best`` instead of the mean if given."""
    mean, cov = particle_estimate_unchecked(poses, weights)
    if covs is not None:
        cov = cov + np.einsum("p,pij->ij", weights, covs)
    if best is not None:
        mean = poses[best].copy()
    return mean, cov
