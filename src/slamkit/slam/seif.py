"""SEIF SLAM: the sparse extended information filter (Thrun et al., IJRR 23(7–8), 2004;
*Probabilistic Robotics*, ch. 12), with known correspondences.

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

The heading is kept unwrapped inside the filter (``ξ = Ω μ`` is linear in it); estimates
are reported wrapped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.datasets.stream import Control, Dataset, Event, LandmarkReadings, Odometry
from slamkit.errors import ConfigError, ConvergenceError, GeometryError, InputError
from slamkit.geometry.angles import wrap_angle_float
from slamkit.localization.kalman import _angular_indices, _motion_jacobians, _move
from slamkit.mapping.ekf_mapping import InvertibleLandmarkModel
from slamkit.maps import LandmarkMap
from slamkit.models import LandmarkModel, MotionModel, odometry_control
from slamkit.models.motion import _MotionBase
from slamkit.pipeline.estimator import (
    EstimatorOutput,
    InnovationLog,
    LandmarkEstimate,
    PoseEstimate,
)
from slamkit.slam.ekf_slam import _h_jacobians, _wrap_components

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
    if isinstance(model, _MotionBase):
        moved, G, V = model._step_single(x, u, dt)
    else:
        moved, (G, V) = _move(model, x, u, dt), _motion_jacobians(model, x, u, dt)
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
    h, Hr, Hj = _h_jacobians(model, x, mu[slot : slot + 2])
    nu = _wrap_components(z - h, angular)
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
    _measurement_block(
        O, x, m, 3 + 2 * int(index), za, model, _inverse(Ra), _angular_indices(model)
    )
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
    """Settings of :class:`Seif` (known correspondences; readings with id ``-1`` are
    skipped)."""

    max_active: int = 6
    """Most landmarks the robot stays linked to. A reading activates its landmark; beyond
    this many the least recently observed are deactivated by sparsification."""
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

    def __post_init__(self) -> None:
        for name in ("max_active", "initial_capacity"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")
        if not (isinstance(self.relax_sweeps, int) and self.relax_sweeps >= 1):
            raise ConfigError(f"relax_sweeps: expected an integer >= 1, got {self.relax_sweeps!r}")
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


class Seif:
    """SEIF SLAM with known correspondences as an estimator of the pipeline.

    Per time step: the motion update (pose and active landmarks), one information update
    per reading (new landmarks start at the inverse-model point with no information of
    their own, which the reading then supplies), sparsification down to ``max_active``
    active landmarks, and the amortised relaxation of the mean. :meth:`estimate` reports
    the pose with no covariance (SEIF has none at hand); :meth:`finish` solves for the
    exact mean once and returns the landmarks with their marginal covariances, and
    diagnostics: ``n_landmarks``, ``updates``, ``sparsifications``, ``max_block`` (the
    largest block of state a motion update or sparsification touched: the robot and at
    most ``max_active`` plus one scan's new landmarks — it does not grow with the map),
    ``max_links`` (most landmarks any landmark is linked to, which bounds a relaxation
    step), ``mean_links`` and ``relaxed_vs_exact_max`` (how far the running mean is from
    ``Ω⁻¹ ξ`` at the end).
    """

    name = "SEIF"

    def __init__(self, dataset: Dataset, config: SeifConfig, rng: np.random.Generator) -> None:
        if dataset.motion is None or dataset.landmark_sensor is None:
            raise InputError(f"seif needs a motion model and a landmark sensor; {dataset.name}")
        model = dataset.landmark_sensor.model()
        if not isinstance(model, InvertibleLandmarkModel):
            raise InputError(
                f"seif cannot use the {dataset.landmark_sensor.kind!r} sensor: one reading does "
                "not locate a landmark"
            )
        if not dataset.landmark_sensor.identities:
            raise InputError(f"seif needs landmark ids (known correspondences); {dataset.name}")
        self._config = config
        self._motion = dataset.motion.model
        self._Q = config.motion_noise_scale * dataset.motion.noise_cov
        self._meas: InvertibleLandmarkModel = model
        self._model: LandmarkModel = dataset.landmark_sensor.model()
        R = as_covariance(config.measurement_noise_scale * dataset.landmark_sensor.noise_cov, "R")
        self._R_inv = _inverse(R)
        self._angular = _angular_indices(self._model)
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
        self._links: list[set[int]] = []  # landmark-landmark links (map rows)
        self._active: list[int] = []  # linked to the robot, least recently observed first
        self._cursor = 0
        self._max_block = 0  # the largest index block a motion update or sparsification used
        self._last_odometry: FloatArray | None = None
        self._counts = {"predictions": 0, "readings": 0, "updates": 0, "new_landmarks": 0,
                        "unlabelled": 0, "degenerate": 0, "sparsifications": 0}  # fmt: skip
        self._log_t: list[float] = []
        self._log_nis: list[float] = []
        self._log_id: list[int] = []

    # -- Estimator protocol ---------------------------------------------------------------

    def handle(self, event: Event) -> None:
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
        if not math.isfinite(float(self._mu[0] + self._mu[1] + self._mu[2])):
            raise ConvergenceError(f"seif at t = {event.t:g} s: the mean became non-finite")

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

    def recover_mean(self) -> FloatArray:
        """The exact mean ``Ω⁻¹ ξ`` (a dense solve, ``O(n³)``)."""
        O, xi = self.information
        try:
            return np.asarray(np.linalg.solve(O, xi), dtype=np.float64)
        except np.linalg.LinAlgError:
            raise ConvergenceError("seif: the information matrix is singular") from None

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
            n_landmarks=L,
            max_block=self._max_block,
            max_links=max(links) if links else 0,
            mean_links=float(np.mean(links)) if links else 0.0,
            mean_nis=float(nis.mean()) if nis.size else None,
            relaxed_vs_exact_max=float(np.abs(self._mu[: self._n] - mu).max()),
        )
        log = InnovationLog(
            times=np.asarray(self._log_t, dtype=float),
            nis=nis,
            dof=np.full(nis.size, self._R_inv.shape[0], dtype=np.int64),
            landmark_ids=np.asarray(self._log_id, dtype=np.int64),
        )
        return EstimatorOutput(landmarks=lm, diagnostics=diagnostics, innovations=log)

    # -- internals ------------------------------------------------------------------------

    @property
    def _n(self) -> int:
        return 3 + 2 * self._L

    def _predict(self, u: FloatArray, dt: float) -> None:
        idx = np.concatenate([_pose_idx(), _lm_idx(self._active)])
        _motion_block(self._Om, self._xi, self._mu, idx, u, dt, self._motion, self._Q)
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

    def _readings(self, event: LandmarkReadings) -> None:
        t = float(event.t)
        self._counts["readings"] += event.ids.size
        for z, lid in zip(event.z, event.ids.tolist(), strict=True):
            if lid < 0:
                self._counts["unlabelled"] += 1
                continue
            j = self._slot_of.get(lid)
            if j is None:  # a new landmark: the inverse-model point, no information yet
                self._ensure_capacity()
                j = self._L
                x = self._mu[:3].copy()
                x[2] = wrap_angle_float(float(x[2]))
                s = 3 + 2 * j
                self._mu[s : s + 2] = self._meas.inverse(x, z)
                self._L += 1
                self._ids.append(lid)
                self._slot_of[lid] = j
                self._links.append(set())
                self._counts["new_landmarks"] += 1
            s = 3 + 2 * j
            try:
                nu, H = _measurement_block(
                    self._Om, self._xi, self._mu, s, z, self._model, self._R_inv, self._angular
                )
            except GeometryError:
                self._counts["degenerate"] += 1
                continue
            self._counts["updates"] += 1
            if j in self._active:
                self._active.remove(j)
            self._active.append(j)  # most recently observed last
            self._log_t.append(t)
            self._log_id.append(lid)
            self._log_nis.append(self._nis(nu, H, s))

    def _nis(self, nu: FloatArray, H: FloatArray, s: int) -> float:
        """``νᵀ S⁻¹ ν`` with ``S = H Σ_b Hᵀ + R``, ``Σ_b`` the covariance of the robot and
        the landmark CONDITIONED on the rest of the map (``Ω_bb⁻¹``): a cheap lower bound
        on ``S``, so this NIS runs high; for diagnostics only."""
        idx = np.array([0, 1, 2, s, s + 1])
        Sb = H @ np.linalg.solve(self._Om[np.ix_(idx, idx)], H.T) + np.linalg.inv(self._R_inv)
        return float(nu @ np.linalg.solve(Sb, nu))

    def _sparsify(self) -> None:
        extra = len(self._active) - self._config.max_active
        if extra <= 0:
            return
        drop = np.asarray(self._active[:extra], dtype=np.int64)
        keep = np.asarray(self._active[extra:], dtype=np.int64)
        _sparsify_block(self._Om, self._xi, self._mu, keep, drop)
        self._max_block = max(self._max_block, 3 + 2 * (keep.size + drop.size))
        self._active = self._active[extra:]
        self._counts["sparsifications"] += 1
        # the block (m+, m0) may have filled in: record the new landmark-landmark links
        group = np.concatenate([keep, drop]).tolist()
        for a in group:
            sa = 3 + 2 * a
            for b in group:
                if a != b and np.any(self._Om[sa : sa + 2, 3 + 2 * b : 5 + 2 * b]):
                    self._links[a].add(b)
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
        for b in blocks:
            if b < 0:
                own = _pose_idx()
                nb = _lm_idx(self._active)
            else:
                own = _lm_idx([b])
                others = list(self._links[b])
                nb = _lm_idx(others)
                if b in self._active:
                    nb = np.concatenate([_pose_idx(), nb])
            rhs = xi[own] - (Om[np.ix_(own, nb)] @ mu[nb] if nb.size else 0.0)
            mu[own] = np.linalg.solve(Om[np.ix_(own, own)], rhs)
