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
  ``landmark_ekf_update``).
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
of the heading noise on cityTrees, the weights collapse and the filter diverges (measurements
in ``docs/estimators/fastslam.md``; ``tests/slam/test_fastslam_real.py``).

Consistency
-----------
The pose covariance the estimators report is the weighted spread of the particles (plus,
for 2.0 between a control and its scan, the mean of the particles' motion covariances). It
is optimistic, as Bailey, Nieto and Nebot (2006) showed FastSLAM to be in general:
resampling prunes the path hypotheses, so after a while every particle shares one ancestor
and the spread no longer holds the drift of the whole map: the pose NEES of both variants
lies far above that of EKF-SLAM on the same runs (``docs/estimators/fastslam.md``). Use the
trajectory, not the covariance, of a FastSLAM run.

Arrays
------
A particle set is a struct of arrays (:class:`FastSlamParticles`): poses ``(P, 3)``,
log-weights ``(P,)``, landmark means ``(P, C, 2)``, covariances ``(P, C, 2, 2)``, existence
counters and ids ``(P, C)``, and the number of landmarks of each particle ``(P,)`` (slots
``0 … counts[p] − 1`` are used). The capacity ``C`` doubles when a particle runs out of slots.
Every step is vectorised over particles; the only Python loops run over the few readings of a
scan. Resampling selects particles by fancy indexing, which copies: two resampled particles
never share a landmark buffer.

Internally the kernels work on a planar, slot-major copy of the maps (``Work``: five
``(C, P)`` planes for the mean and covariance entries, particles last) that the estimators
keep between steps and turn into a :class:`FastSlamParticles` only when asked: at 100
particles and a few readings per scan a step is a couple of hundred NumPy calls on a few
hundred numbers each, and their count — not the arithmetic — is the cost (see
``benchmarks/bench_fastslam.py``).
"""

from slamkit.slam.fastslam.config import FastSlamConfig
from slamkit.slam.fastslam.estimator import FastSlam1, FastSlam2
from slamkit.slam.fastslam.functional import (
    fastslam1_update,
    fastslam2_update,
    fastslam_predict,
    fastslam_resample,
)
from slamkit.slam.fastslam.particles import FastSlamParticles
from slamkit.slam.fastslam.settings import UpdateSettings, default_p0

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
