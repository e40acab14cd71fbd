"""Residuals and analytic Jacobians of every 2D edge kind, one whole edge set per call.

Each kernel takes the current values of the variables an edge set touches (already gathered
per edge, so row ``k`` of every argument belongs to edge ``k``) and its measurements, and
returns the *unwhitened* error ``e (E, m)`` and the Jacobians ``∂e/∂δ`` with respect to the
tangent perturbations of its variables. No Python loop runs per edge.

Perturbations (the retraction used by the solvers, :func:`retract_poses`):

* an SE(2) pose ``X`` moves on the right by the group exponential, ``X ⊕ δ = X · Exp(δ)``:
  ``θ ← θ + δθ`` and ``t ← t + R V(δθ) (δx, δy)`` with ``V`` the arc matrix of
  :meth:`slamkit.geometry.se2.SE2.exp`. Its differential at ``δ = 0`` is the identity, so the
  Jacobians below are those of any first-order retraction (g2o's ``oplus``, which adds
  ``R (δx, δy)`` without ``V``, included); the exponential matters for long steps: a rigid
  motion of a weakly tied part of the graph is one tangent step for which every edge inside
  the part keeps its error exactly, so Gauss-Newton steps along such soft modes are not
  spoilt by the second-order stretching that a straight-line translation update causes;
* a 2D landmark ``l`` moves additively, ``l ← l + δ``.

Notation below: ``R(θ)`` the 2x2 rotation, ``S = R(π/2) = [[0, -1], [1, 0]]`` (so
``∂R(θ)/∂θ = R(θ) S`` and ``S`` commutes with every 2D rotation), ``X_i = (R_i, t_i)``,
measurement ``Z = (R_z, t_z)``.
"""

from __future__ import annotations

import numpy as np

from slamkit.geometry import pose2
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.se2 import SE2
from slamkit.optim.data import FloatArray

__all__ = [
    "bearing_error",
    "range_bearing_error",
    "range_error",
    "retract_poses",
    "se2_between_error",
    "se2_chordal_residual",
    "se2_prior_error",
    "se2_xy_error",
]


def _bf(a: FloatArray) -> FloatArray:
    """Batch-first view of an array built edge-last (``(m, E)`` → ``(E, m)``, ``(m, d, E)`` →
    ``(E, m, d)``). The kernels fill contiguous per-entry rows of length ``E`` (fast), and
    :meth:`GraphProblem.linearize` moves the axis back without copying."""
    return a.transpose(a.ndim - 1, *range(a.ndim - 1))  # np.moveaxis(a, -1, 0), cheaper


def retract_poses(poses: FloatArray, delta: FloatArray) -> FloatArray:
    """``X ⊕ δ = X · Exp(δ)`` for ``(N, 3)`` poses and tangent steps ``(δx, δy, δθ)`` (right
    update by the SE(2) exponential; θ wrapped)."""
    return pose2.compose(poses, SE2.exp(delta).xy_theta())


def se2_between_error(
    xi: FloatArray, xj: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """g2o's relative-pose error ``e = (x, y, θ)`` of ``Z⁻¹ · X_i⁻¹ · X_j`` (θ wrapped).

    With ``d = R_iᵀ (t_j - t_i)`` (``t_j`` seen from pose ``i``)::

        e_t = R_zᵀ (d - t_z)                 e_θ = wrap(θ_j - θ_i - θ_z)
        ∂e/∂δ_i = [[-R_zᵀ, -R_zᵀ S d],       ∂e/∂δ_j = [[R(e_θ'), 0],
                   [ 0,     -1     ]]                    [0,      1]]

    where ``R(e_θ') = R_zᵀ R_iᵀ R_j`` (angle ``θ_j - θ_i - θ_z``, unwrapped is fine).
    Moving ``X_i`` by ``δ_i`` gives ``R_iᵀ → R(-δθ) R_iᵀ`` and ``t_i → t_i + R_i δt``, so
    ``d → (I - δθ S)(d - δt)`` to first order; moving ``X_j`` gives ``d → d + R_iᵀ R_j δt``.
    """
    ci, si = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    cz, sz = np.cos(z[:, 2]), np.sin(z[:, 2])
    dx0, dy0 = xj[:, 0] - xi[:, 0], xj[:, 1] - xi[:, 1]
    dx = ci * dx0 + si * dy0  # d = R_iᵀ (t_j - t_i)
    dy = -si * dx0 + ci * dy0
    ux, uy = dx - z[:, 0], dy - z[:, 1]
    phi = xj[:, 2] - xi[:, 2] - z[:, 2]
    n = xi.shape[0]
    e = np.empty((3, n))
    e[0] = cz * ux + sz * uy  # R_zᵀ (d - t_z)
    e[1] = -sz * ux + cz * uy
    e[2] = wrap_angle(phi)
    Ji = np.zeros((3, 3, n))
    Ji[0, 0] = -cz
    Ji[0, 1] = -sz
    Ji[1, 0] = sz
    Ji[1, 1] = -cz
    Ji[0, 2] = cz * dy - sz * dx  # -R_zᵀ S d with S d = (-d_y, d_x)
    Ji[1, 2] = -sz * dy - cz * dx
    Ji[2, 2] = -1.0
    cp, sp = np.cos(phi), np.sin(phi)
    Jj = np.zeros((3, 3, n))
    Jj[0, 0] = cp
    Jj[0, 1] = -sp
    Jj[1, 0] = sp
    Jj[1, 1] = cp
    Jj[2, 2] = 1.0
    return _bf(e), _bf(Ji), _bf(Jj)


def se2_prior_error(xi: FloatArray, z: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Absolute pose prior: ``e = (x, y, θ)`` of ``Z⁻¹ · X_i`` (θ wrapped), as g2o.

    ``e_t = R_zᵀ (t_i - t_z)``, ``e_θ = wrap(θ_i - θ_z)``;
    ``∂e/∂δ_i = [[R_zᵀ R_i, 0], [0, 1]]`` (``R_zᵀ R_i = R(θ_i - θ_z)``).
    """
    cz, sz = np.cos(z[:, 2]), np.sin(z[:, 2])
    ux, uy = xi[:, 0] - z[:, 0], xi[:, 1] - z[:, 1]
    phi = xi[:, 2] - z[:, 2]
    n = xi.shape[0]
    e = np.empty((3, n))
    e[0] = cz * ux + sz * uy
    e[1] = -sz * ux + cz * uy
    e[2] = wrap_angle(phi)
    cp, sp = np.cos(phi), np.sin(phi)
    J = np.zeros((3, 3, n))
    J[0, 0] = cp
    J[0, 1] = -sp
    J[1, 0] = sp
    J[1, 1] = cp
    J[2, 2] = 1.0
    return _bf(e), _bf(J)


def _landmark_in_robot(xi: FloatArray, lm: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``q = R_iᵀ (l - t_i)`` and ``cos θ_i``, ``sin θ_i``."""
    c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    dx, dy = lm[:, 0] - xi[:, 0], lm[:, 1] - xi[:, 1]
    q = np.empty((xi.shape[0], 2))
    q[:, 0] = c * dx + s * dy
    q[:, 1] = -s * dx + c * dy
    return q, c, s


def se2_xy_error(
    xi: FloatArray, lm: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Landmark position in the robot frame: ``e = R_iᵀ (l - t_i) - z``.

    With ``q = R_iᵀ (l - t_i)``: ``∂e/∂δ_i = [-I, -S q]`` (moving the pose by ``δt`` in its
    own frame shifts ``q`` by ``-δt``; turning it by ``δθ`` gives ``q → (I - δθ S) q``) and
    ``∂e/∂l = R_iᵀ``.
    """
    q, c, s = _landmark_in_robot(xi, lm)
    n = xi.shape[0]
    e = (q - z).T
    Ji = np.zeros((2, 3, n))
    Ji[0, 0] = -1.0
    Ji[1, 1] = -1.0
    Ji[0, 2] = q[:, 1]  # -S q = (q_y, -q_x)
    Ji[1, 2] = -q[:, 0]
    Jl = np.empty((2, 2, n))
    Jl[0, 0] = c
    Jl[0, 1] = s
    Jl[1, 0] = -s
    Jl[1, 1] = c
    return _bf(e), _bf(Ji), _bf(Jl)


def range_error(
    xi: FloatArray, lm: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Range to a landmark: ``e = ‖l - t_i‖ - z``.

    With the unit vector ``u = (l - t_i) / ‖l - t_i‖`` (world frame):
    ``∂e/∂δ_i = [-uᵀ R_i, 0]``, ``∂e/∂l = uᵀ``.
    """
    dx, dy = lm[:, 0] - xi[:, 0], lm[:, 1] - xi[:, 1]
    r = np.hypot(dx, dy)
    safe = np.where(r > 0.0, r, 1.0)
    ux, uy = dx / safe, dy / safe
    c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    n = xi.shape[0]
    e = (r - z[:, 0])[None, :]
    Ji = np.zeros((1, 3, n))
    Ji[0, 0] = -(ux * c + uy * s)  # -uᵀ R_i
    Ji[0, 1] = -(-ux * s + uy * c)
    Jl = np.empty((1, 2, n))
    Jl[0, 0] = ux
    Jl[0, 1] = uy
    return _bf(e), _bf(Ji), _bf(Jl)


def _bearing_rows(q: FloatArray, c: FloatArray, s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rows of ``∂b/∂δ_i`` and ``∂b/∂l`` for ``b = atan2(q_y, q_x)``.

    ``∂b/∂q = (-q_y, q_x) / ‖q‖²``; ``∂q/∂δ_i = [-I, -S q]`` gives ``∂b/∂δθ = -1``;
    ``∂q/∂l = R_iᵀ``.
    """
    r2 = q[:, 0] ** 2 + q[:, 1] ** 2
    r2 = np.where(r2 > 0.0, r2, 1.0)
    gx, gy = -q[:, 1] / r2, q[:, 0] / r2
    n = q.shape[0]
    Ji = np.empty((3, n))
    Ji[0] = -gx
    Ji[1] = -gy
    Ji[2] = -1.0
    Jl = np.empty((2, n))
    Jl[0] = gx * c - gy * s  # (gx, gy) R_iᵀ
    Jl[1] = gx * s + gy * c
    return Ji, Jl


def bearing_error(
    xi: FloatArray, lm: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Bearing of a landmark: ``e = wrap(atan2(q_y, q_x) - z)`` with ``q = R_iᵀ (l - t_i)``
    (slamkit's bearing = ``atan2(dy, dx) - θ``)."""
    q, c, s = _landmark_in_robot(xi, lm)
    e = wrap_angle(np.arctan2(q[:, 1], q[:, 0]) - z[:, 0])[None, :]
    Ji, Jl = _bearing_rows(q, c, s)
    return _bf(e), _bf(Ji[None]), _bf(Jl[None])


def range_bearing_error(
    xi: FloatArray, lm: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(range, bearing)`` of a landmark: ``e = (‖q‖ - z_r, wrap(atan2(q_y, q_x) - z_b))``.

    The range row is ``∂‖q‖/∂q = qᵀ/‖q‖`` times ``∂q/∂δ_i = [-I, -S q]`` (its θ entry is
    ``qᵀ S q / ‖q‖ = 0``) and ``∂q/∂l = R_iᵀ``; the bearing row is :func:`bearing_error`'s.
    """
    q, c, s = _landmark_in_robot(xi, lm)
    n = xi.shape[0]
    r = np.hypot(q[:, 0], q[:, 1])
    safe = np.where(r > 0.0, r, 1.0)
    vx, vy = q[:, 0] / safe, q[:, 1] / safe
    e = np.empty((2, n))
    e[0] = r - z[:, 0]
    e[1] = wrap_angle(np.arctan2(q[:, 1], q[:, 0]) - z[:, 1])
    Ji = np.zeros((2, 3, n))
    Jl = np.empty((2, 2, n))
    Ji[0, 0] = -vx
    Ji[0, 1] = -vy
    Jl[0, 0] = vx * c - vy * s
    Jl[0, 1] = vx * s + vy * c
    Ji[1], Jl[1] = _bearing_rows(q, c, s)
    return _bf(e), _bf(Ji), _bf(Jl)


def se2_chordal_residual(
    xi: FloatArray, xj: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The *unweighted* residual of SE-Sync's objective for one relative-pose edge, (E, 4).

    ``κ ‖R_j - R_i R̃‖²_F + τ ‖t_j - t_i - R_i t̃‖²`` equals ``‖r‖²`` for
    ``r = (√(2κ) (R_j e₁ - R_i R̃ e₁), √τ (t_j - t_i - R_i t̃))``, because a 2D rotation's
    second column is ``S`` times its first, so ``‖A - B‖²_F = 2 ‖(A - B) e₁‖²``. This
    function returns the four rows before the ``√(2κ)``, ``√τ`` weights::

        r_R = (cos θ_j - cos(θ_i + θ̃), sin θ_j - sin(θ_i + θ̃))
        r_t = t_j - t_i - R_i t̃
        ∂r_R/∂δθ_i = -S R_i R̃ e₁ = (sin(θ_i + θ̃), -cos(θ_i + θ̃)),  ∂r_R/∂δθ_j = S R_j e₁
        ∂r_t/∂δt_i = -R_i,  ∂r_t/∂δθ_i = -R_i S t̃,  ∂r_t/∂δt_j = R_j
    """
    ci, si = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    cj, sj = np.cos(xj[:, 2]), np.sin(xj[:, 2])
    a = xi[:, 2] + z[:, 2]
    ca, sa = np.cos(a), np.sin(a)
    n = xi.shape[0]
    r = np.empty((4, n))
    r[0] = cj - ca
    r[1] = sj - sa
    rtx = ci * z[:, 0] - si * z[:, 1]  # R_i t̃
    rty = si * z[:, 0] + ci * z[:, 1]
    r[2] = xj[:, 0] - xi[:, 0] - rtx
    r[3] = xj[:, 1] - xi[:, 1] - rty
    Ji = np.zeros((4, 3, n))
    Jj = np.zeros((4, 3, n))
    Ji[0, 2] = sa
    Ji[1, 2] = -ca
    Jj[0, 2] = -sj
    Jj[1, 2] = cj
    Ji[2, 0] = -ci
    Ji[2, 1] = si
    Ji[3, 0] = -si
    Ji[3, 1] = -ci
    Ji[2, 2] = rty  # -R_i S t̃ = -S R_i t̃ = (R_i t̃)_y, -(R_i t̃)_x
    Ji[3, 2] = -rtx
    Jj[2, 0] = cj
    Jj[2, 1] = -sj
    Jj[3, 0] = sj
    Jj[3, 1] = cj
    return _bf(r), _bf(Ji), _bf(Jj)
