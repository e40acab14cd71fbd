"""The information-form kernels of SEIF: motion update, measurement update and
sparsification on an index block of ``(Ω, ξ, μ)``, in place, and their validated dense forms
(:func:`seif_motion_update`, :func:`seif_measurement_update`, :func:`seif_sparsify`). The
maths is in :mod:`slamkit.slam.seif`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import ConvergenceError, InputError
from slamkit.estimation.gaussian import angular_indices, wrap_components
from slamkit.geometry.angles import wrap_angle_float
from slamkit.models import LandmarkModel, MotionModel
from slamkit.models.motion import motion_kernels
from slamkit.slam.common import reading_jacobians
from slamkit.slam.seif.state import SeifState, link_active

__all__ = [
    "PendingMotion",
    "apply_motion",
    "landmark_indices",
    "link_group",
    "measurement_block",
    "motion_block",
    "motion_step",
    "pose_indices",
    "seif_measurement_update",
    "seif_motion_update",
    "seif_sparsify",
    "sparsify_block",
    "sparsify_state",
]


def pose_indices() -> NDArray[np.int64]:
    """State indices of the pose, ``0, 1, 2``."""
    return np.arange(3)


def landmark_indices(landmarks: ArrayLike) -> NDArray[np.int64]:
    """State indices of the landmarks (map rows) ``landmarks``."""
    j = np.asarray(landmarks, dtype=np.int64).reshape(-1)
    return (3 + 2 * j[:, None] + np.arange(2)).reshape(-1)


def motion_step(
    mu: FloatArray, u: FloatArray, dt: float, model: MotionModel, Q: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """One motion step of the mean: ``μ_x += δ`` in place (``δ = g(μ_x, u) − μ_x``, the
    heading kept unwrapped); returns ``(G, R_x = V Q Vᵀ)``, the linearisation at ``μ_x``."""
    x = mu[:3].copy()
    x[2] = wrap_angle_float(float(x[2]))  # models want a wrapped heading
    moved, G, V = motion_kernels(model).step_single(x, u, dt)  # the fused one-pose kernel
    delta = moved - x
    delta[2] = wrap_angle_float(float(delta[2]))  # the heading inside stays unwrapped
    mu[:3] += delta
    return G, V @ Q @ V.T


class PendingMotion:
    """Motion steps whose mean is applied (:func:`motion_step`) but whose information is
    not yet: composed into one linear step ``y' = A y + c + F_xᵀ w``, ``A = diag(G, I)``,
    ``w ~ N(0, R_x)``, with the pose the mean had before the first of them.

    Two steps compose exactly: ``Σ'' = A₂ (A₁ Σ A₁ᵀ + F_xᵀ R₁ F_x) A₂ᵀ + F_xᵀ R₂ F_x``,
    and ``A₂ F_xᵀ R₁ F_x A₂ᵀ = F_xᵀ G₂ R₁ G₂ᵀ F_x``, so ``G = G₂ G₁`` and
    ``R_x = G₂ R₁ G₂ᵀ + R₂`` (each ``G_k`` at the mean the step started from, as when
    applied one by one). The information vector keeps ``ξ − Ω μ`` through every step, so
    over all of them ``ξ' = ξ + Ω' μ' − Ω μ⁰`` with ``μ⁰`` the mean before the first.
    Between two scans the active set does not change, so the steps since the last scan can
    be applied to ``Ω``, ``ξ`` at once (:func:`apply_motion`): one block update per scan
    instead of one per control, the same numbers up to rounding."""

    def __init__(self, pose: FloatArray) -> None:
        self.start = pose.copy()
        """The pose mean before the first pending step ``(3,)``, heading unwrapped."""
        self.G = np.eye(3)
        """The composed pose Jacobian ``G_k ⋯ G_1``."""
        self.R = np.zeros((3, 3))
        """The composed motion noise in pose space."""
        self.steps = 0
        """Steps pending."""

    def add(self, G: FloatArray, R: FloatArray) -> None:
        """Compose one more step (its Jacobian ``G`` and noise ``R``, from
        :func:`motion_step`)."""
        self.G = G @ self.G
        self.R = G @ self.R @ G.T + R  # R_x = G₂ R₁ G₂ᵀ + R₂
        self.steps += 1

    def restart(self, pose: FloatArray) -> None:
        """No steps pending, from the pose mean ``pose``."""
        self.start[:] = pose
        self.G = np.eye(3)
        self.R = np.zeros((3, 3))
        self.steps = 0


def apply_motion(
    Om: FloatArray, xi: FloatArray, mu: FloatArray, idx: NDArray[np.int64], pending: PendingMotion
) -> None:
    """The information of the ``pending`` motion steps on the block ``idx`` = pose then
    active landmarks (module docstring, with ``G``, ``R_x`` the composed ones); ``Ω``,
    ``ξ`` change in place (``μ`` already moved)."""
    ix = np.ix_(idx, idx)
    O = Om[ix]
    Gi = np.linalg.inv(pending.G)
    Rx = pending.R
    Phi = O.copy()
    Phi[:3, :] = Gi.T @ O[:3, :]  # Φ = A⁻ᵀ Ω A⁻¹: pose rows and columns only
    Phi[:, :3] = Phi[:, :3] @ Gi
    PhiX = Phi[:, :3]  # Φ F_xᵀ (k × 3)
    kappa = PhiX @ Rx @ np.linalg.solve(np.eye(3) + Phi[:3, :3] @ Rx, PhiX.T)
    O_new = Phi - kappa
    O_new = 0.5 * (O_new + O_new.T)
    mu_b = mu[idx]
    mu_0 = mu_b.copy()
    mu_0[:3] = pending.start
    xi[idx] += O_new @ mu_b - O @ mu_0  # ξ' − Ω' μ' = ξ − Ω μ⁰
    Om[ix] = O_new
    pending.restart(mu[:3])


def motion_block(
    Om: FloatArray,
    xi: FloatArray,
    mu: FloatArray,
    idx: NDArray[np.int64],
    u: FloatArray,
    dt: float,
    model: MotionModel,
    Q: FloatArray,
) -> None:
    """One motion update on the block ``idx`` = pose then active landmarks (module
    docstring); ``Ω``, ``ξ``, ``μ`` are changed in place."""
    pending = PendingMotion(mu[:3])
    pending.add(*motion_step(mu, u, dt, model, Q))
    apply_motion(Om, xi, mu, idx, pending)


def measurement_block(
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
    HtRi = H.T @ R_inv
    J = HtRi @ H  # Ω += Hᵀ R⁻¹ H, on the robot and landmark blocks (slices, no gather)
    b = HtRi @ (nu + H @ np.concatenate((mu[:3], mu[slot : slot + 2])))  # ξ += Hᵀ R⁻¹ (ν + H μ)
    end = slot + 2
    Om[:3, :3] += J[:3, :3]
    Om[:3, slot:end] += J[:3, 3:]
    Om[slot:end, :3] += J[3:, :3]
    Om[slot:end, slot:end] += J[3:, 3:]
    xi[:3] += b[:3]
    xi[slot:end] += b[3:]
    return nu, H


def sparsify_block(
    Om: FloatArray,
    xi: FloatArray,
    mu: FloatArray,
    keep: NDArray[np.int64],
    drop: NDArray[np.int64],
) -> None:
    """Remove the robot's links to the landmarks ``drop`` (map rows), keeping those to
    ``keep`` (module docstring)."""
    idx = np.concatenate([pose_indices(), landmark_indices(keep), landmark_indices(drop)])
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


def link_group(Om: FloatArray, group: NDArray[np.int64], links: list[set[int]]) -> None:
    """Record in ``links`` (per map row, the rows it is linked to) every nonzero
    landmark–landmark block of ``Ω`` among the landmarks ``group``: after a sparsification
    the block ``(m+, m0)`` may have filled in."""
    g = group.size
    gi = landmark_indices(group)
    linked = np.any(Om[np.ix_(gi, gi)].reshape(g, 2, g, 2) != 0.0, axis=(1, 3))
    np.fill_diagonal(linked, False)
    for a in np.flatnonzero(linked.any(axis=1)).tolist():
        links[int(group[a])].update(group[linked[a]].tolist())


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
    idx = np.concatenate([pose_indices(), landmark_indices(np.asarray(active, dtype=np.int64))])
    motion_block(O, x, m, idx, ua, float(dt), model, Q)
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
    measurement_block(
        O,
        x,
        m,
        3 + 2 * int(index),
        za,
        model,
        np.asarray(np.linalg.inv(Ra), dtype=np.float64),
        angular_indices(model),
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
    sparsify_block(O, x, m, k, d)
    return O, x


def sparsify_state(state: SeifState, max_active: int) -> int:
    """Sparsify ``state`` down to ``max_active`` active landmarks: cut the robot's links to
    the least recently observed ones (:func:`sparsify_block`) and record the links the
    block may have filled in; returns the state entries of the block touched (0: none)."""
    extra = len(state.active) - max_active
    if extra <= 0:
        return 0
    drop = np.asarray(state.active[:extra], dtype=np.int64)
    keep = np.asarray(state.active[extra:], dtype=np.int64)
    try:
        sparsify_block(state.Om, state.xi, state.mu, keep, drop)
    except np.linalg.LinAlgError:
        raise ConvergenceError("sparsification met a singular block") from None
    state.active = state.active[extra:]
    link_group(state.Om, np.concatenate([keep, drop]), state.links)  # (m+, m0) fill-in
    link_active(state.links, state.active)  # the motion update links the active ones
    return 3 + 2 * (int(keep.size) + int(drop.size))
