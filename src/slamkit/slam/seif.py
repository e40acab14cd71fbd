"""SEIF SLAM: the sparse extended information filter (Thrun et al., IJRR 23(7–8), 2004;
*Probabilistic Robotics*, ch. 12), with known or unknown correspondences.

The belief over ``y = (x_r, m_1, …, m_L)`` (as in :mod:`slamkit.slam.ekf_slam`) is held in
information form, ``Ω = Σ⁻¹`` and ``ξ = Ω μ``, plus a running estimate of the mean ``μ``.
An entry ``Ω_ij`` is a direct link between two variables; the filter keeps the robot linked
to at most ``max_active`` landmarks (the *active* ones), so each step touches the robot, the
active landmarks and what they are linked to — a cost set by ``max_active``, not by ``L``.

Every formula is derived here; ``F_x`` selects the pose, ``G``, ``V`` are the motion
Jacobians and ``R_x = V Q V_ᵀ`` the motion noise in pose space (3 × 3, rank 2 for a
unicycle: never inverted).

Motion (:func:`seif_motion_update`)
-----------------------------------
Linearised, ``y' = A y + c + F_xᵀ w`` with ``A = diag(G, I)``, so
``Σ' = A Σ Aᵀ + F_xᵀ R_x F_x`` and, with ``Φ = A⁻ᵀ Ω A⁻¹`` (the information after the
deterministic part; it changes only the pose rows and columns: ``Φ_xx = G⁻ᵀ Ω_xx G⁻¹``,
``Φ_xm = G⁻ᵀ Ω_xm``), Woodbury gives::

    Ω' = (Φ⁻¹ + F_xᵀ R_x F_x)⁻¹ = Φ − κ,   κ = Φ F_xᵀ R_x (I + Φ_xx R_x)⁻¹ F_x Φ

(using ``(R⁻¹ + B)⁻¹ = R (I + B R)⁻¹``, which needs no ``R⁻¹``). ``Φ F_xᵀ`` is nonzero only
in the rows of the robot and the active landmarks, so both terms live in that block.
The mean moves by ``δ = g(μ_x, u) − μ_x`` and the information vector keeps
``ξ − Ω μ`` unchanged (the mean estimate need not be exact)::

    μ' = μ + F_xᵀ δ,    ξ' = ξ + (Ω' − Ω) μ + Ω' F_xᵀ δ

Measurement (:func:`seif_measurement_update`)
---------------------------------------------
With ``H`` the 5-column Jacobian at ``μ`` and ``ν = z ⊖ h(μ)``, the linearised reading is
``z ≈ h(μ) + H (y − μ)``, i.e. ``z̃ = ν + H μ = H y + noise``; adding its information::

    Ω ← Ω + Hᵀ R⁻¹ H,    ξ ← ξ + Hᵀ R⁻¹ (ν + H μ)

(only the robot and landmark blocks), which makes the landmark active.

Sparsification (:func:`seif_sparsify`)
--------------------------------------
To deactivate ``m0`` (keeping ``m+`` active; ``m-`` the rest) SEIF replaces
``p(x | m0, m+)`` by ``p(x | m+, m- = 0)``: the approximation
``p̃(y) = p(x | m+, m- = 0) p(m0, m+, m-)``. In information form, with ``Ω₀`` the block of
``Ω`` on ``(x, m+, m0)`` (= the information of ``p(x, m0, m+ | m-)``):

* ``p(m0, m+, m-)``: the pose marginalised out, ``Ω − Ω F_x Ω_xx⁻¹ F_xᵀ Ω = Ω − Ω³``;
* ``p(x, m+ | m-)``: ``m0`` marginalised out of ``Ω₀``: ``Ω₀ − Ω₀ F_0 (Ω₀)_00⁻¹ F_0ᵀ Ω₀
  = Ω₀ − Ω¹``; ``p(m+ | m-)``: ``(x, m0)`` marginalised: ``Ω₀ − Ω²``; their quotient
  ``p(x | m+, m-)`` has information ``Ω² − Ω¹``;

so ``Ω̃ = Ω − Ω¹ + Ω² − Ω³``, in which the robot–``m0`` links are exactly zero, and
``ξ̃ = ξ + (Ω̃ − Ω) μ`` keeps the mean. All four terms live in the ``(x, m+, m0)`` block.

Mean recovery
-------------
``μ = Ω⁻¹ ξ`` is not computed. Each step relaxes the pose, the active landmarks and a few
others in turn (block Gauss–Seidel, amortised): ``μ_i ← Ω_ii⁻¹ (ξ_i − Σ_{j≠i} Ω_ij μ_j)``
over the blocks ``j`` linked to ``i``. :meth:`Seif.finish` solves ``Ω μ = ξ`` exactly once
and reports the landmark marginals from ``Ω⁻¹``.

Data association (:meth:`Seif._associate`)
-------------------------------------------
Readings without ids are paired by maximum likelihood, as EKF-SLAM's nearest neighbour does,
but SEIF has no covariance at hand. For a reading ``z`` and a candidate landmark ``j`` the
innovation ``ν = z ⊖ h(μ_x, μ_j)`` (at the running mean) has covariance
``S = H Σ_(x,j) Hᵀ + R``, ``H`` the 5-column Jacobian and ``Σ_(x,j)`` the 5 × 5 marginal
covariance of ``(x, m_j)`` — a block of ``Ω⁻¹``, which is not formed. Split the state into
a *blanket* ``B ∋ x, m_j`` and the rest ``C``. The rows of ``Ω`` on ``B`` are the information
of ``p(y_B | y_C)``, so ``Ω_BB⁻¹`` is the covariance of ``y_B`` *given* ``y_C``; by the law of
total covariance ``Σ_BB = Ω_BB⁻¹ + Cov(E[y_B | y_C]) ⪰ Ω_BB⁻¹``. Conditioning on the rest
gives a lower bound that is exact when ``B`` has no link to ``C`` (``Ω_BC = 0``) and that
grows towards the marginal as ``B`` grows (for ``B ⊂ B'`` the same argument inside ``B'``
gives ``(Ω_B'B'⁻¹)_BB ⪰ Ω_BB⁻¹``). The links of the landmarks far from ``B`` are weak
(sparsification keeps the robot linked to a few), so a blanket of the variables linked to
``x`` and ``m_j`` — their Markov blanket — already holds most of the correlation.

Per scan, the candidates are the landmarks within ``candidate_radius`` of the point a
reading places (at most ``max_candidates``); ``B`` = the robot, the candidates, the active
landmarks (the robot's neighbours) and the candidates' neighbours (``blanket_hops`` rings of
links, at most ``max_blanket`` landmarks), so its size is bounded by the configuration and
the links, not by the map. One Cholesky factorisation of ``Ω_BB``, solved for the columns of
the robot and the candidates, gives every ``Σ_(x,j)`` of the scan. Then
``d²_kj = ν_kjᵀ S_kj⁻¹ ν_kj``; readings and candidates are paired greedily by increasing
``d²`` inside the gate ``χ²_m(gate_probability)``, and an unpaired reading starts a landmark
if its ``d²`` to every candidate exceeds ``χ²_m(new_landmark_probability)`` (else it is
rejected). The landmark search itself is a vectorised distance test over the landmark
means, ``O(L)`` with a tiny constant.

The heading is kept unwrapped inside the filter (``ξ = Ω μ`` is linear in it); estimates
are reported wrapped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.datasets.stream import Control, Dataset, Event, LandmarkReadings, Odometry
from slamkit.errors import (
    ConfigError,
    ConvergenceError,
    GeometryError,
    InputError,
)
from slamkit.estimation.contract import (
    EstimatorOutput,
    InnovationLog,
    LandmarkEstimate,
    PoseEstimate,
    StepClock,
)
from slamkit.estimation.gaussian import angular_indices
from slamkit.geometry import wrap_angle
from slamkit.geometry.angles import wrap_angle_float
from slamkit.mapping.ekf_mapping import (
    NEW,
    REJECTED,
    association_probabilities,
)
from slamkit.mapping.ekf_mapping import associate_nearest_unchecked as _greedy_nearest_neighbour
from slamkit.maps import LandmarkMap
from slamkit.models import MIN_RANGE, LandmarkModel, MotionModel, odometry_control
from slamkit.models.measurement import InvertibleLandmarkModel, LandmarkModelBase
from slamkit.models.motion import motion_kernels
from slamkit.prob import chi2_gate
from slamkit.slam.ekf_slam import (
    DISCARDED,
    INITIALISED,
    OWN_ID_BASE,
    UPDATED,
    reading_jacobians,
    scan_readings,
    wrap_components,
)

__all__ = [
    "Seif",
    "SeifConfig",
    "seif_measurement_update",
    "seif_motion_update",
    "seif_sparsify",
]


def _inverse(A: FloatArray) -> FloatArray:
    return np.asarray(np.linalg.inv(A), dtype=np.float64)


def _pose_idx() -> NDArray[np.int64]:
    return np.arange(3)


def _lm_idx(landmarks: ArrayLike) -> NDArray[np.int64]:
    """State indices of the landmarks (map rows) ``landmarks``."""
    j = np.asarray(landmarks, dtype=np.int64).reshape(-1)
    return (3 + 2 * j[:, None] + np.arange(2)).reshape(-1)


# --------------------------------------------------------------------------------------------
# kernels on index blocks (in place)
# --------------------------------------------------------------------------------------------


def _motion_block(
    Om: FloatArray,
    xi: FloatArray,
    mu: FloatArray,
    idx: NDArray[np.int64],
    u: FloatArray,
    dt: float,
    model: MotionModel,
    Q: FloatArray,
) -> None:
    """The motion update on the block ``idx`` = pose then active landmarks (module
    docstring); ``Ω``, ``ξ``, ``μ`` are changed in place."""
    x = mu[:3].copy()
    x[2] = wrap_angle_float(float(x[2]))  # models want a wrapped heading
    moved, G, V = motion_kernels(model).step_single(x, u, dt)  # the fused one-pose kernel
    delta = moved - x
    delta[2] = wrap_angle_float(float(delta[2]))  # the heading inside stays unwrapped
    Rx = V @ Q @ V.T
    ix = np.ix_(idx, idx)
    O = Om[ix]
    mu_b = mu[idx]
    Gi = np.linalg.inv(G)
    Phi = O.copy()
    Phi[:3, :] = Gi.T @ O[:3, :]  # Φ = A⁻ᵀ Ω A⁻¹: pose rows and columns only
    Phi[:, :3] = Phi[:, :3] @ Gi
    PhiX = Phi[:, :3]  # Φ F_xᵀ (k × 3)
    kappa = PhiX @ Rx @ np.linalg.solve(np.eye(3) + Phi[:3, :3] @ Rx, PhiX.T)
    O_new = Phi - kappa
    O_new = 0.5 * (O_new + O_new.T)
    xi[idx] += (O_new - O) @ mu_b + O_new[:, :3] @ delta
    Om[ix] = O_new
    mu[:3] += delta


def _measurement_block(
    Om: FloatArray,
    xi: FloatArray,
    mu: FloatArray,
    slot: int,
    z: FloatArray,
    model: LandmarkModel,
    R_inv: FloatArray,
    angular: tuple[int, ...],
) -> tuple[FloatArray, FloatArray]:
    """Add the information of reading ``z`` of the landmark in state rows ``slot, slot+1``;
    returns ``(ν, H)``."""
    x = mu[:3].copy()
    x[2] = wrap_angle_float(float(x[2]))
    h, Hr, Hj = reading_jacobians(model, x, mu[slot : slot + 2])
    nu = wrap_components(z - h, angular)
    H = np.hstack((Hr, Hj))  # (m, 5)
    idx = np.array([0, 1, 2, slot, slot + 1])
    HtRi = H.T @ R_inv
    Om[np.ix_(idx, idx)] += HtRi @ H  # Ω += Hᵀ R⁻¹ H
    xi[idx] += HtRi @ (nu + H @ mu[idx])  # ξ += Hᵀ R⁻¹ (ν + H μ)
    return nu, H


def _sparsify_block(
    Om: FloatArray,
    xi: FloatArray,
    mu: FloatArray,
    keep: NDArray[np.int64],
    drop: NDArray[np.int64],
) -> None:
    """Remove the robot's links to the landmarks ``drop`` (map rows), keeping those to
    ``keep`` (module docstring)."""
    idx = np.concatenate([_pose_idx(), _lm_idx(keep), _lm_idx(drop)])
    px = np.arange(3)
    p0 = np.arange(3 + 2 * keep.size, idx.size)
    x0 = np.concatenate([px, p0])
    ix = np.ix_(idx, idx)
    O = Om[ix]

    def schur_term(sel: NDArray[np.int64]) -> FloatArray:
        # O F_s (F_sᵀ O F_s)⁻¹ F_sᵀ O
        return O[:, sel] @ np.linalg.solve(O[np.ix_(sel, sel)], O[sel, :])

    O_new = O - schur_term(p0) + schur_term(x0) - schur_term(px)
    O_new = 0.5 * (O_new + O_new.T)
    O_new[np.ix_(px, p0)] = 0.0  # zero up to rounding: make the sparsity exact
    O_new[np.ix_(p0, px)] = 0.0
    xi[idx] += (O_new - O) @ mu[idx]  # ξ̃ = ξ + (Ω̃ − Ω) μ
    Om[ix] = O_new


# --------------------------------------------------------------------------------------------
# public functional API (dense information matrices; validated; returns copies)
# --------------------------------------------------------------------------------------------


def _check_info(
    omega: ArrayLike, xi: ArrayLike, mu: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    m = as_array(mu, "mu", (None,))
    if m.size < 3 or (m.size - 3) % 2:
        raise InputError(f"mu: expected 3 + 2L entries, got {m.size}")
    O = as_covariance(omega, "omega", m.size)
    x = as_array(xi, "xi", (m.size,))
    return O.copy(), x.copy(), m.copy()


def seif_motion_update(
    omega: ArrayLike,
    xi: ArrayLike,
    mu: ArrayLike,
    u: ArrayLike,
    dt: float,
    model: MotionModel,
    control_cov: ArrayLike,
    active: ArrayLike,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The SEIF motion update of a dense ``(Ω, ξ, μ)``, touching the pose and the
    ``active`` landmarks (map rows) only; the robot must not be linked to any other
    landmark. Returns new ``(Ω, ξ, μ)``."""
    O, x, m = _check_info(omega, xi, mu)
    ua = as_array(u, "u", (model.control_dim,))
    Q = as_covariance(control_cov, "control_cov", model.control_dim, semidefinite=True)
    idx = np.concatenate([_pose_idx(), _lm_idx(np.asarray(active, dtype=np.int64))])
    _motion_block(O, x, m, idx, ua, float(dt), model, Q)
    return O, x, m


def seif_measurement_update(
    omega: ArrayLike,
    xi: ArrayLike,
    mu: ArrayLike,
    index: int,
    z: ArrayLike,
    model: LandmarkModel,
    R: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """Add the information of reading ``z`` of landmark ``index`` (map row): returns the new
    ``(Ω, ξ)`` (the mean estimate is not changed by an information update)."""
    O, x, m = _check_info(omega, xi, mu)
    za = as_array(z, "z", (model.dim,))
    Ra = as_covariance(R, "R", model.dim)
    _measurement_block(O, x, m, 3 + 2 * int(index), za, model, _inverse(Ra), angular_indices(model))
    return O, x


def seif_sparsify(
    omega: ArrayLike, xi: ArrayLike, mu: ArrayLike, keep: ArrayLike, drop: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """SEIF sparsification: cut the robot's links to the landmarks ``drop`` (map rows),
    keeping those to ``keep``; returns the new ``(Ω, ξ)`` (module docstring)."""
    O, x, m = _check_info(omega, xi, mu)
    k = np.asarray(keep, dtype=np.int64).reshape(-1)
    d = np.asarray(drop, dtype=np.int64).reshape(-1)
    _sparsify_block(O, x, m, k, d)
    return O, x


# --------------------------------------------------------------------------------------------
# the estimator
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SeifConfig:
    """Settings of :class:`Seif`. Units: metres, radians."""

    max_active: int = 6
    """Most landmarks the robot stays linked to. A reading activates its landmark; beyond
    this many the least recently observed are deactivated by sparsification. Without ids it
    should hold a scan's landmarks: in ``landmark-clutter`` (~13 readings a scan) the
    default cuts the links to half of what was just seen, SEIF turns overconfident and
    true landmarks fall out of the gate (association accuracy 93.9–99.7 % over seeds 0–5;
    20: 97.9–99.8 %, as EKF-SLAM's nearest neighbour)."""
    relax_per_step: int = 10
    """Landmarks besides the robot and the active ones whose mean is relaxed per step (in
    turn, round robin): the amortised mean recovery."""
    relax_sweeps: int = 2
    """Gauss–Seidel sweeps over the robot and the active landmarks per step (they are
    strongly coupled, and the robot's mean is the estimate reported at every step)."""
    motion_noise_scale: float = 1.0
    """Multiplies the data set's control-noise covariance (>= 0)."""
    measurement_noise_scale: float = 1.0
    """Multiplies the landmark sensor's noise covariance (> 0)."""
    initial_capacity: int = 32
    """Landmarks the buffers hold before their first doubling."""
    prior_information: float = 1e12
    """Information of a pose prior given with zero covariance (the map frame): the
    information form needs a finite value; 1e12 = a standard deviation of 1 µm (rad)."""
    use_ids: bool = True
    """Use the landmark ids the readings carry when the sensor provides them
    (``LandmarkSensorSpec.identities``); ``-1`` readings are then associated with the
    existing landmarks but never start one (an id chosen here could collide with a later
    labelled one). ``False`` (or a sensor without identities) ignores every id and
    associates all readings (module docstring, *Data association*)."""
    gate_probability: float = 0.999
    """The χ² gate of a pairing: ``d² ≤ χ²_m(p)`` (13.8 for ``m = 2``)."""
    new_landmark_probability: float = 0.99999
    """An unpaired reading starts a landmark only if its ``d²`` to every candidate exceeds
    ``χ²_m(new_landmark_probability)`` (23.0 for ``m = 2``); between the two thresholds it
    is rejected rather than allowed to duplicate a landmark it just missed."""
    candidate_radius: float = 3.0
    """A landmark is a candidate for a scan's readings if its mean lies within this distance
    [m] of the point some reading places (inverse model at the mean pose); the others count
    as ``d² = ∞``. It must exceed the robot's position error plus the reading's (a few
    σ): landmarks beyond it cannot be re-found, and become duplicates."""
    max_candidates: int = 40
    """At most this many candidates per scan (nearest to a reading's point first): with
    :attr:`max_blanket` it bounds the cost of one scan's association."""
    blanket_hops: int = 1
    """Rings of links around the robot and the candidates in the blanket whose information
    gives their covariance: 1 = their Markov blanket (the active landmarks and the
    candidates' neighbours), each further ring the neighbours of the last. More rings:
    closer to the marginal, larger solves."""
    max_blanket: int = 120
    """Most landmarks in the blanket (candidates and the active ones first, then the rings
    in order, cut at this size): bounds the Cholesky factorisation per scan, a
    ``(3 + 2 · max_blanket)²`` matrix."""

    def __post_init__(self) -> None:
        for name in ("max_active", "initial_capacity", "max_candidates", "max_blanket"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")
        for name in ("relax_sweeps", "blanket_hops"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")
        if not (isinstance(self.relax_per_step, int) and self.relax_per_step >= 0):
            raise ConfigError(
                f"relax_per_step: expected an integer >= 0, got {self.relax_per_step}"
            )
        if not (math.isfinite(self.motion_noise_scale) and self.motion_noise_scale >= 0):
            raise ConfigError(f"motion_noise_scale: expected >= 0, got {self.motion_noise_scale}")
        s = self.measurement_noise_scale
        if not (math.isfinite(s) and s > 0):
            raise ConfigError(f"measurement_noise_scale: expected > 0, got {s}")
        if not (math.isfinite(self.prior_information) and self.prior_information > 0):
            raise ConfigError(f"prior_information: expected > 0, got {self.prior_information}")
        association_probabilities(self.gate_probability, self.new_landmark_probability)
        r = self.candidate_radius
        if not (math.isfinite(r) and r > 0):
            raise ConfigError(f"candidate_radius: expected a number > 0, got {r}")


_COUNTS = ("predictions", "readings", "updates", "new_landmarks", "unlabelled", "rejected",
           "degenerate", "sparsifications", "association_scans")  # fmt: skip


class Seif:
    """SEIF SLAM as an estimator of the pipeline.

    Per time step: the motion update (pose and active landmarks); per scan, data
    association at the state before the scan (readings with ids and ``use_ids`` go to
    their landmark, the others by maximum likelihood over the candidates near the robot
    with the blanket covariance, module docstring), one information update per reading
    (new landmarks start at the inverse-model point with no information of their own,
    which the reading then supplies), sparsification down to ``max_active`` active
    landmarks, and the amortised relaxation of the mean. Without ids the filter numbers
    its landmarks from :data:`~slamkit.slam.ekf_slam.OWN_ID_BASE`.

    :meth:`estimate` reports the pose with no covariance (SEIF has none at hand);
    :meth:`finish` solves for the exact mean once and returns the landmarks with their
    marginal covariances, and diagnostics: the counts, ``n_landmarks``, ``association``,
    ``max_block`` (the largest block of state a motion update or sparsification touched:
    the robot and at most ``max_active`` plus one scan's new landmarks — it does not grow
    with the map), ``max_blanket`` (most state entries of one association solve),
    ``max_links`` (most landmarks any landmark is linked to, which bounds a relaxation
    step), ``mean_links``, ``mean_nis`` and ``relaxed_vs_exact_max`` (how far the running
    mean is from ``Ω⁻¹ ξ`` at the end).

    Divergence — a non-finite mean, a singular block in the relaxation, an information
    block that is not positive definite (the pose block after every scan, the blanket of
    every association) — raises :class:`~slamkit.errors.ConvergenceError` with the step
    (the runner's numbering: one step per distinct time stamp).
    """

    name = "SEIF"

    def __init__(self, dataset: Dataset, config: SeifConfig, rng: np.random.Generator) -> None:
        if dataset.motion is None or dataset.landmark_sensor is None:
            raise InputError(f"seif needs a motion model and a landmark sensor; {dataset.name}")
        sensor = dataset.landmark_sensor
        model = sensor.model()
        if not isinstance(model, InvertibleLandmarkModel):
            raise InputError(
                f"seif cannot use the {sensor.kind!r} sensor: one reading does not locate a "
                "landmark"
            )
        self._config = config
        self._motion = dataset.motion.model
        self._Q = config.motion_noise_scale * dataset.motion.noise_cov
        self._meas: InvertibleLandmarkModel = model
        self._model: LandmarkModel = sensor.model()
        self._R = as_covariance(config.measurement_noise_scale * sensor.noise_cov, "R")
        self._R_inv = _inverse(self._R)
        self._m = int(self._R.shape[0])
        self._angular = angular_indices(self._model)
        self._use_ids = config.use_ids and sensor.identities
        self._gate = chi2_gate(self._m, config.gate_probability)
        self._new_gate = chi2_gate(self._m, config.new_landmark_probability)
        cap = config.initial_capacity
        N = 3 + 2 * cap
        self._Om = np.zeros((N, N))
        self._xi = np.zeros(N)
        self._mu = np.zeros(N)
        pose = np.zeros(3) if dataset.initial_pose is None else dataset.initial_pose.copy()
        cov = np.zeros((3, 3)) if dataset.initial_cov is None else dataset.initial_cov
        # prior information; a zero variance (the map frame) becomes a very large information
        w, V = np.linalg.eigh(cov)
        info = V @ np.diag(1.0 / np.maximum(w, 1.0 / config.prior_information)) @ V.T
        self._Om[:3, :3] = 0.5 * (info + info.T)
        self._mu[:3] = pose
        self._xi[:3] = self._Om[:3, :3] @ pose
        self._L = 0
        self._ids: list[int] = []
        self._slot_of: dict[int, int] = {}
        self._next_id = OWN_ID_BASE
        self._links: list[set[int]] = []  # landmark-landmark links (map rows)
        self._active: list[int] = []  # linked to the robot, least recently observed first
        self._cursor = 0
        self._max_block = 0  # the largest index block a motion update or sparsification used
        self._max_blanket = 0  # the largest association solve (state entries)
        self._last_odometry: FloatArray | None = None
        self._clock = StepClock()
        self._counts = dict.fromkeys(_COUNTS, 0)
        self._log_t: list[float] = []
        self._log_nis: list[float] = []
        self._log_id: list[int] = []
        self._read_t: list[float] = []
        self._read_id: list[int] = []
        self._read_status: list[int] = []

    # -- Estimator protocol ---------------------------------------------------------------

    def handle(self, event: Event) -> None:
        self._clock.tick(event.t)
        with self._clock.numbering("seif", event.t):
            if isinstance(event, Control):
                self._predict(event.u, event.dt)
            elif isinstance(event, Odometry):
                if self._last_odometry is not None:
                    self._predict(odometry_control(self._last_odometry, event.pose), 0.0)
                self._last_odometry = event.pose
            elif isinstance(event, LandmarkReadings):
                self._readings(event)
                self._sparsify()
                self._relax()
                self._check_pose_block()
            if not math.isfinite(float(self._mu[0] + self._mu[1] + self._mu[2])):
                raise ConvergenceError("the mean became non-finite")

    def estimate(self) -> PoseEstimate:
        pose = self._mu[:3].copy()
        pose[2] = wrap_angle_float(float(pose[2]))
        return PoseEstimate(pose, None)

    @property
    def mean(self) -> FloatArray:
        """The running (relaxed) mean ``(3 + 2L,)``, heading unwrapped."""
        return self._mu[: self._n].copy()

    @property
    def information(self) -> tuple[FloatArray, FloatArray]:
        """Copies of ``(Ω, ξ)`` over the current state."""
        n = self._n
        return self._Om[:n, :n].copy(), self._xi[:n].copy()

    @property
    def active(self) -> list[int]:
        """Map rows of the landmarks linked to the robot."""
        return list(self._active)

    @property
    def landmark_ids(self) -> NDArray[np.int64]:
        return np.asarray(self._ids, dtype=np.int64)

    def reading_log(self) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """Every reading handled so far: ``(times, landmark ids, status)``; the id of the
        landmark the reading updated or started (``-1`` if none), status
        :data:`~slamkit.slam.ekf_slam.UPDATED`, :data:`~slamkit.slam.ekf_slam.INITIALISED`
        or :data:`~slamkit.slam.ekf_slam.DISCARDED` (rejected by the association, or a
        reading too close to the robot to linearise)."""
        return (
            np.asarray(self._read_t, dtype=np.float64),
            np.asarray(self._read_id, dtype=np.int64),
            np.asarray(self._read_status, dtype=np.int64),
        )

    def links(self, row: int) -> set[int]:
        """Map rows of the landmarks that landmark ``row`` is linked to (``Ω`` entries
        between them that may be nonzero); the robot's links are :attr:`active`."""
        return set(self._links[row])

    def blanket_covariance(
        self, rows: ArrayLike, hops: int | None = None, max_blanket: int | None = None
    ) -> FloatArray:
        """The joint covariance ``(3 + 2k, 3 + 2k)`` of the robot and the landmarks ``rows``
        (map rows, ``k`` of them) from the information over their blanket (module docstring,
        *Data association*), ``hops`` and ``max_blanket`` defaulting to the configuration's."""
        sel = np.asarray(rows, dtype=np.int64).reshape(-1)
        if sel.size and (sel.min() < 0 or sel.max() >= self._L):
            raise InputError(f"rows: expected map rows in [0, {self._L}), got {sel.tolist()}")
        if np.unique(sel).size != sel.size:
            raise InputError(f"rows: expected distinct map rows, got {sel.tolist()}")
        cfg = self._config
        B = self._blanket(
            sel,
            cfg.blanket_hops if hops is None else hops,
            cfg.max_blanket if max_blanket is None else max_blanket,
        )
        Y = self._blanket_factor(B, sel.size)
        cov = Y.T @ Y
        return np.asarray(0.5 * (cov + cov.T), dtype=np.float64)

    def recover_mean(self) -> FloatArray:
        """The exact mean ``Ω⁻¹ ξ`` (a dense solve, ``O(n³)``)."""
        O, xi = self.information
        try:
            return np.asarray(np.linalg.solve(O, xi), dtype=np.float64)
        except np.linalg.LinAlgError:
            raise ConvergenceError("seif: the information matrix is singular") from None

    def landmark_estimate(self) -> LandmarkEstimate:
        """The landmarks now at the amortised (relaxed) mean, without covariances: recovering
        those needs the whole information matrix, which only :meth:`finish` does."""
        mean = self._mu[3 : self._n].reshape(-1, 2).copy()
        return LandmarkEstimate(LandmarkMap(mean, np.asarray(self._ids, dtype=np.int64)))

    def finish(self) -> EstimatorOutput:
        O, _ = self.information
        mu = self.recover_mean()
        L = self._L
        covs = np.zeros((L, 2, 2))
        if L:
            try:
                Sigma = np.linalg.inv(O)
            except np.linalg.LinAlgError:
                raise ConvergenceError("seif: the information matrix is singular") from None
            for j in range(L):
                s = 3 + 2 * j
                b = Sigma[s : s + 2, s : s + 2]
                covs[j] = 0.5 * (b + b.T)
        lm = LandmarkEstimate(
            LandmarkMap(mu[3:].reshape(-1, 2).copy(), np.asarray(self._ids, dtype=np.int64)),
            covs,
        )
        links = [len(s) for s in self._links]
        nis = np.asarray(self._log_nis)
        diagnostics: dict[str, Any] = dict(self._counts)
        diagnostics.update(
            association="known ids" if self._use_ids else "nn",
            n_landmarks=L,
            max_block=self._max_block,
            max_blanket=self._max_blanket,
            max_links=max(links) if links else 0,
            mean_links=float(np.mean(links)) if links else 0.0,
            mean_nis=float(nis.mean()) if nis.size else None,
            relaxed_vs_exact_max=float(np.abs(self._mu[: self._n] - mu).max()),
        )
        log = InnovationLog(
            times=np.asarray(self._log_t, dtype=float),
            nis=nis,
            dof=np.full(nis.size, self._m, dtype=np.int64),
            landmark_ids=np.asarray(self._log_id, dtype=np.int64),
        )
        return EstimatorOutput(
            landmarks=lm,
            diagnostics=diagnostics,
            innovations=log,
            reading_landmarks=np.asarray(self._read_id, dtype=np.int64),
        )

    # -- internals ------------------------------------------------------------------------

    @property
    def _n(self) -> int:
        return 3 + 2 * self._L

    def _predict(self, u: FloatArray, dt: float) -> None:
        idx = np.concatenate([_pose_idx(), _lm_idx(self._active)])
        try:
            _motion_block(self._Om, self._xi, self._mu, idx, u, dt, self._motion, self._Q)
        except np.linalg.LinAlgError:
            raise ConvergenceError("the motion update met a singular matrix") from None
        self._counts["predictions"] += 1
        self._max_block = max(self._max_block, idx.size)

    def _ensure_capacity(self) -> None:
        N = self._Om.shape[0]
        if self._n + 2 <= N:
            return
        cap = 2 * ((N - 3) // 2)
        M = 3 + 2 * cap
        n = self._n
        Om = np.zeros((M, M))
        Om[:n, :n] = self._Om[:n, :n]
        xi, mu = np.zeros(M), np.zeros(M)
        xi[:n], mu[:n] = self._xi[:n], self._mu[:n]
        self._Om, self._xi, self._mu = Om, xi, mu

    def _pose(self) -> FloatArray:
        x = self._mu[:3].copy()
        x[2] = wrap_angle_float(float(x[2]))  # models want a wrapped heading
        return x

    def _log_reading(self, t: float, landmark_id: int, status: int) -> None:
        self._read_t.append(t)
        self._read_id.append(landmark_id)
        self._read_status.append(status)

    def _readings(self, event: LandmarkReadings) -> None:
        z, ids = scan_readings(event, self._m, self._use_ids)
        t = float(event.t)
        K = z.shape[0]
        self._counts["readings"] += K
        labelled = ids >= 0
        # association at the state before the scan
        target = np.full(K, REJECTED, dtype=np.int64)  # map row, NEW or REJECTED
        d2 = np.full(K, np.nan)
        for k in np.flatnonzero(labelled).tolist():
            target[k] = self._slot_of.get(int(ids[k]), NEW)
        free = np.flatnonzero(~labelled)
        if free.size:
            self._counts["unlabelled"] += free.size
            match, d2[free] = self._associate(z[free])
            if self._use_ids:  # unlabelled readings never start a landmark there
                match = np.where(match == NEW, REJECTED, match)
            target[free] = match
        for k in range(K):
            j = int(target[k])
            if j == REJECTED:
                self._counts["rejected"] += 1
                self._log_reading(t, -1, DISCARDED)
                continue
            status = UPDATED
            if j == NEW:
                lid = int(ids[k]) if labelled[k] else self._next_id
                j = self._slot_of.get(lid, -1)
                if j < 0:  # a new landmark: the inverse-model point, no information yet
                    point = self._meas.inverse(self._pose(), z[k])
                    if math.hypot(*(point - self._mu[:2])) < MIN_RANGE:
                        self._counts["degenerate"] += 1  # it would get no information
                        self._log_reading(t, -1, DISCARDED)
                        continue
                    j = self._add(point, lid)
                    status = INITIALISED
            s = 3 + 2 * j
            try:
                nu, H = _measurement_block(
                    self._Om, self._xi, self._mu, s, z[k], self._model, self._R_inv, self._angular
                )
            except GeometryError:
                self._counts["degenerate"] += 1
                self._log_reading(t, -1, DISCARDED)
                continue
            self._counts["updates"] += 1
            lid = self._ids[j]
            self._log_reading(t, lid, status)
            if j in self._active:
                self._active.remove(j)
            self._active.append(j)  # most recently observed last
            if status == UPDATED:
                self._log_t.append(t)
                self._log_id.append(lid)
                self._log_nis.append(float(d2[k]) if math.isfinite(d2[k]) else self._nis(nu, H, s))

    def _add(self, point: FloatArray, landmark_id: int) -> int:
        self._ensure_capacity()
        j = self._L
        s = 3 + 2 * j
        self._mu[s : s + 2] = point
        self._L += 1
        self._ids.append(landmark_id)
        self._slot_of[landmark_id] = j
        self._links.append(set())
        self._next_id = max(self._next_id, landmark_id + 1)
        self._counts["new_landmarks"] += 1
        return j

    def _associate(self, z: FloatArray) -> tuple[NDArray[np.int64], FloatArray]:
        """Map row (or NEW / REJECTED) per reading, and the ``d²`` of the pairing (NaN
        for none): maximum likelihood over the candidates, greedy nearest neighbour in
        ``d²`` inside the gate (module docstring)."""
        K, L = z.shape[0], self._L
        d2_pair = np.full(K, np.nan)
        if L == 0:
            return np.full(K, NEW, dtype=np.int64), d2_pair
        x = self._pose()
        cand = self._candidates(x, z)
        if cand.size == 0:
            return np.full(K, NEW, dtype=np.int64), d2_pair
        self._counts["association_scans"] += 1
        B = self._blanket(cand, self._config.blanket_hops, self._config.max_blanket)
        self._max_blanket = max(self._max_blanket, 3 + 2 * B.size)
        Y = self._blanket_factor(B, cand.size)  # Yᵀ Y: robot, then the candidates
        U = cand.size
        lm = self._mu[3 : self._n].reshape(-1, 2)[cand]
        pose = np.broadcast_to(x, (U, 3))
        model = self._model
        if isinstance(model, LandmarkModelBase):
            z_hat, (Hr, Hj) = model.predict_unchecked(pose, lm), model.jacobians_unchecked(pose, lm)
        else:
            z_hat, (Hr, Hj) = model.predict(pose, lm), model.jacobians(pose, lm)
        # H = [H_r H_j] over (x, m_j): S = H Σ_(x,j) Hᵀ + R, Σ_(x,j) = Y_selᵀ Y_sel
        H = np.concatenate([Hr, Hj], axis=-1)  # (U, m, 5)
        sel = np.concatenate(
            [np.broadcast_to(np.arange(3), (U, 3)), 3 + 2 * np.arange(U)[:, None] + np.arange(2)],
            axis=1,
        )  # (U, 5) columns of Y
        HY = np.einsum("umi,rui->urm", H, Y[:, sel])  # (U, c, m): (Y_sel Hᵀ) per candidate
        S = np.einsum("urm,urn->umn", HY, HY) + self._R  # symmetric by construction
        nu = z[:, None, :] - z_hat[None, :, :]  # ν = z ⊖ ẑ, angles wrapped
        for i in self._angular:
            nu[..., i] = wrap_angle(nu[..., i])
        try:
            S_inv = np.linalg.inv(S)
        except np.linalg.LinAlgError:
            raise ConvergenceError("an innovation covariance is singular") from None
        d2 = np.einsum("kui,uij,kuj->ku", nu, S_inv, nu)
        match = _greedy_nearest_neighbour(d2, self._gate, self._new_gate)
        hit = match >= 0
        d2_pair[hit] = d2[np.flatnonzero(hit), match[hit]]
        out = match.copy()
        out[hit] = cand[match[hit]]
        return out, d2_pair

    def _candidates(self, x: FloatArray, z: FloatArray) -> NDArray[np.int64]:
        """Map rows of the landmarks within ``candidate_radius`` of a reading's point (at
        most ``max_candidates``, nearest first; none on the sensor itself)."""
        lm = self._mu[3 : self._n].reshape(-1, 2)
        points = np.atleast_2d(self._meas.inverse(x, z))  # (K, 2)
        d = np.hypot(points[:, None, 0] - lm[None, :, 0], points[:, None, 1] - lm[None, :, 1])
        near = d.min(axis=0)
        near[np.hypot(lm[:, 0] - x[0], lm[:, 1] - x[1]) < MIN_RANGE] = np.inf
        cand = np.flatnonzero(near <= self._config.candidate_radius)
        if cand.size > self._config.max_candidates:
            order = np.argsort(near[cand], kind="stable")
            cand = np.sort(cand[order[: self._config.max_candidates]])
        return cand

    def _blanket(self, sel: NDArray[np.int64], hops: int, cap: int) -> NDArray[np.int64]:
        """Map rows of the blanket of the robot and the landmarks ``sel``: ``sel`` first,
        then the active landmarks, then ``hops`` rings of links (each sorted), at most
        ``max(cap, |sel|)`` landmarks."""
        members: list[int] = list(sel.tolist())
        inside = set(members)
        cap = max(cap, len(members))

        def take(rows: list[int]) -> bool:
            for r in rows:
                if len(members) >= cap:
                    return False
                if r not in inside:
                    inside.add(r)
                    members.append(r)
            return True

        # ring 1, the Markov blanket: the robot's neighbours (the active landmarks) first,
        # then those of ``sel``; each further ring: the neighbours of the last one
        near: set[int] = set()
        for r in members:
            near |= self._links[r]
        active = [r for r in self._active if r not in inside]
        fresh = active + sorted(near - inside - set(active))
        for _ in range(hops):
            if not fresh or not take(fresh):
                break
            ring: set[int] = set()
            for r in fresh:
                ring |= self._links[r]
            fresh = sorted(ring - inside)
        return np.asarray(members, dtype=np.int64)

    def _blanket_factor(self, B: NDArray[np.int64], k: int) -> FloatArray:
        """``Y (c, c)``, ``c = 3 + 2k``, with ``Yᵀ Y`` the block of ``Ω_BB⁻¹`` over the
        robot and the first ``k`` landmarks of ``B`` (columns: pose, then those landmarks).

        Ordered with those ``c`` variables LAST, ``Ω_BB = L Lᵀ`` (Cholesky, ``L`` lower)
        gives ``Ω_BB⁻¹ = L⁻ᵀ L⁻¹``; ``L⁻¹`` is lower triangular, so its last ``c`` columns
        are zero above the last ``c`` rows, where they are ``L_cc⁻¹`` (the inverse of a
        block-triangular matrix has the inverses of its diagonal blocks on its diagonal).
        Hence the block is ``L_cc⁻ᵀ L_cc⁻¹``: one factorisation and a ``c × c`` triangular
        inverse, no solve with the whole blanket."""
        idx = np.concatenate([_lm_idx(B[k:]), _pose_idx(), _lm_idx(B[:k])])
        try:
            chol = np.linalg.cholesky(self._Om[np.ix_(idx, idx)])
        except np.linalg.LinAlgError:
            raise ConvergenceError(
                "the information over an association blanket is not positive definite"
            ) from None
        c = 3 + 2 * k
        Y = scipy.linalg.solve_triangular(chol[-c:, -c:], np.eye(c), lower=True, check_finite=False)
        return np.asarray(Y, dtype=np.float64)

    def _nis(self, nu: FloatArray, H: FloatArray, s: int) -> float:
        """``νᵀ S⁻¹ ν`` with ``S = H Σ_b Hᵀ + R``, ``Σ_b`` the covariance of the robot and
        the landmark CONDITIONED on the rest of the map (``Ω_bb⁻¹``): a cheap lower bound
        on ``S``, so this NIS runs high; for diagnostics only (readings paired by the
        association log their ``d²`` over the blanket instead)."""
        idx = np.array([0, 1, 2, s, s + 1])
        try:
            Sb = H @ np.linalg.solve(self._Om[np.ix_(idx, idx)], H.T) + self._R
            return float(nu @ np.linalg.solve(Sb, nu))
        except np.linalg.LinAlgError:
            raise ConvergenceError("a robot-landmark information block is singular") from None

    def _check_pose_block(self) -> None:
        """The pose block ``Ω_xx`` (the pose's information given the map) must be positive
        definite; a cheap 3 × 3 Cholesky test."""
        try:
            np.linalg.cholesky(self._Om[:3, :3])
        except np.linalg.LinAlgError:
            raise ConvergenceError(
                "the information matrix lost positive definiteness (the pose block)"
            ) from None

    def _sparsify(self) -> None:
        extra = len(self._active) - self._config.max_active
        if extra <= 0:
            return
        drop = np.asarray(self._active[:extra], dtype=np.int64)
        keep = np.asarray(self._active[extra:], dtype=np.int64)
        try:
            _sparsify_block(self._Om, self._xi, self._mu, keep, drop)
        except np.linalg.LinAlgError:
            raise ConvergenceError("sparsification met a singular block") from None
        self._max_block = max(self._max_block, 3 + 2 * (keep.size + drop.size))
        self._active = self._active[extra:]
        self._counts["sparsifications"] += 1
        # the block (m+, m0) may have filled in: record the new landmark-landmark links
        group = np.concatenate([keep, drop])
        g = group.size
        gi = _lm_idx(group)
        linked = np.any(self._Om[np.ix_(gi, gi)].reshape(g, 2, g, 2) != 0.0, axis=(1, 3))
        np.fill_diagonal(linked, False)
        for a, b in zip(*np.nonzero(linked), strict=True):
            self._links[int(group[a])].add(int(group[b]))
        # the motion update links the active landmarks with each other
        for a in self._active:
            self._links[a].update(b for b in self._active if b != a)

    def _relax(self) -> None:
        """Block Gauss–Seidel on the pose, the active landmarks and ``relax_per_step``
        others in turn."""
        for a in self._active:  # motion updates link the active landmarks to each other
            self._links[a].update(b for b in self._active if b != a)
        L = self._L
        blocks: list[int] = [-1, *self._active] * self._config.relax_sweeps
        k = min(self._config.relax_per_step, L)
        for _ in range(k):
            blocks.append(self._cursor % L)
            self._cursor += 1
        Om, xi, mu = self._Om, self._xi, self._mu
        active = set(self._active)
        act_idx = _lm_idx(self._active)
        neighbours: dict[int, NDArray[np.int64]] = {}
        for b in blocks:
            if b < 0:  # the pose, linked to the active landmarks only
                rhs = xi[:3] - Om[:3, act_idx] @ mu[act_idx]
                try:
                    mu[:3] = np.linalg.solve(Om[:3, :3], rhs)
                except np.linalg.LinAlgError:
                    raise ConvergenceError("the pose's information block is singular") from None
                continue
            nb = neighbours.get(b)
            if nb is None:
                nb = _lm_idx(sorted(self._links[b]))
                if b in active:
                    nb = np.concatenate([_pose_idx(), nb])
                neighbours[b] = nb
            s = 3 + 2 * b
            r0, r1 = (xi[s : s + 2] - Om[s : s + 2, nb] @ mu[nb]).tolist()
            # the 2 × 2 block solve in closed form; a diagonal block of a positive definite
            # matrix is positive definite (Sylvester: Ω_ss > 0 and det > 0)
            p, q, r = float(Om[s, s]), float(Om[s, s + 1]), float(Om[s + 1, s + 1])
            det = p * r - q * q
            if not (p > 0.0 and det > 0.0):
                raise ConvergenceError(
                    f"the information block of landmark {self._ids[b]} is not positive definite"
                )
            mu[s] = (r * r0 - q * r1) / det
            mu[s + 1] = (p * r1 - q * r0) / det
