"""FastSLAM 1.0 and 2.0: a particle filter over robot paths, a small EKF per landmark.

The idea (Montemerlo et al. 2002/2003; *Probabilistic Robotics* ch. 13)
------------------------------------------------------------------------
Given the whole robot path, the landmarks are independent of each other: a reading of one
landmark says nothing about another once the pose it was taken from is known. FastSLAM
therefore factors the SLAM posterior as ``p(x_1:t | z, u) Π_j p(m_j | x_1:t, z)``: a particle
filter samples paths, and every particle carries its own map of independent 2-D Gaussian
landmarks, each a 2×2 EKF (the same block-diagonal filter as
:mod:`slamkit.mapping.ekf_mapping`, exact there for the same reason).

Per particle, with pose ``x``, a landmark ``N(μ, Σ)`` and a reading ``z`` (noise ``R``):

* **Innovation**: ``ν = z ⊟ h(x, μ)`` (angles wrapped), ``H = ∂h/∂m`` at ``(x, μ)``,
  ``Q = H Σ Hᵀ + R``.
* **Likelihood**: ``log N(ν; 0, Q) = -½ (νᵀ Q⁻¹ ν + log det Q + m log 2π)``.
* **EKF update**: ``K = Σ Hᵀ Q⁻¹``, ``μ ← μ + K ν``, ``Σ ← Σ − K H Σ`` (the standard form:
  with this closed-form 2×2 gain it is as safe as the Joseph form at half the cost; see
  ``_ekf``).
* **New landmark**: ``μ = g(x, z)`` (the inverse model), ``Σ = L_z R L_zᵀ``; no pose term,
  the pose is given within the particle.

Data association
----------------
A reading carrying an id (and ``use_ids``) updates that landmark of every particle, or starts
it (weight factor ``p0``). An unlabelled reading is associated per particle by maximum
likelihood: the landmark with the largest ``N(ν; 0, Q)`` wins unless that likelihood is below
``p0``, in which case the reading starts a new landmark and the particle's weight is
multiplied by ``p0``. Within a scan the labelled readings come first (a repeated id updates
its landmark again, in reading order), then the unlabelled ones in reading order; an
unlabelled reading cannot pick a landmark that an earlier reading of the scan already updated
or started (one scan sees a landmark at most once). All landmarks started by one unlabelled
reading share one new id, so descendants of a particle agree on what a landmark is called.

Because an update touches only the landmark it matched and excluded landmarks are never
candidates again, the association of a whole scan can be decided on the map before the scan:
FastSLAM 1.0 computes the likelihoods of every (particle, reading, landmark) triple at once,
takes the greedy per-reading decisions with a few cheap array operations per reading, and
applies every EKF update and landmark start of the scan in one batch. The result equals the
reading-by-reading loop exactly (a test compares them to 1e-12).

Landmarks started from unlabelled readings carry an existence counter: it starts at 1, goes
up by ``hit_weight`` (default 1) in each scan that updates the landmark and down by one in
each scan in which it was predicted visible (range within the sensor's minimum and its
*effective* range — where it actually reads landmarks, see
:attr:`FastSlamConfig.miss_max_range` — and inside the field of view, judged from the
particle's pose and the landmark's mean, from where the sensor sits on the robot:
:attr:`FastSlamConfig.sensor_offset`) but not matched; below zero the landmark is removed
(clutter and duplicate landmarks die this way). A landmark known by its id is never
removed and keeps no counter (its counter stays at its start value).

FastSLAM 1.0 vs 2.0
-------------------
1.0 samples the new pose from the motion model, ``x ~ g(x_{t-1}, u + ε)``,
``ε ~ N(0, Q_u)``, and weights by the likelihood of the readings at that pose.

2.0 samples from a proposal that already includes the readings. It is written here in the
space of the control noise ``ε``, whose prior ``N(0, Q_u)`` is non-singular even where the
pose noise ``V Q_u Vᵀ`` is not (a unicycle cannot slide sideways). Linearising
``z ≈ h(x̄, μ) + A (ε − e) + H (m − μ)`` with ``x̄ = g(x_{t-1}, u + e)``,
``A = H_x V``, ``V = ∂g/∂u`` at ``u + e``, the readings are folded in one at a time (labelled
ones first, then unlabelled ones associated by maximum marginal likelihood), each an EKF
update of ``N(e, Σ_ε)``:

    L = A Σ_ε Aᵀ + H Σ Hᵀ + R             (the reading's marginal covariance)
    K_ε = Σ_ε Aᵀ L⁻¹,  e ← e + K_ε ν,  Σ_ε ← (I − K_ε A) Σ_ε (I − K_ε A)ᵀ + K_ε Q K_εᵀ

after which ``x̄`` and ``V`` are recomputed at the new ``u + e``. The importance weight is
the marginal likelihood with the pose integrated out, ``Π_k N(ν_k; 0, L_k)`` (the chain rule
``p(z_1 … z_K | x_{t-1}, u, m) = Π_k p(z_k | z_<k, …)`` under the linearisation); new
landmarks contribute ``p0`` and do not shape the proposal. Finally ``ε ~ N(e, Σ_ε)``, the pose
is ``g(x_{t-1}, u + ε)`` (exact, not linearised) and the landmarks are updated from it as in
1.0. With no reading the proposal is the motion model, so 2.0 reduces to 1.0. A second reading
of the same id in one scan is left out of the proposal and weighted at the sampled pose, as in
1.0 — still correct importance sampling, the proposal just uses fewer readings.

Several controls between two scans (odometry at 1 Hz and a scan every 5 poses on cityTrees,
~10 controls per scan on Victoria Park): the proposal must cover all of them. Each particle
carries the motion since its last scan as a Gaussian ``N(x̄_p, P_p)`` over the pose before
the newest control, built by EKF predictions (``P ← G P Gᵀ + V Q_u Vᵀ``), and the proposal
runs over ``δ = (δx, ε)`` with prior ``N(0, blockdiag(P_p, Q_u))``: ``x = g(x̄_p + δx, u + ε)``,
``A = H_x [G, V]``, the same updates as above. With one control per scan ``P_p = 0`` and this
is the control-space proposal. Sampling only the newest control from the proposal and the
earlier ones blindly is still valid importance sampling, but the proposal then sees a fifth
of the heading noise on cityTrees: the weights collapse (median ESS 1 of 100) and the filter
diverges (ATE 57 m); with the whole motion in the proposal, median ESS ~40, ATE 1.1-3.4 m
over seeds 0-4 (``tests/test_fastslam_real.py``).

Consistency
-----------
The pose covariance the estimators report is the weighted spread of the particles (plus,
for 2.0 between a control and its scan, the mean of the particles' motion covariances). It
is optimistic, as Bailey, Nieto and Nebot (2006) showed FastSLAM to be in general:
resampling prunes the path hypotheses, so after a while every particle shares one ancestor
and the spread no longer holds the drift of the whole map. Measured on the five-feature
world, default settings, seeds 0-4: mean pose NEES (3 dof, 3 when consistent) 5-710 for
1.0 and 21-160 for 2.0, against EKF-SLAM's 0.9-7.1, with ATE RMSE 0.04-0.06 m (1.0),
0.06-0.14 m (2.0) and 0.03-0.06 m (EKF-SLAM). Use the trajectory, not the covariance, of
a FastSLAM run.

Arrays
------
A particle set is a struct of arrays (:class:`FastSlamParticles`): poses ``(P, 3)``,
log-weights ``(P,)``, landmark means ``(P, C, 2)``, covariances ``(P, C, 2, 2)``, existence
counters and ids ``(P, C)``, and the number of landmarks of each particle ``(P,)`` (slots
``0 … counts[p] − 1`` are used). The capacity ``C`` doubles when a particle runs out of slots.
Every step is vectorised over particles; the only Python loops run over the few readings of a
scan. Resampling selects particles by fancy indexing, which copies: two resampled particles
never share a landmark buffer.

Internally the kernels work on a planar, slot-major copy of the maps (``_Work``: five
``(C, P)`` planes for the mean and covariance entries, particles last) that the estimators
keep between steps and turn into a :class:`FastSlamParticles` only when asked: at 100
particles and a few readings per scan a step is a couple of hundred NumPy calls on a few
hundred numbers each, and their count — not the arithmetic — is the cost (see
``benchmarks/bench_fastslam.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.datasets.stream import Control, Dataset, Event, LandmarkReadings, Odometry
from slamkit.errors import ConfigError, ConvergenceError, InputError, ShapeError
from slamkit.estimation.contract import (
    EstimatorOutput,
    LandmarkEstimate,
    ParticleSnapshot,
    PoseEstimate,
    SnapshotSchedule,
    StepClock,
)
from slamkit.geometry.angles import wrap_angle
from slamkit.localization.particles import (
    low_variance_resample,
    low_variance_resample_unchecked,
    normalize_log_weights,
    particle_estimate_unchecked,
)
from slamkit.mapping.ekf_mapping import (
    DISCARDED,
    INITIALISED,
    TOO_CLOSE,
    UPDATED,
)
from slamkit.maps import LandmarkMap
from slamkit.models import MIN_RANGE, Ackermann, MotionModel, RangeBearing, odometry_control
from slamkit.models.measurement import InvertibleLandmarkModel, LandmarkModelBase
from slamkit.models.motion import motion_kernels, propagate_gaussian_unchecked
from slamkit.prob import chi2_gate

__all__ = [
    "FastSlam1",
    "FastSlam2",
    "FastSlamConfig",
    "FastSlamParticles",
    "UpdateSettings",
    "default_p0",
    "fastslam1_update",
    "fastslam2_update",
    "fastslam_predict",
    "fastslam_resample",
]

IntArray = NDArray[np.int64]

_LOG_2PI = math.log(2.0 * math.pi)
_NEGLIGIBLE_LOG_WEIGHT = -700.0


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
        counters = _int_array(self.counters, "counters", (n, cap))
        ids = _int_array(self.ids, "ids", (n, cap))
        counts = _int_array(self.counts, "counts", (n,))
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
        np.exp(lw, out=w, where=lw > _NEGLIGIBLE_LOG_WEIGHT)
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
        return _trusted(
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


def _int_array(value: ArrayLike, name: str, shape: tuple[int, ...]) -> IntArray:
    arr = np.asarray(value)
    if arr.shape != shape:
        raise ShapeError(f"{name}: expected shape {shape}, got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise InputError(f"{name}: expected integers, got {arr.dtype}")
    return arr.astype(np.int64)


def _trusted(
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


# --------------------------------------------------------------------------------------------
# Settings of the measurement update
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class UpdateSettings:
    """How readings are associated and landmarks kept (the estimator builds this from
    :class:`FastSlamConfig` and the data set's sensor).

    ``p0`` is the new-landmark likelihood threshold, a density in the units of the reading
    (1/(m·rad) for range-bearing, 1/m² for relative positions). ``use_ids``: take a reading's
    id (``>= 0``) as its landmark. ``prune``: remove landmarks started by unlabelled readings
    when their existence counter drops below zero. ``visible_min_range``,
    ``visible_max_range`` [m] and ``fov`` [rad, centred on the heading]: where the sensor
    sees a landmark (for the counters), measured from ``sensor_offset`` [m, robot frame:
    x forward, y left], where the sensor sits (readings are still given from the robot's
    origin; see :func:`_predicted_visible`). ``min_range`` [m]: readings that place their landmark
    closer than this are skipped. ``first_unlabelled_id``: landmarks with ids at or above it
    were started by unlabelled readings (only those keep a counter and are pruned).
    ``hit_weight``: what a scan that updates a landmark adds to its counter (a miss
    subtracts 1).
    """

    p0: float
    use_ids: bool = True
    prune: bool = True
    visible_min_range: float = 0.0
    visible_max_range: float = math.inf
    fov: float = 2.0 * math.pi
    min_range: float = 0.0
    first_unlabelled_id: int = 0
    hit_weight: int = 1
    sensor_offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        off = tuple(float(v) for v in self.sensor_offset)
        if len(off) != 2 or not all(math.isfinite(v) for v in off):
            raise ConfigError(f"sensor_offset: expected two finite numbers, got {off}")
        object.__setattr__(self, "sensor_offset", off)
        if not (isinstance(self.hit_weight, int) and self.hit_weight >= 1):
            raise ConfigError(f"hit_weight: expected an integer >= 1, got {self.hit_weight}")
        if not (self.p0 > 0 and math.isfinite(self.p0)):
            raise ConfigError(f"p0: expected a density > 0, got {self.p0}")
        if not 0 <= self.visible_min_range <= self.visible_max_range:
            raise ConfigError("visible ranges: expected 0 <= min <= max")
        if not self.fov > 0:
            raise ConfigError(f"fov: expected an angle > 0, got {self.fov}")
        if not (self.min_range >= 0 and math.isfinite(self.min_range)):
            raise ConfigError(f"min_range: expected a number >= 0, got {self.min_range}")

    @property
    def log_p0(self) -> float:
        return math.log(self.p0)


def default_p0(noise_cov: ArrayLike, probability: float = 0.999) -> float:
    """The density of ``N(0, R)`` at squared Mahalanobis distance ``χ²_m(probability)``:
    ``exp(-½ χ²) / sqrt(det(2π R))``.

    For a landmark whose position is certain and a particle at the true pose, ``Q = R``, and
    a reading then starts a new landmark exactly when it lies outside the ``probability``
    gate of every mapped landmark. A landmark still uncertain has a broader ``Q``, a lower
    peak density, and so a narrower effective gate."""
    R = as_covariance(noise_cov, "noise_cov")
    if not 0.0 < probability < 1.0:
        raise ConfigError(f"probability: expected a value in (0, 1), got {probability}")
    m = R.shape[0]
    d2 = chi2_gate(m, probability)
    _, logdet = np.linalg.slogdet(2.0 * np.pi * R)
    return float(math.exp(-0.5 * d2 - 0.5 * float(logdet)))


# --------------------------------------------------------------------------------------------
# Kernels (trusted inputs)
# --------------------------------------------------------------------------------------------


# Rows of the planar landmark store ``_Work.lm (5, C, P)``: mean x, y; covariance Σ00, Σ01, Σ11.
_MX, _MY, _S00, _S01, _S11 = range(5)
_TWO_PI = 2.0 * math.pi


# The association of a set that has seen no scan yet (shared, read-only).
_NO_IDS: IntArray = np.zeros(0, dtype=np.int64)
_NO_STATUS: NDArray[np.int8] = np.zeros(0, dtype=np.int8)
_NO_IDS.setflags(write=False)
_NO_STATUS.setflags(write=False)


class _Work:
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
        scratch_of: _Work | None = None,
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
    def of(cls, ps: FastSlamParticles) -> _Work:
        """A working copy of the maps of ``ps`` (shares no memory with it)."""
        n, cap = ps.ids.shape
        lm = np.empty((5, cap, n))
        lm[_MX], lm[_MY] = ps.means[..., 0].T, ps.means[..., 1].T
        lm[_S00], lm[_S01] = ps.covs[..., 0, 0].T, ps.covs[..., 0, 1].T
        lm[_S11] = ps.covs[..., 1, 1].T
        return cls(lm, ps.counters.T.copy(), ps.ids.T.copy(), ps.counts.copy(), ps.next_id)

    def particles(self, poses: FloatArray, log_weights: FloatArray) -> FastSlamParticles:
        """The maps as a particle set (new arrays) with ``poses`` and ``log_weights``."""
        means, covs = self.gaussians((slice(None), slice(None)))
        return _trusted(poses, log_weights, np.swapaxes(means, 0, 1).copy(),
                        np.swapaxes(covs, 0, 1).copy(), self.counters.T.copy(),
                        self.ids.T.copy(), self.counts.copy(), self.next_id)  # fmt: skip

    def gaussians(self, index: tuple[Any, Any]) -> tuple[FloatArray, FloatArray]:
        """Means ``(..., 2)`` and covariances ``(..., 2, 2)`` of the slots ``index``
        (``(slots, particles)``, any NumPy index), as new arrays."""
        g = self.lm[(slice(None), *index)]
        means = np.stack((g[_MX], g[_MY]), axis=-1)
        covs = np.empty((*g.shape[1:], 2, 2))
        covs[..., 0, 0], covs[..., 1, 1] = g[_S00], g[_S11]
        covs[..., 0, 1] = covs[..., 1, 0] = g[_S01]
        return means, covs

    def select(self, indices: NDArray[np.intp]) -> _Work:
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
        w = _Work(self.lm[:, :, indices], counters, ids, counts, self.next_id, self)
        w.common = True if self.common else None
        w.maybe_prunable = self.maybe_prunable
        w.slot_of = self.slot_of  # the same slots: resampling keeps a common layout common
        return w

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


# What `_landmark_terms` returns for `ok` when every landmark is off the sensor (broadcasts).
_ALL_OK = np.ones((), dtype=bool)

# Rows of the stacked innovation terms of :func:`_landmark_terms`.
_ZH0, _ZH1, _H00, _H01, _H10, _H11, _T00, _T01, _T10, _T11, _I00, _I01, _I11, _LOGDET = range(14)


def _times_symmetric(
    a: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    b: tuple[FloatArray, FloatArray, FloatArray],
    out: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    tmp: FloatArray,
) -> None:
    """``out = A B`` entry-wise over arrays of 2×2 matrices, in place: ``A`` as
    ``(a00, a01, a10, a11)``, ``B`` symmetric as ``(b00, b01, b11)``."""
    a00, a01, a10, a11 = a
    b00, b01, b11 = b
    o00, o01, o10, o11 = out
    np.multiply(a00, b00, out=o00)
    o00 += np.multiply(a01, b01, out=tmp)
    np.multiply(a00, b01, out=o01)
    o01 += np.multiply(a01, b11, out=tmp)
    np.multiply(a10, b00, out=o10)
    o10 += np.multiply(a11, b01, out=tmp)
    np.multiply(a10, b01, out=o11)
    o11 += np.multiply(a11, b11, out=tmp)


def _landmark_terms(
    model: InvertibleLandmarkModel,
    pose: tuple[FloatArray, FloatArray, FloatArray],
    g: FloatArray,
    R: FloatArray,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """What the readings of the landmarks ``g (5, *batch)`` (planar, see :class:`_Work`)
    from the poses ``pose = (x, y, θ)`` (broadcasting to ``batch``) need before any reading
    is known, stacked in one array ``(14, *batch)`` (rows ``_ZH0`` …): the predicted reading
    ``ẑ`` (angular components unwrapped: the innovation wraps them), ``H = ∂h/∂m``,
    ``T = H Σ``, ``Q⁻¹`` with ``Q = H Σ Hᵀ + R`` (entries 00, 01, 11) and ``log det Q``.
    Also ``ok (*batch)``: False where the landmark is at the sensor (closer than
    ``2 MIN_RANGE``; the terms are then those of a stand-in point 1 m east of the pose).

    One stacked array, so the terms of chosen (slot, particle) pairs are gathered in one
    operation. Range-bearing, the common case, is written out here (``ẑ = (r, atan2(dy, dx)
    − θ)``, ``H = [[dx/r, dy/r], [−dy/r², dx/r²]]``, the convention of
    :class:`~slamkit.models.RangeBearing`); other models go through their batch kernels
    ``predict_unchecked``/``jacobians_unchecked``. A test checks both against the models'
    validated methods."""
    px, py, pth = pose
    batch = g.shape[1:]
    buf = np.empty((20, *batch))  # the terms and, after them, scratch
    F = buf[:14]
    # Every row as a name (one view per row, not one per use: at a few hundred values per
    # row, creating views is a tenth of the cost).
    zh0, zh1, h00, h01, h10, h11, t00, t01, t10, t11, i00, i01, i11, logdet = F
    dx, dy, q00, q01, q11, tmp = buf[14:]
    mx, my, s00, s01, s11 = g
    np.subtract(mx, px, out=dx)
    np.subtract(my, py, out=dy)
    # Sums of products ``a b + c d`` are written out as two in-place calls into preallocated
    # rows, here and in _ekf: allocating a result, or a helper function's Python call,
    # costs a third of the arithmetic at this size.
    d2 = np.multiply(buf[14:16], buf[14:16], out=buf[16:18])  # dx², dy² in one call
    np.add(d2[0], d2[1], out=zh0)
    r = np.sqrt(zh0, out=zh0)  # np.hypot costs 2x
    if r.size and float(r.min()) >= 2.0 * MIN_RANGE:
        ok = _ALL_OK
    else:
        ok = r >= 2.0 * MIN_RANGE
        dx[~ok], dy[~ok], r[~ok] = 1.0, 0.0, 1.0
    if isinstance(model, RangeBearing):
        np.arctan2(dy, dx, out=zh1)
        zh1 -= pth
        inv_r = np.divide(1.0, r, out=tmp)
        np.multiply(dx, inv_r, out=h00)  # (cos, sin) of the direction
        np.multiply(dy, inv_r, out=h01)
        np.multiply(h01, inv_r, out=h10)  # (−sin, cos) / r
        np.negative(h10, out=h10)
        np.multiply(h00, inv_r, out=h11)
    else:
        p = np.empty((*batch, 3))
        p[..., 0], p[..., 1], p[..., 2] = px, py, pth
        m = np.stack((p[..., 0] + dx, p[..., 1] + dy), axis=-1)
        if isinstance(model, LandmarkModelBase):
            z_hat, (_, Hm) = model.predict_unchecked(p, m), model.jacobians_unchecked(p, m)
        else:  # pragma: no cover - every invertible model of slamkit has the kernels
            z_hat, (_, Hm) = model.predict(p, m), model.jacobians(p, m)
        zh0[...], zh1[...] = z_hat[..., 0], z_hat[..., 1]
        h00[...], h01[...] = Hm[..., 0, 0], Hm[..., 0, 1]
        h10[...], h11[...] = Hm[..., 1, 0], Hm[..., 1, 1]
    _times_symmetric((h00, h01, h10, h11), (s00, s01, s11), (t00, t01, t10, t11), tmp)  # T = H Σ
    np.multiply(t00, h00, out=q00)  # Q = T Hᵀ + R
    q00 += np.multiply(t01, h01, out=tmp)
    q00 += float(R[0, 0])
    np.multiply(t00, h10, out=q01)
    q01 += np.multiply(t01, h11, out=tmp)
    q01 += float(R[0, 1])
    np.multiply(t10, h10, out=q11)
    q11 += np.multiply(t11, h11, out=tmp)
    q11 += float(R[1, 1])
    det = np.multiply(q00, q11, out=dx)
    det -= np.multiply(q01, q01, out=tmp)  # > 0: R is positive definite, H Σ Hᵀ semidefinite
    np.log(det, out=logdet)
    inv_det = np.divide(1.0, det, out=det)
    np.multiply(q11, inv_det, out=i00)
    np.multiply(q01, inv_det, out=i01)
    np.negative(i01, out=i01)
    np.multiply(q00, inv_det, out=i11)
    return F, ok


def _wrap_innovation(a: FloatArray) -> FloatArray:
    """An angular innovation brought to ``[-π, π]`` in place: ``a − 2π round(a / 2π)``.

    Not :func:`~slamkit.geometry.wrap_angle` (``[-π, π)`` exactly, bit-identical in range):
    an innovation only enters ``νᵀ Q⁻¹ ν`` and ``K ν``, where ``±π`` are the same point
    of the circle, and this form costs 3 array operations instead of ~10 — a tenth of a
    FastSLAM step on 100 particles. Innovations already within ``[-π, π]`` (the usual
    case) are left as they are, which is what the formula gives them."""
    if float(np.abs(a).max(initial=0.0)) <= math.pi:
        return a
    k = np.multiply(a, 1.0 / _TWO_PI)
    np.round(k, out=k)
    k *= _TWO_PI
    a -= k
    return a


def _innovations(
    model: InvertibleLandmarkModel, F: FloatArray, z0: ArrayLike, z1: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """``ν = z ⊟ ẑ`` as two planes (angular components wrapped), broadcast with the terms."""
    nu0 = z0 - F[_ZH0]
    nu1 = z1 - F[_ZH1]
    a0, a1 = model.angular
    return (_wrap_innovation(nu0) if a0 else nu0), (_wrap_innovation(nu1) if a1 else nu1)


def _log_likelihood(F: FloatArray, nu0: FloatArray, nu1: FloatArray) -> FloatArray:
    """``log N(ν; 0, Q) = −½ (νᵀ Q⁻¹ ν + log det Q) − log 2π`` (m = 2)."""
    i00, i01, i11, logdet = F[_I00 : _LOGDET + 1]
    d2 = i00 * nu0
    d2 += i01 * nu1
    d2 *= nu0
    e = i01 * nu0
    e += i11 * nu1
    e *= nu1
    d2 += e  # νᵀ Q⁻¹ ν
    d2 += logdet
    d2 *= -0.5
    d2 -= _LOG_2PI
    return d2


def _ekf(
    F: FloatArray, g: FloatArray, nu0: FloatArray, nu1: FloatArray, R: FloatArray
) -> FloatArray:
    """The 2×2 EKF update of the landmarks ``g (5, *batch)`` with the terms ``F`` and the
    innovations ``ν``: the new planar landmarks ``(5, *batch)``.

    ``K = Σ Hᵀ Q⁻¹ = Tᵀ Q⁻¹``, ``μ ← μ + K ν``, ``Σ ← Σ − K T`` (``= Σ − Tᵀ Q⁻¹ T``), written
    out in matrix entries into preallocated buffers (a stacked ``matmul`` of 2×2 blocks
    costs ~25x an elementwise operation). Only the entries 00, 01, 11 are formed, so the
    result is exactly symmetric.

    Why not the Joseph form here (EKF-SLAM uses it): with the optimal gain it is the same
    matrix, and it guards against a gain perturbed by round-off in large filters. This gain
    comes from a closed-form 2×2 inverse (relative error ~1e-16), and the subtraction can
    only lose precision in proportion to how much one reading shrinks the covariance: the
    posterior over the prior variance is ``1/(1 + λ)`` with ``λ`` an eigenvalue of
    ``Σ Hᵀ R⁻¹ H``, about 1 at a landmark's second reading (its covariance came from one
    reading) and at most the squared ratio of the ranges it was first and is now seen at
    (``λ ≈ 250`` for 80 m then 5 m): a loss of under 3 of 16 digits, far from an indefinite
    result. The Joseph form costs twice the operations, ~20 % of a FastSLAM step on 100
    particles. The tests compare this update with a Joseph-form reference to 1e-12."""
    t00, t01, t10, t11 = F[_T00 : _T11 + 1]
    i00, i01, i11 = F[_I00 : _I11 + 1]
    mx, my, s00, s01, s11 = g
    buf = np.empty((10, *g.shape[1:]))
    out = buf[:5]
    ox, oy, o00, o01, o11, k00, k01, k10, k11, tmp = buf
    _times_symmetric((t00, t10, t01, t11), (i00, i01, i11), (k00, k01, k10, k11), tmp)  # K = Tᵀ Q⁻¹
    np.multiply(k00, nu0, out=ox)  # μ + K ν
    ox += np.multiply(k01, nu1, out=tmp)
    ox += mx
    np.multiply(k10, nu0, out=oy)
    oy += np.multiply(k11, nu1, out=tmp)
    oy += my
    # Σ − K T: (K T)_ij = k_i0 t_0j + k_i1 t_1j
    for o, s_ij, ka, kb, ta, tb in (
        (o00, s00, k00, k01, t00, t10),
        (o01, s01, k00, k01, t01, t11),
        (o11, s11, k10, k11, t01, t11),
    ):
        np.multiply(ka, ta, out=tmp)
        tmp += np.multiply(kb, tb, out=o)
        np.subtract(s_ij, tmp, out=o)
    return out


def _update_landmarks(
    w: _Work,
    index: tuple[Any, Any],
    pose: tuple[FloatArray, FloatArray, FloatArray],
    z0: FloatArray,
    z1: FloatArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    mark: bool = True,
) -> FloatArray:
    """Update the landmarks ``index = (slots, particles)`` (any batch shape; no pair may
    repeat: fancy assignment keeps one) with readings ``(z0, z1)`` from ``pose = (x, y, θ)``
    (all broadcasting to the batch), in place, and mark them seen and updated (``mark``
    False: not, where no later step of the scan reads the marks). Returns the
    log-likelihoods (``-inf`` where the landmark is at the sensor, which is left alone)."""
    full = (slice(None), *index)
    g = w.lm[full]
    F, ok = _landmark_terms(model, pose, g, R)
    nu0, nu1 = _innovations(model, F, z0, z1)
    ll = _log_likelihood(F, nu0, nu1)
    new = _ekf(F, g, nu0, nu1, R)
    w.all_ok = ok is _ALL_OK or bool(ok.all())
    if w.all_ok:
        w.lm[full] = new
        if mark:
            w.seen[index] = True
            w.updated[index] = True
        return ll
    w.lm[full] = np.where(ok, new, g)
    w.seen[index] |= ok
    w.updated[index] |= ok
    return np.where(ok, ll, -np.inf)


def _start_landmarks(
    w: _Work,
    rows: NDArray[np.intp],
    rank: NDArray[np.intp],
    poses: FloatArray,
    z: FloatArray,
    ids: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> None:
    """Start landmark ``ids[i]`` from reading ``z[i]`` in particle ``rows[i]``, in its slot
    ``counts + rank[i]`` (``rank``: 0, 1, … over the new landmarks of one particle)."""
    slots = w.counts[rows] + rank
    w.grow(int(slots.max()) + 1)
    _, Lz = model.inverse_jacobians(poses, z)
    m = model.inverse(poses, z)
    C = _congruence(Lz, R)  # L_z R L_zᵀ: the pose is given in the particle
    w.lm[:, slots, rows] = np.stack((m[:, 0], m[:, 1], C[:, 0, 0], C[:, 0, 1], C[:, 1, 1]))
    w.counters[slots, rows] = 1
    w.ids[slots, rows] = ids
    w.seen[slots, rows] = True
    w.updated[slots, rows] = False
    np.add.at(w.counts, rows, 1)
    w.common = None


def _new_landmarks(
    w: _Work,
    new: NDArray[np.bool_],
    poses: FloatArray,
    z: FloatArray,
    ids: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> None:
    """Start a landmark for every ``new[k, p]`` (reading ``k``, particle ``p``): id
    ``ids[k]``, appended to each particle's map in reading order."""
    kr, pr = np.nonzero(new)
    if pr.size == 0:
        return
    rank = (np.cumsum(new, axis=0) - 1)[kr, pr]
    _start_landmarks(w, pr, rank, poses[pr], z[kr], ids[kr], R, model)


def _pose_planes(poses: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(x, y, θ)`` of poses ``(P, 3)`` as contiguous ``(P,)`` rows."""
    t = poses.T.copy()
    return t[0], t[1], t[2]


def _labelled_round(
    w: _Work,
    poses: FloatArray,
    pose: tuple[FloatArray, FloatArray, FloatArray],
    z: FloatArray,
    rid: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    log_p0: float,
    mark: bool = True,
) -> tuple[FloatArray, NDArray[np.bool_] | None]:
    """Readings ``z (K, 2)`` of the distinct landmarks ``rid (K,)``, all at once: update the
    landmark with that id in every particle, or start it. Returns log-likelihoods ``(K, P)``
    (``log p0`` for a start, ``-inf`` for a landmark at the sensor) and which readings found
    their landmark ``(K, P)`` (None: all). ``mark``: see :func:`_update_landmarks`."""
    n, k = poses.shape[0], z.shape[0]
    cmax = w.ids.shape[0] if w.slot_of is not None else int(w.counts.max())
    if cmax and (w.slot_of is not None or w.is_common(cmax)):
        # Every particle holds the same ids in the same slots (the usual case with labelled
        # readings only): look the ids up once, work on (K, P) blocks.
        where = w.slot_of
        if where is None:
            where = w.slot_of = {lid: j for j, lid in enumerate(w.ids[:cmax, 0].tolist())}
        slot_k = [where.get(lid, -1) for lid in rid.tolist()]
        if min(slot_k) >= 0:  # every id mapped
            slots = np.array(slot_k, dtype=np.intp)
            ll_all = _update_landmarks(
                w, (slots, slice(None)), pose, z[:, 0:1], z[:, 1:2], R, model, mark
            )
            return ll_all, None
        kf = [j for j, sl in enumerate(slot_k) if sl >= 0]
        ll = np.full((k, n), log_p0)
        found = np.zeros((k, n), dtype=bool)
        if kf:
            slot = np.array([slot_k[j] for j in kf], dtype=np.intp)
            rows: Any = slice(None) if len(kf) == k else np.array(kf, dtype=np.intp)
            zf = z[rows]
            ll[rows] = _update_landmarks(
                w, (slot, slice(None)), pose, zf[:, 0:1], zf[:, 1:2], R, model
            )
            found[rows] = True
        if len(kf) < k:
            _new_landmarks(w, ~found, poses, z, rid, R, model)
            w.common = True  # every particle started the same ids in the same slots
        return ll, found
    ll = np.full((k, n), log_p0)
    found = np.zeros((k, n), dtype=bool)
    if cmax:
        valid = w.valid(cmax)
        hit = (w.ids[None, :cmax] == rid[:, None, None]) & valid  # (K, C, P)
        found = hit.any(axis=1)
        kr, pr = np.nonzero(found)
        if pr.size:
            slot = hit[kr, :, pr].argmax(axis=1)
            px, py, pth = pose
            ll[kr, pr] = _update_landmarks(
                w, (slot, pr), (px[pr], py[pr], pth[pr]), z[kr, 0], z[kr, 1], R, model
            )
    _new_landmarks(w, ~found, poses, z, rid, R, model)
    return ll, found


def _labelled_rounds(rid: IntArray, index: NDArray[np.intp]) -> list[NDArray[np.intp]]:
    """Split the readings ``index`` into rounds of distinct ids, round ``r`` holding the
    ``r``-th reading of each id, each round in reading order."""
    if len(set(rid[index].tolist())) == index.size:  # the usual case: every id once
        return [index] if index.size else []
    rounds = []
    rest = index
    while rest.size:
        _, first = np.unique(rid[rest], return_index=True)
        if first.size == rest.size:
            rounds.append(rest)
            break
        take = np.zeros(rest.size, dtype=bool)
        take[first] = True
        rounds.append(rest[take])
        rest = rest[~take]
    return rounds


def _associate_greedy(ll_all: FloatArray, log_p0: float) -> tuple[NDArray[np.intp], FloatArray]:
    """Maximum-likelihood association of ``K`` readings, in order, in every particle:
    ``ll_all (K, C, P)`` log-likelihoods (``-inf``: not a candidate); a reading may not take
    a landmark an earlier reading of the scan took. Returns slots ``(K, P)`` (``-1``: new
    landmark) and log-likelihoods ``(K, P)`` (``log p0`` for a new landmark).

    Where the readings' unconstrained choices are distinct (the usual case) they are the
    greedy ones: by induction, no reading's best landmark was taken by an earlier one. Only
    the particles where two readings want the same landmark run the reading-by-reading
    loop."""
    k = ll_all.shape[0]
    best = np.argmax(ll_all, axis=1)  # (K, P)
    lb = np.take_along_axis(ll_all, best[:, None, :], axis=1)[:, 0]
    match = lb >= log_p0  # below p0 (or no candidate): a new landmark
    slots = np.where(match, best, -1)
    ll = np.where(match, lb, log_p0)
    if k > 1:
        key = np.sort(np.where(match, best, -1 - np.arange(k)[:, None]), axis=0)
        clash = np.flatnonzero((key[1:] == key[:-1]).any(axis=0))
        if clash.size:
            slots[:, clash], ll[:, clash] = _associate_sequential(ll_all[:, :, clash], log_p0)
    return slots, ll


def _associate_sequential(ll_all: FloatArray, log_p0: float) -> tuple[NDArray[np.intp], FloatArray]:
    """:func:`_associate_greedy` reading by reading (the exclusion applied as it goes)."""
    k, c, n = ll_all.shape
    cols = np.arange(n)
    taken = np.zeros((c, n), dtype=bool)
    slots = np.full((k, n), -1, dtype=np.intp)
    ll = np.full((k, n), log_p0)
    for j in range(k):
        llk = np.where(taken, -np.inf, ll_all[j])
        best = np.argmax(llk, axis=0)
        lb = llk[best, cols]
        match = lb >= log_p0
        p = cols[match]
        slots[j, p] = best[match]
        ll[j, p] = lb[match]
        taken[best[match], p] = True
    return slots, ll


def _unlabelled(
    w: _Work,
    poses: FloatArray,
    pose: tuple[FloatArray, FloatArray, FloatArray],
    z: FloatArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    log_p0: float,
    forced: NDArray[np.intp] | None = None,
) -> tuple[FloatArray, IntArray, NDArray[np.int8]]:
    """Unlabelled readings ``z (K, 2)``: associate each in every particle by maximum
    likelihood (excluding landmarks already used in this scan) or take the ``forced`` slots
    ``(K, P)`` (``-1`` new, ``-2`` skip); update or start the landmarks, all at once.
    Returns the log-likelihoods ``(K, P)`` (meaningless with ``forced``), and the id of the
    landmark each reading updated or started with its status code ``(K, P)`` (see
    :meth:`FastSlam1.reading_log`)."""
    n, k = poses.shape[0], z.shape[0]
    cmax = int(w.counts.max())
    if forced is None:
        slots = np.full((k, n), -1, dtype=np.intp)
        ll = np.full((k, n), log_p0)
        if cmax:
            # The terms of the landmarks do not depend on the reading: (C, P) once, then the
            # innovations and likelihoods of every (reading, landmark, particle).
            F, ok = _landmark_terms(model, pose, w.lm[:, :cmax], R)
            Fb = F[:, None]
            nu0, nu1 = _innovations(model, Fb, z[:, 0, None, None], z[:, 1, None, None])
            cand = w.valid(cmax) & ok & ~w.seen[:cmax]
            ll_all = _log_likelihood(Fb, nu0, nu1)
            ll_all[:, ~cand] = -np.inf
            slots, ll = _associate_greedy(ll_all, log_p0)
            kr, pr = np.nonzero(slots >= 0)
            if pr.size:
                sl = slots[kr, pr]
                g = w.lm[:, sl, pr]
                w.lm[:, sl, pr] = _ekf(F[:, sl, pr], g, nu0[kr, sl, pr], nu1[kr, sl, pr], R)
                w.seen[sl, pr] = True
                w.updated[sl, pr] = True
    else:
        slots, ll = forced, np.zeros((k, n))
        kr, pr = np.nonzero(slots >= 0)
        if pr.size:
            px, py, pth = pose
            _update_landmarks(
                w, (slots[kr, pr], pr), (px[pr], py[pr], pth[pr]), z[kr, 0], z[kr, 1], R,
                model,
            )  # fmt: skip
    new = slots == -1
    matched = slots >= 0
    assoc = np.full((k, n), -1, dtype=np.int64)
    status = np.full((k, n), DISCARDED, dtype=np.int8)
    kr, pr = np.nonzero(matched)
    assoc[kr, pr] = w.ids[slots[kr, pr], pr]  # before new landmarks or pruning move slots
    status[matched] = UPDATED
    spawning = new.any(axis=1)  # readings that start a landmark somewhere get one id each
    if spawning.any():
        w.maybe_prunable = True
        ids = np.full(k, -1, dtype=np.int64)
        ids[spawning] = w.next_id + np.arange(int(spawning.sum()))
        w.next_id += int(spawning.sum())
        _new_landmarks(w, new, poses, z, ids, R, model)
        assoc[new] = np.broadcast_to(ids[:, None], (k, n))[new]
        status[new] = INITIALISED
    return ll, assoc, status


def _split(rid: IntArray, s: UpdateSettings) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices of the labelled readings (ids used) and of the unlabelled ones."""
    lab = (rid >= 0) if s.use_ids else np.zeros(rid.size, dtype=bool)
    return np.flatnonzero(lab), np.flatnonzero(~lab)


def _scan_at_poses(
    w: _Work,
    poses: FloatArray,
    z: FloatArray,
    rid: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    s: UpdateSettings,
    *,
    forced_unlabelled: NDArray[np.intp] | None = None,
    weigh_first_round: bool = True,
) -> FloatArray:
    """One scan at given particle poses (FastSLAM 1.0, and 2.0 after sampling): labelled
    readings first (in rounds of distinct ids), then the unlabelled ones. Returns each
    particle's log-likelihood of the readings ``(P,)`` — for 2.0 (``forced_unlabelled``
    ``(K_unlabelled, P)`` given, ``weigh_first_round`` False) only of the readings its
    proposal left out."""
    pose = _pose_planes(poses)
    ids = rid.tolist()
    if s.use_ids and ids and min(ids) >= 0 and len(set(ids)) == len(ids):
        # The usual case with known correspondences: every reading labelled, each id once.
        # Labelled landmarks keep no existence counter and no unlabelled reading follows:
        # nothing reads the seen/updated marks of this scan.
        w.all_ok = True
        l_all, found = _labelled_round(w, poses, pose, z, rid, R, model, s.log_p0, mark=False)
        if found is None and w.all_ok:  # every particle: every reading updated
            w.assoc, w.assoc_status = rid, np.empty(rid.size, dtype=np.int8)
            w.assoc_status.fill(UPDATED)  # (np.full costs 3x: a Python wrapper)
        else:
            w.assoc, w.assoc_status = _labelled_association(rid, found, l_all == -np.inf)
        return l_all.sum(axis=0) if weigh_first_round else np.zeros(poses.shape[0])
    n, k = poses.shape[0], rid.size
    assoc = np.full((k, n), -1, dtype=np.int64)
    status = np.full((k, n), DISCARDED, dtype=np.int8)
    ll = np.zeros(n)
    lab, unl = _split(rid, s)
    for r, idx in enumerate(_labelled_rounds(rid, lab)):
        l_round, found = _labelled_round(w, poses, pose, z[idx], rid[idx], R, model, s.log_p0)
        assoc[idx], status[idx] = _labelled_association(rid[idx], found, l_round == -np.inf)
        if r > 0 or weigh_first_round:
            ll += l_round.sum(axis=0)
    if unl.size:
        l_unl, assoc[unl], status[unl] = _unlabelled(
            w, poses, pose, z[unl], R, model, s.log_p0, forced_unlabelled
        )
        if forced_unlabelled is None:
            ll += l_unl.sum(axis=0)
    w.assoc, w.assoc_status = assoc, status
    return ll


def _labelled_association(
    rid: IntArray, found: NDArray[np.bool_] | None, at_sensor: NDArray[np.bool_]
) -> tuple[IntArray, NDArray[np.int8]]:
    """Ids and status codes ``(K, P)`` of labelled readings: the reading's id, updated where
    the landmark was found (discarded where it was at the sensor), started elsewhere."""
    k, n = at_sensor.shape
    status = np.full((k, n), UPDATED if found is None else INITIALISED, dtype=np.int8)
    if found is not None:
        status[found] = UPDATED
    status[at_sensor] = DISCARDED
    assoc = np.where(at_sensor, -1, rid[:, None])
    return assoc, status


def _predicted_visible(
    x: FloatArray, y: FloatArray, poses: FloatArray, s: UpdateSettings
) -> NDArray[np.bool_]:
    """Which landmarks at world positions ``(x, y)`` ``(C, P)`` the sensor should see from
    the particles' poses ``(P, 3)``: range from the sensor within ``[visible_min_range,
    visible_max_range]`` and bearing from the sensor within ``±fov/2`` of the heading, the
    sensor sitting at ``sensor_offset`` in the robot frame.

    The offset matters where it is large beside the ranges: Victoria Park's laser sits 3.78
    m ahead of the rear axle, the pose's origin, and sees only the half-plane ahead of
    itself; judged from the axle, the trees beside the cab (between axle and laser) would
    count as missed at every scan. (A candidate for a method of the sensor specification,
    next to the simulator's visibility test, once the specification carries the offset.)"""
    px, py, pth = _pose_planes(poses)
    dx, dy = x - px, y - py
    a, b = s.sensor_offset
    limited_fov = s.fov < 2.0 * math.pi
    if limited_fov or a or b:
        c, sn = np.cos(pth), np.sin(pth)
        xs, ys = c * dx + sn * dy - a, c * dy - sn * dx - b  # in the sensor frame
        if a or b:  # (without an offset the world-frame range is the same)
            dx, dy = xs, ys
    r2 = dx * dx
    r2 += dy * dy
    visible = r2 >= s.visible_min_range**2
    if math.isfinite(s.visible_max_range):
        visible &= r2 <= s.visible_max_range**2
    if limited_fov:
        visible &= np.abs(np.arctan2(ys, xs)) <= 0.5 * s.fov
    return visible


def _prune(w: _Work, poses: FloatArray, s: UpdateSettings) -> None:
    """End of a scan, for the landmarks that can be removed (started by unlabelled readings,
    ``prune`` on; the others keep no counter): existence counters up for updated landmarks,
    down for landmarks predicted visible but not seen; remove those below zero (stable
    compaction)."""
    if not (s.prune and w.maybe_prunable):
        return
    cmax = int(w.counts.max()) if w.counts.size else 0
    if cmax == 0:
        return
    prunable = w.ids[:cmax] >= s.first_unlabelled_id  # (unused slots hold id -1)
    if not prunable.any():
        return
    visible = prunable & _predicted_visible(w.lm[_MX, :cmax], w.lm[_MY, :cmax], poses, s)
    counters = w.counters[:cmax]
    hits = w.updated[:cmax] & prunable
    counters += hits if s.hit_weight == 1 else s.hit_weight * hits  # views: in place
    counters -= visible & ~w.seen[:cmax]
    remove = prunable & (counters < 0)
    if not remove.any():
        return
    w.removed += int(remove.sum())
    keep = w.valid(cmax) & ~remove
    order = np.argsort(~keep, axis=0, kind="stable")  # kept slots first, in their order
    w.lm[:, :cmax] = np.take_along_axis(w.lm[:, :cmax], order[None], axis=1)
    w.counters[:cmax] = np.take_along_axis(counters, order, axis=0)
    w.ids[:cmax] = np.take_along_axis(w.ids[:cmax], order, axis=0)
    w.counts = keep.sum(axis=0).astype(np.int64)
    unused = ~w.valid()
    w.ids[unused] = -1
    w.counters[unused] = 0
    w.common = None


def _usable_readings(
    z: FloatArray, model: InvertibleLandmarkModel, s: UpdateSettings
) -> NDArray[np.bool_]:
    if s.min_range <= 0 or z.shape[0] == 0:
        return np.ones(z.shape[0], dtype=bool)
    lm = model.inverse(np.zeros(3), z)  # the landmark in the robot frame
    return np.asarray(np.hypot(lm[:, 0], lm[:, 1]) >= s.min_range)


def _normalised(log_weights: FloatArray) -> FloatArray:
    """Log-weights minus their log-sum-exp; ConvergenceError if every weight is zero or one
    is NaN (:func:`normalize_log_weights`, called for its errors only on that path)."""
    m = float(log_weights.max())
    if not math.isfinite(m):
        lw, _ = normalize_log_weights(log_weights)  # raises: all zero, NaN or +inf
        return lw
    return log_weights - (m + math.log(float(np.sum(np.exp(log_weights - m)))))


def _normalised_with_weights(log_weights: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`_normalised` and :func:`_weights_of` at once (one exponential)."""
    m = float(log_weights.max())
    if not math.isfinite(m):
        lw = _normalised(log_weights)  # raises: all zero, NaN or +inf
        return lw, _weights_of(lw)
    d = log_weights - m
    e = np.exp(d)
    total = float(e.sum())
    d -= math.log(total)
    e /= total
    if float(d.min()) <= _NEGLIGIBLE_LOG_WEIGHT:
        e[d <= _NEGLIGIBLE_LOG_WEIGHT] = 0.0
        e /= e.sum()
    return d, e


def _weights_of(log_weights: FloatArray) -> FloatArray:
    """Normalised weights; log-weights below ``-700`` give exactly 0 (see
    :attr:`FastSlamParticles.weights`)."""
    w: FloatArray = np.zeros(log_weights.shape)
    np.exp(log_weights, out=w, where=log_weights > _NEGLIGIBLE_LOG_WEIGHT)
    w /= w.sum()
    return w


def _update1(
    w: _Work,
    poses: FloatArray,
    log_weights: FloatArray,
    z: FloatArray,
    rid: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    s: UpdateSettings,
) -> tuple[FloatArray, FloatArray]:
    """FastSLAM 1.0's scan on the maps ``w`` (in place) at ``poses``: the new normalised
    log-weights and each particle's log-likelihood of the scan ``(P,)``."""
    w.begin_scan()
    ll = _scan_at_poses(w, poses, z, rid, R, model, s)
    _prune(w, poses, s)
    return _normalised(log_weights + ll), ll


# FastSLAM 2.0's proposal works on batched 2×2 matrices (with the pose Jacobian).


@dataclass(frozen=True)
class _Terms:
    """Innovation terms of readings against landmarks, batch ``(...)``."""

    nu: FloatArray  # (..., 2)
    Hx: FloatArray  # (..., 2, 3)
    Hm: FloatArray  # (..., 2, 2)
    Q: FloatArray  # (..., 2, 2)   H Σ Hᵀ + R
    ok: NDArray[np.bool_]  # (...)  False: landmark at the sensor, terms undefined

    def take(self, index: Any, pose_jacobian: bool = True) -> _Terms:
        """The terms at ``index`` of the batch (the Jacobians, which do not depend on the
        reading, may lack a readings axis that ``ν`` has: they are broadcast first).
        ``pose_jacobian=False`` leaves ``H_x`` out (empty): FastSLAM 1.0 never needs it."""
        batch = self.nu.shape[:-1]

        def at(a: NDArray[Any], tail: tuple[int, ...]) -> NDArray[Any]:
            return np.broadcast_to(a, (*batch, *tail))[index]

        Hx = at(self.Hx, (2, 3)) if pose_jacobian else np.empty((0, 2, 3))
        return _Terms(self.nu[index], Hx, at(self.Hm, (2, 2)), at(self.Q, (2, 2)),
                      at(self.ok, ()))  # fmt: skip


def _terms(
    model: InvertibleLandmarkModel,
    poses: FloatArray,
    mu: FloatArray,
    cov: FloatArray,
    z: FloatArray,
    R: FloatArray,
) -> _Terms:
    """``ν = z ⊟ h(x, μ)``, ``H_x``, ``H_m`` and ``Q = H_m Σ H_mᵀ + R`` for poses ``(..., 3)``,
    landmarks ``(..., 2)``, ``(..., 2, 2)`` and readings ``(..., 2)`` (broadcast).

    A landmark closer than ``MIN_RANGE`` to the pose has no bearing: it is evaluated at a
    stand-in point and flagged ``ok = False``. The models' batch kernels
    ``predict_unchecked`` and ``jacobians_unchecked`` are called directly: the inputs were
    validated once (data set, public functions), and the checks of ``predict``/``jacobians``
    cost more than the arithmetic here."""
    batch = np.broadcast_shapes(poses.shape[:-1], mu.shape[:-1])
    p = np.broadcast_to(poses, (*batch, 3))
    m = np.broadcast_to(mu, (*batch, 2))
    d = m - p[..., :2]
    ok = np.hypot(d[..., 0], d[..., 1]) >= 2.0 * MIN_RANGE
    if not ok.all():
        m = np.where(ok[..., None], m, p[..., :2] + np.array([1.0, 0.0]))
    if isinstance(model, LandmarkModelBase):
        z_hat = model.predict_unchecked(p, m)
        Hx, Hm = model.jacobians_unchecked(p, m)
    else:  # pragma: no cover - every invertible model of slamkit has the kernels
        z_hat = model.predict(p, m)
        Hx, Hm = model.jacobians(p, m)
    nu = z - z_hat
    for j, angular in enumerate(model.angular):
        if angular:
            nu[..., j] = wrap_angle(nu[..., j])
    return _Terms(nu, Hx, Hm, _congruence(Hm, cov) + R, ok)


def _congruence(H: FloatArray, S: FloatArray) -> FloatArray:
    """``H S Hᵀ`` ``(..., 2, 2)`` for a symmetric ``S``, written out: exactly symmetric, and on
    large batches (every landmark of every particle) ~3x faster than stacked ``matmul``."""
    h00, h01, h10, h11 = H[..., 0, 0], H[..., 0, 1], H[..., 1, 0], H[..., 1, 1]
    s00, s01, s11 = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
    t00, t01 = h00 * s00 + h01 * s01, h00 * s01 + h01 * s11  # first row of H S
    t10, t11 = h10 * s00 + h11 * s01, h10 * s01 + h11 * s11  # second row
    out = np.empty(np.broadcast_shapes(H.shape, S.shape))
    out[..., 0, 0] = t00 * h00 + t01 * h01
    out[..., 0, 1] = out[..., 1, 0] = t00 * h10 + t01 * h11
    out[..., 1, 1] = t10 * h10 + t11 * h11
    return out


def _congruence_2x3(H: FloatArray, S: FloatArray) -> FloatArray:
    """``H S Hᵀ`` ``(..., 2, 2)`` for ``H (..., 2, 3)`` and a symmetric ``S (..., 3, 3)``
    (broadcast), written out as :func:`_congruence`: exactly symmetric, and on every
    landmark of every particle several times faster than stacked ``matmul``."""
    h = [[H[..., i, k] for k in range(3)] for i in range(2)]
    s = [[S[..., i, k] for k in range(3)] for i in range(3)]
    hs = [[h[i][0] * s[0][k] + h[i][1] * s[1][k] + h[i][2] * s[2][k] for k in range(3)]
          for i in range(2)]  # fmt: skip
    out = np.empty((*np.broadcast_shapes(H.shape[:-2], S.shape[:-2]), 2, 2))
    out[..., 0, 0] = hs[0][0] * h[0][0] + hs[0][1] * h[0][1] + hs[0][2] * h[0][2]
    out[..., 0, 1] = out[..., 1, 0] = hs[0][0] * h[1][0] + hs[0][1] * h[1][1] + hs[0][2] * h[1][2]
    out[..., 1, 1] = hs[1][0] * h[1][0] + hs[1][1] * h[1][1] + hs[1][2] * h[1][2]
    return out


def _inv2(S: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Inverse and determinant of 2×2 matrices ``(..., 2, 2)`` in closed form (LAPACK's
    per-matrix overhead is ~100x the arithmetic of a 2×2)."""
    a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = a * d - b * c
    inv = np.empty_like(S)
    inv[..., 0, 0] = d / det
    inv[..., 0, 1] = -b / det
    inv[..., 1, 0] = -c / det
    inv[..., 1, 1] = a / det
    return inv, det


def _log_gauss(nu: FloatArray, S: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(log N(ν; 0, S), S⁻¹)`` for 2-D ``ν (..., 2)``, ``S (..., 2, 2)``."""
    S_inv, det = _inv2(S)
    n0, n1 = nu[..., 0], nu[..., 1]
    d2 = n0 * (S_inv[..., 0, 0] * n0 + S_inv[..., 0, 1] * n1) + n1 * (
        S_inv[..., 1, 0] * n0 + S_inv[..., 1, 1] * n1
    )  # νᵀ S⁻¹ ν
    with np.errstate(invalid="ignore", divide="ignore"):
        ll = -0.5 * (d2 + np.log(det)) - _LOG_2PI  # m = 2: (m/2) log 2π = log 2π
    return ll, S_inv


def _sym_sqrt(S: FloatArray) -> FloatArray:
    """Symmetric square roots ``(..., k, k)`` of PSD matrices (eigen-decomposition, negative
    round-off eigenvalues clipped): unique, and defined where a Cholesky factor is not."""
    lam, vec = np.linalg.eigh(S)
    return (vec * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]) @ np.swapaxes(vec, -1, -2)


class _Proposal:
    """The Gaussian ``N(e, Σ_δ)`` over each particle's motion noise ``δ``, and the motion
    linearised at its mean.

    Without ``pose_cov`` the particle's pose ``x_{t-1}`` is exact and ``δ = ε`` is the
    control noise: prior ``N(0, Q_u)``, ``x̄ = g(x_{t-1}, u + e)``, ``V = ∂g/∂u`` there. With
    ``pose_cov (P, 3, 3)`` the pose before the control is itself uncertain (earlier controls
    since the last scan, folded in by :func:`_fold_motion`): ``δ = (δx, ε)`` with prior
    ``N(0, blockdiag(pose_cov, Q_u))``, ``x̄ = g(x_{t-1} + e_x, u + e_u)`` and
    ``V = [∂g/∂x, ∂g/∂u]`` ``(P, 3, 3 + k)``, so the readings shape every step of the motion
    since the last scan, not only the last one."""

    def __init__(
        self,
        motion: MotionModel,
        x0: FloatArray,
        u: FloatArray,
        dt: float,
        Qu: FloatArray,
        pose_cov: FloatArray | None = None,
    ) -> None:
        n, k = x0.shape[0], Qu.shape[0]
        self.motion, self.x0, self.u, self.dt = motion, x0, u, dt
        self.limit = _steering_limit(motion)
        self.b = 0 if pose_cov is None else 3  # where the control noise starts in δ
        d = self.b + k
        self.e = np.zeros((n, d))
        self.S = np.zeros((n, d, d))
        self.S[:, self.b :, self.b :] = Qu
        if pose_cov is not None:
            self.S[:, :3, :3] = pose_cov
        self.x_bar = np.empty((n, 3))
        self.V = np.empty((n, 3, d))
        self.Px = np.empty((n, 3, 3))  # V Σ_δ Vᵀ: the proposal's pose covariance
        self._linearise(slice(None))

    def _motion_at(self, rows: Any, delta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The pose before the control and the (feasible) control at noise ``delta``."""
        x = self.x0[rows] if self.b == 0 else self.x0[rows] + delta[:, :3]
        return x, self._feasible(self.u + delta[:, self.b :])

    def _linearise(self, rows: Any) -> None:
        """``x̄``, ``V`` and ``P_x = V Σ_δ Vᵀ`` of the particles ``rows`` at their current
        mean ``e``."""
        x, u = self._motion_at(rows, self.e[rows])
        self.x_bar[rows] = self.motion.apply(x, u, self.dt)
        G, V = self.motion.jacobians(x, u, self.dt)
        if self.b:
            self.V[rows, :, :3] = G
            self.V[rows, :, 3:] = V
        else:
            self.V[rows] = V
        Vr = self.V[rows]
        Px = Vr @ self.S[rows] @ np.swapaxes(Vr, -1, -2)
        self.Px[rows] = 0.5 * (Px + np.swapaxes(Px, -1, -2))

    def marginal(self, t: _Terms, rows: Any) -> FloatArray:
        """``L = A Σ_δ Aᵀ + Q = H_x P_x H_xᵀ + Q`` with ``A = H_x V`` (the reading's
        covariance, motion noise integrated out) for terms ``t`` of the particles ``rows``
        (broadcasting over extra axes). Through the 3×3 ``P_x``, whatever the size of
        ``δ``, and written out: the association tries every landmark of every particle."""
        return _congruence_2x3(t.Hx, self.Px[rows]) + t.Q

    def update(self, rows: NDArray[np.intp], t: _Terms, L: FloatArray) -> None:
        """Fold one reading (terms ``t``, marginal covariance ``L``) into the proposal of
        the particles ``rows``, then relinearise the motion at the new mean."""
        A = t.Hx @ self.V[rows]  # (N, 2, d): ∂h/∂δ = H_x V
        S = self.S[rows]
        L_inv, _ = _inv2(L)
        K = S @ np.swapaxes(A, -1, -2) @ L_inv  # K_δ = Σ_δ Aᵀ L⁻¹, (N, d, 2)
        self.e[rows] += (K @ t.nu[..., None])[..., 0]
        IKA = np.eye(S.shape[-1]) - K @ A
        # Joseph form, with Q (L without the motion part) as the noise of the reading.
        S_new = IKA @ S @ np.swapaxes(IKA, -1, -2) + K @ t.Q @ np.swapaxes(K, -1, -2)
        self.S[rows] = 0.5 * (S_new + np.swapaxes(S_new, -1, -2))
        self._linearise(rows)

    def sample(self, rng: np.random.Generator) -> FloatArray:
        """Poses ``g(x_{t-1} + δx, u + ε)``, ``δ ~ N(e, Σ_δ)`` (draws
        ``rng.standard_normal((P, d))``, coloured by the symmetric square root)."""
        n, d = self.e.shape
        draws = rng.standard_normal((n, d))
        delta = self.e + (_sym_sqrt(self.S) @ draws[..., None])[..., 0]
        return self.motion.apply(*self._motion_at(slice(None), delta), self.dt)

    def _feasible(self, u: FloatArray) -> FloatArray:
        """Controls with the steering saturated (Ackermann, see :func:`_steering_limit`)."""
        if self.limit is not None:
            np.clip(u[..., 1], -self.limit, self.limit, out=u[..., 1])
        return u


def _update2(
    w: _Work,
    poses0: FloatArray,
    log_weights: FloatArray,
    motion: MotionModel,
    u: FloatArray,
    dt: float,
    Qu: FloatArray,
    z: FloatArray,
    rid: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    s: UpdateSettings,
    rng: np.random.Generator,
    pose_cov: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """FastSLAM 2.0's step on the maps ``w`` (in place) from ``poses0`` (uncertain by
    ``pose_cov (P, 3, 3)`` if given, see :class:`_Proposal`): the sampled poses, the new
    normalised log-weights and each particle's log-weight increment ``(P,)``."""
    n = poses0.shape[0]
    rows_all = np.arange(n)
    prop = _Proposal(motion, poses0, u, dt, Qu, pose_cov)
    w.begin_scan()
    log_p0 = s.log_p0
    ll_total = np.zeros(n)
    lab, unl = _split(rid, s)
    rounds = _labelled_rounds(rid, lab)
    # Labelled readings of the first round (distinct ids) shape the proposal one by one.
    for k in rounds[0] if rounds else ():
        slot = _lookup(w, int(rid[k]))
        upd = np.flatnonzero(slot >= 0)
        ll = np.full(n, log_p0)  # a new landmark: p0, the proposal is unchanged
        if upd.size:
            t = _terms(model, prop.x_bar[upd], *w.gaussians((slot[upd], upd)), z[k], R)
            L = prop.marginal(t, upd)
            l_upd, _ = _log_gauss(t.nu, L)
            ll[upd] = np.where(t.ok, l_upd, -np.inf)
            g = t.ok
            if g.any():
                prop.update(upd[g], t.take(g), L[g])
                w.seen[slot[upd[g]], upd[g]] = True
        ll_total += ll
    # Unlabelled readings: maximum likelihood under the marginal, excluding used landmarks.
    forced = np.full((unl.size, n), -1, dtype=np.intp)
    for j, k in enumerate(unl):
        cmax, cand = _candidates(w)
        ll = np.full(n, log_p0)
        if cmax:
            mu_all, cov_all = w.gaussians((slice(0, cmax), slice(None)))  # (C, P, ...)
            tall = _terms(model, prop.x_bar[:, None, :], np.swapaxes(mu_all, 0, 1),
                          np.swapaxes(cov_all, 0, 1), z[k], R)  # fmt: skip
            L_all = prop.marginal(tall, (rows_all, None))
            ll_all, _ = _log_gauss(tall.nu, L_all)
            ll_all = np.where(cand & tall.ok, ll_all, -np.inf)
            best = np.argmax(ll_all, axis=1)
            lb = ll_all[rows_all, best]
            match = np.flatnonzero(lb >= log_p0)
            if match.size:
                bm = best[match]
                ll[match] = lb[match]
                forced[j, match] = bm
                prop.update(match, tall.take((match, bm)), L_all[match, bm])
                w.seen[bm, match] = True
        ll_total += ll
    poses = prop.sample(rng)
    # The landmarks, from the sampled poses, with the proposal's associations.
    w.seen[:] = False
    ll_total += _scan_at_poses(w, poses, z, rid, R, model, s, forced_unlabelled=forced,
                               weigh_first_round=False)  # fmt: skip
    _prune(w, poses, s)
    return poses, _normalised(log_weights + ll_total), ll_total


def _lookup(w: _Work, rid: int) -> NDArray[np.intp]:
    """Slot of landmark ``rid`` in each particle, ``-1`` where it is not mapped."""
    hit = (w.ids == rid) & w.valid()  # (C, P)
    return np.where(hit.any(axis=0), hit.argmax(axis=0), -1).astype(np.intp)


def _fold_motion(
    motion: MotionModel,
    mean: FloatArray,
    cov: FloatArray | None,
    u: FloatArray,
    dt: float,
    Qu: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """One control folded into the Gaussians ``N(mean_p, cov_p)`` of the particles' poses
    ``(P, 3)``, ``(P, 3, 3)`` (``cov`` None: the poses are exact), linearised as an EKF
    prediction (:func:`~slamkit.models.motion.propagate_gaussian_unchecked`):
    ``mean ← g(mean, u)``, ``cov ← G cov Gᵀ + V Q_u Vᵀ``. FastSLAM 2.0 keeps the motion since
    the last scan this way, so that its proposal covers all of it (see :class:`_Proposal`)."""
    P = np.zeros((mean.shape[0], 3, 3)) if cov is None else cov
    return propagate_gaussian_unchecked(motion, mean, P, u, dt, Qu)


def _candidates(w: _Work) -> tuple[int, NDArray[np.bool_]]:
    """Columns in use and the slots an unlabelled reading may still match ``(P, cmax)``."""
    cmax = int(w.counts.max())
    cand = w.valid(cmax) & ~w.seen[:cmax]
    return cmax, cand.T


# --------------------------------------------------------------------------------------------
# Public functional core (validated)
# --------------------------------------------------------------------------------------------


def _check_particles(particles: FastSlamParticles) -> FastSlamParticles:
    if not isinstance(particles, FastSlamParticles):
        raise InputError(f"particles: expected FastSlamParticles, got {type(particles).__name__}")
    return particles


def _check_readings(
    z: ArrayLike, ids: ArrayLike | None, noise_cov: ArrayLike, model: object
) -> tuple[FloatArray, IntArray, FloatArray, InvertibleLandmarkModel]:
    if not isinstance(model, InvertibleLandmarkModel) or model.dim != 2:
        raise InputError(
            f"FastSLAM needs a 2-D measurement model with an inverse (range-bearing or relative "
            f"position: one reading must locate a landmark), got {type(model).__name__}"
        )
    za = as_array(z, "readings z", (None, 2))
    rid = (
        np.full(za.shape[0], -1, dtype=np.int64)
        if ids is None
        else _int_array(ids, "ids", (za.shape[0],))
    )
    R = as_covariance(noise_cov, "measurement noise_cov", 2)
    return za, rid, R, model


def fastslam_predict(
    particles: FastSlamParticles,
    u: ArrayLike,
    dt: float,
    model: MotionModel,
    control_cov: ArrayLike,
    rng: np.random.Generator,
) -> FastSlamParticles:
    """FastSLAM's prediction: every pose moves through ``model`` with its own control noise
    ``ε ~ N(0, control_cov)`` (:meth:`MotionModel.sample`); maps and weights are copied."""
    ps = _check_particles(particles)
    poses = model.sample(ps.poses, u, dt, control_cov, rng)
    return _trusted(
        poses,
        ps.log_weights.copy(),
        ps.means.copy(),
        ps.covs.copy(),
        ps.counters.copy(),
        ps.ids.copy(),
        ps.counts.copy(),
        ps.next_id,
    )


def fastslam1_update(
    particles: FastSlamParticles,
    z: ArrayLike,
    ids: ArrayLike | None,
    model: InvertibleLandmarkModel,
    noise_cov: ArrayLike,
    settings: UpdateSettings,
) -> tuple[FastSlamParticles, FloatArray]:
    """The FastSLAM 1.0 measurement update with one scan ``z (K, 2)``, ``ids (K,)`` (``-1`` or
    ``None``: unknown) at the particles' current poses.

    Returns the new set (normalised log-weights, see the module docstring for association and
    existence counters) and each particle's log-likelihood of the scan ``(P,)``. Raises
    :class:`ConvergenceError` when every particle's weight is zero or NaN afterwards."""
    ps = _check_particles(particles)
    za, rid, R, m = _check_readings(z, ids, noise_cov, model)
    use = _usable_readings(za, m, settings)
    w = _Work.of(ps)
    lw, ll = _update1(w, ps.poses, ps.log_weights, za[use], rid[use], R, m, settings)
    return w.particles(ps.poses.copy(), lw), ll


def fastslam2_update(
    particles: FastSlamParticles,
    u: ArrayLike,
    dt: float,
    motion: MotionModel,
    control_cov: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike | None,
    model: InvertibleLandmarkModel,
    noise_cov: ArrayLike,
    settings: UpdateSettings,
    rng: np.random.Generator,
    pose_cov: ArrayLike | None = None,
) -> tuple[FastSlamParticles, FloatArray]:
    """One FastSLAM 2.0 step: the motion ``u`` over ``dt`` and the scan ``z``, ``ids`` taken
    after it. Poses are drawn from the Gaussian proposal that includes the readings (see the
    module docstring; the draws are ``rng.standard_normal((P, d))``, ``d = k`` or ``3 + k``
    with ``pose_cov``), weights are the marginal likelihoods. Returns the new set and each
    particle's log-weight increment.

    ``pose_cov`` ``(P, 3, 3)`` (or ``(3, 3)`` for all): the particles' poses are uncertain
    by this much before the motion (earlier motion since the last scan, linearised; their
    ``poses`` are then the means), and the proposal covers it too. None: the poses are
    exact."""
    ps = _check_particles(particles)
    za, rid, R, m = _check_readings(z, ids, noise_cov, model)
    k = motion.control_dim
    ua = as_array(u, "control u", (k,))
    Qu = as_covariance(control_cov, "control_cov", k, semidefinite=True)
    if not (dt >= 0 and math.isfinite(dt)):
        raise InputError(f"dt: expected a time step >= 0, got {dt}")
    Px = None
    if pose_cov is not None:
        Px = as_covariance(pose_cov, "pose_cov", 3, semidefinite=True)
        if Px.ndim != 2 and Px.shape != (len(ps), 3, 3):
            raise ShapeError(f"pose_cov: expected (3, 3) or ({len(ps)}, 3, 3), got {Px.shape}")
        Px = np.broadcast_to(Px, (len(ps), 3, 3))
    use = _usable_readings(za, m, settings)
    w = _Work.of(ps)
    poses, lw, ll = _update2(w, ps.poses, ps.log_weights, motion, ua, float(dt), Qu, za[use],
                             rid[use], R, m, settings, rng, Px)  # fmt: skip
    return w.particles(poses, lw), ll


def fastslam_resample(particles: FastSlamParticles, rng: np.random.Generator) -> FastSlamParticles:
    """Low-variance resampling (:func:`low_variance_resample`); the result holds copies of
    the chosen particles' maps, with equal weights."""
    ps = _check_particles(particles)
    return ps.select(low_variance_resample(ps.weights, rng))


# --------------------------------------------------------------------------------------------
# The estimators
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FastSlamConfig:
    """Settings of :class:`FastSlam1` and :class:`FastSlam2` (one config for both: every
    setting means the same in either, and which proposal is used is the estimator's name).
    Units: metres, radians."""

    n_particles: int = 100
    """Number of particles (paths with their maps)."""
    resample_threshold: float = 0.5
    """Resample (low variance) when the effective sample size ``1/Σw²`` falls below this
    fraction of the particles; resampling is done just before the next motion, so the
    estimate and the map after a scan are those of the weighted set."""
    p0: float | None = None
    """New-landmark likelihood threshold: an unlabelled reading whose best likelihood
    ``N(ν; 0, Q)`` in a particle is below ``p0`` starts a new landmark there, and the
    particle's weight is multiplied by ``p0``. A density in the reading's units
    (1/(m·rad) for range-bearing, 1/m² for positions). ``None``: :func:`default_p0` of the
    (scaled) sensor noise at ``new_landmark_probability``."""
    new_landmark_probability: float = 0.99999
    """Used when ``p0`` is None: ``p0`` is the density of ``N(0, R)`` at the edge of this
    χ² gate (m = 2: 0.99999 → squared Mahalanobis distance 23.0, the same threshold as
    :attr:`~slamkit.mapping.ekf_mapping.EkfMappingConfig.new_landmark_probability`). On
    "five-features" without ids (50 particles, seeds 0-5, both versions) 0.999 (13.8) left a
    duplicate of the first landmark at the loop closure in 4 of 12 runs, 0.99999 in none."""
    use_ids: bool = True
    """Use the landmark ids readings carry (known correspondences). False ignores them and
    associates every reading by maximum likelihood."""
    prune: bool = True
    """Remove landmarks started by unlabelled readings when their existence counter falls
    below zero (see the module docstring)."""
    motion_noise_scale: float = 1.0
    """Multiplies the data set's control-noise covariance (> 1 spreads the particles more)."""
    measurement_noise_scale: float = 1.0
    """Multiplies the sensor's standard deviations (its covariance by the square)."""
    prior_cov_scale: float = 1.0
    """The particles start from ``N(initial_pose, prior_cov_scale · initial_cov)``; without a
    prior in the data set, all at the origin (the map then defines the frame)."""
    min_range: float = 0.0
    """Readings that place their landmark closer than this [m] are skipped (see
    :attr:`~slamkit.mapping.ekf_mapping.EkfMappingConfig.min_range`)."""
    estimate: Literal["mean", "best"] = "mean"
    """The pose reported after each step: the weighted mean of the particles (circular mean
    of the heading) or the pose of the particle with the largest weight. The covariance is
    the particles' weighted covariance about their mean in both cases."""
    initial_capacity: int = 8
    """Landmark slots per particle to start with; doubled whenever a particle needs more."""
    hit_weight: int = 1
    """What one scan that updates a landmark adds to its existence counter (a scan that
    predicted it visible but did not read it subtracts 1): a landmark survives if it is read
    in more than ``1 / (1 + hit_weight)`` of the scans that should see it. "Should see it"
    cannot know occlusion (a tree behind another) nor a detector that misses a tree now and
    then: raise it for such sensors. Clutter, read once, still dies after ``hit_weight + 1``
    misses, but a duplicate made at a loop closure, read now and then, may live (five-features
    without ids, 50 particles, seeds 0-5: 2 and 3 keep one in seed 1, 1 none). On Victoria
    Park (first 300 s, 100 particles, seed 0, misses judged from the laser): 1 → 118
    landmarks in the best particle, 3 → 156 (EKF-SLAM: 155), GPS RMSE 4.14 and 4.18 m,
    association accuracy 0.71 and 0.77 (EKF-SLAM: 0.96)."""
    miss_max_range: float | None = None
    """A missed landmark counts against its existence only when predicted closer than this
    [m]. None: the sensor's *effective* range, ``min(max_range, q₉₀ / √0.9)`` with ``q₉₀`` the
    90th percentile of the ranges of the data set's readings — the range of an ideal sensor
    (reads every landmark within it, none beyond) whose readings of landmarks spread evenly
    in the plane (range CDF ``(r/R)²``) have that percentile. For the simulated sensors it is
    within a few % of their maximum range (five-features: 7.75 of 8 m); on Victoria Park,
    where trees beyond ~40 m are seldom detected though the laser reaches 80 m, 38 m (the
    ranges measured from the laser, see :attr:`sensor_offset`)."""
    miss_fov_margin: float = 0.0
    """... and only when predicted this far [rad] inside the field of view's edges."""
    sensor_offset: tuple[float, float] | None = None
    """Where the landmark sensor sits in the robot frame [m] (x forward, y left): ranges and
    the field of view of the miss test above are measured from there. None: the data set's
    (its landmark sensor's ``offset``; Victoria Park's laser is 3.78 m ahead of and 0.5 m
    left of the rear axle). On Victoria Park (first 300 s, 100 particles, seed 0, nominal
    reading noise) judging from the axle counts the trees beside the cab as missed
    at every scan: 96 landmarks in the best particle, GPS RMSE 4.26 m; from the laser 118,
    4.14 m (seeds 1-3: 94-96 against 116-118 landmarks)."""
    n_snapshots: int = 6
    """Copies of the particle poses and weights kept for the plots (``particles.png``) when
    neither ``snapshot_every`` nor ``snapshot_times`` is set: at the first measurement update
    at or after each of this many times evenly spread from the data set's first to its last
    event (the last one at the end of the run). 0: none."""
    snapshot_every: int = 0
    """Keep a snapshot every this many measurement updates (0: not by count), plus the
    initial set (as :class:`~slamkit.localization.mcl.MclConfig`)."""
    snapshot_times: tuple[float, ...] = ()
    """Keep a snapshot at the first measurement update at or after each of these times [s]."""

    def __post_init__(self) -> None:
        if not self.n_particles >= 1:
            raise ConfigError(f"n_particles: expected an integer >= 1, got {self.n_particles}")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise ConfigError(
                f"resample_threshold: expected a fraction in [0, 1], got {self.resample_threshold}"
            )
        if self.p0 is not None and not (self.p0 > 0 and math.isfinite(self.p0)):
            raise ConfigError(f"p0: expected a density > 0 or None, got {self.p0}")
        if not 0.0 < self.new_landmark_probability < 1.0:
            raise ConfigError(
                "new_landmark_probability: expected a probability in (0, 1), got "
                f"{self.new_landmark_probability}"
            )
        for name in ("motion_noise_scale", "prior_cov_scale", "min_range"):
            v = getattr(self, name)
            if not (v >= 0 and math.isfinite(v)):
                raise ConfigError(f"{name}: expected a number >= 0, got {v}")
        if not (self.measurement_noise_scale > 0 and math.isfinite(self.measurement_noise_scale)):
            raise ConfigError(
                "measurement_noise_scale: expected a number > 0, got "
                f"{self.measurement_noise_scale}"
            )
        if self.estimate not in ("mean", "best"):
            raise ConfigError(f"estimate: expected 'mean' or 'best', got {self.estimate!r}")
        if not self.initial_capacity >= 1:
            raise ConfigError(
                f"initial_capacity: expected an integer >= 1, got {self.initial_capacity}"
            )
        if not self.hit_weight >= 1:
            raise ConfigError(f"hit_weight: expected an integer >= 1, got {self.hit_weight}")
        if self.miss_max_range is not None and not self.miss_max_range > 0:
            raise ConfigError(
                f"miss_max_range: expected a range > 0 or None, got {self.miss_max_range}"
            )
        if not 0.0 <= self.miss_fov_margin < math.pi:
            raise ConfigError(
                f"miss_fov_margin: expected an angle in [0, π), got {self.miss_fov_margin}"
            )
        if self.sensor_offset is not None:
            off = tuple(float(v) for v in self.sensor_offset)
            if len(off) != 2 or not all(math.isfinite(v) for v in off):
                raise ConfigError(f"sensor_offset: expected two finite numbers or None, got {off}")
            object.__setattr__(self, "sensor_offset", off)
        if not (self.n_snapshots >= 0 and self.snapshot_every >= 0):
            raise ConfigError(
                "n_snapshots and snapshot_every: expected integers >= 0, got "
                f"{self.n_snapshots} and {self.snapshot_every}"
            )
        if not all(math.isfinite(t) for t in self.snapshot_times):
            raise ConfigError(f"snapshot_times: expected finite times, got {self.snapshot_times}")


def _effective_range(
    dataset: Dataset,
    model: InvertibleLandmarkModel,
    max_range: float,
    sensor_offset: tuple[float, float] = (0.0, 0.0),
) -> float:
    """``min(max_range, q₉₀ / √0.9)`` of the readings' ranges from the sensor (at
    ``sensor_offset`` in the robot frame; see :attr:`FastSlamConfig.miss_max_range`);
    ``max_range`` when there are no readings."""
    z = [ev.z for ev in dataset.events if isinstance(ev, LandmarkReadings) and ev.z.size]
    if not z:
        return max_range
    lm = model.inverse(np.zeros(3), np.concatenate(z))  # in the robot frame
    q90 = float(np.quantile(np.hypot(lm[:, 0] - sensor_offset[0], lm[:, 1] - sensor_offset[1]),
                            0.9))  # fmt: skip
    return min(max_range, q90 / math.sqrt(0.9))


def _sensor_offset(dataset: Dataset) -> tuple[float, float]:
    """Where the data set's landmark sensor sits in the robot frame [m]
    (:attr:`LandmarkSensorSpec.offset <slamkit.datasets.stream.LandmarkSensorSpec.offset>`;
    the robot's origin without a sensor)."""
    sensor = dataset.landmark_sensor
    return (0.0, 0.0) if sensor is None else sensor.offset


def _steering_limit(motion: MotionModel) -> float | None:
    """The largest steering angle [rad] a sampled Ackermann control may have (None: another
    model, nothing to limit).

    :class:`~slamkit.models.Ackermann` is defined for ``|α| < π/2`` and while the encoder
    wheel is off the centre of rotation (``tan α < L / H``). Control noise is Gaussian, so
    with 100 particles and tens of thousands of controls (Victoria Park: σ = 0.3 rad per
    25-ms sample) some draws fall outside; like a real steering rack, the draw saturates at
    99 % of the limit (such a particle turns sharply and loses its weight at the next scan)
    instead of stopping the run."""
    if not isinstance(motion, Ackermann):
        return None
    return 0.99 * motion.max_steering


class _FastSlam:
    """The stateful shell shared by both versions (see :class:`FastSlam1`)."""

    version = 1
    name = "fastslam1"

    def __init__(self, dataset: Dataset, config: FastSlamConfig, rng: np.random.Generator) -> None:
        if not isinstance(config, FastSlamConfig):
            raise ConfigError(f"config: expected a FastSlamConfig, got {type(config).__name__}")
        if dataset.motion is None:
            raise InputError(
                f"{self.name} needs a motion model; data set {dataset.name!r} has none"
            )
        sensor = dataset.landmark_sensor
        if sensor is None:
            raise InputError(
                f"{self.name} needs a landmark sensor; data set {dataset.name!r} has none"
            )
        model = sensor.model()
        if not isinstance(model, InvertibleLandmarkModel) or model.dim != 2:
            raise InputError(
                f"{self.name} cannot use the {sensor.kind!r} sensor of {dataset.name!r}: one "
                "reading must locate a landmark (use range-bearing or position readings)"
            )
        self._cfg = config
        self._rng = rng
        self._motion = dataset.motion.model
        self._Q = as_covariance(
            config.motion_noise_scale * dataset.motion.noise_cov,
            "scaled motion noise_cov",
            self._motion.control_dim,
            semidefinite=True,
        )
        self._Q_root = _sym_sqrt(self._Q)  # symmetric: ε = n @ root = root @ n
        self._model: InvertibleLandmarkModel = model
        self._R = as_covariance(
            config.measurement_noise_scale**2 * sensor.noise_cov, "scaled landmark noise_cov", 2
        )
        p0 = (
            config.p0
            if config.p0 is not None
            else default_p0(self._R, config.new_landmark_probability)
        )
        first_unlabelled = 0
        if config.use_ids:
            labelled = [
                int(ev.ids.max())
                for ev in dataset.events
                if isinstance(ev, LandmarkReadings) and ev.ids.size
            ]
            first_unlabelled = max(labelled, default=-1) + 1
        offset = _sensor_offset(dataset) if config.sensor_offset is None else config.sensor_offset
        miss_range = config.miss_max_range
        if miss_range is None:
            miss_range = _effective_range(dataset, model, sensor.max_range, offset)
        fov = min(float(sensor.fov), 2.0 * math.pi)
        if fov < 2.0 * math.pi:
            fov = max(fov - 2.0 * config.miss_fov_margin, 1e-9)
        self._settings = UpdateSettings(
            p0=p0,
            use_ids=config.use_ids,
            prune=config.prune,
            visible_min_range=sensor.min_range,
            visible_max_range=min(sensor.max_range, miss_range),
            fov=fov,
            hit_weight=config.hit_weight,
            sensor_offset=offset,
            min_range=config.min_range,
            first_unlabelled_id=max(first_unlabelled, 0),
        )
        n = config.n_particles
        if dataset.initial_pose is None:
            start = np.zeros((n, 3))
        else:
            cov = dataset.initial_cov if dataset.initial_cov is not None else np.zeros((3, 3))
            start = rng.multivariate_normal(
                dataset.initial_pose, config.prior_cov_scale * cov, n, method="eigh"
            )
        ps = FastSlamParticles.start(
            start, config.initial_capacity, self._settings.first_unlabelled_id
        )
        # The state, mutated in place by the kernels: poses, log-weights, weights and the
        # planar maps (the particle set is built from them on demand, see `particles`).
        self._poses = ps.poses
        self._log_weights = ps.log_weights
        self._weights = ps.weights
        self._w = _Work.of(ps)
        self._w.common = True
        self._w.maybe_prunable = False  # no landmark yet
        self._kernels = motion_kernels(self._motion)
        self._steering_limit = _steering_limit(self._motion)
        self._pending: tuple[FloatArray, float] | None = None  # 2.0: a motion not yet sampled
        # 2.0: the earlier controls since the last scan, as each particle's Gaussian (mean
        # poses, covariances) before the pending control (None: the poses are exact).
        self._moved: tuple[FloatArray, FloatArray] | None = None
        self._after: tuple[FloatArray, FloatArray] | None = None  # ... and after it (cache)
        self._resample_pending = False
        self._last_odometry: FloatArray | None = None
        self._updates = 0
        self._clock = StepClock()
        self._t = dataset.start_time
        self._resamplings = 0
        self._readings_skipped = 0
        self._removed = 0
        self._ess: list[float] = []
        self._snapshots: list[ParticleSnapshot] = []
        # Per scan (time, ids (K,) or (K, P), status codes) and per resampling the parent
        # indices (P,): the association of any final particle, traced through its ancestors.
        self._history: list[tuple[float, IntArray, NDArray[np.int8]] | NDArray[np.intp]] = []
        times: Any = config.snapshot_times
        if config.snapshot_every == 0 and not times and config.n_snapshots > 0:
            times = np.linspace(dataset.start_time, dataset.end_time, config.n_snapshots)
        self._schedule = SnapshotSchedule(config.snapshot_every, times)
        if config.snapshot_every > 0:
            self._snapshot(dataset.start_time)

    # -- the Estimator protocol -------------------------------------------------------------

    def handle(self, event: Event) -> None:
        self._clock.tick(event.t)
        self._t = float(event.t)
        if isinstance(event, Control):
            self._motion_step(np.asarray(event.u, dtype=float), float(event.dt))
        elif isinstance(event, Odometry):
            if self._last_odometry is not None:
                self._motion_step(odometry_control(self._last_odometry, event.pose), 0.0)
            self._last_odometry = np.asarray(event.pose, dtype=float)
        elif isinstance(event, LandmarkReadings) and event.ids.size:
            self._update(event)

    def estimate(self) -> PoseEstimate:
        poses = self._poses
        spread = None
        if self._pending is not None:
            # 2.0 between a control and its scan: each particle's motion since the scan as a
            # Gaussian; the estimate is their mixture (mean, spread of the means + mean cov).
            poses, covs = self._pending_gaussian()
            spread = np.einsum("p,pij->ij", self._weights, covs)
        # The weights are normalised by construction, the poses the filter's own.
        mean, cov = particle_estimate_unchecked(poses, self._weights)
        if spread is not None:
            cov = cov + spread
        if self._cfg.estimate == "best":
            mean = poses[int(np.argmax(self._log_weights))].copy()
        return PoseEstimate(mean, cov)

    def finish(self) -> EstimatorOutput:
        ps = self.particles
        best = ps.best
        ess = np.asarray(self._ess) if self._ess else np.zeros(0)
        counts = ps.counts
        diagnostics: dict[str, Any] = {
            "version": self.version,
            "n_particles": len(ps),
            "measurement_updates": self._updates,
            "resamplings": self._resamplings,
            "readings_skipped": self._readings_skipped,
            "landmarks": int(counts[best]),
            "landmarks_mean": float(counts.mean()),
            "landmarks_min": int(counts.min()),
            "landmarks_max": int(counts.max()),
            "landmarks_removed": self._removed,
            "capacity": ps.capacity,
            "p0": self._settings.p0,
            "ess_min": float(ess.min()) if ess.size else None,
            "ess_mean": float(ess.mean()) if ess.size else None,
            "ess_median": float(np.median(ess)) if ess.size else None,
            "ess_final": float(ess[-1]) if ess.size else None,
            "best_particle_weight": float(ps.weights[best]),
        }
        if self._schedule.pending and (not self._snapshots or self._snapshots[-1].t < self._t):
            self._snapshot(self._t)  # times left after the last update: the final set
        _, chosen, status = self.reading_log()
        diagnostics["readings"] = int(chosen.size)
        diagnostics["readings_new_landmark"] = int(np.count_nonzero(status == INITIALISED))
        return EstimatorOutput(
            landmarks=ps.landmarks_of(best),
            diagnostics=diagnostics,
            particle_snapshots=tuple(self._snapshots),
            reading_landmarks=chosen,
        )

    def landmark_estimate(self) -> LandmarkEstimate:
        """The map of the particle with the largest weight now (animation frames)."""
        ps = self.particles
        return ps.landmarks_of(ps.best)

    def particle_poses(self) -> FloatArray:
        """The particle poses ``(P, 3)`` now (animation frames); for 2.0 between a control
        and its scan, the means of each particle's motion since the scan."""
        if self._pending is not None:
            return self._pending_gaussian()[0].copy()
        return self._poses.copy()

    # -- read-only views (tests, plots) ---------------------------------------------------

    @property
    def particles(self) -> FastSlamParticles:
        """The current particle set (a copy: later steps do not change it)."""
        return self._w.particles(self._poses.copy(), self._log_weights.copy())

    @property
    def settings(self) -> UpdateSettings:
        return self._settings

    @property
    def resample_pending(self) -> bool:
        """Whether the ESS fell below the threshold: the set is resampled before it moves."""
        return self._resample_pending

    @property
    def ess_history(self) -> tuple[float, ...]:
        """The effective sample size after every measurement update."""
        return tuple(self._ess)

    def reading_log(self) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """Every reading handled so far, as the particle that now has the largest weight saw
        it (its own association and those of its ancestors): ``(times, landmark ids,
        status)`` — the id of the landmark the reading updated or started (``-1`` if none);
        status codes as :meth:`EkfSlam.reading_log <slamkit.slam.EkfSlam.reading_log>`'s:
        :data:`~slamkit.mapping.ekf_mapping.UPDATED`, ``INITIALISED``, ``DISCARDED`` (the
        landmark was at the sensor) and ``TOO_CLOSE`` (skipped, see
        :attr:`FastSlamConfig.min_range`)."""
        p = int(np.argmax(self._log_weights))
        times, ids, status = [], [], []
        for entry in reversed(self._history):
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

    # -- steps ----------------------------------------------------------------------------

    def _log_scan(
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
        self._history.append((float(t), assoc, status))

    def _maybe_snapshot(self, t: float) -> None:
        if self._schedule.due(t, self._updates):
            self._snapshot(t)

    def _snapshot(self, t: float) -> None:
        self._snapshots.append(ParticleSnapshot(float(t), self._poses.copy(), self._weights.copy()))

    def _resample_if_due(self) -> None:
        if self._resample_pending:
            # The weights are normalised and finite by construction: the unchecked kernel.
            idx = low_variance_resample_unchecked(self._weights, self._rng, self._weights.size)
            n = idx.size
            self._history.append(idx)
            self._poses = self._poses[idx]
            if self._moved is not None:
                self._moved = (self._moved[0][idx], self._moved[1][idx])
            if self._after is not None:
                self._after = (self._after[0][idx], self._after[1][idx])
            self._w = self._w.select(idx)
            self._log_weights, self._weights = np.empty(n), np.empty(n)
            self._log_weights.fill(-math.log(n))
            self._weights.fill(1.0 / n)
            self._resamplings += 1
            self._resample_pending = False

    def _predict(self, u: FloatArray, dt: float) -> None:
        self._resample_if_due()
        poses = self._poses
        # g(x, u + ε), ε = Q^½ n, n ~ N(0, I): MotionModel.sample with Q's root computed once.
        eps = self._rng.standard_normal((poses.shape[0], self._Q_root.shape[0])) @ self._Q_root
        eps += u
        if self._steering_limit is not None:  # Ackermann: keep sampled steering in its domain
            np.clip(eps[:, 1], -self._steering_limit, self._steering_limit, out=eps[:, 1])
        self._kernels.move_particles(poses, eps, dt)  # validated once: the in-place kernel

    def _motion_step(self, u: FloatArray, dt: float) -> None:
        self._predict(u, dt)

    def _pending_gaussian(self) -> tuple[FloatArray, FloatArray]:
        """2.0: each particle's pose after the pending control as a Gaussian (means
        ``(P, 3)``, covariances ``(P, 3, 3)``), the motion since the last scan linearised
        (:func:`_fold_motion`); computed once per control."""
        assert self._pending is not None
        if self._after is None:
            u, dt = self._pending
            x0, cov0 = self._moved if self._moved is not None else (self._poses, None)
            self._after = _fold_motion(self._motion, x0, cov0, u, dt, self._Q)
        return self._after

    def _scan(self, z: FloatArray, rid: IntArray) -> FloatArray:
        """The scan on the state (in place); returns the new log-weights (not normalised)."""
        w = self._w
        w.begin_scan()
        ll = _scan_at_poses(w, self._poses, z, rid, self._R, self._model, self._settings)
        _prune(w, self._poses, self._settings)
        return self._log_weights + ll

    def _update(self, event: LandmarkReadings) -> None:
        z = np.asarray(event.z, dtype=float)
        rid = np.asarray(event.ids, dtype=np.int64)
        use = None
        if self._settings.min_range > 0:
            use = _usable_readings(z, self._model, self._settings)
            n_use = int(np.count_nonzero(use))
            self._readings_skipped += use.size - n_use
            if n_use == 0:
                self._log_scan(event.t, np.zeros(0, np.int64), np.zeros(0, np.int8), use)
                return
            if n_use < use.size:
                z, rid = z[use], rid[use]
            else:
                use = None
        self._updates += 1
        self._resample_if_due()
        try:
            self._log_weights, w = _normalised_with_weights(self._scan(z, rid))
        except ConvergenceError as exc:
            raise ConvergenceError(
                f"{self.name} at t = {event.t:g} s (measurement update {self._updates}): {exc}",
                step=self._clock.step,
            ) from exc
        self._removed += self._w.removed
        self._log_scan(event.t, self._w.assoc, self._w.assoc_status, use)
        self._weights = w
        self._maybe_snapshot(event.t)
        ess = 1.0 / float((w * w).sum())  # effective_sample_size of normalised weights
        self._ess.append(ess)
        if ess < self._cfg.resample_threshold * w.size:
            self._resample_pending = True


class FastSlam1(_FastSlam):
    """FastSLAM 1.0 (registered as ``fastslam1``): poses sampled from the motion model,
    weighted by the readings' likelihood; per-particle landmark EKFs, maximum-likelihood
    association with a new-landmark threshold, existence counters, low-variance resampling
    when the effective sample size drops. See the module docstring and
    :class:`FastSlamConfig`.

    Needs a motion model and a range-bearing or relative-position landmark sensor. The
    estimate is the particles' weighted mean (or best particle) with their covariance;
    :meth:`finish` returns the map of the particle with the largest weight.
    """


class FastSlam2(_FastSlam):
    """FastSLAM 2.0 (registered as ``fastslam2``): as :class:`FastSlam1`, but the controls
    since the last scan and the scan are processed together, and each particle's pose is
    drawn from the Gaussian proposal that includes the readings (over the control noise and
    the linearised error of the earlier controls, see the module docstring), weighted by the
    marginal likelihood with the motion noise integrated out.

    Nothing is sampled until the scan: each particle's pose since its last scan is a
    Gaussian (EKF predictions), and :meth:`estimate` meanwhile reports their mixture (the
    weighted mean of the means; the spread of the means plus the mean covariance).
    """

    version = 2
    name = "fastslam2"

    def _motion_step(self, u: FloatArray, dt: float) -> None:
        if self._pending is None:
            self._resample_if_due()  # before the motion, as 1.0
        else:  # an earlier control since the scan: into each particle's pose Gaussian
            self._moved = self._pending_gaussian()
        self._pending, self._after = (u, dt), None

    def _scan(self, z: FloatArray, rid: IntArray) -> FloatArray:
        if self._pending is None:
            return super()._scan(z, rid)
        u, dt = self._pending
        x0, cov0 = self._moved if self._moved is not None else (self._poses, None)
        self._pending = self._moved = self._after = None
        self._poses, lw, _ = _update2(
            self._w, x0, self._log_weights, self._motion, u, dt, self._Q, z, rid,
            self._R, self._model, self._settings, self._rng, cov0,
        )  # fmt: skip
        return lw  # normalised already: normalising again changes nothing
