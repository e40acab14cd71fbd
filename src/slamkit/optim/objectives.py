"""Objective values of a solution, computed by one piece of code for every solver.

* :func:`g2o_chi2`: ``χ² = Σ_k e_kᵀ Ω_k e_k`` over every edge, with g2o's errors (for SE(2):
  ``(x, y, θ)`` of ``Z⁻¹ X_i⁻¹ X_j``, θ wrapped). GTSAM's ``graph.error`` is ``½ χ²`` for the
  same graph (with its own, log-map, SE(2) error, equal to first order).
* :func:`sesync_objective`: SE-Sync's ``F = Σ κ ‖R_j - R_i R̃_ij‖²_F + τ ‖t_j - t_i - R_i
  t̃_ij‖²`` over the relative-pose edges, with (2D) ``κ = Ω_θθ`` and ``τ = 2 / tr(Ω_tt⁻¹)``
  (Rosen et al., IJRR 2019; Cartan-Sync reports ``F / 2``); in 3D ``κ = 3 / (2 tr(Ω_RR⁻¹))``
  and ``τ = 3 / tr(Ω_tt⁻¹)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import as_array
from slamkit.errors import InputError
from slamkit.optim.data import GraphData
from slamkit.optim.graph import GraphProblem

__all__ = ["g2o_chi2", "sesync_objective"]


def _values(
    problem: GraphProblem, poses: ArrayLike, landmarks: ArrayLike | None
) -> tuple[np.ndarray, np.ndarray]:
    width = 3 if problem.dim == 2 else 7
    p = problem.to_internal(as_array(poses, "poses", (problem.pose_ids.shape[0], width)))
    n_l = problem.landmark_ids.shape[0]
    if landmarks is None:
        lm = problem.data.landmarks if problem.data.landmarks.shape[0] == n_l else None
        if lm is None:
            if n_l:
                raise InputError("landmarks: the graph has landmarks but none were given")
            lm = np.zeros((0, 2))
    else:
        lm = as_array(landmarks, "landmarks", (n_l, 2))
    return p, lm


def g2o_chi2(data: GraphData, poses: ArrayLike, landmarks: ArrayLike | None = None) -> float:
    """``Σ eᵀ Ω e`` of every edge of ``data`` at ``poses`` (rows in the order of the problem's
    ``pose_ids``: the file's vertex order, or sorted ids when it has no vertices) and
    ``landmarks`` (default: the file's)."""
    problem = GraphProblem.from_data(data, objective="g2o")
    p, lm = _values(problem, poses, landmarks)
    return float(sum(float(s.sum()) for s in problem.block_terms(p, lm)))


def sesync_objective(data: GraphData, poses: ArrayLike) -> float:
    """SE-Sync's ``F`` over the relative-pose (``se2``/``se3``) edges of ``data`` at ``poses``
    (3D: ``(N, 7)`` rows ``(x, y, z, qw, qx, qy, qz)``)."""
    problem = GraphProblem.from_data(data, objective="sesync")
    width = 3 if problem.dim == 2 else 7
    p = problem.to_internal(as_array(poses, "poses", (problem.pose_ids.shape[0], width)))
    no_landmarks = np.zeros((problem.landmark_ids.shape[0], 2))  # pose edges do not read them
    kind = "se2" if problem.dim == 2 else "se3"
    return float(sum(float(s.sum()) for s in problem.block_terms(p, no_landmarks, kind=kind)))
