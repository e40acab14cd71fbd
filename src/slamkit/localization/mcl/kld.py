"""KLD-sampling (Fox 2003): resample and predict in one pass, drawing particles until their
number suffices, with probability ``1 - δ``, to keep the KL divergence between the sample
and the true posterior below ``ε``, judged by how many histogram bins the sample occupies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import ndtri

from slamkit._validation import FloatArray, as_positive
from slamkit.errors import InputError
from slamkit.estimation.particles import ParticleSet
from slamkit.geometry.angles import wrap_angle
from slamkit.localization.mcl.core import moved_finite
from slamkit.localization.mcl.sampling import PoseSampler, sample_poses
from slamkit.models import MotionModel

__all__ = ["kld_resample_predict", "kld_sample_size"]


def kld_sample_size(k: ArrayLike, epsilon: float, upper_quantile: float) -> NDArray[np.int64]:
    """Fox's bound: particles needed when the sample occupies ``k`` histogram bins.

    ``n = (k - 1)/(2ε) · (1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) z)³`` with ``z`` the
    ``upper_quantile`` (``1 - δ``) of the standard normal: the Wilson-Hilferty approximation
    of the chi-square quantile ``χ²_{k-1, 1-δ} / (2ε)``. With ``k <= 1`` the bound is 1.
    """
    kk = np.asarray(k, dtype=np.float64)
    eps = as_positive(epsilon, "epsilon")
    q = float(upper_quantile)
    if not 0.0 < q < 1.0:
        raise InputError(f"upper_quantile: expected a probability in (0, 1), got {q}")
    z = float(ndtri(q))
    dof = np.maximum(kk - 1.0, 1.0)
    a = 2.0 / (9.0 * dof)
    n = dof / (2.0 * eps) * (1.0 - a + np.sqrt(a) * z) ** 3
    out: NDArray[np.int64] = np.where(kk <= 1.0, 1, np.ceil(n)).astype(np.int64)
    return out


@dataclass(frozen=True)
class _KldBins:
    """Bin sizes (m, m, rad) and how poses map to one int64 key per bin."""

    size_xy: float
    size_theta: float

    # 24 bits for each of the x and y bin numbers, 15 for the heading bin: 63 bits.
    _XY_HALF = 1 << 23

    def keys(self, poses: FloatArray) -> NDArray[np.int64]:
        ix = np.floor(poses[:, 0] / self.size_xy)
        iy = np.floor(poses[:, 1] / self.size_xy)
        it = np.floor((wrap_angle(poses[:, 2]) + np.pi) / self.size_theta)
        h = self._XY_HALF
        ix = np.clip(ix, -h, h - 1).astype(np.int64) + h
        iy = np.clip(iy, -h, h - 1).astype(np.int64) + h
        it_i = it.astype(np.int64)
        key: NDArray[np.int64] = (ix << 39) | (iy << 15) | it_i
        return key


def kld_resample_predict(
    particles: ParticleSet,
    u: ArrayLike,
    dt: float,
    model: MotionModel,
    control_cov: ArrayLike,
    rng: np.random.Generator,
    *,
    epsilon: float = 0.05,
    upper_quantile: float = 0.99,
    bin_size: tuple[float, float] = (0.5, np.deg2rad(10.0)),
    min_particles: int = 100,
    max_particles: int = 100_000,
    p_random: float = 0.0,
    sampler: PoseSampler | None = None,
) -> tuple[ParticleSet, int]:
    """KLD-sampling (Fox 2003, table 1): resample, predict and size the set in one pass.

    Particles are drawn independently in proportion to their weights and moved through the
    motion model (each with probability ``p_random`` replaced by a random pose from
    ``sampler`` instead, for augmented MCL). Each new particle falls into a bin of
    ``bin_size = (xy, theta)``; drawing stops at the first count ``n`` with
    ``n >= kld_sample_size(k)`` for the ``k`` bins occupied so far and
    ``n >= min_particles``, or at ``max_particles``. Returns the new equally weighted set and
    how many of its particles are random ones.

    Vectorised: candidates are drawn in blocks (doubling from ``min_particles``), the running
    count of occupied bins within a block comes from the first occurrence of each bin key,
    and the stopping count is the first index at which the bound is met.
    """
    n_min, n_max = int(min_particles), int(max_particles)
    if not 1 <= n_min <= n_max:
        raise InputError(
            f"min_particles, max_particles: expected 1 <= min <= max, got {n_min}, {n_max}"
        )
    if not 0.0 <= p_random <= 1.0:
        raise InputError(f"p_random: expected a probability, got {p_random}")
    if p_random > 0 and sampler is None:
        raise InputError("p_random > 0 needs a sampler of random poses")
    bins = _KldBins(as_positive(bin_size[0], "bin_size xy"), as_positive(bin_size[1], "bin_size"))
    if 2 * np.pi / bins.size_theta >= 1 << 15:
        raise InputError("bin_size: the heading bin is too small (at most 2^15 bins per turn)")
    cum = np.cumsum(particles.weights)
    cum /= cum[-1]
    seen = np.empty(0, dtype=np.int64)  # sorted keys of the occupied bins
    chunks: list[FloatArray] = []
    n_done, k_done, n_random = 0, 0, 0
    block = n_min
    while n_done < n_max:
        m = min(block, n_max - n_done)
        idx = np.minimum(np.searchsorted(cum, rng.random(m), side="right"), cum.size - 1)
        new = moved_finite(model.sample(particles.poses[idx], u, dt, control_cov, rng))
        is_random = np.zeros(m, dtype=bool)
        if p_random > 0 and sampler is not None:
            is_random = rng.random(m) < p_random
            if is_random.any():
                new[is_random] = sample_poses(sampler, int(is_random.sum()), rng)
        keys = bins.keys(new)
        uniq, first = np.unique(keys, return_index=True)
        fresh = ~np.isin(uniq, seen, assume_unique=True)
        opens_bin = np.zeros(m, dtype=bool)
        opens_bin[first[fresh]] = True
        k_running = k_done + np.cumsum(opens_bin)
        n_running = n_done + np.arange(1, m + 1)
        enough = (n_running >= kld_sample_size(k_running, epsilon, upper_quantile)) & (
            n_running >= n_min
        )
        if enough.any():
            stop = int(np.argmax(enough)) + 1
            chunks.append(new[:stop])
            n_random += int(is_random[:stop].sum())
            break
        chunks.append(new)
        n_random += int(is_random.sum())
        seen = np.union1d(seen, uniq)
        n_done += m
        k_done = int(k_running[-1])
        block *= 2
    return ParticleSet.uniform_weights(np.concatenate(chunks, axis=0)), n_random
