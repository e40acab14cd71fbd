"""FastSLAM 2.0's association kernel: the marginal log-likelihood of one reading against every
landmark of every particle, in the planar slot-major layout of :class:`~slamkit.slam.fastslam.
store.Work` (``(C, P)`` planes, particles on the last axis).

For a reading ``z``, landmark ``N(μ, Σ)`` and a particle whose proposal puts its pose at
``x̄`` with covariance ``P_x`` (motion noise linearised, see :class:`~slamkit.slam.fastslam.
proposal`):

    ν = z ⊟ h(x̄, μ),   L = H_x P_x H_xᵀ + (H_m Σ H_mᵀ + R),
    log p(z) = −½ (νᵀ L⁻¹ ν + log det L) − log 2π        (m = 2)

with ``H_x = ∂h/∂x``, ``H_m = ∂h/∂m`` at ``(x̄, μ)``. The proposal evaluates this for every
unlabelled reading (the association is the maximum over landmarks): the bulk of a FastSLAM
2.0 run as stacked ``(P, C, 2, 3)`` matrices (profile in docs/estimators/fastslam.md). Here
every matrix entry is one contiguous ``(C, P)`` plane and the 2×2 / 2×3 products are written
out, in the SAME order of floating-point operations as the matrix form
(:func:`~slamkit.slam.fastslam.proposal.update2`'s reference, ``_terms`` → ``marginal`` →
``_log_gauss``), so the two give bit-identical numbers (a test holds that). Only products with
the structural zeros of range-bearing's ``H_x = [−H_m | (0, −1)ᵀ]`` are left out: ``a + 0·s``
is ``a``, and ``−1·s`` is ``−s``, exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.geometry.angles import wrap_angle
from slamkit.models import MIN_RANGE, RangeBearing
from slamkit.models.measurement import InvertibleLandmarkModel, LandmarkModelBase
from slamkit.slam.fastslam.particles import LOG_2PI

# A 2×3 Jacobian as planes: entries are arrays, or the floats 0.0 / -1.0 (structural, skipped).
_Entry = Any


def _row_times_symmetric(h: tuple[_Entry, _Entry, _Entry], s: list[list[FloatArray]]) -> list[Any]:
    """``(h S)_k = h_0 s_0k + h_1 s_1k + h_2 s_2k`` for k = 0..2, left to right as
    ``_congruence_2x3`` sums them, skipping the terms whose ``h_j`` is the constant 0.0 and
    writing ``−s`` for the constant −1.0 (exact)."""
    out = []
    for k in range(3):
        acc: Any = None
        for j in range(3):
            hj = h[j]
            if isinstance(hj, float):
                if hj == 0.0:
                    continue
                assert hj == -1.0  # the only other structural entry
                term = -s[j][k]
                acc = term if acc is None else acc - s[j][k]
                continue
            term = hj * s[j][k]
            acc = term if acc is None else acc + term
        out.append(acc)
    return out


def _dot3(a: list[Any], h: tuple[_Entry, _Entry, _Entry]) -> Any:
    """``a_0 h_0 + a_1 h_1 + a_2 h_2`` left to right, structural entries as above."""
    acc: Any = None
    for aj, hj in zip(a, h, strict=True):
        if isinstance(hj, float):
            if hj == 0.0:
                continue
            assert hj == -1.0
            acc = -aj if acc is None else acc - aj
            continue
        term = aj * hj
        acc = term if acc is None else acc + term
    return acc


def _wrapped(a: FloatArray) -> FloatArray:
    """:func:`wrap_angle`, skipped when every angle is in ``[-π, π)`` already (it returns
    those bit-identical): two reductions instead of its ~10 operations."""
    if a.size and float(a.min()) >= -math.pi and float(a.max()) < math.pi:
        return a
    return wrap_angle(a)


@dataclass(frozen=True)
class PairTerms:
    """What :func:`pair_terms` computed for a batch of (landmark, pose) pairs, as planes of
    that batch: ``ll``, ``ok``, the innovation ``ν``, ``H_x`` (entries: planes, or the
    structural floats 0.0 / −1.0), ``Q = H_m Σ H_mᵀ + R`` and ``L = H_x P_x H_xᵀ + Q``."""

    ll: FloatArray
    ok: NDArray[np.bool_]
    nu: tuple[FloatArray, FloatArray]
    Hx: tuple[tuple[Any, Any, Any], tuple[Any, Any, Any]]
    Q: tuple[FloatArray, FloatArray, FloatArray, FloatArray]  # 00, 01, 10, 11
    L: tuple[FloatArray, FloatArray, FloatArray, FloatArray]

    def take(self, index: Any) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(ν (N, 2), H_x (N, 2, 3), Q (N, 2, 2), L (N, 2, 2))`` of the pairs ``index``
        (a NumPy index into the batch), as stacked matrices for the proposal's update."""
        shape = self.ll.shape

        def at(a: Any) -> Any:
            if isinstance(a, float):
                return a
            return (a if a.shape == shape else np.broadcast_to(a, shape))[index]

        n = self.ll[index].shape
        nu = np.empty((*n, 2))
        Hx = np.empty((*n, 2, 3))
        Q = np.empty((*n, 2, 2))
        L = np.empty((*n, 2, 2))
        for i in range(2):
            nu[..., i] = at(self.nu[i])
            for k in range(3):
                Hx[..., i, k] = at(self.Hx[i][k])
            for k in range(2):
                Q[..., i, k] = at(self.Q[2 * i + k])
                L[..., i, k] = at(self.L[2 * i + k])
        return nu, Hx, Q, L


def marginal_log_likelihoods(
    model: InvertibleLandmarkModel,
    pose: tuple[FloatArray, FloatArray, FloatArray],
    pose_cov: FloatArray,
    g: FloatArray,
    z: FloatArray,
    R: FloatArray,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """:func:`pair_terms`' log-likelihoods and ``ok`` only."""
    t = pair_terms(model, pose, pose_cov, g, z, R)
    return t.ll, t.ok


def pair_terms(
    model: InvertibleLandmarkModel,
    pose: tuple[FloatArray, FloatArray, FloatArray],
    pose_cov: FloatArray,
    g: FloatArray,
    z: FloatArray,
    R: FloatArray,
) -> PairTerms:
    """``log p(z)`` of one reading ``z (2,)`` against the landmarks ``g (5, C, P)`` (planar:
    mean x, y and Σ00, Σ01, Σ11) from the proposal poses ``pose = (x, y, θ)`` ``(P,)`` with
    covariances ``pose_cov (P, 3, 3)`` (symmetric): ``(C, P)``, and ``ok (C, P)``: False
    (any batch shape ``g (5, *batch)`` to which the pose planes and ``pose_cov (*batch', 3,
    3)`` broadcast; entry-wise, so a gathered subset gives the same numbers)
    where the landmark is within ``2 MIN_RANGE`` of the pose (its value is then that of a
    stand-in point 1 m east of the pose, for the caller to discard).

    Range-bearing is written out; other models go through their batch kernels
    ``predict_unchecked`` / ``jacobians_unchecked``. Same numbers, bit for bit, as the matrix
    form (module docstring)."""
    px, py, pth = pose
    mx, my, s00, s01, s11 = g
    dx, dy = mx - px, my - py
    r = np.hypot(dx, dy)  # (np.hypot costs many products: computed once)
    ok = r >= 2.0 * MIN_RANGE
    if not ok.all():
        mx = np.where(ok, mx, px + 1.0)
        my = np.where(ok, my, py + 0.0)
        dx, dy = mx - px, my - py
        r = np.hypot(dx, dy)
    if isinstance(model, RangeBearing):
        zh0 = r
        zh1 = _wrapped(np.arctan2(dy, dx) - pth)
        q = r * r
        h00, h01 = dx / r, dy / r
        h10, h11 = -dy / q, dx / q
        hx: tuple[tuple[_Entry, _Entry, _Entry], ...] = ((-h00, -h01, 0.0), (-h10, -h11, -1.0))
    else:
        batch = np.broadcast_shapes(mx.shape, px.shape)
        p = np.empty((*batch, 3))
        p[..., 0], p[..., 1], p[..., 2] = px, py, pth
        m = np.stack(np.broadcast_arrays(mx, my), axis=-1)
        if isinstance(model, LandmarkModelBase):
            z_hat = model.predict_unchecked(p, m)
            Hx, Hm = model.jacobians_unchecked(p, m)
        else:  # pragma: no cover - every invertible model of slamkit has the kernels
            z_hat = model.predict(p, m)
            Hx, Hm = model.jacobians(p, m)
        zh0, zh1 = z_hat[..., 0], z_hat[..., 1]
        h00, h01, h10, h11 = Hm[..., 0, 0], Hm[..., 0, 1], Hm[..., 1, 0], Hm[..., 1, 1]
        hx = tuple((Hx[..., i, 0], Hx[..., i, 1], Hx[..., i, 2]) for i in range(2))
    nu0, nu1 = z[0] - zh0, z[1] - zh1
    a0, a1 = model.angular
    if a0:
        nu0 = _wrapped(nu0)
    if a1:
        nu1 = _wrapped(nu1)
    # Q = H_m Σ H_mᵀ + R (``congruence``: T = H_m Σ row by row, then T H_mᵀ).
    t00, t01 = h00 * s00 + h01 * s01, h00 * s01 + h01 * s11
    t10, t11 = h10 * s00 + h11 * s01, h10 * s01 + h11 * s11
    c00 = t00 * h00 + t01 * h01
    c01 = t00 * h10 + t01 * h11
    c11 = t10 * h10 + t11 * h11
    # L = H_x P_x H_xᵀ + Q (``_congruence_2x3``: hs = H_x P_x row by row, then hs H_xᵀ).
    S = [[pose_cov[..., i, k] for k in range(3)] for i in range(3)]
    hs0 = _row_times_symmetric(hx[0], S)
    hs1 = _row_times_symmetric(hx[1], S)
    q00, q01, q11 = c00 + float(R[0, 0]), c01 + float(R[0, 1]), c11 + float(R[1, 1])
    q10 = q01 if R[1, 0] == R[0, 1] else c01 + float(R[1, 0])
    L00 = _dot3(hs0, hx[0]) + q00
    e01 = _dot3(hs0, hx[1])
    L01 = e01 + q01
    L10 = L01 if q10 is q01 else e01 + q10
    L11 = _dot3(hs1, hx[1]) + q11
    # log N(ν; 0, L) with L⁻¹ in closed form (``_inv2``, ``_log_gauss``).
    det = L00 * L11 - L01 * L10
    i00, i01, i10, i11 = L11 / det, -L01 / det, -L10 / det, L00 / det
    d2 = nu0 * (i00 * nu0 + i01 * nu1) + nu1 * (i10 * nu0 + i11 * nu1)
    with np.errstate(invalid="ignore", divide="ignore"):
        ll = -0.5 * (d2 + np.log(det)) - LOG_2PI
    return PairTerms(ll, ok, (nu0, nu1), (hx[0], hx[1]), (q00, q01, q10, q11),
                     (L00, L01, L10, L11))  # fmt: skip


def gate_bound(log_p0: float, R: FloatArray) -> float:
    """The largest ``νᵀ L⁻¹ ν`` of a landmark whose likelihood can reach ``p0``, with slack.

    ``log p(z) ≥ log p0`` needs ``νᵀ L⁻¹ ν ≤ −2 log p0 − 2 log 2π − log det L``, and
    ``L ⪰ R`` (``R`` plus positive semidefinite terms) gives ``det L ≥ det R``, so
    ``νᵀ L⁻¹ ν ≤ D = −2 log p0 − 2 log 2π − log det R`` (χ²₂(0.999) = 13.8 with the default
    ``p0``). Returned as ``D (1 + 10⁻⁶) + 1``: a landmark beyond it is at least ½ below
    ``log p0``, far more than the round-off of either side."""
    det_R = float(R[0, 0] * R[1, 1] - R[0, 1] * R[1, 0])
    d = -2.0 * log_p0 - 2.0 * LOG_2PI - math.log(det_R)
    return max(d, 0.0) * (1.0 + 1e-6) + 1.0


@dataclass(frozen=True)
class BestLandmarks:
    """:func:`best_landmarks`' answer: each particle's best slot ``(P,)`` and its
    log-likelihood ``(P,)``, and the terms of those pairs (``where``: their index into
    ``terms``' batch)."""

    slot: NDArray[np.intp]
    ll: FloatArray
    terms: PairTerms
    where: Any

    def take(self, rows: NDArray[np.intp]) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """:meth:`PairTerms.take` of the best pairs of the particles ``rows`` (which must
        have reached ``log_p0``: the others' pairs may not have been evaluated)."""
        if isinstance(self.where, tuple):
            return self.terms.take((self.where[0][rows], self.where[1][rows]))
        return self.terms.take(self.where[rows])


def best_landmarks(
    model: InvertibleLandmarkModel,
    pose: tuple[FloatArray, FloatArray, FloatArray],
    pose_cov: FloatArray,
    g: FloatArray,
    cand: NDArray[np.bool_],
    z: FloatArray,
    R: FloatArray,
    log_p0: float,
    sigma_trace: FloatArray | None = None,
) -> BestLandmarks:
    """Each particle's most likely landmark for one reading: the slot ``(P,)`` maximising
    :func:`marginal_log_likelihoods` over the candidates ``cand (C, P)`` (at the sensor: not
    a candidate), and its log-likelihood ``(P,)``. Where that maximum is at least
    ``log_p0`` both are exactly those of the full ``(C, P)`` evaluation; below it the
    caller starts a landmark, and they are only some candidate's (or ``-inf``).

    Range-bearing readings are gated first (the other models evaluate every pair): a
    landmark can reach ``log_p0`` only if ``ν_r² ≤ D L_rr`` (``νᵀ L⁻¹ ν ≥ ν_r² / L_rr`` for
    positive definite ``L``; ``D`` from :func:`gate_bound`), and with ``H_x = [−u, 0]``,
    ``H_m = u`` in the range row (``u`` the unit direction) ``L_rr = uᵀ (P_xy + Σ) u + R_rr
    ≤ tr P_xy + tr Σ + R_rr``. So only the pairs with ``(z_r − r)² ≤ D (tr P_xy + tr Σ +
    R_rr)`` — a ring around the reading's range, a few % of the pairs (docs) — get
    the full evaluation. ``sigma_trace (C, P)``: ``Σ00 + Σ11`` of ``g`` if known (it does
    not change while a scan's proposal is built)."""
    n = cand.shape[1]
    if not isinstance(model, RangeBearing):
        rows = np.arange(n)
        t = pair_terms(model, pose, pose_cov, g, z, R)
        ll = np.where(cand & t.ok, t.ll, -np.inf)
        best = np.argmax(ll, axis=0)
        return BestLandmarks(best, ll[best, rows], t, (best, rows))
    px, py, _ = pose
    mx, my = g[0], g[1]
    tr = g[2] + g[4] if sigma_trace is None else sigma_trace
    # (z_r − r)² ≤ B = D (tr Σ + tr P_xy + R_rr) over every pair, without a square root
    # (np.hypot over (C, P) cost more than all the rest, docs): with d² = r², a = z_r² + d² − B,
    # (z_r − r)² ≤ B ⟺ a ≤ 2 z_r r ⟺ a ≤ 0 or a² ≤ 4 z_r² d² (z_r, r ≥ 0). The slack of
    # gate_bound (≥ R_rr in B) dwarfs the round-off of either side.
    zr = float(z[0])
    bound = tr + (pose_cov[:, 0, 0] + pose_cov[:, 1, 1] + float(R[0, 0]))
    bound *= gate_bound(log_p0, R)
    dx = mx - px
    d2 = dx * dx
    np.subtract(my, py, out=dx)
    dx *= dx
    d2 += dx
    a = d2 + zr * zr
    a -= bound
    keep = a <= 0.0
    a *= a
    d2 *= 4.0 * zr * zr
    keep |= a <= d2
    keep &= cand
    flat = np.flatnonzero(keep)  # (C, P) order: slot-major (2-D nonzero is much slower)
    c_in, p_in = np.divmod(flat, n)
    t = pair_terms(
        model, (px[p_in], py[p_in], pose[2][p_in]), pose_cov[p_in], g[:, c_in, p_in], z, R
    )
    ll = np.where(t.ok, t.ll, -np.inf)
    # Each particle's maximum over its evaluated pairs, and the first slot that attains it
    # (as argmax takes it), by unbuffered scatter reductions over the few pairs: an argmax
    # down the (C, P) columns cost several times more.
    lb = np.full(n, -np.inf)
    np.maximum.at(lb, p_in, ll)
    top = ll == lb[p_in]
    best = np.full(n, g.shape[1], dtype=np.intp)
    np.minimum.at(best, p_in[top], c_in[top])
    has = best < g.shape[1]
    best[~has] = 0
    where = np.zeros(n, dtype=np.intp)  # each particle's best pair among the evaluated
    where[has] = np.searchsorted(flat, best[has] * n + np.flatnonzero(has))
    return BestLandmarks(best, lb, t, where)
