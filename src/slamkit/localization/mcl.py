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
  measurement likelihood; when the fast one drops below the slow one — by more than its
  natural spread (``MclConfig.injection_sigmas``) — the robot has probably been moved, and
  :func:`mcl_resample` replaces a fraction ``max(0, 1 - w_fast/w_slow)`` (against the
  lowered slow average) of the particles by random poses;
* **KLD-sampling** (Fox 2003): :func:`kld_resample_predict` draws particles until their
  number suffices, with probability ``1 - δ``, to keep the KL divergence between the sample
  and the true posterior below ``ε``, judged by how many histogram bins the sample occupies.
  The estimator resamples this way whenever it resamples, which the ESS trigger decides;
* **tempering** of laser scans (``MclConfig.laser_independent_beams``) and the
  **innovation log** of landmark readings against the particle mean and covariance
  (:func:`landmark_innovations`), which gives MCL the NIS statistics of the EKF.

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
from slamkit.errors import ConfigError, ConvergenceError, GeometryError, InputError
from slamkit.estimation.contract import (
    EstimatorOutput,
    InnovationLog,
    ParticleSnapshot,
    PoseEstimate,
    SnapshotSchedule,
)
from slamkit.geometry.angles import wrap_angle
from slamkit.localization.likelihood_field import LikelihoodField, log_likelihood, usable_beams
from slamkit.localization.particles import (
    ParticleSet,
    effective_sample_size,
    low_variance_resample,
    normalize_log_weights,
    particle_estimate_unchecked,
    uniform_particles_in_box,
    uniform_particles_in_free_space,
)
from slamkit.maps import LandmarkMap
from slamkit.models import LandmarkModel, MotionModel, odometry_control
from slamkit.models.motion import motion_kernels

__all__ = [
    "Augmentation",
    "LandmarkInnovations",
    "MclConfig",
    "MeasurementUpdate",
    "MonteCarloLocalization",
    "PoseSampler",
    "kld_resample_predict",
    "kld_sample_size",
    "landmark_innovations",
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


def _control_noise_root(control_cov: FloatArray) -> FloatArray:
    """A square root ``A`` with ``A Aᵀ = Q`` of a PSD control covariance (``eigh``, like the
    motion models' sampler, so that singular ``Q`` works)."""
    eigval, eigvec = np.linalg.eigh(control_cov)
    root: FloatArray = eigvec * np.sqrt(np.clip(eigval, 0.0, None))[None, :]
    return root


def _predict_unchecked(
    poses: FloatArray,
    u: FloatArray,
    dt: float,
    model: MotionModel,
    noise_root: FloatArray,
    rng: np.random.Generator,
) -> FloatArray:
    """:func:`mcl_predict`'s poses for validated arrays and a precomputed noise root (see
    :func:`_control_noise_root`): the estimator's per-step kernel. It draws the same numbers
    in the same order as ``model.sample`` (a test checks the two agree to 1e-12), but skips
    validating and factorising ``Q`` at every step, which cost more than moving a few
    hundred particles."""
    k = noise_root.shape[0]
    eps = rng.standard_normal((poses.shape[0], k)) @ noise_root.T  # ε ~ N(0, A Aᵀ)
    return motion_kernels(model).apply_unchecked(poses, u + eps, dt)


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


def _known_readings(
    z: ArrayLike, ids: ArrayLike, landmarks: LandmarkMap, model: LandmarkModel, noise_cov: ArrayLike
) -> tuple[FloatArray, NDArray[np.int64], FloatArray]:
    """Validated readings ``z (K, m)`` with ids ``(K,)`` and noise ``(m, m)``: the readings
    ``(K', m)`` of landmarks in the map, their ids ``(K',)``, and the noise."""
    m = model.dim
    zz = as_array(z, "z", (None, m))
    id_arr = np.asarray(ids)
    if id_arr.shape != (zz.shape[0],) or not np.issubdtype(id_arr.dtype, np.integer):
        raise InputError(f"ids: expected {zz.shape[0]} integers, got shape {id_arr.shape}")
    R = as_covariance(noise_cov, "noise_cov", m)
    known = np.isin(id_arr, landmarks.ids)
    return zz[known], id_arr[known].astype(np.int64), R


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
    zk, used, R = _known_readings(z, ids, landmarks, model, noise_cov)
    if used.size == 0:
        return np.zeros(p.shape[0]), 0
    lm = landmarks.position_of(used)  # (K, 2)
    L_inv, log_norm = _whitener(R)
    return _landmark_log_likelihood_unchecked(p, zk, lm, model, L_inv, log_norm), int(zk.shape[0])


def _whitener(R: FloatArray) -> tuple[FloatArray, float]:
    """``(L⁻¹, log_norm)`` for a reading noise ``R = L Lᵀ`` (Cholesky): ``|L⁻¹ ν|²`` is the
    Mahalanobis distance ``νᵀ R⁻¹ ν`` and ``log_norm = -½ log|2πR|`` the log of the Gaussian's
    normaliser (``log|R| = 2 Σ log diag(L)``)."""
    m = R.shape[0]
    L = np.linalg.cholesky(R)
    # L⁻¹ comes from one m × m solve (NumPy's solve, not SciPy's solve_triangular: on the
    # 2-core development machine a SciPy LAPACK call right after NumPy BLAS work took 15-25
    # ms, as the two libraries' OpenBLAS thread pools competed for the cores; NumPy's took
    # 0.1 ms).
    L_inv: FloatArray = np.linalg.solve(L, np.eye(m))
    log_norm = -(float(np.sum(np.log(np.diag(L)))) + 0.5 * m * float(np.log(2.0 * np.pi)))
    return L_inv, log_norm


def _landmark_log_likelihood_unchecked(
    poses: FloatArray,
    zk: FloatArray,
    lm: FloatArray,
    model: LandmarkModel,
    L_inv: FloatArray,
    log_norm: float,
) -> FloatArray:
    """:func:`landmark_log_likelihood` of validated poses ``(P, 3)``, known readings ``zk
    (K, m)`` of the landmarks at ``lm (K, 2)`` and the :func:`_whitener` of their noise."""
    z_hat = model.predict(poses[:, None, :], lm[None, :, :])  # (P, K, m)
    nu = model.residual(zk[None, :, :], z_hat)
    # Mahalanobis distance |L⁻¹ ν|², no inverse of R; einsum keeps the (P, K) batch out of
    # BLAS/LAPACK.
    white = np.einsum("ij,pkj->pki", L_inv, nu)
    maha = np.sum(white * white, axis=(1, 2))
    # log N(ν; 0, R) = -½ νᵀR⁻¹ν - ½ log|2πR| per reading; the K readings are independent.
    out: FloatArray = -0.5 * maha + zk.shape[0] * log_norm
    return out


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


@dataclass(frozen=True)
class LandmarkInnovations:
    """Innovations of landmark readings against a Gaussian summary of the belief.

    ``landmark_ids (K,)`` of the readings used, innovations ``nu (K, m)`` (bearings wrapped),
    their covariances ``S (K, m, m)`` and ``nis (K,) = νᵀ S⁻¹ ν``, each with ``m`` degrees of
    freedom.
    """

    landmark_ids: NDArray[np.int64]
    nu: FloatArray
    S: FloatArray
    nis: FloatArray


def landmark_innovations(
    mean: ArrayLike,
    cov: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike,
    landmarks: LandmarkMap,
    model: LandmarkModel,
    noise_cov: ArrayLike,
) -> LandmarkInnovations:
    """Each reading's innovation against the belief ``N(mean (3,), cov (3, 3))``, as an EKF
    would see it: ``ν_k = z_k ⊖ h(μ, l_k)`` and ``S_k = H_k Σ H_kᵀ + R`` with ``H_k`` the pose
    Jacobian of ``h`` at the mean.

    For a particle filter, pass the weighted mean and covariance of the particles *before*
    the update (:func:`~slamkit.localization.particles.particle_estimate`): if the filter is
    consistent, each ``nis`` is then (approximately) ``χ²_m`` distributed, so the standard
    NIS statistics apply to it. Every reading of the call is compared with the same belief
    (an EKF would condition the second reading on the first): readings of one event share
    the belief's error, which correlates their NIS values slightly. Readings with an id that
    is unknown or not in ``landmarks`` are left out; readings at zero range from the mean
    raise :class:`~slamkit.errors.GeometryError`.
    """
    mu = as_array(mean, "mean", (3,))
    sigma = as_covariance(cov, "cov", 3, semidefinite=True)
    zk, used, R = _known_readings(z, ids, landmarks, model, noise_cov)
    return _landmark_innovations_unchecked(
        mu, sigma, zk, used, landmarks.position_of(used), model, R
    )


def _landmark_innovations_unchecked(
    mu: FloatArray,
    sigma: FloatArray,
    zk: FloatArray,
    ids: NDArray[np.int64],
    lm: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
) -> LandmarkInnovations:
    """:func:`landmark_innovations` of validated arrays: known readings ``zk (K, m)`` with
    ids ``(K,)`` of the landmarks at ``lm (K, 2)``."""
    poses = np.broadcast_to(mu, (ids.size, 3))
    z_hat = model.predict(poses, lm)  # (K, m)
    H, _ = model.jacobians(poses, lm)  # (K, m, 3)
    nu = model.residual(zk, z_hat)
    S = np.einsum("kia,ab,kjb->kij", H, sigma, H) + R  # H Σ Hᵀ + R
    S = 0.5 * (S + np.swapaxes(S, -1, -2))
    # νᵀ S⁻¹ ν by a solve per reading (S is m × m, m <= 2), no inverse.
    nis = np.einsum("ki,ki->k", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    return LandmarkInnovations(ids, nu, S, nis)


def mcl_update_laser(
    particles: ParticleSet,
    ranges: ArrayLike,
    field: LikelihoodField,
    beam_angles: ArrayLike,
    sensor_offset: ArrayLike | None = None,
    beam_stride: int = 1,
    exponent: float = 1.0,
) -> MeasurementUpdate:
    """Weight the particles by a laser scan through the likelihood field (see
    :func:`slamkit.localization.likelihood_field.log_likelihood`), tempered:
    ``w_i ← w_i p(z | x_i)^exponent``.

    The field scores the beams as independent, but neighbouring beams' errors are not (they
    hit the same wall, through the same map cells): ``exponent = 1/k`` counts every ``k``
    used beams as one independent reading. Raises :class:`ConvergenceError` if every weight
    becomes zero.
    """
    e = as_positive(exponent, "exponent")
    ll = log_likelihood(field, particles.poses, ranges, beam_angles, sensor_offset, beam_stride)
    if e != 1.0:
        ll = e * ll
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


_SPREAD_WARMUP = 20
"""Updates after which deviations of the log evidence are clipped (see Augmentation)."""
_SPREAD_CLIP = 3.0
"""... to this many of its standard deviations."""


@dataclass(frozen=True)
class Augmentation:
    """The slow and fast averages of the measurement likelihood (Thrun table 8.3), in log
    space: ``w ← w + α (w_avg - w)`` becomes a ``logaddexp``; and how much the likelihood
    naturally varies from update to update.

    The likelihood that is averaged is the filter's evidence ``Σ_i w_i p(z | x_i)``
    (which equals Thrun's ``w_avg`` right after resampling, when all ``w_i = 1/P``) taken
    **per reading**: its ``n``-th root for ``n`` readings. A 90-beam scan's likelihood spans
    hundreds of orders of magnitude and grows with the number of beams that returned; per
    reading, ``w_fast / w_slow`` measures how well the particles explain the scans and not
    how many beams they had.

    Per reading is not enough, though: how much the evidence varies between updates while
    the filter tracks well depends on the sensor. The mean of 45 beams' log-likelihoods
    varies by ±0.01 from scan to scan; a single range reading's ``log N(ν; 0, S)`` by ±1
    (its ``ν²/S`` is χ²₁). Thrun's rule injects ``1 - w_fast/w_slow`` whenever the fast
    average is below the slow one — for a well-localized robot half the time, and on
    range-only beacons by up to 24 % of the particles (Plaza 1). So the update also keeps a
    slow (rate ``alpha_slow``) mean and variance ``s²`` of the per-reading log evidence, and
    :meth:`tolerance` gives the natural spread of ``log w_fast``,
    ``s · sqrt(α_fast / (2 - α_fast))`` (an exponential average of rate ``α`` of values with
    variance ``s²`` has variance ``s² α / (2 - α)``).
    """

    log_w_slow: float
    log_w_fast: float
    mean_log_w: float = 0.0
    """Slow average of the per-reading log evidence."""
    var_log_w: float = 0.0
    """Slow average of its squared deviation (not yet bias-corrected)."""
    count: int = 1
    """Updates averaged so far (the start included)."""

    @classmethod
    def start(cls, log_w: float) -> Augmentation:
        """Both averages at ``log_w`` (e.g. the first measured per-reading evidence)."""
        return cls(float(log_w), float(log_w), float(log_w), 0.0, 1)

    def update(self, log_w_avg: float, alpha_slow: float, alpha_fast: float) -> Augmentation:
        """``w_slow += α_slow (w_avg - w_slow)`` and ``w_fast += α_fast (w_avg - w_fast)``;
        the mean and variance of ``log w_avg`` with rate ``α_slow``."""

        def step(log_w: float, alpha: float) -> float:
            return float(np.logaddexp(np.log1p(-alpha) + log_w, np.log(alpha) + log_w_avg))

        # Exponentially weighted mean and variance (West 1979): d = x - m, m += α d,
        # v = (1 - α)(v + α d²), with d clipped to ±3 standard deviations once there are
        # some: the spread is that of the evidence while tracking, and a kidnapping's
        # collapse of the evidence must not widen the tolerance that is to detect it.
        d = float(log_w_avg) - self.mean_log_w
        if self.count > _SPREAD_WARMUP:
            s = np.sqrt(self._variance(alpha_slow))
            d = float(np.clip(d, -_SPREAD_CLIP * s, _SPREAD_CLIP * s))
        return Augmentation(
            step(self.log_w_slow, alpha_slow),
            step(self.log_w_fast, alpha_fast),
            self.mean_log_w + alpha_slow * d,
            (1.0 - alpha_slow) * (self.var_log_w + alpha_slow * d * d),
            self.count + 1,
        )

    def _variance(self, alpha_slow: float) -> float:
        """The variance of the per-reading log evidence so far, corrected for the bias of an
        exponential average started at zero; 0 before the second update."""
        n = self.count - 1  # deviations averaged
        if n < 1:
            return 0.0
        return max(float(self.var_log_w / -np.expm1(n * np.log1p(-alpha_slow))), 0.0)

    def tolerance(self, alpha_slow: float, alpha_fast: float) -> float:
        """The natural spread of ``log w_fast`` about ``log w_slow`` (see the class
        docstring): ``s · sqrt(α_fast / (2 - α_fast))``."""
        return float(np.sqrt(self._variance(alpha_slow) * alpha_fast / (2.0 - alpha_fast)))

    @property
    def injection_probability(self) -> float:
        """``max(0, 1 - w_fast / w_slow)``: Thrun's fraction of particles to replace by random
        poses at the next resampling."""
        return self.injection_probability_below(1.0)

    def injection_probability_below(self, ratio: float) -> float:
        """``max(0, 1 - w_fast / (ratio · w_slow))``: no injection until the fast average has
        dropped below ``ratio`` times the slow one (``ratio = 1``: Thrun's rule)."""
        r = as_positive(ratio, "ratio")
        return float(max(0.0, -np.expm1(self.log_w_fast - self.log_w_slow - np.log(r))))


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
    n_particles_global: int | None = None
    """Particles of a uniform start when there is no prior (global localization); ``None``:
    ``global_particles_per_m2`` times the area they are spread over (free space of the grid,
    or the landmarks' box), within [1000, 2·10⁶]. With KLD-sampling the set then shrinks
    towards what the posterior needs (after the first measurement: see
    :class:`MonteCarloLocalization` for why it costs only that one update)."""
    global_particles_per_m2: float = 1700.0
    """Density of a uniform start [1/m²] (particles per square metre, headings uniform).
    A start this dense has about one particle per 10 cm × 10 cm × 20° of poses. Measured in
    the Intel map (583 m² free, 10⁶ particles) global localization converged within 6
    scans in 10 of 10 seeds, with 3·10⁵ one seed needed 120 and with 2·10⁴ (the former
    default) 21-65 scans and only through random injections; in the simulated rooms
    (267 m², 4.5·10⁵) within 15 steps in 20 of 20 seeds. The first update scores them all
    (10⁶ particles × 45 beams: ~0.3 s); every later step works on the KLD-sized set."""
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
    injection_sigmas: float = 8.0
    """Augmented MCL: inject only once the fast average has dropped below the slow one by
    more than this many times its natural spread ``σ_f`` (:meth:`Augmentation.tolerance`),
    then ``1 - w_fast / (w_slow e^{-k σ_f})`` of the particles (``k = 0``: Thrun's rule).
    The spread's distribution has heavy tails: while tracking without injections, the
    smallest ``log(w_fast/w_slow) / σ_f`` measured was -6.1 (Intel, 910 scans), -4.4
    (Plaza 1, 3526 range readings) and -5.8 (rooms-laser, 522 scans); Thrun's rule fell
    below in 37 %, 46 % and 25 % of the updates. A kidnapped robot's ratio falls by a
    factor ``1 - α_fast`` per update whatever ``σ_f``: with 8, the kidnapped robots of
    "rooms-laser-kidnapped" (seeds 0-7) recovered 4-13 scans after the kidnapping."""
    injection_margin: float = 2.0
    """Landmark worlds: random particles are drawn from the landmarks' bounding box grown by
    this margin [m] (laser worlds: from the free cells of the map)."""
    kld: bool = True
    """KLD-sampling (Fox 2003): each resampling draws as many particles as the belief needs,
    many while it is spread out (global start, after a kidnapping), few once it has
    converged. Resampling itself is triggered as without KLD (``resample_threshold``, or an
    injection): KLD-sampling does not need to resample at every prediction, and doing so
    redraws a set of equal weights whenever several predictions come between two
    measurements (5 Hz odometry, 2 Hz ranges on Plaza 1), which only loses particles.
    False: a fixed set of ``n_particles``, resampled by the low-variance scheme."""
    kld_epsilon: float = 0.05
    """KLD-sampling: bound on the Kullback-Leibler divergence between sample and posterior."""
    kld_quantile: float = 0.99
    """KLD-sampling: ``1 - δ``, the probability with which the bound holds."""
    kld_bin_xy: float = 0.5
    """KLD-sampling: histogram bin size in x and y [m]."""
    kld_bin_theta_deg: float = 10.0
    """KLD-sampling: histogram bin size in heading [deg]."""
    kld_min_particles: int = 500
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
    laser_independent_beams: float | None = 4.5
    """Laser: temper each scan's likelihood so that it counts as this many independent
    readings, ``p(z | x)^e`` with ``e = min(1, laser_independent_beams / B)`` for its ``B``
    used beams (see :func:`mcl_update_laser`); ``None``: no tempering (``e = 1``).
    The likelihood field scores beams as independent, but neighbouring beams' errors are
    not (same wall, same map cells, same pose error): untempered, 45 beams made every scan
    collapse the set onto one or a few particles (ESS 1-7 of 200 in the Intel map), which
    then drifted 0.1-0.3 m off the true pose and lost it (mean NEES 4e15). Measured in the
    Intel map (910 scans, seeds 0-9, with the other defaults): median NEES after
    convergence 2.6-3.1 (χ²₃: 2.37) with 4.5; 6-9 with 9; and 4.5 also converged fastest."""
    laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Pose of the laser in the robot frame: (forward [m], left [m], yaw [rad])."""
    measurement_noise_scale: float = 1.0
    """Multiplies the measurement standard deviations: the landmark sensor's (its covariance
    by the square) and the laser's range noise when ``sigma_hit`` is derived."""
    on_weight_underflow: Literal["skip", "raise"] = "skip"
    """What to do when a measurement leaves every particle with zero weight: ``"skip"``
    drops that measurement (keeps the predicted weights) and reports it in the
    diagnostics; ``"raise"`` raises :class:`~slamkit.errors.ConvergenceError`."""
    record_innovations: bool = True
    """Landmark readings: keep every used reading's NIS against the particle mean and
    covariance before the update (see :func:`landmark_innovations`) in the output's
    :class:`~slamkit.estimation.contract.InnovationLog`, as the EKF does."""
    snapshot_every: int = 0
    """Keep a copy of the particle set every this many measurement updates (0: never),
    plus the initial set."""
    snapshot_times: tuple[float, ...] = ()
    """Keep a copy of the particle set at the first measurement update at or after each of
    these times [s]."""

    def __post_init__(self) -> None:
        if self.n_particles_global is not None and not self.n_particles_global >= 1:
            raise ConfigError(
                f"n_particles_global: expected an integer >= 1 or None, got "
                f"{self.n_particles_global}"
            )
        if not self.global_particles_per_m2 > 0:
            raise ConfigError(
                f"global_particles_per_m2: expected a number > 0, got "
                f"{self.global_particles_per_m2}"
            )
        for name in ("n_particles", "kld_min_particles"):
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
        for name in (
            "prior_cov_scale",
            "motion_noise_scale",
            "injection_margin",
            "injection_sigmas",
        ):
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
    innovations_skipped: int = 0
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
        self._Q_root = _control_noise_root(self._Q)

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
            area = float(np.count_nonzero(grid.free())) * grid.resolution**2
        self._landmarks: LandmarkMap | None = None
        if use_landmarks:
            assert dataset.landmark_sensor is not None and dataset.known_landmarks is not None
            self._landmarks = dataset.known_landmarks
            self._lm_model = dataset.landmark_sensor.model()
            self._lm_cov = config.measurement_noise_scale**2 * dataset.landmark_sensor.noise_cov
            self._lm_whitener = _whitener(self._lm_cov)
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
                area = (box[2] - box[0]) * (box[3] - box[1])

        self._global_start = dataset.initial_pose is None or config.global_start
        if self._global_start:
            n_global = config.n_particles_global
            if n_global is None:
                n_global = int(
                    np.clip(np.ceil(config.global_particles_per_m2 * area), 1000, 2_000_000)
                )
            start = self._sampler(n_global, rng)
        else:
            assert dataset.initial_pose is not None
            cov = dataset.initial_cov if dataset.initial_cov is not None else np.zeros((3, 3))
            start = rng.multivariate_normal(
                dataset.initial_pose, config.prior_cov_scale * cov, config.n_particles
            )
        self._particles = ParticleSet.uniform_weights(start)
        # A uniform belief over the map stays (nearly) uniform under the motion model, so a
        # global start's particles are not moved until the first measurement has weighted
        # them: that saves moving n_particles_global particles at every step before it.
        self._uniform = self._global_start
        self._estimate: PoseEstimate | None = None
        self._estimate_of: ParticleSet | None = None
        self._n_target = len(self._particles)
        self._aug: Augmentation | None = None
        self._resample_pending = False
        self._inject_pending = 0
        self._p_inject = 0.0
        self._last_odometry: FloatArray | None = None
        self._c = _Counters(particle_counts=[len(self._particles)])
        self._snapshots: list[ParticleSnapshot] = []
        self._innov_t: list[float] = []
        self._innov_nis: list[float] = []
        self._innov_id: list[int] = []
        self._schedule = SnapshotSchedule(config.snapshot_every, config.snapshot_times)
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
                exponent = 1.0
                if cfg.laser_independent_beams is not None:
                    used = usable_beams(field_, event.ranges, angles, cfg.beam_stride)
                    exponent = min(1.0, cfg.laser_independent_beams / max(used, 1))
                self._update(
                    event.t,
                    lambda ps: mcl_update_laser(
                        ps, event.ranges, field_, angles, offset, cfg.beam_stride, exponent
                    ),
                    exponent,
                )
        elif isinstance(event, LandmarkReadings) and self._landmarks is not None:
            self._landmark_readings(event, self._landmarks)

    def estimate(self) -> PoseEstimate:
        ps = self._particles
        if self._estimate_of is not ps:  # the set changed since the last call
            mean, cov = particle_estimate_unchecked(ps.poses, ps.weights)
            self._estimate, self._estimate_of = PoseEstimate(mean, cov), ps
        assert self._estimate is not None
        return PoseEstimate(
            self._estimate.pose.copy(),
            None if self._estimate.cov is None else self._estimate.cov.copy(),
        )

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
        innovations = None
        if self._landmarks is not None and self._cfg.record_innovations:
            nis = np.asarray(self._innov_nis, dtype=np.float64)
            dim = self._lm_model.dim
            diagnostics["innovations_skipped"] = c.innovations_skipped
            diagnostics["mean_nis_per_dof"] = float(nis.mean()) / dim if nis.size else None
            innovations = InnovationLog(
                times=np.asarray(self._innov_t, dtype=np.float64),
                nis=nis,
                dof=np.full(nis.size, dim, dtype=np.int64),
                landmark_ids=np.asarray(self._innov_id, dtype=np.int64),
            )
        return EstimatorOutput(
            diagnostics=diagnostics,
            innovations=innovations,
            particle_snapshots=tuple(self._snapshots),
        )

    def particle_poses(self) -> FloatArray:
        """The particle poses ``(P, 3)`` now (animation frames)."""
        return self._particles.poses.copy()

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
        if self._uniform:  # see __init__: a uniform set is left where it is
            self._c.predictions += 1
            self._c.particle_counts.append(len(self._particles))
            return
        if cfg.kld and self._resample_pending:
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
            if self._resample_pending and not cfg.kld:
                self._particles = mcl_resample(
                    self._particles,
                    rng,
                    self._n_target,
                    n_random=min(self._inject_pending, self._n_target),
                    sampler=self._sampler,
                )
                self._c.resamplings += 1
                self._count_injection(min(self._inject_pending, self._n_target))
            ps = self._particles
            moved = _predict_unchecked(
                ps.poses, np.asarray(u, dtype=np.float64), dt, self._motion.model, self._Q_root, rng
            )
            self._particles = ParticleSet(moved, ps.log_weights.copy())
        self._resample_pending = False
        self._inject_pending = 0
        self._p_inject = 0.0
        self._c.predictions += 1
        self._c.particle_counts.append(len(self._particles))

    def _landmark_readings(self, event: LandmarkReadings, lms: LandmarkMap) -> None:
        ids = np.asarray(event.ids)
        known = np.isin(ids, lms.ids)
        self._c.readings_skipped += int(np.count_nonzero(~known))
        if not known.any():
            return
        used = ids[known].astype(np.int64)
        zk, lm = event.z[known], lms.position_of(used)
        model = self._lm_model
        innov = None
        if self._cfg.record_innovations:
            ps = self._particles
            mean, cov = particle_estimate_unchecked(ps.poses, ps.weights)
            try:
                innov = _landmark_innovations_unchecked(
                    mean, cov, zk, used, lm, model, self._lm_cov
                )
            except GeometryError:  # a landmark on the mean pose: no bearing
                self._c.innovations_skipped += 1
        L_inv, log_norm = self._lm_whitener

        def correct(ps: ParticleSet) -> MeasurementUpdate:
            ll = _landmark_log_likelihood_unchecked(ps.poses, zk, lm, model, L_inv, log_norm)
            out = reweight(ps, ll)
            return MeasurementUpdate(out.particles, ll, out.log_evidence, int(used.size))

        if self._update(event.t, correct) and innov is not None:
            self._innov_t.extend([float(event.t)] * innov.nis.size)
            self._innov_nis.extend(innov.nis.tolist())
            self._innov_id.extend(innov.landmark_ids.tolist())

    def _count_injection(self, n: int) -> None:
        if n > 0:
            self._c.injected += n
            self._c.injection_events += 1

    def _update(
        self,
        t: float,
        step: Callable[[ParticleSet], MeasurementUpdate],
        exponent: float = 1.0,
    ) -> bool:
        """Apply a correction; False if it was skipped (every weight underflowed).

        ``exponent``: the likelihood was tempered by this power, so its ``n`` readings count
        as ``n · exponent`` in the per-reading evidence that augmented MCL averages (for a
        concentrated set, ``log Σ w p^e ≈ e log p``: the same per-reading value as untempered).
        """
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
            return False
        self._particles = result.particles
        self._uniform = False
        n = len(self._particles)
        if result.n_readings > 0 and cfg.augmented:
            log_w_avg = result.log_evidence / (result.n_readings * exponent)
            if self._aug is None:
                self._aug = Augmentation.start(log_w_avg)
            else:
                self._aug = self._aug.update(log_w_avg, cfg.alpha_slow, cfg.alpha_fast)
            # KLD-sampling injects with this probability per drawn particle; a fixed-size set
            # replaces a binomial number of particles at its next resampling.
            spread = self._aug.tolerance(cfg.alpha_slow, cfg.alpha_fast)
            ratio = float(np.exp(-cfg.injection_sigmas * spread))
            self._p_inject = self._aug.injection_probability_below(ratio)
            if not cfg.kld and self._p_inject > 0:
                self._inject_pending = int(self._rng.binomial(n, self._p_inject))
        ess = effective_sample_size(self._particles.weights)
        if ess < cfg.resample_threshold * n or self._inject_pending > 0 or self._p_inject > 0:
            self._resample_pending = True
        self._maybe_snapshot(t)
        return True

    def _maybe_snapshot(self, t: float) -> None:
        if self._schedule.due(t, self._c.updates):
            self._snapshot(t)

    def _snapshot(self, t: float) -> None:
        ps = self._particles
        self._snapshots.append(ParticleSnapshot(float(t), ps.poses.copy(), ps.weights))
