"""Monte Carlo localization: particle-filter steps and the ``mcl`` estimator.

The filter (Probabilistic Robotics, chapter 8) as pure functions over a
:class:`~slamkit.localization.particles.ParticleSet`:

* :func:`mcl_predict` moves every particle through the motion model with its own control
  noise draw;
* :func:`mcl_update_landmarks` and :func:`mcl_update_laser` add ``log p(z | x_i)`` to each
  log-weight (point landmarks with known identities; a laser scan through the
  likelihood field) and renormalise;
* :func:`mcl_resample` draws a new, equally weighted set by low-variance resampling;
* **augmented MCL** (table 8.3): :class:`Augmentation` keeps a slow and a fast average of the
  measurement likelihood; when the fast one drops below the slow one the robot has probably
  been moved, and :func:`mcl_resample` replaces a fraction ``max(0, 1 - w_fast/w_slow)`` of
  the particles by random poses;
* **KLD-sampling** (Fox 2003): :func:`kld_resample_predict` draws particles until their
  number suffices, with probability ``1 - δ``, to keep the KL divergence between the sample
  and the true posterior below ``ε``, judged by how many histogram bins the sample occupies.

:class:`MonteCarloLocalization` is the thin stateful shell the runner drives.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import ndtri

from slamkit._validation import FloatArray, as_array, as_covariance, as_positive
from slamkit.datasets.stream import (
    Control,
    Dataset,
    Event,
    LandmarkReadings,
    LaserScan,
    Odometry,
)
from slamkit.errors import ConfigError, ConvergenceError, InputError
from slamkit.geometry.angles import wrap_angle
from slamkit.localization.likelihood_field import LikelihoodField, log_likelihood, usable_beams
from slamkit.localization.particles import (
    ParticleSet,
    effective_sample_size,
    low_variance_resample,
    normalize_log_weights,
    particle_estimate,
    uniform_particles_in_box,
    uniform_particles_in_free_space,
)
from slamkit.maps import LandmarkMap
from slamkit.models import LandmarkModel, MotionModel, odometry_control
from slamkit.pipeline.estimator import EstimatorOutput, ParticleSnapshot, PoseEstimate

__all__ = [
    "Augmentation",
    "MclConfig",
    "MeasurementUpdate",
    "MonteCarloLocalization",
    "PoseSampler",
    "kld_resample_predict",
    "kld_sample_size",
    "landmark_log_likelihood",
    "mcl_predict",
    "mcl_resample",
    "mcl_update_landmarks",
    "mcl_update_laser",
    "reweight",
]

log = logging.getLogger(__name__)

PoseSampler = Callable[[int, np.random.Generator], FloatArray]
"""``sampler(n, rng) -> poses (n, 3)``: where random (injected) particles come from."""


# --------------------------------------------------------------------------------------------
# Prediction, correction, resampling
# --------------------------------------------------------------------------------------------


def mcl_predict(
    particles: ParticleSet,
    u: ArrayLike,
    dt: float,
    model: MotionModel,
    control_cov: ArrayLike,
    rng: np.random.Generator,
) -> ParticleSet:
    """Sample every particle's next pose: ``x_i ← g(x_i, u + ε_i, dt)``, ``ε_i ~ N(0, Q)``
    independently per particle (``Q = control_cov``). Weights are unchanged."""
    poses = model.sample(particles.poses, u, dt, control_cov, rng)
    return ParticleSet(poses, particles.log_weights.copy())


@dataclass(frozen=True)
class MeasurementUpdate:
    """The result of a correction step.

    ``particles`` carry the new normalised weights; ``log_likelihood (P,)`` is
    ``log p(z | x_i)`` of each particle; ``log_evidence`` is ``log Σ_i w_i p(z | x_i)`` with
    the weights *before* the update — the filter's estimate of ``p(z_t | z_1:t-1)``, which
    augmented MCL averages; ``n_readings`` is how many readings (beams, landmark readings)
    entered the update.
    """

    particles: ParticleSet
    log_likelihood: FloatArray
    log_evidence: float
    n_readings: int


def reweight(particles: ParticleSet, log_lik: ArrayLike) -> MeasurementUpdate:
    """Bayes' rule in log space: ``log w_i ← log w_i + log p(z | x_i)``, then normalise.

    Raises :class:`ConvergenceError` when no particle has a non-zero weight afterwards (see
    :func:`~slamkit.localization.particles.normalize_log_weights`); the particles are never
    silently reset.
    """
    ll = as_array(log_lik, "log_likelihood", (len(particles),), finite=False)
    logw, total = normalize_log_weights(particles.log_weights + ll)
    return MeasurementUpdate(ParticleSet(particles.poses.copy(), logw), ll, total, 0)


def landmark_log_likelihood(
    poses: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike,
    landmarks: LandmarkMap,
    model: LandmarkModel,
    noise_cov: ArrayLike,
) -> tuple[FloatArray, int]:
    """``log p(z | x_i)`` ``(P,)`` of landmark readings ``z (K, m)`` with identities ``ids
    (K,)``, and how many readings were used.

    Each reading is Gaussian about the model's prediction, ``N(z_k; h(x_i, l_k), R)``
    (``R = noise_cov (m, m)``), with bearing residuals wrapped; readings are independent, so
    their log-densities add. Readings with an unknown id (``-1``) or an id that is not in
    ``landmarks`` are skipped (the count tells how many were not).
    """
    p = as_array(poses, "poses", (None, 3))
    m = model.dim
    zz = as_array(z, "z", (None, m))
    id_arr = np.asarray(ids)
    if id_arr.shape != (zz.shape[0],) or not np.issubdtype(id_arr.dtype, np.integer):
        raise InputError(f"ids: expected {zz.shape[0]} integers, got shape {id_arr.shape}")
    R = as_covariance(noise_cov, "noise_cov", m)
    known = np.isin(id_arr, landmarks.ids)
    if not known.any():
        return np.zeros(p.shape[0]), 0
    lm = landmarks.position_of(id_arr[known])  # (K, 2)
    zk = zz[known]
    z_hat = model.predict(p[:, None, :], lm[None, :, :])  # (P, K, m)
    nu = model.residual(zk[None, :, :], z_hat)
    # Mahalanobis distance through the Cholesky factor R = L Lᵀ: |L⁻¹ ν|², no inverse of R.
    # L⁻¹ comes from one m × m solve; applying it with einsum keeps the (P, K) batch out of
    # BLAS/LAPACK. (NumPy's solve, not SciPy's solve_triangular: on the 2-core development
    # machine a SciPy LAPACK call right after NumPy BLAS work took 15-25 ms, as the two
    # libraries' OpenBLAS thread pools competed for the cores; NumPy's took 0.1 ms.)
    L = np.linalg.cholesky(R)
    L_inv = np.linalg.solve(L, np.eye(m))
    white = np.einsum("ij,pkj->pki", L_inv, nu)
    maha = np.sum(white * white, axis=(1, 2))
    k = zk.shape[0]
    # log N(ν; 0, R) = -½ νᵀR⁻¹ν - ½ log|2πR|, and log|R| = 2 Σ log diag(L)
    log_norm = -k * (np.sum(np.log(np.diag(L))) + 0.5 * m * np.log(2.0 * np.pi))
    return -0.5 * maha + log_norm, int(k)


def mcl_update_landmarks(
    particles: ParticleSet,
    z: ArrayLike,
    ids: ArrayLike,
    landmarks: LandmarkMap,
    model: LandmarkModel,
    noise_cov: ArrayLike,
) -> MeasurementUpdate:
    """Weight the particles by landmark readings (see :func:`landmark_log_likelihood`).

    Raises :class:`ConvergenceError` if every weight becomes zero.
    """
    ll, n = landmark_log_likelihood(particles.poses, z, ids, landmarks, model, noise_cov)
    out = reweight(particles, ll)
    return MeasurementUpdate(out.particles, out.log_likelihood, out.log_evidence, n)


def mcl_update_laser(
    particles: ParticleSet,
    ranges: ArrayLike,
    field: LikelihoodField,
    beam_angles: ArrayLike,
    sensor_offset: ArrayLike | None = None,
    beam_stride: int = 1,
) -> MeasurementUpdate:
    """Weight the particles by a laser scan through the likelihood field (see
    :func:`slamkit.localization.likelihood_field.log_likelihood`).

    Raises :class:`ConvergenceError` if every weight becomes zero.
    """
    ll = log_likelihood(field, particles.poses, ranges, beam_angles, sensor_offset, beam_stride)
    n = usable_beams(field, ranges, beam_angles, beam_stride)
    out = reweight(particles, ll)
    return MeasurementUpdate(out.particles, out.log_likelihood, out.log_evidence, n)


def mcl_resample(
    particles: ParticleSet,
    rng: np.random.Generator,
    n: int | None = None,
    *,
    n_random: int = 0,
    sampler: PoseSampler | None = None,
) -> ParticleSet:
    """An equally weighted set of ``n`` particles (default: as many as now).

    ``n - n_random`` are drawn by low-variance resampling (copies, by fancy indexing); the
    other ``n_random`` are fresh poses from ``sampler`` (augmented MCL's random particles).
    """
    count = len(particles) if n is None else int(n)
    k = int(n_random)
    if not 0 <= k <= count or count < 1:
        raise InputError(f"n_random: expected 0 <= n_random <= n (n = {count}), got {n_random}")
    parts = []
    if count - k > 0:
        idx = low_variance_resample(particles.weights, rng, count - k)
        parts.append(particles.poses[idx])
    if k > 0:
        if sampler is None:
            raise InputError("n_random > 0 needs a sampler of random poses")
        parts.append(_sample(sampler, k, rng))
    return ParticleSet.uniform_weights(np.concatenate(parts, axis=0))


def _sample(sampler: PoseSampler, n: int, rng: np.random.Generator) -> FloatArray:
    poses = as_array(sampler(n, rng), "sampled poses", (n, 3))
    return poses


# --------------------------------------------------------------------------------------------
# Augmented MCL
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Augmentation:
    """The slow and fast averages of the measurement likelihood (Thrun table 8.3), in log
    space: ``w ← w + α (w_avg - w)`` becomes a ``logaddexp``.

    The likelihood that is averaged is the filter's evidence ``Σ_i w_i p(z | x_i)``
    (which equals Thrun's ``w_avg`` right after resampling, when all ``w_i = 1/P``) taken
    **per reading**: its ``n``-th root for ``n`` readings. A 90-beam scan's likelihood spans
    hundreds of orders of magnitude and grows with the number of beams that returned; per
    reading, ``w_fast / w_slow`` measures how well the particles explain the scans and not
    how many beams they had.
    """

    log_w_slow: float
    log_w_fast: float

    @classmethod
    def start(cls, log_w: float) -> Augmentation:
        """Both averages at ``log_w`` (e.g. the first measured per-reading evidence)."""
        return cls(float(log_w), float(log_w))

    def update(self, log_w_avg: float, alpha_slow: float, alpha_fast: float) -> Augmentation:
        """``w_slow += α_slow (w_avg - w_slow)`` and ``w_fast += α_fast (w_avg - w_fast)``."""

        def step(log_w: float, alpha: float) -> float:
            return float(np.logaddexp(np.log1p(-alpha) + log_w, np.log(alpha) + log_w_avg))

        return Augmentation(step(self.log_w_slow, alpha_slow), step(self.log_w_fast, alpha_fast))

    @property
    def injection_probability(self) -> float:
        """``max(0, 1 - w_fast / w_slow)``: the fraction of particles to replace by random
        poses at the next resampling."""
        return float(max(0.0, -np.expm1(self.log_w_fast - self.log_w_slow)))


# --------------------------------------------------------------------------------------------
# KLD-sampling
# --------------------------------------------------------------------------------------------


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
        new = model.sample(particles.poses[idx], u, dt, control_cov, rng)
        is_random = np.zeros(m, dtype=bool)
        if p_random > 0 and sampler is not None:
            is_random = rng.random(m) < p_random
            if is_random.any():
                new[is_random] = _sample(sampler, int(is_random.sum()), rng)
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


# --------------------------------------------------------------------------------------------
# The estimator
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MclConfig:
    """Settings of :class:`MonteCarloLocalization`. Units: metres, radians unless the name
    says degrees."""

    n_particles: int = 2000
    """Particles when the data set gives a prior pose (tracking), and the fixed set size
    without KLD-sampling."""
    n_particles_global: int = 20_000
    """Particles of a uniform start when there is no prior (global localization). With
    KLD-sampling the set then shrinks towards what the posterior needs."""
    global_start: bool = False
    """True: ignore any prior and start from particles uniform over the map."""
    prior_cov_scale: float = 1.0
    """Multiplies the prior covariance the start particles are drawn from (> 1: a broad
    prior, which tolerates a wrong prior mean)."""
    resample_threshold: float = 0.5
    """Resample (low variance) when the effective sample size ``1/Σw²`` falls below this
    fraction of the number of particles; 1 = after every update, 0 = only for injections.
    Resampling is done just before the next prediction, so the estimate after a measurement
    is always that of the weighted set."""
    motion_noise_scale: float = 1.0
    """Multiplies the data set's nominal control-noise covariance (> 1 helps a particle set
    cover unmodelled motion)."""
    augmented: bool = True
    """Augmented MCL: inject random particles when the fast likelihood average drops below
    the slow one (recovers from kidnapping and from a wrong prior)."""
    alpha_slow: float = 0.01
    """Rate of the slow likelihood average, per measurement update (0 < alpha_slow <
    alpha_fast <= 1)."""
    alpha_fast: float = 0.2
    """Rate of the fast likelihood average, per measurement update."""
    injection_margin: float = 2.0
    """Landmark worlds: random particles are drawn from the landmarks' bounding box grown by
    this margin [m] (laser worlds: from the free cells of the map)."""
    kld: bool = True
    """KLD-sampling: adapt the number of particles at every prediction (Fox 2003): many while
    the belief is spread out (global start, after a kidnapping), few once it has converged.
    False: a fixed set, resampled when the ESS drops."""
    kld_epsilon: float = 0.05
    """KLD-sampling: bound on the Kullback-Leibler divergence between sample and posterior."""
    kld_quantile: float = 0.99
    """KLD-sampling: ``1 - δ``, the probability with which the bound holds."""
    kld_bin_xy: float = 0.5
    """KLD-sampling: histogram bin size in x and y [m]."""
    kld_bin_theta_deg: float = 10.0
    """KLD-sampling: histogram bin size in heading [deg]."""
    kld_min_particles: int = 200
    """KLD-sampling: never fewer particles than this."""
    kld_max_particles: int = 20_000
    """KLD-sampling: never more particles than this."""
    sigma_hit: float | None = 0.2
    """Likelihood field: standard deviation of a hit's end-point distance [m]. ``None``:
    derived from the data set, ``measurement_noise_scale · sqrt(σ_r² + res²/3)`` with the
    laser's range noise ``σ_r`` and the map resolution (an end point and the wall it hits
    each lie anywhere in their cells: variance ``res²/6`` each). That is right for a particle
    at the true pose but far too sharp for a particle set, whose particles are never exactly
    there. On "rooms-laser-global" (σ_r = 3 cm, 5 cm cells: derived 4.2 cm) global
    localization in seeds 0-9 converged after 0 - - 184 - 26 88 33 184 0 steps (-: not within
    the 300 steps), with the default 0.2 m after 0 39 26 0 19 1 1 0 81 0. The broader value
    also absorbs the correlation between neighbouring beams, which the model ignores."""
    z_hit: float = 0.95
    """Likelihood field: weight of the hit component."""
    z_rand: float = 0.05
    """Likelihood field: weight of the uniform random-reading component."""
    beam_stride: int = 4
    """Use every ``beam_stride``-th laser beam (neighbouring beams are strongly correlated,
    and the cost is linear in the number of beams)."""
    laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Pose of the laser in the robot frame: (forward [m], left [m], yaw [rad])."""
    measurement_noise_scale: float = 1.0
    """Multiplies the measurement standard deviations: the landmark sensor's (its covariance
    by the square) and the laser's range noise when ``sigma_hit`` is derived."""
    on_weight_underflow: Literal["skip", "raise"] = "skip"
    """What to do when a measurement leaves every particle with zero weight: ``"skip"``
    drops that measurement (keeps the predicted weights) and reports it in the
    diagnostics; ``"raise"`` raises :class:`~slamkit.errors.ConvergenceError`."""
    snapshot_every: int = 0
    """Keep a copy of the particle set every this many measurement updates (0: never),
    plus the initial set."""
    snapshot_times: tuple[float, ...] = ()
    """Keep a copy of the particle set at the first measurement update at or after each of
    these times [s]."""

    def __post_init__(self) -> None:
        for name in ("n_particles", "n_particles_global", "kld_min_particles"):
            if not getattr(self, name) >= 1:
                raise ConfigError(f"{name}: expected an integer >= 1, got {getattr(self, name)}")
        if self.kld_max_particles < self.kld_min_particles:
            raise ConfigError("kld_max_particles: expected >= kld_min_particles")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise ConfigError(
                f"resample_threshold: expected a fraction in [0, 1], got {self.resample_threshold}"
            )
        if not 0.0 < self.alpha_slow < self.alpha_fast <= 1.0:
            raise ConfigError(
                f"alpha_slow, alpha_fast: expected 0 < alpha_slow < alpha_fast <= 1, got "
                f"{self.alpha_slow}, {self.alpha_fast}"
            )
        for name in ("prior_cov_scale", "motion_noise_scale", "injection_margin"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"{name}: expected a number >= 0, got {getattr(self, name)}")
        for name in ("kld_epsilon", "kld_bin_xy", "kld_bin_theta_deg", "measurement_noise_scale"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a number > 0, got {getattr(self, name)}")
        if not 0.0 < self.kld_quantile < 1.0:
            raise ConfigError(f"kld_quantile: expected a probability, got {self.kld_quantile}")
        if self.sigma_hit is not None and not self.sigma_hit > 0:
            raise ConfigError(f"sigma_hit: expected a number > 0 or None, got {self.sigma_hit}")
        if not (self.z_hit >= 0 and self.z_rand >= 0 and self.z_hit + self.z_rand > 0):
            raise ConfigError("z_hit, z_rand: expected numbers >= 0, not both 0")
        if self.beam_stride < 1 or self.snapshot_every < 0:
            raise ConfigError("beam_stride >= 1 and snapshot_every >= 0 expected")
        if self.on_weight_underflow not in ("skip", "raise"):
            raise ConfigError(
                f"on_weight_underflow: expected 'skip' or 'raise', got {self.on_weight_underflow!r}"
            )


@dataclass
class _Counters:
    predictions: int = 0
    updates: int = 0
    resamplings: int = 0
    injected: int = 0
    injection_events: int = 0
    underflows: int = 0
    first_underflow_update: int | None = None
    first_underflow_t: float | None = None
    readings_skipped: int = 0
    particle_counts: list[int] = dataclass_field(default_factory=list)


class MonteCarloLocalization:
    """Particle-filter localization in a known map (registered as ``mcl``).

    Needs a motion model and either a landmark sensor with ``known_landmarks`` or a laser
    with ``known_grid`` (both are used when both are there). With a prior pose the particles
    start from ``N(initial_pose, prior_cov_scale · initial_cov)``; without one (or with
    ``global_start``) uniformly over the map's free space (laser) or the landmarks' bounding
    box grown by ``injection_margin``. See :class:`MclConfig` for the rest.
    """

    def __init__(self, dataset: Dataset, config: MclConfig, rng: np.random.Generator) -> None:
        if not isinstance(config, MclConfig):
            raise ConfigError(f"config: expected an MclConfig, got {type(config).__name__}")
        if dataset.motion is None:
            raise InputError(f"mcl needs a motion model; data set {dataset.name!r} has none")
        use_laser = dataset.laser is not None and dataset.known_grid is not None
        use_landmarks = dataset.landmark_sensor is not None and dataset.known_landmarks is not None
        if not (use_laser or use_landmarks):
            raise InputError(
                f"mcl needs a laser with a known grid map or a landmark sensor with known "
                f"landmarks; data set {dataset.name!r} has laser={dataset.laser is not None}, "
                f"known_grid={dataset.known_grid is not None}, "
                f"landmark_sensor={dataset.landmark_sensor is not None}, "
                f"known_landmarks={dataset.known_landmarks is not None}"
            )
        self._cfg = config
        self._rng = rng
        self._motion = dataset.motion
        self._Q = config.motion_noise_scale * dataset.motion.noise_cov

        self._field: LikelihoodField | None = None
        self._beam_angles: FloatArray | None = None
        self._sampler: PoseSampler
        if use_laser:
            assert dataset.laser is not None and dataset.known_grid is not None
            grid = dataset.known_grid
            sigma = config.sigma_hit
            if sigma is None:
                s_r = dataset.laser.range_sigma
                sigma = config.measurement_noise_scale * float(
                    np.sqrt(s_r**2 + grid.resolution**2 / 3.0)
                )
            self._field = LikelihoodField.from_grid(
                grid, sigma, config.z_hit, config.z_rand, dataset.laser.max_range
            )
            self._beam_angles = dataset.laser.beam_angles

            def free_space(n: int, rng: np.random.Generator) -> FloatArray:
                return uniform_particles_in_free_space(grid, n, rng)

            self._sampler = free_space
        self._landmarks: LandmarkMap | None = None
        if use_landmarks:
            assert dataset.landmark_sensor is not None and dataset.known_landmarks is not None
            self._landmarks = dataset.known_landmarks
            self._lm_model = dataset.landmark_sensor.model()
            self._lm_cov = config.measurement_noise_scale**2 * dataset.landmark_sensor.noise_cov
            if not use_laser:
                pos = self._landmarks.positions
                mg = config.injection_margin
                box = (
                    float(pos[:, 0].min()) - mg,
                    float(pos[:, 1].min()) - mg,
                    float(pos[:, 0].max()) + mg,
                    float(pos[:, 1].max()) + mg,
                )
                if not (box[2] > box[0] and box[3] > box[1]):
                    raise InputError(
                        "mcl: the landmarks' bounding box is degenerate; set injection_margin > 0"
                    )

                def in_box(n: int, rng: np.random.Generator) -> FloatArray:
                    return uniform_particles_in_box(box, n, rng)

                self._sampler = in_box

        self._global_start = dataset.initial_pose is None or config.global_start
        if self._global_start:
            start = self._sampler(config.n_particles_global, rng)
        else:
            assert dataset.initial_pose is not None
            cov = dataset.initial_cov if dataset.initial_cov is not None else np.zeros((3, 3))
            start = rng.multivariate_normal(
                dataset.initial_pose, config.prior_cov_scale * cov, config.n_particles
            )
        self._particles = ParticleSet.uniform_weights(start)
        self._n_target = len(self._particles)
        self._aug: Augmentation | None = None
        self._resample_pending = False
        self._inject_pending = 0
        self._p_inject = 0.0
        self._last_odometry: FloatArray | None = None
        self._c = _Counters(particle_counts=[len(self._particles)])
        self._snapshots: list[ParticleSnapshot] = []
        self._snapshot_times = sorted(config.snapshot_times)
        if config.snapshot_every > 0:
            self._snapshot(dataset.start_time)

    # -- the Estimator protocol ---------------------------------------------------------

    def handle(self, event: Event) -> None:
        if isinstance(event, Control):
            self._predict(event.u, event.dt)
        elif isinstance(event, Odometry):
            if self._last_odometry is not None:
                u = odometry_control(self._last_odometry, event.pose)
                self._predict(u, 0.0)
            self._last_odometry = event.pose
        elif isinstance(event, LaserScan):
            if self._field is not None and self._beam_angles is not None:
                field_, angles = self._field, self._beam_angles
                cfg = self._cfg
                offset = cfg.laser_offset if any(cfg.laser_offset) else None
                self._update(
                    event.t,
                    lambda ps: mcl_update_laser(
                        ps, event.ranges, field_, angles, offset, cfg.beam_stride
                    ),
                )
        elif isinstance(event, LandmarkReadings) and self._landmarks is not None:
            lms = self._landmarks
            ids = np.asarray(event.ids)
            known = np.isin(ids, lms.ids)
            self._c.readings_skipped += int(np.count_nonzero(~known))
            if known.any():
                self._update(
                    event.t,
                    lambda ps: mcl_update_landmarks(
                        ps, event.z, ids, lms, self._lm_model, self._lm_cov
                    ),
                )

    def estimate(self) -> PoseEstimate:
        mean, cov = particle_estimate(self._particles.poses, self._particles.weights)
        return PoseEstimate(mean, cov)

    def finish(self) -> EstimatorOutput:
        c = self._c
        counts = np.asarray(c.particle_counts)
        diagnostics: dict[str, Any] = {
            "global_start": self._global_start,
            "predictions": c.predictions,
            "measurement_updates": c.updates,
            "resamplings": c.resamplings,
            "injected_particles": c.injected,
            "injection_events": c.injection_events,
            "weight_underflows": c.underflows,
            "first_underflow_update": c.first_underflow_update,
            "first_underflow_t": c.first_underflow_t,
            "readings_skipped": c.readings_skipped,
            "particles_initial": int(counts[0]),
            "particles_final": int(counts[-1]),
            "particles_min": int(counts.min()),
            "particles_max": int(counts.max()),
            "particles_mean": float(counts.mean()),
        }
        return EstimatorOutput(diagnostics=diagnostics, particle_snapshots=tuple(self._snapshots))

    # -- read-only views (tests, plots) ---------------------------------------------------

    @property
    def global_start(self) -> bool:
        """Whether the particles started uniform over the map (no prior, or ``global_start``)."""
        return self._global_start

    @property
    def particles(self) -> ParticleSet:
        return self._particles

    @property
    def augmentation(self) -> Augmentation | None:
        return self._aug

    @property
    def particle_counts(self) -> tuple[int, ...]:
        """The number of particles after every prediction (the first entry: at the start)."""
        return tuple(self._c.particle_counts)

    # -- steps ------------------------------------------------------------------------------

    def _predict(self, u: ArrayLike, dt: float) -> None:
        cfg, rng = self._cfg, self._rng
        if cfg.kld:
            self._particles, n_random = kld_resample_predict(
                self._particles,
                u,
                dt,
                self._motion.model,
                self._Q,
                rng,
                epsilon=cfg.kld_epsilon,
                upper_quantile=cfg.kld_quantile,
                bin_size=(cfg.kld_bin_xy, np.deg2rad(cfg.kld_bin_theta_deg)),
                min_particles=cfg.kld_min_particles,
                max_particles=cfg.kld_max_particles,
                p_random=self._p_inject,
                sampler=self._sampler,
            )
            self._c.resamplings += 1
            self._count_injection(n_random)
        else:
            if self._resample_pending:
                self._particles = mcl_resample(
                    self._particles,
                    rng,
                    self._n_target,
                    n_random=min(self._inject_pending, self._n_target),
                    sampler=self._sampler,
                )
                self._c.resamplings += 1
                self._count_injection(min(self._inject_pending, self._n_target))
            self._particles = mcl_predict(self._particles, u, dt, self._motion.model, self._Q, rng)
        self._resample_pending = False
        self._inject_pending = 0
        self._p_inject = 0.0
        self._c.predictions += 1
        self._c.particle_counts.append(len(self._particles))

    def _count_injection(self, n: int) -> None:
        if n > 0:
            self._c.injected += n
            self._c.injection_events += 1

    def _update(self, t: float, step: Callable[[ParticleSet], MeasurementUpdate]) -> None:
        cfg = self._cfg
        self._c.updates += 1
        try:
            result = step(self._particles)
        except ConvergenceError as exc:
            self._c.underflows += 1
            if self._c.first_underflow_update is None:
                self._c.first_underflow_update = self._c.updates
                self._c.first_underflow_t = float(t)
            if cfg.on_weight_underflow == "raise":
                raise ConvergenceError(f"mcl at t = {t}: {exc}", step=self._c.updates) from exc
            log.warning("mcl at t = %s: measurement skipped (%s)", t, exc)
            return
        self._particles = result.particles
        n = len(self._particles)
        if result.n_readings > 0 and cfg.augmented:
            log_w_avg = result.log_evidence / result.n_readings
            if self._aug is None:
                self._aug = Augmentation.start(log_w_avg)
            else:
                self._aug = self._aug.update(log_w_avg, cfg.alpha_slow, cfg.alpha_fast)
            # KLD-sampling injects with this probability per drawn particle; a fixed-size set
            # replaces a binomial number of particles at its next resampling.
            self._p_inject = self._aug.injection_probability
            if not cfg.kld and self._p_inject > 0:
                self._inject_pending = int(self._rng.binomial(n, self._p_inject))
        ess = effective_sample_size(self._particles.weights)
        if ess < cfg.resample_threshold * n or self._inject_pending > 0:
            self._resample_pending = True
        self._maybe_snapshot(t)

    def _maybe_snapshot(self, t: float) -> None:
        due = False
        every = self._cfg.snapshot_every
        if every > 0 and self._c.updates % every == 0:
            due = True
        while self._snapshot_times and self._snapshot_times[0] <= t:
            self._snapshot_times.pop(0)
            due = True
        if due:
            self._snapshot(t)

    def _snapshot(self, t: float) -> None:
        ps = self._particles
        self._snapshots.append(ParticleSnapshot(float(t), ps.poses.copy(), ps.weights))
