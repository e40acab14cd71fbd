"""Marginal covariances of chosen variables at a solution, from the sparse factorisation.

At the optimum the Laplace approximation of the posterior is Gaussian with information
``H = Jᵀ W J`` (the Gauss-Newton matrix, whitened and IRLS-weighted, gauge fixed as in the
solve), because the cost is ``Σ ‖U e‖² = -2 log p + const``. The marginal covariance of a
variable ``v`` is the diagonal block ``(H⁻¹)_vv``. It is read off ``H⁻¹ E_v`` where ``E_v``
holds the identity columns of ``v``: one solve with the (once factored) sparse Cholesky per
column, in chunks, never a dense inverse of ``H``. Poses held fixed by the gauge have zero
covariance (the marginals are relative to them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from slamkit.errors import GeometryError, InputError
from slamkit.optim.data import FloatArray, GraphData, IntArray
from slamkit.optim.graph import GraphProblem, lookup_rows
from slamkit.optim.loop import indeterminate_error
from slamkit.optim.settings import OptimizerConfig
from slamkit.optim.solvers import OptimizeResult
from slamkit.optim.sparse import SingularSystem, make_factorizer

__all__ = ["Marginals", "marginal_covariances"]

_CHUNK = 96  # right-hand sides per solve: bounds the dense (n, chunk) work array


@dataclass(frozen=True)
class Marginals:
    """``pose_covariances[k]`` (3x3, order x, y, θ in the pose's tangent; 3D: 6x6, order
    ``δv, δω`` of the right perturbation) of ``pose_ids[k]``;
    ``landmark_covariances[k]`` (2x2) of ``landmark_ids[k]``."""

    pose_ids: IntArray
    pose_covariances: FloatArray
    landmark_ids: IntArray
    landmark_covariances: FloatArray


def marginal_covariances(
    data: GraphData,
    result: OptimizeResult,
    pose_ids: ArrayLike = (),
    landmark_ids: ArrayLike = (),
    *,
    config: OptimizerConfig | None = None,
) -> Marginals:
    """Marginal covariances of ``pose_ids`` and ``landmark_ids`` at ``result``.

    ``config`` should be the one used for the solve (objective, gauge, robust kernel, linear
    solver); by default the result's objective with default settings.
    """
    cfg = config if config is not None else OptimizerConfig(objective=result.objective)
    problem = GraphProblem.from_data(data, objective=cfg.objective, gauge=cfg.gauge)
    kernel = cfg.kernel
    lin = problem.linearize(problem.to_internal(result.poses), result.landmarks, kernel)
    assert lin.H is not None
    fac = make_factorizer(cfg.linear_solver, problem.pattern)
    try:
        fac.factor(lin.H)
    except SingularSystem as exc:
        raise GeometryError(f"marginals: {indeterminate_error(problem, exc, lin.H)}") from None

    p_ids = np.asarray(pose_ids, dtype=np.int64).reshape(-1)
    l_ids = np.asarray(landmark_ids, dtype=np.int64).reshape(-1)
    p_rows, found = lookup_rows(problem.pose_ids, p_ids)
    if not found.all():
        raise InputError(f"marginals: pose {int(p_ids[~found][0])} is not in the graph")
    l_rows, found = lookup_rows(problem.landmark_ids, l_ids)
    if not found.all():
        raise InputError(f"marginals: landmark {int(l_ids[~found][0])} is not in the graph")
    # (first column, size) of every requested variable; -1 for a fixed pose.
    dof = problem.pose_dof
    p_var = problem.pose_var[problem.alias[p_rows]]
    starts = np.concatenate(
        [
            np.where(p_var >= 0, dof * p_var, -1),
            dof * problem.n_free_poses + 2 * l_rows,
        ]
    ).astype(np.int64)
    sizes = np.concatenate([np.full(p_ids.shape[0], dof), np.full(l_ids.shape[0], 2)])
    blocks: list[FloatArray] = []
    for lo in range(0, starts.shape[0], _CHUNK):
        st, sz = starts[lo : lo + _CHUNK], sizes[lo : lo + _CHUNK]
        live = st >= 0
        cols = np.concatenate([s + np.arange(z) for s, z in zip(st[live], sz[live], strict=True)])
        X = np.zeros((0, 0))
        if cols.shape[0]:
            E = np.zeros((problem.n, cols.shape[0]))
            E[cols, np.arange(cols.shape[0])] = 1.0
            X = fac.solve(E)  # H⁻¹ E: the columns of H⁻¹ of the requested variables
        k = 0
        for s, z, ok in zip(st, sz, live, strict=True):
            if not ok:
                blocks.append(np.zeros((z, z)))
                continue
            C = X[s : s + z, k : k + z]
            blocks.append(0.5 * (C + C.T))
            k += z
    n_p = p_ids.shape[0]
    pose_cov = np.array(blocks[:n_p]).reshape(n_p, dof, dof)
    lm_cov = np.array(blocks[n_p:]).reshape(l_ids.shape[0], 2, 2)
    return Marginals(p_ids, pose_cov, l_ids, lm_cov)
