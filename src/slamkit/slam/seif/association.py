"""SEIF data association of readings without ids: maximum likelihood over the candidates
near the robot, with the covariance of the robot and each candidate taken from the
information over their blanket (the maths: :mod:`slamkit.slam.seif`, *Data association*).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError, InputError
from slamkit.geometry import wrap_angle
from slamkit.geometry.angles import wrap_angle_float
from slamkit.mapping.ekf_mapping import NEW, associate_nearest_unchecked
from slamkit.models import MIN_RANGE, LandmarkModel
from slamkit.models.measurement import InvertibleLandmarkModel, LandmarkModelBase
from slamkit.slam.seif.config import SeifConfig
from slamkit.slam.seif.kernels import landmark_indices, pose_indices
from slamkit.slam.seif.state import SeifState

__all__ = [
    "associate",
    "blanket",
    "blanket_covariance",
    "blanket_factor",
    "candidates",
    "conditional_nis",
    "wrapped_pose",
]


def wrapped_pose(mu: FloatArray) -> FloatArray:
    """The pose of the running mean with its heading wrapped (the filter keeps it
    unwrapped; the models want it wrapped)."""
    x = mu[:3].copy()
    x[2] = wrap_angle_float(float(x[2]))  # models want a wrapped heading
    return x


def candidates(
    lm: FloatArray,
    x: FloatArray,
    z: FloatArray,
    meas: InvertibleLandmarkModel,
    config: SeifConfig,
) -> NDArray[np.int64]:
    """Map rows of the landmarks ``lm (L, 2)`` within ``candidate_radius`` of the point a
    reading of ``z (K, m)`` places from the pose ``x`` (at most ``max_candidates``, nearest
    first; none on the sensor itself)."""
    points = np.atleast_2d(meas.inverse(x, z))  # (K, 2)
    d = np.hypot(points[:, None, 0] - lm[None, :, 0], points[:, None, 1] - lm[None, :, 1])
    near = d.min(axis=0)
    near[np.hypot(lm[:, 0] - x[0], lm[:, 1] - x[1]) < MIN_RANGE] = np.inf
    cand = np.flatnonzero(near <= config.candidate_radius)
    if cand.size > config.max_candidates:
        order = np.argsort(near[cand], kind="stable")
        cand = np.sort(cand[order[: config.max_candidates]])
    return cand


def blanket(
    sel: NDArray[np.int64], active: list[int], links: list[set[int]], hops: int, cap: int
) -> NDArray[np.int64]:
    """Map rows of the blanket of the robot and the landmarks ``sel``: ``sel`` first,
    then the ``active`` landmarks (the robot's links), then ``hops`` rings of ``links``
    (per map row, the rows it is linked to; each ring sorted), at most ``max(cap, |sel|)``
    landmarks."""
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
        near |= links[r]
    act = [r for r in active if r not in inside]
    fresh = act + sorted(near - inside - set(act))
    for _ in range(hops):
        if not fresh or not take(fresh):
            break
        ring: set[int] = set()
        for r in fresh:
            ring |= links[r]
        fresh = sorted(ring - inside)
    return np.asarray(members, dtype=np.int64)


def blanket_factor(Om: FloatArray, B: NDArray[np.int64], k: int) -> FloatArray:
    """``Y (c, c)``, ``c = 3 + 2k``, with ``Yᵀ Y`` the block of ``Ω_BB⁻¹`` over the
    robot and the first ``k`` landmarks of ``B`` (columns: pose, then those landmarks).

    Ordered with those ``c`` variables LAST, ``Ω_BB = L Lᵀ`` (Cholesky, ``L`` lower)
    gives ``Ω_BB⁻¹ = L⁻ᵀ L⁻¹``; ``L⁻¹`` is lower triangular, so its last ``c`` columns
    are zero above the last ``c`` rows, where they are ``L_cc⁻¹`` (the inverse of a
    block-triangular matrix has the inverses of its diagonal blocks on its diagonal).
    Hence the block is ``L_cc⁻ᵀ L_cc⁻¹``: one factorisation and a ``c × c`` triangular
    inverse, no solve with the whole blanket. Raises
    :class:`~slamkit.errors.ConvergenceError` if ``Ω_BB`` is not positive definite."""
    idx = np.concatenate([landmark_indices(B[k:]), pose_indices(), landmark_indices(B[:k])])
    try:
        chol = np.linalg.cholesky(Om[np.ix_(idx, idx)])
    except np.linalg.LinAlgError:
        raise ConvergenceError(
            "the information over an association blanket is not positive definite"
        ) from None
    c = 3 + 2 * k
    Y = scipy.linalg.solve_triangular(chol[-c:, -c:], np.eye(c), lower=True, check_finite=False)
    return np.asarray(Y, dtype=np.float64)


def blanket_covariance(
    Om: FloatArray,
    rows: ArrayLike,
    active: list[int],
    links: list[set[int]],
    hops: int,
    cap: int,
) -> FloatArray:
    """The joint covariance ``(3 + 2k, 3 + 2k)`` of the robot and the landmarks ``rows``
    (map rows, ``k`` of them, checked against the ``len(links)`` landmarks) from the
    information over their blanket (:func:`blanket`, :func:`blanket_factor`)."""
    L = len(links)
    sel = np.asarray(rows, dtype=np.int64).reshape(-1)
    if sel.size and (sel.min() < 0 or sel.max() >= L):
        raise InputError(f"rows: expected map rows in [0, {L}), got {sel.tolist()}")
    if np.unique(sel).size != sel.size:
        raise InputError(f"rows: expected distinct map rows, got {sel.tolist()}")
    B = blanket(sel, active, links, hops, cap)
    Y = blanket_factor(Om, B, sel.size)
    cov = Y.T @ Y
    return np.asarray(0.5 * (cov + cov.T), dtype=np.float64)


def associate(
    state: SeifState,
    z: FloatArray,
    meas: InvertibleLandmarkModel,
    model: LandmarkModel,
    R: FloatArray,
    angular: tuple[int, ...],
    config: SeifConfig,
    gates: tuple[float, float],
) -> tuple[NDArray[np.int64], FloatArray, int]:
    """Map row (or NEW / REJECTED) per reading of ``z (K, m)``, the ``d²`` of the pairing
    (NaN for none), and the state entries of the blanket solved (0: no candidates, no
    solve): maximum likelihood over the candidates, greedy nearest neighbour in ``d²``
    inside the gate; ``gates``: ``χ²_m(gate_probability)``, ``χ²_m(new_landmark_probability)``.
    """
    Om, mu, active, links = state.Om, state.mu[: state.n], state.active, state.links
    K, L = z.shape[0], (mu.size - 3) // 2
    d2_pair = np.full(K, np.nan)
    if L == 0:
        return np.full(K, NEW, dtype=np.int64), d2_pair, 0
    x = wrapped_pose(mu)
    lm_all = mu[3:].reshape(-1, 2)
    cand = candidates(lm_all, x, z, meas, config)
    if cand.size == 0:
        return np.full(K, NEW, dtype=np.int64), d2_pair, 0
    B = blanket(cand, active, links, config.blanket_hops, config.max_blanket)
    Y = blanket_factor(Om, B, cand.size)  # Yᵀ Y: robot, then the candidates
    U = cand.size
    lm = lm_all[cand]
    pose = np.broadcast_to(x, (U, 3))
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
    S = np.einsum("urm,urn->umn", HY, HY) + R  # symmetric by construction
    nu = z[:, None, :] - z_hat[None, :, :]  # ν = z ⊖ ẑ, angles wrapped
    for i in angular:
        nu[..., i] = wrap_angle(nu[..., i])
    try:
        S_inv = np.linalg.inv(S)
    except np.linalg.LinAlgError:
        raise ConvergenceError("an innovation covariance is singular") from None
    d2 = np.einsum("kui,uij,kuj->ku", nu, S_inv, nu)
    match = associate_nearest_unchecked(d2, *gates)
    hit = match >= 0
    d2_pair[hit] = d2[np.flatnonzero(hit), match[hit]]
    out = match.copy()
    out[hit] = cand[match[hit]]
    return out, d2_pair, 3 + 2 * int(B.size)


def conditional_nis(Om: FloatArray, nu: FloatArray, H: FloatArray, s: int, R: FloatArray) -> float:
    """``νᵀ S⁻¹ ν`` with ``S = H Σ_b Hᵀ + R``, ``Σ_b`` the covariance of the robot and
    the landmark in state rows ``s, s + 1`` CONDITIONED on the rest of the map
    (``Ω_bb⁻¹``): a cheap lower bound on ``S``, so this NIS runs high; for diagnostics only
    (readings paired by the association log their ``d²`` over the blanket instead)."""
    idx = np.array([0, 1, 2, s, s + 1])
    try:
        Sb = H @ np.linalg.solve(Om[np.ix_(idx, idx)], H.T) + R
        return float(nu @ np.linalg.solve(Sb, nu))
    except np.linalg.LinAlgError:
        raise ConvergenceError("a robot-landmark information block is singular") from None
