"""SEIF mean recovery: the amortised block Gauss–Seidel relaxation run every step, the exact
solve ``Ω μ = ξ`` and the landmark marginals done once at the end, and the cheap
definiteness check of the pose block.

``μ = Ω⁻¹ ξ`` is not computed per step. Each step relaxes the pose, the active landmarks and
a few others in turn: ``μ_i ← Ω_ii⁻¹ (ξ_i − Σ_{j≠i} Ω_ij μ_j)`` over the blocks ``j``
linked to ``i`` (:func:`relax`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError
from slamkit.estimation.contract import LandmarkEstimate
from slamkit.estimation.gaussian import check_covariance
from slamkit.maps import LandmarkMap
from slamkit.slam.seif.kernels import landmark_indices, pose_indices
from slamkit.slam.seif.state import SeifState, link_active

__all__ = [
    "check_pose_block",
    "exact_estimate",
    "exact_mean",
    "landmark_marginals",
    "relax",
    "relax_step",
    "relaxation_order",
]


def relaxation_order(
    active: list[int], sweeps: int, per_step: int, L: int, cursor: int
) -> tuple[list[int], int]:
    """The blocks one relaxation step visits (``-1``: the pose; else a map row) and the
    new round-robin cursor: ``sweeps`` times the pose and the ``active`` landmarks, then
    ``per_step`` of the ``L`` landmarks from ``cursor`` on."""
    blocks: list[int] = [-1, *active] * sweeps
    for _ in range(min(per_step, L)):
        blocks.append(cursor % L)
        cursor += 1
    return blocks, cursor


def relax(
    Om: FloatArray,
    xi: FloatArray,
    mu: FloatArray,
    blocks: list[int],
    active: list[int],
    links: list[set[int]],
    ids: list[int],
    cache: dict[int, tuple[int, NDArray[np.int64]]] | None = None,
) -> None:
    """Block Gauss–Seidel on ``mu`` (in place) over ``blocks`` in order (``-1``: the pose,
    linked to the ``active`` landmarks only; a map row: a landmark, linked to ``links``
    of it and to the pose if active); ``ids`` name a landmark whose block is not positive
    definite in the :class:`~slamkit.errors.ConvergenceError`. ``cache`` keeps the state
    indices of each landmark's links from call to call (per map row: the number of links
    and their indices; links are only ever added, so an unchanged count is an unchanged
    set)."""
    if cache is None:
        cache = {}
    act = set(active)
    act_idx = landmark_indices(active)
    pose = pose_indices()
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
            linked = links[b]
            known = cache.get(b)
            if known is None or known[0] != len(linked):
                known = (len(linked), landmark_indices(sorted(linked)))
                cache[b] = known
            nb = np.concatenate([pose, known[1]]) if b in act else known[1]
            neighbours[b] = nb
        s = 3 + 2 * b
        r0, r1 = (xi[s : s + 2] - Om[s : s + 2, nb] @ mu[nb]).tolist()
        # the 2 × 2 block solve in closed form; a diagonal block of a positive definite
        # matrix is positive definite (Sylvester: Ω_ss > 0 and det > 0)
        p, q, r = float(Om[s, s]), float(Om[s, s + 1]), float(Om[s + 1, s + 1])
        det = p * r - q * q
        if not (p > 0.0 and det > 0.0):
            raise ConvergenceError(
                f"the information block of landmark {ids[b]} is not positive definite"
            )
        mu[s] = (r * r0 - q * r1) / det
        mu[s + 1] = (p * r1 - q * r0) / det


def check_pose_block(Om: FloatArray) -> None:
    """Raise :class:`~slamkit.errors.ConvergenceError` unless the pose block ``Ω_xx`` (the
    pose's information given the map) is positive definite: the shared definiteness check
    (:func:`~slamkit.estimation.gaussian.check_covariance`, ~1 µs at 3 × 3), then — as an
    information block must be regular, not only PSD — a Cholesky test."""
    check_covariance(Om[:3, :3], "seif", "information matrix")
    try:
        np.linalg.cholesky(Om[:3, :3])
    except np.linalg.LinAlgError:
        raise ConvergenceError(
            "seif: the information matrix is singular (the pose block)"
        ) from None


def exact_mean(Om: FloatArray, xi: FloatArray) -> FloatArray:
    """The exact mean ``Ω⁻¹ ξ`` (a dense solve, ``O(n³)``)."""
    try:
        return np.asarray(np.linalg.solve(Om, xi), dtype=np.float64)
    except np.linalg.LinAlgError:
        raise ConvergenceError("seif: the information matrix is singular") from None


def landmark_marginals(Om: FloatArray, L: int) -> FloatArray:
    """The ``(L, 2, 2)`` marginal covariances of the landmarks, blocks of ``Ω⁻¹`` (one dense
    inverse, ``O(n³)``)."""
    covs = np.zeros((L, 2, 2))
    if L:
        try:
            Sigma = np.linalg.inv(Om)
        except np.linalg.LinAlgError:
            raise ConvergenceError("seif: the information matrix is singular") from None
        for j in range(L):
            s = 3 + 2 * j
            b = Sigma[s : s + 2, s : s + 2]
            covs[j] = 0.5 * (b + b.T)
    return covs


def relax_step(state: SeifState, sweeps: int, per_step: int, cursor: int) -> int:
    """One step of the amortised mean recovery on ``state``: link the active landmarks to
    each other (the motion updates did), then :func:`relax` over
    :func:`relaxation_order`; returns the new round-robin cursor."""
    link_active(state.links, state.active)  # motion updates link the active landmarks
    blocks, cursor = relaxation_order(state.active, sweeps, per_step, state.n_landmarks, cursor)
    relax(
        state.Om, state.xi, state.mu, blocks, state.active, state.links, state.ids,
        state.neighbour_cache,
    )  # fmt: skip
    return cursor


def exact_estimate(state: SeifState) -> tuple[LandmarkEstimate, FloatArray]:
    """The landmarks at the exact mean with their marginal covariances, and that mean
    ``Ω⁻¹ ξ`` (``(3 + 2L,)``) — dense, ``O(n³)``, done once at the end."""
    n = state.n
    O, xi = state.Om[:n, :n].copy(), state.xi[:n].copy()
    mu = exact_mean(O, xi)
    covs = landmark_marginals(O, state.n_landmarks)
    ids = np.asarray(state.ids, dtype=np.int64)
    return LandmarkEstimate(LandmarkMap(mu[3:].reshape(-1, 2).copy(), ids), covs), mu
