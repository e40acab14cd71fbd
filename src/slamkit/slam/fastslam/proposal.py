"""FastSLAM 2.0: the proposal distribution that includes the measurement (batched 2x2 algebra
with the pose Jacobian), its sampling and the weight update."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError
from slamkit.geometry.angles import wrap_angle
from slamkit.models import MIN_RANGE, MotionModel
from slamkit.models.measurement import InvertibleLandmarkModel, LandmarkModelBase
from slamkit.models.motion import motion_kernels
from slamkit.slam.fastslam.association import (
    labelled_rounds,
    normalised_log_weights,
    prune_landmarks,
    scan_at_poses,
    split_labelled,
)
from slamkit.slam.fastslam.config import steering_limit
from slamkit.slam.fastslam.kernels import congruence
from slamkit.slam.fastslam.marginal import best_landmarks
from slamkit.slam.fastslam.particles import LOG_2PI, IntArray
from slamkit.slam.fastslam.settings import UpdateSettings
from slamkit.slam.fastslam.store import Work

# FastSLAM 2.0's proposal works on batched 2×2 matrices (with the pose Jacobian).


@dataclass(frozen=True)
class _Terms:
    """Innovation terms of readings against landmarks, batch ``(...)``."""

    nu: FloatArray  # (..., 2)
    Hx: FloatArray  # (..., 2, 3)
    Hm: FloatArray  # (..., 2, 2)
    Q: FloatArray  # (..., 2, 2)   H Σ Hᵀ + R
    ok: NDArray[np.bool_]  # (...)  False: landmark at the sensor, terms undefined

    def take(self, index: Any, pose_jacobian: bool = True) -> _Terms:
        """The terms at ``index`` of the batch (the Jacobians, which do not depend on the
        reading, may lack a readings axis that ``ν`` has: they are broadcast first).
        ``pose_jacobian=False`` leaves ``H_x`` out (empty): FastSLAM 1.0 never needs it."""
        batch = self.nu.shape[:-1]

        def at(a: NDArray[Any], tail: tuple[int, ...]) -> NDArray[Any]:
            return np.broadcast_to(a, (*batch, *tail))[index]

        Hx = at(self.Hx, (2, 3)) if pose_jacobian else np.empty((0, 2, 3))
        return _Terms(self.nu[index], Hx, at(self.Hm, (2, 2)), at(self.Q, (2, 2)),
                      at(self.ok, ()))  # fmt: skip


def _terms(
    model: InvertibleLandmarkModel,
    poses: FloatArray,
    mu: FloatArray,
    cov: FloatArray,
    z: FloatArray,
    R: FloatArray,
) -> _Terms:
    """``ν = z ⊟ h(x, μ)``, ``H_x``, ``H_m`` and ``Q = H_m Σ H_mᵀ + R`` for poses ``(..., 3)``,
    landmarks ``(..., 2)``, ``(..., 2, 2)`` and readings ``(..., 2)`` (broadcast).

    A landmark closer than ``MIN_RANGE`` to the pose has no bearing: it is evaluated at a
    stand-in point and flagged ``ok = False``. The models' batch kernels
    ``predict_unchecked`` and ``jacobians_unchecked`` are called directly: the inputs were
    validated once (data set, public functions), and the checks of ``predict``/``jacobians``
    cost more than the arithmetic here."""
    batch = np.broadcast_shapes(poses.shape[:-1], mu.shape[:-1])
    p = np.broadcast_to(poses, (*batch, 3))
    m = np.broadcast_to(mu, (*batch, 2))
    d = m - p[..., :2]
    ok = np.hypot(d[..., 0], d[..., 1]) >= 2.0 * MIN_RANGE
    if not ok.all():
        m = np.where(ok[..., None], m, p[..., :2] + np.array([1.0, 0.0]))
    if isinstance(model, LandmarkModelBase):
        z_hat = model.predict_unchecked(p, m)
        Hx, Hm = model.jacobians_unchecked(p, m)
    else:  # pragma: no cover - every invertible model of slamkit has the kernels
        z_hat = model.predict(p, m)
        Hx, Hm = model.jacobians(p, m)
    nu = z - z_hat
    for j, angular in enumerate(model.angular):
        if angular:
            nu[..., j] = wrap_angle(nu[..., j])
    return _Terms(nu, Hx, Hm, congruence(Hm, cov) + R, ok)


def _congruence_2x3(H: FloatArray, S: FloatArray) -> FloatArray:
    """``H S Hᵀ`` ``(..., 2, 2)`` for ``H (..., 2, 3)`` and a symmetric ``S (..., 3, 3)``
    (broadcast), written out as :func:`congruence`: exactly symmetric, and on every
    landmark of every particle several times faster than stacked ``matmul``."""
    h = [[H[..., i, k] for k in range(3)] for i in range(2)]
    s = [[S[..., i, k] for k in range(3)] for i in range(3)]
    hs = [[h[i][0] * s[0][k] + h[i][1] * s[1][k] + h[i][2] * s[2][k] for k in range(3)]
          for i in range(2)]  # fmt: skip
    out = np.empty((*np.broadcast_shapes(H.shape[:-2], S.shape[:-2]), 2, 2))
    out[..., 0, 0] = hs[0][0] * h[0][0] + hs[0][1] * h[0][1] + hs[0][2] * h[0][2]
    out[..., 0, 1] = out[..., 1, 0] = hs[0][0] * h[1][0] + hs[0][1] * h[1][1] + hs[0][2] * h[1][2]
    out[..., 1, 1] = hs[1][0] * h[1][0] + hs[1][1] * h[1][1] + hs[1][2] * h[1][2]
    return out


def _inv2(S: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Inverse and determinant of 2×2 matrices ``(..., 2, 2)`` in closed form (LAPACK's
    per-matrix overhead is ~100x the arithmetic of a 2×2)."""
    a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = a * d - b * c
    inv = np.empty_like(S)
    inv[..., 0, 0] = d / det
    inv[..., 0, 1] = -b / det
    inv[..., 1, 0] = -c / det
    inv[..., 1, 1] = a / det
    return inv, det


def _log_gauss(nu: FloatArray, S: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(log N(ν; 0, S), S⁻¹)`` for 2-D ``ν (..., 2)``, ``S (..., 2, 2)``."""
    S_inv, det = _inv2(S)
    n0, n1 = nu[..., 0], nu[..., 1]
    d2 = n0 * (S_inv[..., 0, 0] * n0 + S_inv[..., 0, 1] * n1) + n1 * (
        S_inv[..., 1, 0] * n0 + S_inv[..., 1, 1] * n1
    )  # νᵀ S⁻¹ ν
    with np.errstate(invalid="ignore", divide="ignore"):
        ll = -0.5 * (d2 + np.log(det)) - LOG_2PI  # m = 2: (m/2) log 2π = log 2π
    return ll, S_inv


def sym_sqrt(S: FloatArray) -> FloatArray:
    """Symmetric square roots ``(..., k, k)`` of PSD matrices (eigen-decomposition, negative
    round-off eigenvalues clipped): unique, and defined where a Cholesky factor is not."""
    lam, vec = np.linalg.eigh(S)
    return (vec * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]) @ np.swapaxes(vec, -1, -2)


class _Proposal:
    """The Gaussian ``N(e, Σ_δ)`` over each particle's motion noise ``δ``, and the motion
    linearised at its mean.

    Without ``pose_cov`` the particle's pose ``x_{t-1}`` is exact and ``δ = ε`` is the
    control noise: prior ``N(0, Q_u)``, ``x̄ = g(x_{t-1}, u + e)``, ``V = ∂g/∂u`` there. With
    ``pose_cov (P, 3, 3)`` the pose before the control is itself uncertain (earlier controls
    since the last scan, folded in by :func:`fold_motion`): ``δ = (δx, ε)`` with prior
    ``N(0, blockdiag(pose_cov, Q_u))``, ``x̄ = g(x_{t-1} + e_x, u + e_u)`` and
    ``V = [∂g/∂x, ∂g/∂u]`` ``(P, 3, 3 + k)``, so the readings shape every step of the motion
    since the last scan, not only the last one."""

    def __init__(
        self,
        motion: MotionModel,
        x0: FloatArray,
        u: FloatArray,
        dt: float,
        Qu: FloatArray,
        pose_cov: FloatArray | None = None,
    ) -> None:
        n, k = x0.shape[0], Qu.shape[0]
        self.motion, self.x0, self.u, self.dt = motion, x0, u, dt
        # The unchecked kernels (validated once by the caller; the checks of apply/jacobians
        # cost more than a few particles' motion): the same numbers.
        self.kernels = motion_kernels(motion)
        self.limit = steering_limit(motion)
        self.b = 0 if pose_cov is None else 3  # where the control noise starts in δ
        d = self.b + k
        self.e = np.zeros((n, d))
        self.S = np.zeros((n, d, d))
        self.S[:, self.b :, self.b :] = Qu
        if pose_cov is not None:
            self.S[:, :3, :3] = pose_cov
        self.x_bar = np.empty((n, 3))
        self.V = np.empty((n, 3, d))
        self.Px = np.empty((n, 3, 3))  # V Σ_δ Vᵀ: the proposal's pose covariance
        self._linearise(slice(None))

    def _motion_at(self, rows: Any, delta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The pose before the control and the (feasible) control at noise ``delta``."""
        x = self.x0[rows] if self.b == 0 else self.x0[rows] + delta[:, :3]
        return x, self._feasible(self.u + delta[:, self.b :])

    def _linearise(self, rows: Any) -> None:
        """``x̄``, ``V`` and ``P_x = V Σ_δ Vᵀ`` of the particles ``rows`` at their current
        mean ``e``."""
        x, u = self._motion_at(rows, self.e[rows])
        if not (math.isfinite(float(x.sum())) and math.isfinite(float(u.sum()))):
            raise ConvergenceError("the proposal's poses or controls became non-finite")
        self.x_bar[rows] = self.kernels.apply_unchecked(x, u, self.dt)
        G, V = self.kernels.jacobians_unchecked(x, u, self.dt)
        if self.b:
            self.V[rows, :, :3] = G
            self.V[rows, :, 3:] = V
        else:
            self.V[rows] = V
        Vr = self.V[rows]
        Px = Vr @ self.S[rows] @ np.swapaxes(Vr, -1, -2)
        self.Px[rows] = 0.5 * (Px + np.swapaxes(Px, -1, -2))

    def marginal(self, t: _Terms, rows: Any) -> FloatArray:
        """``L = A Σ_δ Aᵀ + Q = H_x P_x H_xᵀ + Q`` with ``A = H_x V`` (the reading's
        covariance, motion noise integrated out) for terms ``t`` of the particles ``rows``
        (broadcasting over extra axes). Through the 3×3 ``P_x``, whatever the size of
        ``δ``, and written out: the association tries every landmark of every particle."""
        return _congruence_2x3(t.Hx, self.Px[rows]) + t.Q

    def update(
        self, rows: Any, nu: FloatArray, Hx: FloatArray, Q: FloatArray, L: FloatArray
    ) -> None:
        """Fold one reading (innovation ``ν (N, 2)``, pose Jacobian ``H_x (N, 2, 3)``, its
        covariance without the motion ``Q`` and with it ``L``, ``(N, 2, 2)``) into the
        proposal of the particles ``rows`` (indices or a slice), then relinearise the motion
        at the new mean."""
        A = Hx @ self.V[rows]  # (N, 2, d): ∂h/∂δ = H_x V
        S = self.S[rows]
        L_inv, _ = _inv2(L)
        K = S @ np.swapaxes(A, -1, -2) @ L_inv  # K_δ = Σ_δ Aᵀ L⁻¹, (N, d, 2)
        self.e[rows] += (K @ nu[..., None])[..., 0]
        IKA = np.eye(S.shape[-1]) - K @ A
        # Joseph form, with Q (L without the motion part) as the noise of the reading.
        S_new = IKA @ S @ np.swapaxes(IKA, -1, -2) + K @ Q @ np.swapaxes(K, -1, -2)
        self.S[rows] = 0.5 * (S_new + np.swapaxes(S_new, -1, -2))
        self._linearise(rows)

    def sample(self, rng: np.random.Generator) -> FloatArray:
        """Poses ``g(x_{t-1} + δx, u + ε)``, ``δ ~ N(e, Σ_δ)`` (draws
        ``rng.standard_normal((P, d))``, coloured by the symmetric square root)."""
        n, d = self.e.shape
        draws = rng.standard_normal((n, d))
        delta = self.e + (sym_sqrt(self.S) @ draws[..., None])[..., 0]
        return self.kernels.apply_unchecked(*self._motion_at(slice(None), delta), self.dt)

    def _feasible(self, u: FloatArray) -> FloatArray:
        """Controls with the steering saturated (Ackermann, see :func:`steering_limit`)."""
        if self.limit is not None:
            np.clip(u[..., 1], -self.limit, self.limit, out=u[..., 1])
        return u


def update2(
    w: Work,
    poses0: FloatArray,
    log_weights: FloatArray,
    motion: MotionModel,
    u: FloatArray,
    dt: float,
    Qu: FloatArray,
    z: FloatArray,
    rid: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    s: UpdateSettings,
    rng: np.random.Generator,
    pose_cov: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """FastSLAM 2.0's step on the maps ``w`` (in place) from ``poses0`` (uncertain by
    ``pose_cov (P, 3, 3)`` if given, see :class:`_Proposal`): the sampled poses, the new
    normalised log-weights and each particle's log-weight increment ``(P,)``."""
    n = poses0.shape[0]
    prop = _Proposal(motion, poses0, u, dt, Qu, pose_cov)
    w.begin_scan()
    log_p0 = s.log_p0
    ll_total = np.zeros(n)
    lab, unl = split_labelled(rid, s)
    rounds = labelled_rounds(rid, lab)
    # Labelled readings of the first round (distinct ids) shape the proposal one by one.
    for k in rounds[0] if rounds else ():
        slot = _lookup(w, int(rid[k]))
        upd = np.flatnonzero(slot >= 0)
        ll = np.full(n, log_p0)  # a new landmark: p0, the proposal is unchanged
        if upd.size:
            t = _terms(model, prop.x_bar[upd], *w.gaussians((slot[upd], upd)), z[k], R)
            L = prop.marginal(t, upd)
            l_upd, _ = _log_gauss(t.nu, L)
            ll[upd] = np.where(t.ok, l_upd, -np.inf)
            g = t.ok
            if g.any():
                tg = t.take(g)
                prop.update(upd[g], tg.nu, tg.Hx, tg.Q, L[g])
                w.seen[slot[upd[g]], upd[g]] = True
        ll_total += ll
    # Unlabelled readings: maximum likelihood under the marginal, excluding used landmarks.
    forced = np.full((unl.size, n), -1, dtype=np.intp)
    pose_xy = (prop.x_bar[:, 0], prop.x_bar[:, 1], prop.x_bar[:, 2])  # views: kept current
    cmax = int(w.counts.max()) if unl.size else 0
    if cmax:  # the landmarks stay as they are until the sampling: Σ00 + Σ11 once
        cand = _candidates(w, cmax)  # kept current below
        sigma_trace = w.lm[2, :cmax] + w.lm[4, :cmax]
    for j, k in enumerate(unl):
        ll = np.full(n, log_p0)
        if cmax:
            # Every landmark of every particle (gated, planar): the bulk of a 2.0 run.
            found = best_landmarks(model, pose_xy, prop.Px, w.lm[:, :cmax], cand, z[k], R,
                                   log_p0, sigma_trace)  # fmt: skip
            best, lb = found.slot, found.ll
            match = np.flatnonzero(lb >= log_p0)
            if match.size:
                bm = best[match]
                ll[match] = lb[match]
                forced[j, match] = bm
                # Usually every particle matches: a slice (views) instead of fancy copies.
                prop.update(slice(None) if match.size == n else match, *found.take(match))
                w.seen[bm, match] = True
                cand[bm, match] = False  # a landmark takes one reading per scan
        ll_total += ll
    poses = prop.sample(rng)
    # The landmarks, from the sampled poses, with the proposal's associations.
    w.seen[:] = False
    ll_total += scan_at_poses(w, poses, z, rid, R, model, s, forced_unlabelled=forced,
                               weigh_first_round=False)  # fmt: skip
    prune_landmarks(w, poses, s)
    return poses, normalised_log_weights(log_weights + ll_total), ll_total


def _lookup(w: Work, rid: int) -> NDArray[np.intp]:
    """Slot of landmark ``rid`` in each particle, ``-1`` where it is not mapped."""
    hit = (w.ids == rid) & w.valid()  # (C, P)
    return np.where(hit.any(axis=0), hit.argmax(axis=0), -1).astype(np.intp)


def fold_motion(
    motion: MotionModel,
    mean: FloatArray,
    cov: FloatArray | None,
    u: FloatArray,
    dt: float,
    Qu: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """One control folded into the Gaussians ``N(mean_p, cov_p)`` of the particles' poses
    ``(P, 3)``, ``(P, 3, 3)`` (``cov`` None: the poses are exact), linearised as an EKF
    prediction (:func:`~slamkit.models.motion.propagate_gaussian_unchecked`):
    ``mean ← g(mean, u)``, ``cov ← G cov Gᵀ + V Q_u Vᵀ``. FastSLAM 2.0 keeps the motion since
    the last scan this way, so that its proposal covers all of it (see :class:`_Proposal`)."""
    P = np.zeros((mean.shape[0], 3, 3)) if cov is None else cov
    # propagate_gaussian_unchecked's lines on the motion's unchecked kernels (its apply and
    # jacobians validate the poses again, half the cost of a fold): the same numbers.
    kernels = motion_kernels(motion)
    ub = np.broadcast_to(u, (mean.shape[0], u.shape[-1]))
    new_mean = kernels.apply_unchecked(mean, ub, dt)
    G, V = kernels.jacobians_unchecked(mean, ub, dt)
    Gt, Vt = np.swapaxes(G, -1, -2), np.swapaxes(V, -1, -2)
    new_cov = G @ P @ Gt + V @ Qu @ Vt
    return new_mean, 0.5 * (new_cov + np.swapaxes(new_cov, -1, -2))


def _candidates(w: Work, cmax: int) -> NDArray[np.bool_]:
    """The slots an unlabelled reading may still match ``(cmax, P)``."""
    return w.valid(cmax) & ~w.seen[:cmax]
