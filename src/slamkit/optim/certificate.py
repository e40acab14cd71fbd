"""A certificate of global optimality for pose graphs under SE-Sync's objective (2D and 3D).

The problem (Rosen et al., "SE-Sync", IJRR 2019) is ``min F`` over ``R_i ∈ SO(d)``,
``t_i ∈ R^d`` with ``F = Σ_e κ_e ‖R_j - R_i R̃_e‖²_F + τ_e ‖t_j - t_i - R_i t̃_e‖²``
(``κ``, ``τ`` from each edge's information: :func:`~slamkit.optim.graph.sesync_row_weights`,
:func:`~slamkit.optim.factors3d.sesync_row_weights_3d`). Below ``d = 2`` or ``3``.

**Data matrix.** Stack ``X = [T R]`` with ``T = [t_1 … t_n]`` (d x n) and ``R = [R_1 … R_n]``
(d x dn). Each term is a squared norm of ``X`` times a vector or matrix: ``R_j - R_i R̃ = R A_e``
with ``A_e`` the dn x d column of blocks ``I`` at ``j`` and ``-R̃`` at ``i``;
``t_j - t_i - R_i t̃ = X b_e`` with ``b_e = [e_j - e_i; -(e_i ⊗ t̃)]``. So ``F = tr(X M Xᵀ)``,

    M = Σ τ b bᵀ + Σ κ [0 0; 0 A Aᵀ] = [[L_τ, V], [Vᵀ, B]],   B = L_κ + Σ̃,

with ``L_τ`` the graph Laplacian of the ``τ``, ``L_κ = Σ κ A Aᵀ`` the connection Laplacian
(blocks ``κI`` on the diagonal, ``-κR̃`` at ``(i, j)``), ``Σ̃`` block diagonal
``Σ τ t̃ t̃ᵀ`` at ``i`` and ``V`` (n x dn) ``+τ t̃ᵀ`` at ``(i, i)``, ``-τ t̃ᵀ`` at ``(j, i)``.
``F`` does not change when every ``t`` moves by the same vector, so ``t_1 = 0`` loses nothing;
minimising the remaining quadratic over ``T`` (``L_r``, ``V_r``: ``L_τ``, ``V`` without pose 1's
row, ``L_r ≻ 0`` on a connected graph) leaves ``F(R) = tr(R Q Rᵀ)`` with the Schur complement
``Q = B - V_rᵀ L_r⁻¹ V_r`` (dense: only ever applied through a Cholesky factor of ``L_r``).

**Certificate.** Let ``Λ = SymBlockDiag(Q Rᵀ R)`` (d x d blocks ``sym(G_i R_i)``, ``G_i`` the
rows of ``Q Rᵀ`` at pose ``i``: the Lagrange multipliers of ``R_iᵀ R_i = I``) and
``S = Q - Λ``; note ``tr Λ = tr(R Q Rᵀ) = F(R)``. For any rotations ``R'``, ``Z = R'ᵀR' ⪰ 0``
has identity diagonal blocks and ``tr Z = dn``, so

    F(R') = tr(Q Z) = tr(S Z) + tr(Λ Z) ≥ λ_min(S) · dn + tr Λ = F(R) + dn λ_min(S).

Hence ``F* ≥ F(R) + dn min(λ_min(S), 0)`` for *any* ``R``, and ``S ⪰ 0`` proves ``R`` globally
optimal (``Z`` may even come from ``O(d)``: the bound is the SDP relaxation's). (At a critical
point ``S Rᵀ = 0``, so ``λ_min ≤ 0`` and the test is ``λ_min = 0``
to within rounding.)

**Tests without forming Q.** With ``L_r ≻ 0``, ``S - σI ≻ 0`` iff the sparse matrix
``K(σ) = [[L_r, V_r], [V_rᵀ, B - Λ - σI]] ≻ 0`` (its Schur complement is ``S - σI``), which a
sparse Cholesky decides. The same factor gives ``(S - σI)⁻¹ x`` (solve with ``[0; x]``, keep
the lower part), so ARPACK in shift-invert mode from a ``σ`` below the spectrum returns
``λ_min`` directly. Below every eigenvalue lies ``σ_0 = -max_i ‖Λ_i‖₂`` (``Q ⪰ 0``).

**Tolerance.** Certified iff ``K(-tol)`` factors, i.e. ``λ_min(S) > -tol`` with
``tol = CERTIFY_RTOL · ‖Q‖₂``: an eigenvalue of a matrix known to relative accuracy ``ε`` is
known to ``ε ‖Q‖``, and the solution itself (an optimiser's stopping point, not an exact
critical point) moves ``λ_min`` by about ``‖Q‖`` times its rotation error; the measured values
behind ``1e-6`` are in docs/estimators/optim.md. The reported bound uses a lower bound on
``λ_min`` that a Cholesky verified, never the Ritz value alone.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from numpy.typing import ArrayLike

from slamkit._validation import as_array
from slamkit.errors import ConvergenceError, InputError
from slamkit.optim import factors3d
from slamkit.optim.data import EdgeKind, FloatArray, GraphData
from slamkit.optim.graph import GraphProblem, lookup_rows, sesync_row_weights
from slamkit.optim.sparse import Factorizer, LinearSolverName, SingularSystem, factor_spd

__all__ = [
    "CERTIFY_RTOL",
    "Certificate",
    "LiftedCertificate",
    "SchurQ",
    "SesyncMatrices",
    "certify",
    "certify_blocks",
    "check_certifiable",
    "multipliers",
    "rotation_blocks",
    "sesync_matrices",
]

CERTIFY_RTOL = 1e-6
"""``tol = CERTIFY_RTOL · ‖Q‖₂``: certified iff ``λ_min(S) > -tol`` (module docstring)."""


@dataclass(frozen=True)
class Certificate:
    """The outcome of :func:`certify` (all values in units of ``F``)."""

    certified: bool
    """``S + tol·I`` factored by Cholesky: ``λ_min(S) > -tol``."""
    lambda_min: float
    """ARPACK's estimate of ``λ_min(S)`` (shift-invert, converged to 1e-10 relative)."""
    lambda_lower: float
    """A lower bound on ``λ_min(S)``: a shift at which ``K`` factored (at worst the shift the
    eigenvalue search started from, which factored too)."""
    tolerance: float
    """``tol = CERTIFY_RTOL · q_norm``."""
    q_norm: float
    """``‖Q‖₂ = λ_max(Q)`` (Lanczos, 1e-3 relative)."""
    objective: float
    """``F(R) = tr(R Q Rᵀ)``: SE-Sync's ``F`` with the translations optimal for ``R``."""
    lower_bound: float
    """``F(R) + dn · min(lambda_lower, 0)``: no solution has a smaller ``F``."""
    poses: int
    seconds: float

    @property
    def gap(self) -> float:
        """``objective - lower_bound``: at most this far from the global optimum."""
        return self.objective - self.lower_bound

    def as_dict(self) -> dict[str, float | bool | int]:
        """The fields and ``gap``, for ``metrics.json``."""
        return {
            "certified": self.certified,
            "lambda_min": self.lambda_min,
            "lambda_lower": self.lambda_lower,
            "tolerance": self.tolerance,
            "q_norm": self.q_norm,
            "objective": self.objective,
            "lower_bound": self.lower_bound,
            "gap": self.gap,
            "poses": self.poses,
            "seconds": self.seconds,
        }


@dataclass(frozen=True)
class SesyncMatrices:
    """The sparse pieces of ``M`` (module docstring), pose rows in the problem's order.

    ``laplacian`` is ``L_r`` ((n-1) x (n-1), pose 0's row and column removed), ``coupling`` is
    ``V_r`` ((n-1) x dn) and ``rotation`` is ``B = L_κ + Σ̃`` (dn x dn, pose ``i`` at columns
    ``di … di + d - 1``).
    """

    dim: int
    laplacian: scipy.sparse.csc_matrix
    coupling: scipy.sparse.csc_matrix
    rotation: scipy.sparse.csc_matrix

    @property
    def n(self) -> int:
        return int(self.rotation.shape[0] // self.dim)


def check_certifiable(data: GraphData) -> None:
    """``InputError`` unless ``data`` is a graph of relative-pose edges only: the
    certificate is for SE-Sync's problem, which has neither priors, landmarks nor merged
    poses."""
    kind = "se2" if data.dim == 2 else "se3"
    other = sorted({e.kind for e in data.edges if e.kind != kind and len(e)})
    if other:
        raise InputError(
            f"certificate: SE-Sync's problem has relative-pose ({kind}) edges only; this graph "
            f"also has {', '.join(other)} edges"
        )
    if data.equivalences.shape[0]:
        raise InputError("certificate: graphs with merged (EQUIV) poses are not supported")


def sesync_matrices(data: GraphData, pose_ids: ArrayLike) -> SesyncMatrices:
    """``L_r``, ``V_r`` and ``B`` of the relative-pose edges of ``data``, poses in the order
    ``pose_ids``."""
    ids = np.asarray(pose_ids, dtype=np.int64)
    n, d = ids.shape[0], int(data.dim)
    kind: EdgeKind = "se2" if d == 2 else "se3"
    es = data.edges_of(kind)
    if es is None or len(es) == 0 or n < 2:
        raise InputError(f"certificate: the graph needs at least two poses and one {kind} edge")
    a, found_a = lookup_rows(ids, es.i)
    b, found_b = lookup_rows(ids, es.j)
    if not (found_a.all() and found_b.all()):
        raise InputError(f"certificate: an {kind} edge names a pose not in pose_ids")
    if d == 2:
        w = sesync_row_weights(es.information)
        kappa, tau = 0.5 * w[:, 0] ** 2, w[:, 2] ** 2
    else:
        w = factors3d.sesync_row_weights_3d(es.information)
        kappa, tau = w[:, 0] ** 2, w[:, 9] ** 2
    rt = rotation_blocks(es.measurement, d)  # (E, d, d) R̃
    tt = es.measurement[:, :d]  # (E, d) t̃
    r2 = np.arange(d)

    # B: κI at (i, i) and (j, j), -κR̃ at (i, j), -κR̃ᵀ at (j, i), τ t̃ t̃ᵀ at (i, i).
    ri = d * a[:, None, None] + r2[None, :, None]  # (E, d, 1) rows of block i
    ci = d * a[:, None, None] + r2[None, None, :]  # (E, 1, d) columns of block i
    rj, cj = d * b[:, None, None] + r2[None, :, None], d * b[:, None, None] + r2[None, None, :]
    eye = np.broadcast_to(np.eye(d), rt.shape)
    k3 = kappa[:, None, None]
    blocks = [
        (ri, ci, k3 * eye + tau[:, None, None] * tt[:, :, None] * tt[:, None, :]),
        (rj, cj, k3 * eye),
        (ri, cj, -k3 * rt),
        (rj, ci, -k3 * np.swapaxes(rt, 1, 2)),
    ]
    rows = np.concatenate([np.broadcast_to(r, v.shape).ravel() for r, _, v in blocks])
    cols = np.concatenate([np.broadcast_to(q, v.shape).ravel() for _, q, v in blocks])
    vals = np.concatenate([v.ravel() for _, _, v in blocks])
    rotation = scipy.sparse.csc_matrix((vals, (rows, cols)), shape=(d * n, d * n))

    # V: +τ t̃ᵀ at (i, block i), -τ t̃ᵀ at (j, block i); then pose 0's row dropped.
    vcols = (d * a[:, None] + r2[None, :]).ravel()
    tv = (tau[:, None] * tt).ravel()
    coupling = scipy.sparse.csc_matrix(
        (
            np.concatenate([tv, -tv]),
            (np.concatenate([np.repeat(a, d), np.repeat(b, d)]), np.concatenate([vcols, vcols])),
        ),
        shape=(n, d * n),
    )[1:, :]
    lap = scipy.sparse.csc_matrix(
        (
            np.concatenate([tau, tau, -tau, -tau]),
            (np.concatenate([a, b, a, b]), np.concatenate([a, b, b, a])),
        ),
        shape=(n, n),
    )[1:, 1:]
    return SesyncMatrices(d, lap.tocsc(), coupling.tocsc(), rotation)


def rotation_blocks(poses: FloatArray, d: int) -> FloatArray:
    """``(N, d, d)`` rotation matrices of file-format poses or measurements (2D ``(x, y, θ)``,
    3D ``(x, y, z, qw, qx, qy, qz)``)."""
    if d == 3:
        return factors3d.poses_to_internal(poses)[:, 3:].reshape(-1, 3, 3)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _block_diag(blocks: FloatArray) -> scipy.sparse.csc_matrix:
    """The dn x dn block-diagonal matrix of ``(n, d, d)`` blocks."""
    n, d = blocks.shape[0], blocks.shape[1]
    r = d * np.arange(n)[:, None, None] + np.arange(d)[None, :, None]
    c = d * np.arange(n)[:, None, None] + np.arange(d)[None, None, :]
    r, c = np.broadcast_to(r, blocks.shape).ravel(), np.broadcast_to(c, blocks.shape).ravel()
    return scipy.sparse.csc_matrix((blocks.ravel(), (r, c)), shape=(d * n, d * n))


class SchurQ:
    """``Q x = B x - V_rᵀ L_r⁻¹ V_r x`` without forming ``Q`` (one Cholesky factor of ``L_r``)."""

    def __init__(self, mats: SesyncMatrices, solver: LinearSolverName = "auto"):
        self.mats, self.solver = mats, solver
        try:
            self.lap = factor_spd(mats.laplacian, solver)
        except SingularSystem as exc:
            raise InputError(
                "certificate: the translational Laplacian is singular (a pose without a "
                "translation-carrying edge path to the others)"
            ) from exc

    def __call__(self, x: FloatArray) -> FloatArray:
        """``Q x`` for ``x`` of shape ``(dn,)`` or ``(dn, k)``."""
        m = self.mats
        return np.asarray(m.rotation @ x - m.coupling.T @ self.lap.solve(m.coupling @ x))

    def translations(self, stacked: FloatArray) -> FloatArray:
        """The ``(n, d)`` translations minimising ``F`` for the rotations ``stacked``
        (``R = [R_1 … R_n]``, d x dn), pose 0 at the origin: ``∂F/∂T = 2 T L_r + 2 R V_rᵀ = 0``
        gives ``Tᵀ = -L_r⁻¹ V_r Rᵀ``."""
        t = -self.lap.solve(np.asarray(self.mats.coupling @ stacked.T))
        return np.vstack([np.zeros((1, stacked.shape[0])), t])

    def norm(self) -> float:
        """``‖Q‖₂ = λ_max(Q)`` (Lanczos, 1e-3 relative)."""
        n2 = self.mats.dim * self.mats.n
        op = scipy.sparse.linalg.LinearOperator((n2, n2), matvec=self, dtype=float)
        return float(_eigsh(op, 1, 1e-3)[0][0])


def _eigsh(
    op: scipy.sparse.linalg.LinearOperator, k: int, tol: float
) -> tuple[FloatArray, FloatArray]:
    v0 = 1.0 + 0.5 * np.cos(0.7 * np.arange(op.shape[0]))  # fixed: the same answer every run
    try:
        vals, vecs = scipy.sparse.linalg.eigsh(op, k=k, which="LA", tol=tol, v0=v0)
    except scipy.sparse.linalg.ArpackNoConvergence as exc:
        raise ConvergenceError(f"certificate: the eigenvalue search stopped ({exc})") from exc
    return np.asarray(vals), np.asarray(vecs)


def multipliers(q: SchurQ, blocks: FloatArray) -> FloatArray:
    """``Λ_i = sym((Q Yᵀ)_i Y_i)`` for ``(n, r, d)`` blocks ``Y_i`` (``r = d``: rotations
    ``R_i``): the ``(n, d, d)`` Lagrange multipliers of ``Y_iᵀ Y_i = I``."""
    n, r, d = blocks.shape
    stacked = blocks.transpose(1, 0, 2).reshape(r, n * d)  # Y = [Y_1 … Y_n]
    gy = q(stacked.T).reshape(n, d, r) @ blocks  # (Q Yᵀ)_i Y_i
    return np.asarray(0.5 * (gy + gy.transpose(0, 2, 1)))


class _Certifier:
    """The multipliers and the factorisations of ``K(σ)`` for one ``Y`` (rotations or a
    lifted point, ``(n, r, d)`` blocks)."""

    def __init__(self, q: SchurQ, blocks: FloatArray):
        self.q, self.mats, self.solver = q, q.mats, q.solver
        mats = q.mats
        n, d = mats.n, mats.dim
        self.lam = multipliers(q, blocks)  # (n, d, d)
        self.objective = float(np.trace(self.lam, axis1=1, axis2=2).sum())  # tr Λ = F(Y)
        self.lam_norm = float(np.abs(np.linalg.eigvalsh(self.lam)).max())
        m = mats.laplacian.shape[0]
        self.k0 = scipy.sparse.bmat(
            [
                [mats.laplacian, mats.coupling],
                [mats.coupling.T, mats.rotation - _block_diag(self.lam)],
            ],
            format="csc",
        )
        self.shift = scipy.sparse.diags(np.r_[np.zeros(m), np.ones(d * n)], format="csc")

    def factor(self, sigma: float) -> Factorizer | None:
        """The Cholesky factor of ``K(σ)``, or ``None`` when ``S - σI`` is not ``≻ 0``."""
        try:
            return factor_spd(self.k0 - sigma * self.shift, self.solver)
        except SingularSystem:
            return None

    def smallest(self, sigma: float, fac: Factorizer) -> tuple[float, FloatArray]:
        """``λ_min(S)`` and its unit eigenvector by shift-invert Lanczos from ``σ`` (below
        every eigenvalue)."""
        n2, m = self.mats.dim * self.mats.n, self.mats.laplacian.shape[0]

        def inv(x: FloatArray) -> FloatArray:  # (S - σI)⁻¹ x: K(σ) [y; z] = [0; x]
            return fac.solve(np.r_[np.zeros(m), np.ravel(x)])[m:]

        op = scipy.sparse.linalg.LinearOperator((n2, n2), matvec=inv, dtype=float)
        vals, vecs = _eigsh(op, min(2, n2 - 1), 1e-10)
        k = int(np.argmax(vals))  # eigenvalues of (S - σI)⁻¹ are 1/(λ - σ)
        return float(sigma + 1.0 / vals[k]), vecs[:, k]


@dataclass(frozen=True)
class LiftedCertificate:
    """:func:`certify_blocks`' verdict and the eigenvector of ``λ_min(S)``."""

    certificate: Certificate
    eigenvector: FloatArray
    """Unit ``(dn,)`` eigenvector of ``S`` for ``lambda_min`` (a descent direction of the
    lifted problem when ``lambda_min < 0``: :mod:`slamkit.optim.staircase`)."""


def certify_blocks(
    q: SchurQ,
    blocks: FloatArray,
    *,
    rtol: float = CERTIFY_RTOL,
    q_norm: float | None = None,
) -> LiftedCertificate:
    """The certificate of ``(n, r, d)`` blocks ``Y_i`` (``Y_iᵀ Y_i = I``; ``r = d``: the
    rotations, else a point of the rank-``r`` relaxation, whose ``Z = YᵀY`` the same bound
    covers) and the eigenvector of ``λ_min(S)``; ``q_norm``: ``‖Q‖₂`` if already known."""
    t0 = time.perf_counter()
    if not (np.isfinite(rtol) and rtol > 0):
        raise InputError(f"rtol: expected a positive number, got {rtol!r}")
    cert = _Certifier(q, blocks)
    q_norm = q.norm() if q_norm is None else q_norm
    tol = rtol * q_norm
    fac = cert.factor(-tol)  # the verdict: S + tol·I ≻ 0
    certified, sigma = fac is not None, -tol
    if fac is None:
        sigma = -cert.lam_norm - tol  # below λ_min(S) since Q ⪰ 0: K(σ) ≻ 0
        fac = cert.factor(sigma)
        if fac is None:  # rounding at that floor: step further down, still a valid shift
            sigma = 2.0 * sigma - tol
            fac = cert.factor(sigma)
        if fac is None:
            raise ConvergenceError("certificate: K(σ) does not factor below every eigenvalue of S")
    lam, vec = cert.smallest(sigma, fac)
    # A verified lower bound: the first of λ - δ, δ = tol·10^k, whose K factors.
    lower, delta = sigma, 1e-4 * tol
    while lam - delta > sigma:
        if cert.factor(lam - delta) is not None:
            lower = lam - delta
            break
        delta *= 10.0
    n, d = q.mats.n, q.mats.dim
    result = Certificate(
        certified=certified,
        lambda_min=lam,
        lambda_lower=lower,
        tolerance=tol,
        q_norm=q_norm,
        objective=cert.objective,
        lower_bound=cert.objective + d * n * min(lower, 0.0),
        poses=n,
        seconds=time.perf_counter() - t0,
    )
    return LiftedCertificate(result, vec)


def certify(
    data: GraphData,
    poses: ArrayLike,
    *,
    rtol: float = CERTIFY_RTOL,
    linear_solver: LinearSolverName = "auto",
) -> Certificate:
    """Decide whether ``poses`` (rows in the order of
    ``GraphProblem.from_data(data).pose_ids``, as :class:`~slamkit.optim.OptimizeResult`'s)
    globally minimise SE-Sync's ``F`` over the relative-pose edges of ``data``, and bound
    ``F*``. 2D poses are ``(x, y, θ)`` rows, 3D ``(x, y, z, qw, qx, qy, qz)``.

    Only the rotations matter: ``F`` is evaluated with the translations optimal for them
    (equal to :func:`~slamkit.optim.sesync_objective` at a converged solution).
    """
    t0 = time.perf_counter()
    check_certifiable(data)
    if not (np.isfinite(rtol) and rtol > 0):
        raise InputError(f"rtol: expected a positive number, got {rtol!r}")
    problem = GraphProblem.from_data(data, objective="sesync")
    d = int(data.dim)
    p = as_array(poses, "poses", (problem.pose_ids.shape[0], 3 if d == 2 else 7))
    q = SchurQ(sesync_matrices(data, problem.pose_ids), linear_solver)
    cert = certify_blocks(q, rotation_blocks(p, d), rtol=rtol).certificate
    return dataclasses.replace(cert, seconds=time.perf_counter() - t0)
