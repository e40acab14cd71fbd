"""The map belief of EKF mapping: block-diagonal (:class:`LandmarkBelief`, the fast form) and
full-matrix (:class:`DenseLandmarkBelief`, the textbook reference)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError, ShapeError
from slamkit.estimation.contract import LandmarkEstimate
from slamkit.mapping.ekf_mapping.inputs import as_landmark_ids
from slamkit.maps import LandmarkMap

__all__ = ["DenseLandmarkBelief", "LandmarkBelief", "trusted_belief"]


@dataclass(frozen=True)
class LandmarkBelief:
    """The map belief in block-diagonal form: landmark ``k`` with id ``ids[k]`` is
    ``N(means[k], covs[k])``, independent of every other (see
    :mod:`slamkit.mapping.ekf_mapping` for why this is exact when the poses are known).

    ``ids (n,)`` unique integers, ``means (n, 2)`` world metres, ``covs (n, 2, 2)``. Values
    are treated as immutable: the functions below return new beliefs.
    """

    ids: NDArray[np.int64]
    means: FloatArray
    covs: FloatArray

    def __post_init__(self) -> None:
        means = as_array(self.means, "landmark means", (None, 2))
        n = means.shape[0]
        ids = as_landmark_ids(self.ids, "landmark ids", n)
        if np.unique(ids).size != n:
            raise InputError("landmark ids: expected unique ids, got duplicates")
        covs = as_array(self.covs, "landmark covariances", (n, 2, 2))
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "means", means)
        object.__setattr__(self, "covs", covs)

    @classmethod
    def empty(cls) -> LandmarkBelief:
        return cls(np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros((0, 2, 2)))

    def __len__(self) -> int:
        return int(self.ids.size)

    def index_of(self, ids: ArrayLike) -> NDArray[np.int64]:
        """Row of each id in this belief, ``-1`` for ids not (yet) mapped."""
        want = np.asarray(ids, dtype=np.int64)
        if self.ids.size == 0:
            return np.full(want.shape, -1, dtype=np.int64)
        order = np.argsort(self.ids)
        pos = np.clip(np.searchsorted(self.ids, want, sorter=order), 0, self.ids.size - 1)
        rows = order[pos]
        return np.where(self.ids[rows] == want, rows, -1).astype(np.int64)

    def to_landmark_estimate(self) -> LandmarkEstimate:
        """The map and per-landmark covariances in the estimator-output form."""
        return LandmarkEstimate(LandmarkMap(self.means.copy(), self.ids.copy()), self.covs.copy())

    def to_dense(self) -> DenseLandmarkBelief:
        """The same belief as one ``2n`` vector and a block-diagonal ``2n × 2n`` matrix."""
        n = len(self)
        cov = np.zeros((2 * n, 2 * n))
        for k in range(n):
            cov[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = self.covs[k]
        return DenseLandmarkBelief(self.ids.copy(), self.means.reshape(-1).copy(), cov)


@dataclass(frozen=True)
class DenseLandmarkBelief:
    """The map belief as the textbook EKF holds it: ``mean (2n,)`` = ``(x_1, y_1, …)`` and
    the full covariance ``cov (2n, 2n)``, landmark ``k`` with id ``ids[k]`` in rows
    ``2k, 2k+1``. The reference implementation; :class:`LandmarkBelief` is the fast one."""

    ids: NDArray[np.int64]
    mean: FloatArray
    cov: FloatArray

    def __post_init__(self) -> None:
        mean = as_array(self.mean, "map mean", (None,))
        if mean.size % 2:
            raise ShapeError(f"map mean: expected an even length (x, y pairs), got {mean.size}")
        ids = as_landmark_ids(self.ids, "landmark ids", mean.size // 2)
        if np.unique(ids).size != ids.size:
            raise InputError("landmark ids: expected unique ids, got duplicates")
        cov = as_array(self.cov, "map covariance", (mean.size, mean.size))
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

    @classmethod
    def empty(cls) -> DenseLandmarkBelief:
        return cls(np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros((0, 0)))

    def __len__(self) -> int:
        return int(self.ids.size)

    def to_blocks(self) -> LandmarkBelief:
        """The diagonal 2×2 blocks (exact when the belief is block-diagonal, see
        :attr:`max_cross_covariance`)."""
        n = len(self)
        idx = np.arange(n)
        c = self.cov.reshape(n, 2, n, 2)
        covs = c[idx, :, idx, :]  # (n, 2, 2): block (k, k)
        return LandmarkBelief(self.ids.copy(), self.mean.reshape(n, 2).copy(), covs.copy())

    @property
    def max_cross_covariance(self) -> float:
        """Largest ``|Σ_ij|`` outside the 2×2 diagonal blocks (0 for independent landmarks)."""
        n = len(self)
        if n < 2:
            return 0.0
        c = np.abs(self.cov.reshape(n, 2, n, 2)).max(axis=(1, 3))
        np.fill_diagonal(c, 0.0)
        return float(c.max())


def trusted_belief(ids: NDArray[np.int64], means: FloatArray, covs: FloatArray) -> LandmarkBelief:
    """A belief from arrays the kernels built themselves (no re-validation on the hot path)."""
    belief = object.__new__(LandmarkBelief)
    object.__setattr__(belief, "ids", ids)
    object.__setattr__(belief, "means", means)
    object.__setattr__(belief, "covs", covs)
    return belief


# The public functions validate their arguments and call these kernels, which trust them.
