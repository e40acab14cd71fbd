"""The hierarchical variant of GPS fusion: local maps joined by GPS-anchored base frames.

The run's pose nodes are cut into submaps of ``P`` poses: submap ``k`` holds nodes
``kP … (k+1)P`` (the last one up to the final node), so neighbours share one node, the end of
``k`` being the base of ``k + 1``. An odometry edge ``(i, i+1)`` and the readings and fixes of
node ``i`` belong to submap ``min(i // P, K - 1)``.

1. **Local level.** Each submap is solved on its own, in the frame of its base (base held at
   the identity): its odometry and range-bearing edges, no GPS. A landmark seen in two
   submaps is two local landmarks: the local maps share nothing but the boundary node.
   At the local optimum the Laplace approximation gives the marginal covariance ``Σ_v`` of a
   pose ``v`` relative to the base: ``Σ_v = (H⁻¹)_vv``, the inverse of the Schur complement
   of ``H`` onto ``v`` (:func:`slamkit.optim.marginals.marginal_covariances`). It is read for
   the end pose ``E_k`` and for the pose ``Y_f`` of every fix of the submap.
2. **Top level.** Variables: the base frames ``B_0 … B_{K-1}`` (global SE(2)), the final
   node as ``B_K`` (the end of the last submap, so that every submap ends at a top node and
   a fix at the final node is anchored there), and the lever arm ``o``.
   Factors: between ``B_k`` and ``B_{k+1}`` the relative pose the local map implies,
   ``Z = E_k`` with information ``Σ_E⁻¹`` (g2o's error is a right perturbation of ``Z``, the
   tangent of ``Σ_E``); each fix through its local pose,
   ``e = t_B + R_B (t_Y + R_Y o) - z`` (:func:`slamkit.optim.gps.anchored_gps_error`) with
   covariance ``Σ_z + R_B J_Y Σ_Y J_Yᵀ R_Bᵀ``, ``J_Y = [R_Y, R_Y S o]`` (the fix's noise plus
   the local pose's uncertainty pushed through the antenna; the correlations between the
   fixes of one submap and its relative pose are left out). The top level is started from
   the chained relative poses moved onto the fixes (:func:`~slamkit.slam.landmark_graph.
   solve.fit_to_fixes`), solved by Levenberg-Marquardt on its sparse normal equations, the
   fixes re-weighted between solves as the flat graph's are (the inflated covariance is
   refreshed at each round's ``B`` and ``o``).
3. **Placement.** Every local pose goes to ``B_k ∘ Y``, every local landmark to
   ``B_k · l``; a landmark of several submaps is the mean of its placements, weighted by
   the number of readings each submap has of it.

Submaps are rigid at the top level: the fixes move a local map as a whole, never bend it,
and a tree seen from two submaps does not tie them. That is what the hierarchy trades for
small systems. With ``P = 1`` each submap is one odometry edge and the readings of its base
alone (a landmark is then determined by one submap's readings and never ties two poses), so
the top level is the flat fused graph without its readings: a test holds that identity.
Measured on Victoria Park: ``docs/estimators/gps.md``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.linalg import spsolve

from slamkit._validation import FloatArray
from slamkit.errors import ConfigError, InputError
from slamkit.geometry import pose2
from slamkit.optim import OptimizerConfig, g2o_chi2, optimize
from slamkit.optim.data import EdgeSet, GraphData, IntArray
from slamkit.optim.factors import retract_poses, se2_between_error
from slamkit.optim.gps import anchored_gps_error, gps_weights, reweight
from slamkit.optim.marginals import marginal_covariances
from slamkit.runtime import blas_threads
from slamkit.slam.landmark_graph.build import LandmarkGraph
from slamkit.slam.landmark_graph.solve import (
    GraphSolution,
    LandmarkGraphConfig,
    fit_to_fixes,
)

__all__ = ["HierarchicalResult", "solve_hierarchical"]

_LM_START = 1e-4  # initial Levenberg-Marquardt damping of the top level (relative to diag H)
_MAX_ITERATIONS = 100  # top-level iterations per round at most
_REL_TOL = 1e-10  # top level: stop when the cost falls by less than this fraction


@dataclass(frozen=True, eq=False)
class HierarchicalResult:
    """:func:`solve_hierarchical`'s answer: the placed solution and what the hierarchy did."""

    solution: GraphSolution
    """Poses at every node, the merged landmark map, the lever arm and the fixes' weights
    (rows as the flat graph's ``gps`` edges); ``chi2`` is the flat fused graph's at the placed
    solution and final weights; ``seconds`` covers the local and top solves."""
    submaps: int
    """Number of local maps ``K``."""
    largest_local: int
    """Variables of the largest local system (3 per pose, 2 per landmark)."""
    top_variables: int
    """Variables of the top level (``3(K + 1) + 2``)."""
    flat_variables: int
    """Variables of the flat fused graph, for comparison."""
    local_seconds: float
    """Wall time of the local solves and their marginals."""
    top_seconds: float
    """Wall time of the top level (all rounds) and the placement."""


@dataclass(frozen=True)
class _Local:
    """One solved submap in its base frame."""

    nodes: IntArray  # global node ids of its poses, base first
    poses: FloatArray  # (n, 3) in the base frame
    landmark_ids: IntArray
    landmarks: FloatArray  # (L, 2) in the base frame
    counts: FloatArray  # readings of each landmark in this submap
    end_cov: FloatArray  # (3, 3) marginal of the end pose
    fix_cov: FloatArray  # (F, 3, 3) marginals of the poses of its fixes
    iterations: int
    converged: bool


def _edges(built: LandmarkGraph, kind: str) -> EdgeSet | None:
    return next((e for e in built.graph.edges if e.kind == kind), None)


def _take(e: EdgeSet, keep: NDArray[np.bool_]) -> EdgeSet:
    return EdgeSet(e.kind, e.i[keep], e.j[keep], e.measurement[keep], e.information[keep],
                   e.lines[keep])  # fmt: skip


def _solve_local(
    built: LandmarkGraph,
    nodes: IntArray,
    odo: EdgeSet,
    readings: EdgeSet | None,
    fix_nodes: IntArray,
    opt: OptimizerConfig,
) -> _Local:
    base = built.initial_poses[nodes[0]]
    poses0 = pose2.compose(pose2.inverse(base), built.initial_poses[nodes])
    edges = [odo]
    ids = np.zeros(0, dtype=np.int64)
    lm0 = np.zeros((0, 2))
    counts = np.zeros(0)
    if readings is not None and len(readings):
        edges.append(readings)
        ids, first, counts_i = np.unique(readings.j, return_index=True, return_counts=True)
        counts = counts_i.astype(np.float64)
        r, b = readings.measurement[first, 0], readings.measurement[first, 1]
        x = poses0[readings.i[first] - nodes[0]]
        ang = x[:, 2] + b  # the first sighting: l = t + r (cos(θ + b), sin(θ + b))
        lm0 = np.stack([x[:, 0] + r * np.cos(ang), x[:, 1] + r * np.sin(ang)], axis=1)
    data = GraphData(
        dim=2,
        pose_ids=nodes.astype(np.int64),
        poses=poses0,
        landmark_ids=ids.astype(np.int64),
        landmarks=lm0,
        edges=tuple(edges),
        fixed_ids=nodes[:1].astype(np.int64),
        source=built.graph.source,
    )
    res = optimize(data, opt, initial_poses=poses0, initial_landmarks=lm0, objectives=False)
    want = np.concatenate([nodes[-1:], fix_nodes])
    marg = marginal_covariances(data, res, pose_ids=want, config=opt)
    covs = marg.pose_covariances
    return _Local(
        nodes, res.poses, ids, res.landmarks, counts, covs[0], covs[1:], res.iterations,
        res.converged,
    )  # fmt: skip


def _rot(theta: FloatArray) -> FloatArray:
    c, s = np.cos(theta), np.sin(theta)
    out = np.empty((theta.shape[0], 2, 2))
    out[:, 0, 0] = c
    out[:, 0, 1] = -s
    out[:, 1, 0] = s
    out[:, 1, 1] = c
    return out


def _inflated_covariance(
    base: FloatArray,
    local: FloatArray,
    local_cov: FloatArray,
    lever: FloatArray,
    fix_cov: FloatArray,
) -> FloatArray:
    """``Σ_z + R_B J_Y Σ_Y J_Yᵀ R_Bᵀ`` with ``J_Y = [R_Y, R_Y S o]`` (module docstring)."""
    ry = _rot(local[:, 2])
    ro = ry @ lever  # R_Y o
    J = np.empty((local.shape[0], 2, 3))
    J[:, :, :2] = ry
    J[:, 0, 2] = -ro[:, 1]  # S R_Y o = (-(R_Y o)_y, (R_Y o)_x)
    J[:, 1, 2] = ro[:, 0]
    A = _rot(base[:, 2]) @ J
    cov = fix_cov + A @ local_cov @ np.swapaxes(A, 1, 2)
    return 0.5 * (cov + np.swapaxes(cov, 1, 2))


def _whitener(information: FloatArray) -> FloatArray:
    """``U`` with ``UᵀU = Ω`` (``U = Lᵀ`` of the Cholesky factor ``Ω = L Lᵀ``)."""
    return np.swapaxes(np.linalg.cholesky(information), 1, 2)


@dataclass(frozen=True)
class _Top:
    """The top level's data: relative poses between consecutive bases, fixes through their
    local poses."""

    rel: FloatArray  # (K, 3): the end of submap k in its base frame
    rel_u: FloatArray  # (K, 3, 3) whiteners
    sub: IntArray  # (F,) submap of each fix
    local: FloatArray  # (F, 3)
    z: FloatArray  # (F, 2)


def _residuals(
    top: _Top, B: FloatArray, o: FloatArray, gps_u: FloatArray
) -> tuple[FloatArray, sp.csr_matrix]:
    """Whitened residuals and their sparse Jacobian; variables ``[B_0 … B_K, o]``."""
    K = B.shape[0]
    rows: list[IntArray] = []
    cols: list[IntArray] = []
    vals: list[FloatArray] = []
    res: list[FloatArray] = []
    n_rel = top.rel.shape[0]
    if n_rel:
        e, Ji, Jj = se2_between_error(B[:-1], B[1:], top.rel)
        res.append(np.einsum("eab,eb->ea", top.rel_u, e).ravel())
        for J, first in ((top.rel_u @ Ji, 0), (top.rel_u @ Jj, 1)):
            ri = np.arange(n_rel)[:, None, None] * 3 + np.arange(3)[None, :, None]
            c = (np.arange(n_rel) + first)[:, None, None] * 3 + np.arange(3)[None, None, :]
            rows.append(np.broadcast_to(ri, J.shape).ravel())
            cols.append(np.broadcast_to(c, J.shape).ravel())
            vals.append(J.ravel())
    m0 = 3 * n_rel
    n_fix = top.sub.shape[0]
    e, Jb, Jo = anchored_gps_error(B[top.sub], top.local, np.broadcast_to(o, top.z.shape), top.z)
    res.append(np.einsum("eab,eb->ea", gps_u, e).ravel())
    r2 = m0 + np.arange(n_fix)[:, None, None] * 2 + np.arange(2)[None, :, None]
    for J, c in (
        (gps_u @ Jb, top.sub[:, None, None] * 3 + np.arange(3)[None, None, :]),
        (gps_u @ Jo, 3 * K + np.arange(2)[None, None, :]),
    ):
        rows.append(np.broadcast_to(r2, J.shape).ravel())
        cols.append(np.broadcast_to(c, J.shape).ravel())
        vals.append(J.ravel())
    r = np.concatenate(res)
    jac = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(r.shape[0], 3 * K + 2),
    )
    return r, jac


def _solve_top(
    top: _Top, B: FloatArray, o: FloatArray, gps_u: FloatArray
) -> tuple[FloatArray, FloatArray, int, bool]:
    """Levenberg-Marquardt on the top level (``(H + λ diag H) δ = -Jᵀ r``; a step is kept
    only when it lowers the cost); stops when the cost falls by less than ``_REL_TOL``."""
    K = B.shape[0]
    r, J = _residuals(top, B, o, gps_u)
    cost = float(r @ r)
    lam = _LM_START
    for it in range(1, _MAX_ITERATIONS + 1):
        H = (J.T @ J).tocsc()
        g = J.T @ r
        d = H.diagonal()
        while True:
            step = spsolve(H + sp.diags(lam * np.maximum(d, 1e-12)), -g)
            B_new = retract_poses(B, step[: 3 * K].reshape(K, 3))
            o_new = o + step[3 * K :]
            r_new, J_new = _residuals(top, B_new, o_new, gps_u)
            cost_new = float(r_new @ r_new)
            if cost_new <= cost:
                break
            lam *= 10.0
            if lam > 1e12:
                return B, o, it, True  # no step lowers the cost: at the minimum
        drop = cost - cost_new
        B, o, r, J, cost = B_new, o_new, r_new, J_new, cost_new
        lam = max(lam / 10.0, 1e-12)
        if drop <= _REL_TOL * max(cost, 1e-300):
            return B, o, it, True
    return B, o, _MAX_ITERATIONS, False


def solve_hierarchical(
    built: LandmarkGraph,
    submap_poses: int,
    config: LandmarkGraphConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> HierarchicalResult:
    """Fuse ``built``'s fixes hierarchically (module docstring): local maps of
    ``submap_poses`` odometry steps each, joined at a top level of their base frames
    anchored by the fixes. Needs at least two fixes in the graph. ``progress(k, K)`` is
    called after each local solve."""
    cfg = config or LandmarkGraphConfig()
    if submap_poses < 1:
        raise ConfigError(f"hierarchical submap_poses: expected >= 1, got {submap_poses}")
    gps = _edges(built, "gps")
    if gps is None or len(gps) < 2:
        raise InputError(
            f"{built.graph.source or 'the graph'}: fewer than two GPS fixes in the graph "
            "(the hierarchy's top level is anchored by them)"
        )
    odo = _edges(built, "se2")
    readings = _edges(built, "range_bearing")
    assert odo is not None
    n = built.times.shape[0]
    K = max(1, -(-(n - 1) // submap_poses))  # ceil((N - 1) / P)
    owner = np.minimum(np.arange(n) // submap_poses, K - 1)
    opt = replace(cfg.optimizer, initialization="vertices")
    t0 = time.perf_counter()
    fix_sub = np.where(gps.i == n - 1, K, owner[gps.i])  # the final node: a top node
    locals_: list[_Local] = []
    with blas_threads():  # one policy decision for all the small solves, not one per solve
        for k in range(K):
            last = n - 1 if k == K - 1 else min((k + 1) * submap_poses, n - 1)
            nodes = np.arange(k * submap_poses, last + 1)
            local_odo = _take(odo, owner[odo.i] == k)
            local_rb = None if readings is None else _take(readings, owner[readings.i] == k)
            fixes = gps.i[fix_sub == k]
            locals_.append(_solve_local(built, nodes, local_odo, local_rb, fixes, opt))
            if progress is not None:
                progress(k + 1, K)
    local_seconds = time.perf_counter() - t0

    t1 = time.perf_counter()
    local_of_fix = np.zeros((len(gps), 3))  # a fix at the final node: at B_K itself
    fix_local_cov = np.zeros((len(gps), 3, 3))
    for k, loc in enumerate(locals_):
        idx = np.flatnonzero(fix_sub == k)
        local_of_fix[idx] = loc.poses[gps.i[idx] - loc.nodes[0]]
        fix_local_cov[idx] = loc.fix_cov
    rel = np.array([loc.poses[-1] for loc in locals_])
    rel_cov = np.array([loc.end_cov for loc in locals_])
    rel_info = np.linalg.inv(0.5 * (rel_cov + np.swapaxes(rel_cov, 1, 2)))
    top = _Top(rel, _whitener(rel_info), fix_sub, local_of_fix, gps.measurement)
    fix_cov = np.asarray(np.linalg.inv(gps.information), dtype=np.float64)

    # Start: the relative poses chained from the data set's start, moved onto the fixes.
    B = np.empty((K + 1, 3))
    B[0] = built.initial_poses[0]
    for k in range(1, K + 1):
        B[k] = pose2.compose(B[k - 1], rel[k - 1])
    o = np.asarray(built.initial_landmarks[built.graph.landmark_ids == built.lever_id][0])
    antenna0 = pose2.compose(B[fix_sub], local_of_fix)[:, :2]
    B = fit_to_fixes(antenna0, gps.measurement).apply_to_poses(B)

    weights = np.ones(len(gps))
    rounds = iterations = 0
    settled = top_converged = False
    while rounds < cfg.weighting.max_rounds:
        rounds += 1
        cov = _inflated_covariance(B[fix_sub], local_of_fix, fix_local_cov, o, fix_cov)
        info = np.asarray(np.linalg.inv(cov), dtype=np.float64)
        B, o, it, top_converged = _solve_top(
            top, B, o, _whitener(info * np.maximum(weights, 1e-12)[:, None, None])
        )
        iterations += it
        if cfg.weighting.name == "none":
            settled = True
            break
        cov = _inflated_covariance(B[fix_sub], local_of_fix, fix_local_cov, o, fix_cov)
        levers = np.broadcast_to(o, gps.measurement.shape)
        e, _, _ = anchored_gps_error(B[fix_sub], local_of_fix, levers, gps.measurement)
        s = np.einsum("ei,eij,ej->e", e, np.linalg.inv(cov), e)
        new = gps_weights(cfg.weighting, s)
        moved = float(np.max(np.abs(new - weights)))
        weights = new
        if moved <= cfg.weighting.tolerance:
            settled = True
            break

    poses, ids, landmarks = _place(locals_, B, n)
    top_seconds = time.perf_counter() - t1

    # The flat fused graph's χ² at the placed solution and final weights (not timed).
    g = built.graph
    edges = [reweight(e, e.information, weights) if e.kind == "gps" else e for e in g.edges]
    lm_all = np.array(g.landmarks, copy=True)
    lever_row = g.landmark_ids == built.lever_id
    lm_all[lever_row] = o
    rows = np.searchsorted(ids, g.landmark_ids[~lever_row])
    lm_all[~lever_row] = landmarks[rows]
    chi2 = g2o_chi2(replace(g, edges=tuple(edges)), poses, lm_all)

    converged = all(loc.converged for loc in locals_) and top_converged and settled
    solution = GraphSolution(
        times=built.times,
        poses=poses,
        landmark_ids=ids,
        landmarks=landmarks,
        lever_arm=o,
        weights=weights,
        rounds=rounds,
        iterations=iterations + sum(loc.iterations for loc in locals_),
        chi2=chi2,
        converged=converged,
        seconds=local_seconds + top_seconds,
    )
    largest = max(3 * loc.nodes.shape[0] + 2 * loc.landmark_ids.shape[0] for loc in locals_)
    flat = 3 * n + 2 * int(g.landmark_ids.shape[0])
    return HierarchicalResult(solution, K, largest, 3 * K + 5, flat, local_seconds, top_seconds)


def _place(locals_: list[_Local], B: FloatArray, n: int) -> tuple[FloatArray, IntArray, FloatArray]:
    """Every node at ``B_k ∘ Y`` (a shared node from the submap it is the base of), every
    landmark the reading-weighted mean of its placements (module docstring, step 3)."""
    poses = np.empty((n, 3))
    all_ids, all_xy, all_w = [], [], []
    for k, loc in enumerate(locals_):  # in order: a base overwrites the previous end
        poses[loc.nodes] = pose2.compose(B[k], loc.poses)
        all_ids.append(loc.landmark_ids)
        all_xy.append(pose2.transform_points(B[k], loc.landmarks))
        all_w.append(loc.counts)
    poses[n - 1] = B[-1]  # the final node is a top node of its own
    ids_cat = np.concatenate(all_ids).astype(np.int64)
    ids, inv = np.unique(ids_cat, return_inverse=True)
    w = np.concatenate(all_w)
    xy = np.concatenate(all_xy).reshape(-1, 2)
    total = np.bincount(inv, weights=w, minlength=ids.shape[0])
    landmarks = np.stack(
        [np.bincount(inv, weights=w * xy[:, a], minlength=ids.shape[0]) / total for a in (0, 1)],
        axis=1,
    )
    return poses, ids, landmarks
