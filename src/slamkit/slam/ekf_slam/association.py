"""EKF-SLAM data association of readings without ids: the Mahalanobis distance of every
reading to every landmark, greedy nearest neighbour, and joint compatibility branch and
bound (JCBB), which respects that every prediction shares the robot's error.

For a landmark ``j`` the predicted reading ``ẑ_j = h(x_r, m_j)`` has the covariance
``S_j = H_r Σ_rr H_rᵀ + H_r Σ_rj H_jᵀ + (H_r Σ_rj H_jᵀ)ᵀ + H_j Σ_jj H_jᵀ + R`` and a reading
``z`` the distance ``d² = νᵀ S_j⁻¹ ν``, ``ν = z ⊖ ẑ_j`` (angles wrapped, so a landmark read
at bearing ``+π − ε`` and ``−π + ε`` is one landmark, not two).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import ConvergenceError, InputError
from slamkit.geometry import wrap_angle
from slamkit.mapping.ekf_mapping import NEW, REJECTED, associate_nearest_unchecked
from slamkit.models import MIN_RANGE, LandmarkModel
from slamkit.models.measurement import LandmarkModelBase
from slamkit.prob import chi2_gate
from slamkit.slam.common import reading_jacobians
from slamkit.slam.ekf_slam.config import EkfSlamConfig
from slamkit.slam.ekf_slam.state import diagonal_blocks

__all__ = [
    "JcbbResult",
    "associate_scan",
    "jcbb",
    "jcbb_unchecked",
    "joint_prediction_cov",
    "predicted_readings",
    "reading_distances",
]


@dataclass(frozen=True)
class JcbbResult:
    """The JCBB hypothesis: for each of ``K`` readings the landmark column it is paired with
    (``-1``: none), the joint ``D² = ν_Hᵀ S_H⁻¹ ν_H`` of the pairs, the number of search
    nodes visited and whether the search finished inside its node budget (``False``: the
    best hypothesis found before the budget ran out)."""

    assignment: NDArray[np.int64]
    d2: float
    nodes: int
    complete: bool

    @property
    def pairings(self) -> int:
        return int(np.count_nonzero(self.assignment >= 0))


def jcbb(
    nu: ArrayLike,
    M: ArrayLike,
    R: ArrayLike,
    gate_probability: float = 0.999,
    max_nodes: int = 20_000,
) -> JcbbResult:
    """Joint compatibility branch and bound (Neira & Tardós, IEEE T-RA 17(6), 2001).

    ``nu (K, U, m)``: the innovation of each of ``K`` readings against each of ``U``
    candidate landmarks (angles wrapped). ``M (U·m, U·m)``: the joint covariance of the
    ``U`` predicted readings ``H Σ Hᵀ`` — off-diagonal blocks nonzero, since every
    prediction shares the robot pose — WITHOUT the noise; ``R (m, m)`` is the noise of one
    reading. A hypothesis pairs readings with distinct landmarks; it is *jointly
    compatible* when the stacked innovation ``ν_H`` and ``S_H = M_H + I ⊗ R`` give
    ``D² = ν_Hᵀ S_H⁻¹ ν_H ≤ χ²_{m·p}(gate_probability)`` (``p`` pairs). The search returns
    the jointly compatible hypothesis with the most pairs, the smallest ``D²`` among those.
    Each pair must also be individually compatible (the same test with ``p = 1``).

    ``D²`` grows incrementally: adding a pair with innovation ``ν_p``, noise-free block
    ``c`` against the pairs so far and own block ``s`` extends the Cholesky factor ``L`` of
    ``S_H`` by ``B = L⁻¹ c``, ``L_pp = chol(s + R − Bᵀ B)``, and
    ``D² += ‖L_pp⁻¹ (ν_p − Bᵀ y)‖²`` with ``y = L⁻¹ ν_H`` — ``O(p²)`` per node instead of a
    new factorisation. Readings are searched in order of increasing candidate count; the
    bound prunes a branch that cannot reach the best number of pairs (or, at equal count,
    has already a larger ``D²``). After ``max_nodes`` nodes the best hypothesis found so far
    is returned with ``complete=False``.
    """
    v = as_array(nu, "nu", (None, None, None))
    _, U, m = v.shape
    Ma = as_array(M, "M", (U * m, U * m))
    Ra = as_covariance(R, "R", m)
    if not 0 < gate_probability < 1:
        raise InputError(f"gate_probability: expected a number in (0, 1), got {gate_probability}")
    if not (isinstance(max_nodes, int) and max_nodes >= 1):
        raise InputError(f"max_nodes: expected an integer >= 1, got {max_nodes!r}")
    return jcbb_unchecked(v, Ma, Ra, gate_probability, max_nodes)


@lru_cache(maxsize=256)
def _chi2(dof: int, probability: float) -> float:
    return chi2_gate(dof, probability)


def _individual_d2(nu: FloatArray, M: FloatArray, R: FloatArray) -> FloatArray:
    """``d² (K, U)`` of every reading against every candidate with ``S_u = M_uu + R``."""
    _, U, m = nu.shape
    blocks = M.reshape(U, m, U, m)[np.arange(U), :, np.arange(U), :] + R  # (U, m, m)
    try:
        Sinv = np.linalg.inv(0.5 * (blocks + np.swapaxes(blocks, -1, -2)))
    except np.linalg.LinAlgError:
        raise ConvergenceError("jcbb: an innovation covariance is singular") from None
    return np.einsum("kui,uij,kuj->ku", nu, Sinv, nu)


def _lower_cholesky_inverse(C: FloatArray) -> FloatArray | None:
    """``L⁻¹`` of the lower Cholesky factor of a small SPD ``C``; ``None`` if ``C`` is not
    positive definite. Closed form for 2 × 2 (the usual reading), LAPACK otherwise."""
    if C.shape[0] == 2:
        a, b, d = float(C[0, 0]), 0.5 * float(C[0, 1] + C[1, 0]), float(C[1, 1])
        if not a > 0.0:
            return None
        l11 = math.sqrt(a)
        l21 = b / l11
        q = d - l21 * l21
        if not q > 0.0:
            return None
        l22 = math.sqrt(q)
        return np.array([[1.0 / l11, 0.0], [-l21 / (l11 * l22), 1.0 / l22]])
    try:
        L = np.linalg.cholesky(0.5 * (C + C.T))
    except np.linalg.LinAlgError:
        return None
    return np.asarray(scipy.linalg.solve_triangular(L, np.eye(C.shape[0]), lower=True))


def jcbb_unchecked(
    nu: FloatArray,
    M: FloatArray,
    R: FloatArray,
    probability: float,
    max_nodes: int,
    d2_ind: FloatArray | None = None,
) -> JcbbResult:
    """:func:`jcbb` on checked arrays; ``d2_ind (K, U)``, the individual distances, when the
    caller has them (else computed from ``M`` and ``R``)."""
    K, U, m = nu.shape
    if K == 0 or U == 0:
        return JcbbResult(np.full(K, -1, dtype=np.int64), 0.0, 0, True)
    if d2_ind is None:
        d2_ind = _individual_d2(nu, M, R)
    gates = [0.0] + [_chi2(m * p, probability) for p in range(1, min(K, U) + 1)]
    cands = [[int(u) for u in np.argsort(d2_ind[k]) if d2_ind[k, u] <= gates[1]] for k in range(K)]
    order = sorted(range(K), key=lambda k: (len(cands[k]), k))
    # remaining[i]: readings from position i on that have a candidate (the bound).
    remaining = [0] * (K + 1)
    for i in range(K - 1, -1, -1):
        remaining[i] = remaining[i + 1] + (1 if cands[order[i]] else 0)

    M4 = M.reshape(U, m, U, m)
    cap = m * min(K, U)
    # Inverse of the Cholesky factor of S_H, grown and shrunk with the hypothesis: with
    # S_H = L Lᵀ and a new pair, L' = [[L, 0], [Bᵀ, L_pp]] has the inverse
    # [[L⁻¹, 0], [−L_pp⁻¹ Bᵀ L⁻¹, L_pp⁻¹]] — matrix products only, no triangular solves.
    Linv = np.zeros((cap, cap))
    y = np.zeros(cap)  # L⁻¹ ν_H
    landmarks: list[int] = []  # landmark of each pair, in hypothesis order
    assign = [-1] * K
    used = [False] * U
    best: dict[str, Any] = {"pairs": 0, "d2": math.inf, "assign": [-1] * K}
    state = {"nodes": 0}

    def extend(k: int, u: int, d2: float) -> float | None:
        """D² with the pair (k, u) added, writing the factor's new rows; None if the pair
        is not jointly compatible."""
        p = len(landmarks)
        r0 = p * m
        C = M4[u, :, u, :] + R  # the new pair's own block of S_H
        rhs = nu[k, u]
        if p:
            c = M4[landmarks, :, u, :].reshape(r0, m)  # cross-covariance, no noise
            Li = Linv[:r0, :r0]
            B = Li @ c  # L⁻¹ c
            C = C - B.T @ B  # Schur complement: L_pp L_ppᵀ = s − Bᵀ B
            rhs = rhs - B.T @ y[:r0]
        Lpp_inv = _lower_cholesky_inverse(C)
        if Lpp_inv is None:
            return None
        y_p = Lpp_inv @ rhs
        d2_new = d2 + float(y_p @ y_p)  # D² grows by ‖L_pp⁻¹ (ν_p − Bᵀ y)‖²
        if d2_new > gates[p + 1]:
            return None
        if p:
            Linv[r0 : r0 + m, :r0] = -Lpp_inv @ B.T @ Li
        Linv[r0 : r0 + m, r0 : r0 + m] = Lpp_inv
        y[r0 : r0 + m] = y_p
        return d2_new

    def search(i: int, d2: float) -> None:
        state["nodes"] += 1
        pairs = len(landmarks)
        if i == K:
            if pairs > best["pairs"] or (pairs == best["pairs"] and d2 < best["d2"]):
                best.update(pairs=pairs, d2=d2, assign=list(assign))
            return
        if state["nodes"] >= max_nodes:
            return
        k = order[i]
        # Pair reading k with each free, individually compatible landmark (nearest first)
        # if the result can still beat the best (more pairs, or as many with less D²).
        for u in cands[k]:
            bound = pairs + remaining[i]
            if bound < best["pairs"] or (bound == best["pairs"] and d2 >= best["d2"]):
                break
            if used[u]:
                continue
            d2_new = extend(k, u, d2)
            if d2_new is None:
                continue
            landmarks.append(u)
            used[u] = True
            assign[k] = u
            search(i + 1, d2_new)
            assign[k] = -1
            used[u] = False
            landmarks.pop()
        # Leave reading k unpaired if the others alone can still beat the best.
        bound = pairs + remaining[i + 1]
        if bound > best["pairs"] or (bound == best["pairs"] and d2 < best["d2"]):
            search(i + 1, d2)

    search(0, 0.0)
    complete = state["nodes"] < max_nodes
    assignment = np.asarray(best["assign"], dtype=np.int64)
    return JcbbResult(assignment, float(best["d2"]), state["nodes"], complete)


def predicted_readings(
    mean: FloatArray,
    cov: FloatArray,
    sel: NDArray[np.int64],
    model: LandmarkModel,
    R: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """For the landmarks ``sel`` (state indices) at the state ``mean (n,)``, ``cov (n, n)``:
    ``z_hat (U, m)``, the Jacobians ``H_r (U, m, 3)``, ``H_j (U, m, 2)`` and ``S (U, m, m)``
    with the noise ``R``. The landmarks must be off the sensor."""
    U = sel.size
    lm = mean[3:].reshape(-1, 2)[sel]
    pose = np.broadcast_to(mean[:3], (U, 3))
    if isinstance(model, LandmarkModelBase):
        z_hat, (Hr, Hj) = model.predict_unchecked(pose, lm), model.jacobians_unchecked(pose, lm)
    else:
        z_hat, (Hr, Hj) = model.predict(pose, lm), model.jacobians(pose, lm)
    C = cov[:3, 3:].reshape(3, -1, 2)[:, sel, :].transpose(1, 0, 2)  # Σ_r,j (U, 3, 2)
    B = diagonal_blocks(cov, (mean.size - 3) // 2)[sel]
    HrT, HjT = np.swapaxes(Hr, -1, -2), np.swapaxes(Hj, -1, -2)
    HC = Hr @ C @ HjT
    S = Hr @ cov[:3, :3] @ HrT + HC + np.swapaxes(HC, -1, -2) + Hj @ B @ HjT + R
    return z_hat, Hr, Hj, 0.5 * (S + np.swapaxes(S, -1, -2))


def reading_distances(
    mean: FloatArray,
    cov: FloatArray,
    z: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
    angular: tuple[int, ...],
    window: NDArray[np.bool_] | None = None,
) -> tuple[FloatArray, FloatArray]:
    """``(d² (K, L), ν (K, L, m))`` of readings ``z (K, m)`` against every landmark
    (``d² = inf`` for a landmark on the sensor, whose reading and Jacobian are undefined).
    ``window (K, L)``: each reading's candidates (:func:`~slamkit.slam.ekf_slam.window.
    reading_window`); the others get ``d² = inf`` and no prediction is formed for a
    landmark in no window."""
    K, L = z.shape[0], (mean.size - 3) // 2
    d2 = np.full((K, L), np.inf)
    nu = np.zeros((K, L, int(R.shape[0])))
    if L == 0 or K == 0:
        return d2, nu
    lm = mean[3:].reshape(L, 2)
    off = np.hypot(lm[:, 0] - mean[0], lm[:, 1] - mean[1]) >= MIN_RANGE
    if window is not None:
        off &= window.any(axis=0)
    sel = np.flatnonzero(off)
    if sel.size == 0:
        return d2, nu
    z_hat, _, _, S = predicted_readings(mean, cov, sel, model, R)
    v = z[:, None, :] - z_hat[None, :, :]  # ν = z ⊖ ẑ, angles wrapped
    for i in angular:
        v[..., i] = wrap_angle(v[..., i])
    nu[:, sel, :] = v
    d2_sel = np.einsum("kli,lij,klj->kl", v, np.linalg.inv(S), v)
    if window is not None:
        d2_sel[~window[:, sel]] = np.inf
    d2[:, sel] = d2_sel
    return d2, nu


def joint_prediction_cov(
    mean: FloatArray, cov: FloatArray, cand: NDArray[np.int64], model: LandmarkModel
) -> FloatArray:
    """``H Σ Hᵀ (U m × U m)`` of the predicted readings of the landmarks ``cand``."""
    m = model.dim
    U = cand.size
    idx = np.concatenate([np.arange(3), (3 + 2 * cand[:, None] + np.arange(2)).ravel()])
    sub = cov[np.ix_(idx, idx)]
    J = np.zeros((U * m, idx.size))
    for a, j in enumerate(cand.tolist()):
        _, Hr, Hj = reading_jacobians(model, mean[:3], mean[3 + 2 * j : 5 + 2 * j])
        J[a * m : (a + 1) * m, :3] = Hr
        J[a * m : (a + 1) * m, 3 + 2 * a : 5 + 2 * a] = Hj
    M = J @ sub @ J.T
    return 0.5 * (M + M.T)


def associate_scan(
    mean: FloatArray,
    cov: FloatArray,
    z: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
    angular: tuple[int, ...],
    config: EkfSlamConfig,
    window: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.int64], JcbbResult | None]:
    """Landmark index per reading of ``z (K, m)``, or NEW / REJECTED (codes of
    :mod:`~slamkit.mapping.ekf_mapping`), by ``config.association``; and the JCBB search
    when one ran. A reading not paired starts a feature only if ``d² > χ²_m(new_landmark_
    probability)`` for every landmark. ``window``: each reading's candidates, as in
    :func:`reading_distances`."""
    K, m = z.shape[0], int(R.shape[0])
    gate = _chi2(m, config.gate_probability)
    new_gate = _chi2(m, config.new_landmark_probability)
    d2, nu = reading_distances(mean, cov, z, model, R, angular, window)
    if config.association == "nn" or mean.size == 3:
        return associate_nearest_unchecked(d2, gate, new_gate), None
    # JCBB over the landmarks individually compatible with some reading.
    cand = np.flatnonzero((d2 <= gate).any(axis=0))
    out = np.full(K, REJECTED, dtype=np.int64)
    res = None
    if cand.size:
        M = joint_prediction_cov(mean, cov, cand, model)
        res = jcbb_unchecked(nu[:, cand, :], M, R, config.gate_probability,
                             config.jcbb_max_nodes, d2[:, cand])  # fmt: skip
        hit = res.assignment >= 0
        out[hit] = cand[res.assignment[hit]]
    else:
        hit = np.zeros(K, dtype=bool)
    out[~hit & (d2.min(axis=1, initial=np.inf) > new_gate)] = NEW
    return out, res
