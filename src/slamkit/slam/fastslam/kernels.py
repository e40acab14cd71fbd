"""FastSLAM's vectorised per-landmark kernels over all particles: predicted readings and
Jacobians, innovations, likelihoods, the 2x2 EKF update and landmark initialisation."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray
from slamkit.estimation.gaussian import check_covariance_entries
from slamkit.models import MIN_RANGE, RangeBearing
from slamkit.models.measurement import InvertibleLandmarkModel, LandmarkModelBase
from slamkit.slam.fastslam.particles import LOG_2PI, IntArray
from slamkit.slam.fastslam.store import ALL_OK, I00, I11, LOGDET, T00, T11, TWO_PI, ZH0, ZH1, Work


def _times_symmetric(
    a: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    b: tuple[FloatArray, FloatArray, FloatArray],
    out: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    tmp: FloatArray,
) -> None:
    """``out = A B`` entry-wise over arrays of 2×2 matrices, in place: ``A`` as
    ``(a00, a01, a10, a11)``, ``B`` symmetric as ``(b00, b01, b11)``."""
    a00, a01, a10, a11 = a
    b00, b01, b11 = b
    o00, o01, o10, o11 = out
    np.multiply(a00, b00, out=o00)
    o00 += np.multiply(a01, b01, out=tmp)
    np.multiply(a00, b01, out=o01)
    o01 += np.multiply(a01, b11, out=tmp)
    np.multiply(a10, b00, out=o10)
    o10 += np.multiply(a11, b01, out=tmp)
    np.multiply(a10, b01, out=o11)
    o11 += np.multiply(a11, b11, out=tmp)


def landmark_terms(
    model: InvertibleLandmarkModel,
    pose: tuple[FloatArray, FloatArray, FloatArray],
    g: FloatArray,
    R: FloatArray,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """What the readings of the landmarks ``g (5, *batch)`` (planar, see :class:`Work`)
    from the poses ``pose = (x, y, θ)`` (broadcasting to ``batch``) need before any reading
    is known, stacked in one array ``(14, *batch)`` (rows ``ZH0`` …): the predicted reading
    ``ẑ`` (angular components unwrapped: the innovation wraps them), ``H = ∂h/∂m``,
    ``T = H Σ``, ``Q⁻¹`` with ``Q = H Σ Hᵀ + R`` (entries 00, 01, 11) and ``log det Q``.
    Also ``ok (*batch)``: False where the landmark is at the sensor (closer than
    ``2 MIN_RANGE``; the terms are then those of a stand-in point 1 m east of the pose).

    One stacked array, so the terms of chosen (slot, particle) pairs are gathered in one
    operation. Range-bearing, the common case, is written out here (``ẑ = (r, atan2(dy, dx)
    − θ)``, ``H = [[dx/r, dy/r], [−dy/r², dx/r²]]``, the convention of
    :class:`~slamkit.models.RangeBearing`); other models go through their batch kernels
    ``predict_unchecked``/``jacobians_unchecked``. A test checks both against the models'
    validated methods."""
    px, py, pth = pose
    batch = g.shape[1:]
    buf = np.empty((20, *batch))  # the terms and, after them, scratch
    F = buf[:14]
    # Every row as a name (one view per row, not one per use: at a few hundred values per
    # row, creating views is a tenth of the cost).
    zh0, zh1, h00, h01, h10, h11, t00, t01, t10, t11, i00, i01, i11, logdet = F
    dx, dy, q00, q01, q11, tmp = buf[14:]
    mx, my, s00, s01, s11 = g
    np.subtract(mx, px, out=dx)
    np.subtract(my, py, out=dy)
    # Sums of products ``a b + c d`` are written out as two in-place calls into preallocated
    # rows, here and in landmark_ekf_update: allocating a result, or a helper function's
    # Python call, costs a third of the arithmetic at this size.
    d2 = np.multiply(buf[14:16], buf[14:16], out=buf[16:18])  # dx², dy² in one call
    np.add(d2[0], d2[1], out=zh0)
    r = np.sqrt(zh0, out=zh0)  # np.hypot costs 2x
    if r.size and float(r.min()) >= 2.0 * MIN_RANGE:
        ok = ALL_OK
    else:
        ok = r >= 2.0 * MIN_RANGE
        dx[~ok], dy[~ok], r[~ok] = 1.0, 0.0, 1.0
    if isinstance(model, RangeBearing):
        np.arctan2(dy, dx, out=zh1)
        zh1 -= pth
        inv_r = np.divide(1.0, r, out=tmp)
        np.multiply(dx, inv_r, out=h00)  # (cos, sin) of the direction
        np.multiply(dy, inv_r, out=h01)
        np.multiply(h01, inv_r, out=h10)  # (−sin, cos) / r
        np.negative(h10, out=h10)
        np.multiply(h00, inv_r, out=h11)
    else:
        p = np.empty((*batch, 3))
        p[..., 0], p[..., 1], p[..., 2] = px, py, pth
        m = np.stack((p[..., 0] + dx, p[..., 1] + dy), axis=-1)
        if isinstance(model, LandmarkModelBase):
            z_hat, (_, Hm) = model.predict_unchecked(p, m), model.jacobians_unchecked(p, m)
        else:  # pragma: no cover - every invertible model of slamkit has the kernels
            z_hat, (_, Hm) = model.predict(p, m), model.jacobians(p, m)
        zh0[...], zh1[...] = z_hat[..., 0], z_hat[..., 1]
        h00[...], h01[...] = Hm[..., 0, 0], Hm[..., 0, 1]
        h10[...], h11[...] = Hm[..., 1, 0], Hm[..., 1, 1]
    _times_symmetric((h00, h01, h10, h11), (s00, s01, s11), (t00, t01, t10, t11), tmp)  # T = H Σ
    np.multiply(t00, h00, out=q00)  # Q = T Hᵀ + R
    q00 += np.multiply(t01, h01, out=tmp)
    q00 += float(R[0, 0])
    np.multiply(t00, h10, out=q01)
    q01 += np.multiply(t01, h11, out=tmp)
    q01 += float(R[0, 1])
    np.multiply(t10, h10, out=q11)
    q11 += np.multiply(t11, h11, out=tmp)
    q11 += float(R[1, 1])
    det = np.multiply(q00, q11, out=dx)
    det -= np.multiply(q01, q01, out=tmp)  # > 0: R is positive definite, H Σ Hᵀ semidefinite
    np.log(det, out=logdet)
    inv_det = np.divide(1.0, det, out=det)
    np.multiply(q11, inv_det, out=i00)
    np.multiply(q01, inv_det, out=i01)
    np.negative(i01, out=i01)
    np.multiply(q00, inv_det, out=i11)
    return F, ok


def _wrap_innovation(a: FloatArray) -> FloatArray:
    """An angular innovation brought to ``[-π, π]`` in place: ``a − 2π round(a / 2π)``.

    Not :func:`~slamkit.geometry.wrap_angle` (``[-π, π)`` exactly, bit-identical in range):
    an innovation only enters ``νᵀ Q⁻¹ ν`` and ``K ν``, where ``±π`` are the same point
    of the circle, and this form costs 3 array operations instead of ~10 — a tenth of a
    FastSLAM step on 100 particles. Innovations already within ``[-π, π]`` (the usual
    case) are left as they are, which is what the formula gives them."""
    if float(np.abs(a).max(initial=0.0)) <= math.pi:
        return a
    k = np.multiply(a, 1.0 / TWO_PI)
    np.round(k, out=k)
    k *= TWO_PI
    a -= k
    return a


def innovation_pairs(
    model: InvertibleLandmarkModel, F: FloatArray, z0: ArrayLike, z1: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """``ν = z ⊟ ẑ`` as two planes (angular components wrapped), broadcast with the terms."""
    nu0 = z0 - F[ZH0]
    nu1 = z1 - F[ZH1]
    a0, a1 = model.angular
    return (_wrap_innovation(nu0) if a0 else nu0), (_wrap_innovation(nu1) if a1 else nu1)


def log_likelihood(F: FloatArray, nu0: FloatArray, nu1: FloatArray) -> FloatArray:
    """``log N(ν; 0, Q) = −½ (νᵀ Q⁻¹ ν + log det Q) − log 2π`` (m = 2)."""
    i00, i01, i11, logdet = F[I00 : LOGDET + 1]
    d2 = i00 * nu0
    d2 += i01 * nu1
    d2 *= nu0
    e = i01 * nu0
    e += i11 * nu1
    e *= nu1
    d2 += e  # νᵀ Q⁻¹ ν
    d2 += logdet
    d2 *= -0.5
    d2 -= LOG_2PI
    return d2


def landmark_ekf_update(
    F: FloatArray, g: FloatArray, nu0: FloatArray, nu1: FloatArray, R: FloatArray
) -> FloatArray:
    """The 2×2 EKF update of the landmarks ``g (5, *batch)`` with the terms ``F`` and the
    innovations ``ν``: the new planar landmarks ``(5, *batch)``.

    ``K = Σ Hᵀ Q⁻¹ = Tᵀ Q⁻¹``, ``μ ← μ + K ν``, ``Σ ← Σ − K T`` (``= Σ − Tᵀ Q⁻¹ T``), written
    out in matrix entries into preallocated buffers (a stacked ``matmul`` of 2×2 blocks
    costs ~25x an elementwise operation). Only the entries 00, 01, 11 are formed, so the
    result is exactly symmetric.

    Why not the Joseph form here (EKF-SLAM uses it): with the optimal gain it is the same
    matrix, and it guards against a gain perturbed by round-off in large filters. This gain
    comes from a closed-form 2×2 inverse (relative error ~1e-16), and the subtraction can
    only lose precision in proportion to how much one reading shrinks the covariance: the
    posterior over the prior variance is ``1/(1 + λ)`` with ``λ`` an eigenvalue of
    ``Σ Hᵀ R⁻¹ H``, about 1 at a landmark's second reading (its covariance came from one
    reading) and at most the squared ratio of the ranges it was first and is now seen at
    (``λ ≈ 250`` for 80 m then 5 m): a loss of under 3 of 16 digits, far from an indefinite
    result. The Joseph form costs twice the operations, ~20 % of a FastSLAM step on 100
    particles. The tests compare this update with a Joseph-form reference to 1e-12."""
    t00, t01, t10, t11 = F[T00 : T11 + 1]
    i00, i01, i11 = F[I00 : I11 + 1]
    mx, my, s00, s01, s11 = g
    buf = np.empty((10, *g.shape[1:]))
    out = buf[:5]
    ox, oy, o00, o01, o11, k00, k01, k10, k11, tmp = buf
    _times_symmetric((t00, t10, t01, t11), (i00, i01, i11), (k00, k01, k10, k11), tmp)  # K = Tᵀ Q⁻¹
    np.multiply(k00, nu0, out=ox)  # μ + K ν
    ox += np.multiply(k01, nu1, out=tmp)
    ox += mx
    np.multiply(k10, nu0, out=oy)
    oy += np.multiply(k11, nu1, out=tmp)
    oy += my
    # Σ − K T: (K T)_ij = k_i0 t_0j + k_i1 t_1j
    for o, s_ij, ka, kb, ta, tb in (
        (o00, s00, k00, k01, t00, t10),
        (o01, s01, k00, k01, t01, t11),
        (o11, s11, k10, k11, t01, t11),
    ):
        np.multiply(ka, ta, out=tmp)
        tmp += np.multiply(kb, tb, out=o)
        np.subtract(s_ij, tmp, out=o)
    return out


def update_landmarks(
    w: Work,
    index: tuple[Any, Any],
    pose: tuple[FloatArray, FloatArray, FloatArray],
    z0: FloatArray,
    z1: FloatArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    mark: bool = True,
) -> FloatArray:
    """Update the landmarks ``index = (slots, particles)`` (any batch shape; no pair may
    repeat: fancy assignment keeps one) with readings ``(z0, z1)`` from ``pose = (x, y, θ)``
    (all broadcasting to the batch), in place, and mark them seen and updated (``mark``
    False: not, where no later step of the scan reads the marks). Returns the
    log-likelihoods (``-inf`` where the landmark is at the sensor, which is left alone)."""
    full = (slice(None), *index)
    g = w.lm[full]
    F, ok = landmark_terms(model, pose, g, R)
    nu0, nu1 = innovation_pairs(model, F, z0, z1)
    ll = log_likelihood(F, nu0, nu1)
    new = landmark_ekf_update(F, g, nu0, nu1, R)
    w.all_ok = ok is ALL_OK or bool(ok.all())
    if w.all_ok:
        check_covariance_entries(new[2], new[3], new[4], "fastslam landmark update")
        w.lm[full] = new
        if mark:
            w.seen[index] = True
            w.updated[index] = True
        return ll
    kept = np.where(ok, new, g)  # a landmark at the sensor keeps its belief
    check_covariance_entries(kept[2], kept[3], kept[4], "fastslam landmark update")
    w.lm[full] = kept
    w.seen[index] |= ok
    w.updated[index] |= ok
    return np.where(ok, ll, -np.inf)


def _start_landmarks(
    w: Work,
    rows: NDArray[np.intp],
    rank: NDArray[np.intp],
    poses: FloatArray,
    z: FloatArray,
    ids: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> None:
    """Start landmark ``ids[i]`` from reading ``z[i]`` in particle ``rows[i]``, in its slot
    ``counts + rank[i]`` (``rank``: 0, 1, … over the new landmarks of one particle)."""
    slots = w.counts[rows] + rank
    w.grow(int(slots.max()) + 1)
    _, Lz = model.inverse_jacobians(poses, z)
    m = model.inverse(poses, z)
    C = congruence(Lz, R)  # L_z R L_zᵀ: the pose is given in the particle
    w.lm[:, slots, rows] = np.stack((m[:, 0], m[:, 1], C[:, 0, 0], C[:, 0, 1], C[:, 1, 1]))
    w.counters[slots, rows] = 1
    w.ids[slots, rows] = ids
    w.seen[slots, rows] = True
    w.updated[slots, rows] = False
    np.add.at(w.counts, rows, 1)
    w.common = None


def new_landmarks(
    w: Work,
    new: NDArray[np.bool_],
    poses: FloatArray,
    z: FloatArray,
    ids: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> None:
    """Start a landmark for every ``new[k, p]`` (reading ``k``, particle ``p``): id
    ``ids[k]``, appended to each particle's map in reading order."""
    kr, pr = np.nonzero(new)
    if pr.size == 0:
        return
    rank = (np.cumsum(new, axis=0) - 1)[kr, pr]
    _start_landmarks(w, pr, rank, poses[pr], z[kr], ids[kr], R, model)


def pose_planes(poses: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(x, y, θ)`` of poses ``(P, 3)`` as contiguous ``(P,)`` rows."""
    t = poses.T.copy()
    return t[0], t[1], t[2]


def congruence(H: FloatArray, S: FloatArray) -> FloatArray:
    """``H S Hᵀ`` ``(..., 2, 2)`` for a symmetric ``S``, written out: exactly symmetric, and on
    large batches (every landmark of every particle) ~3x faster than stacked ``matmul``."""
    h00, h01, h10, h11 = H[..., 0, 0], H[..., 0, 1], H[..., 1, 0], H[..., 1, 1]
    s00, s01, s11 = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
    t00, t01 = h00 * s00 + h01 * s01, h00 * s01 + h01 * s11  # first row of H S
    t10, t11 = h10 * s00 + h11 * s01, h10 * s01 + h11 * s11  # second row
    out = np.empty(np.broadcast_shapes(H.shape, S.shape))
    out[..., 0, 0] = t00 * h00 + t01 * h01
    out[..., 0, 1] = out[..., 1, 0] = t00 * h10 + t01 * h11
    out[..., 1, 1] = t10 * h10 + t11 * h11
    return out
